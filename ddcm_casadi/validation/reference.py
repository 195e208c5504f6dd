r"""Independent reference: the classical contact problem as a convex QP, solved by ``casadi.conic``.

For a linear elastic structure the classical contact problem is the minimum of the potential
energy over the admissible set,

.. math::  \min_u \tfrac12 u^T K u - f^T u \quad \text{s.t.}\quad G u + g_0 \ge 0 ,

whose KKT conditions are the model's equilibrium with contact forces ``G^T lambda`` and
``lambda = a p``. The penalty formulation is a QP too, with slacks ``s`` (the penetrations):

.. math::  \min_{u, s} \tfrac12 u^T K u - f^T u + \tfrac{\gamma}{2} \sum_i a_i s_i^2
           \quad\text{s.t.}\quad G u + g_0 + s \ge 0 ,

so the penalty is checked against its own exact solution. Nothing here shares code with the
formulations (no complementarity function, no Newton): the QP solver (qpOASES by default, an
active-set method, in its sparse mode) is the independent check. The problem is nondimensionalised with the
model's scales, built once, and solved for every load step by passing new vectors.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ddcm_casadi.errors import InputError
from ddcm_casadi.models.base import ContactModel
from ddcm_casadi.linalg import to_casadi

@contextlib.contextmanager
def _quiet_stdout():
    """Silence C-level stdout (qpOASES prints a licence banner, OSQP a polishing note)."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # captured or replaced stdout: nothing to silence
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), fd)
            yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


@dataclass
class QPSolution:
    """Per-step reference: ``u`` (n_steps, n), ``p`` (n_steps, nc), and the solver's status."""

    u: np.ndarray
    p: np.ndarray
    success: np.ndarray
    status: list[str]
    seconds: float


class ContactQP:
    """The classical (or penalty) problem of a model as one ``casadi.conic`` (built once).

    Parameters
    ----------
    model : ContactModel
        Needs a Young's modulus.
    solver : {"qpoases", "highs", "osqp"}
        Any QP plugin of CasADi; options are passed through with ``solver_options``. qpOASES
        (active set, default) reaches machine precision; HiGHS and OSQP stop at their
        feasibility tolerances (about 1e-7 and 1e-12 relative here).
    penalty : float, optional
        ``gamma`` (Pa/m): solve the penalty problem instead of the exact one.
    """

    def __init__(self, model: ContactModel, *, solver: str = "qpoases", penalty: float | None = None,
                 solver_options: dict | None = None) -> None:
        if model.youngs_modulus is None:
            raise InputError("the QP reference needs a Young's modulus")
        if model.prescribed is not None:
            raise InputError("the QP reference takes no prescribed displacements (see "
                             "ddcm_casadi.validation.hard_device_rungs.stiffness_method)")
        if not ca.has_conic(solver):
            raise InputError(f"QP solver {solver!r} is not available in this CasADi build")
        self.model = model
        s = model.scales
        U, F = s["displacement"], s["force"]
        self._U = U
        n, nc = model.n_dofs, model.n_contacts
        K = model.stiffness() * (U / F)
        G = model.gap_operator
        self.penalty = penalty
        if penalty is None:
            H = K
            A = G
            self._n_slack = 0
        else:
            # Slack s_i (scaled by U); its energy gamma a s^2 / 2 scaled like K.
            w = penalty * model.contact_area * U / F
            H = sp.block_diag([K, sp.diags(w)])
            A = sp.hstack([G, sp.identity(nc)])
            self._n_slack = nc
        self._H = to_casadi(sp.csc_matrix(H))
        self._A = to_casadi(sp.csc_matrix(A)) if nc else ca.DM(0, n + self._n_slack)
        opts = dict(solver_options or {})
        opts.setdefault("error_on_fail", False)
        if solver == "highs":
            opts.setdefault("highs", {"output_flag": False, "primal_feasibility_tolerance": 1e-10,
                                      "dual_feasibility_tolerance": 1e-10})
        elif solver == "qpoases":
            opts.setdefault("printLevel", "none")
            opts.setdefault("sparse", True)
        elif solver == "osqp":
            opts.setdefault("osqp", {"verbose": False, "eps_abs": 1e-12, "eps_rel": 1e-12, "polish": True,
                                     "max_iter": 100000})
        self.solver_name = solver
        with _quiet_stdout():
            self._qp = ca.conic("contact_qp", solver, {"h": self._H.sparsity(), "a": self._A.sparsity()}, opts)

    def solve(self) -> QPSolution:
        """Solve every load step (each step is one call with new ``g`` and bounds)."""
        m = self.model
        n, nc = m.n_dofs, m.n_contacts
        U, F = self._U, m.scales["force"]
        us, ps, ok, status = [], [], [], []
        t0 = time.perf_counter()
        for k in range(m.n_steps):
            g = np.concatenate([-m.loads[k] / F, np.zeros(self._n_slack)])
            lba = -m.gap_offsets[k] / U
            with _quiet_stdout():
                sol = self._qp(h=self._H, g=g, a=self._A, lba=lba, uba=np.full(nc, np.inf),
                               lbx=np.concatenate([np.full(n, -np.inf), np.zeros(self._n_slack)]),
                               ubx=np.full(n + self._n_slack, np.inf))
            stats = self._qp.stats()
            ok.append(bool(stats.get("success", False)))
            status.append(str(stats.get("return_status", "")))
            x = np.asarray(sol["x"], float).ravel()
            lam = -np.asarray(sol["lam_a"], float).ravel()  # CasADi: negative at an active lower bound
            us.append(x[:n] * U)
            # Equilibrium K u - f = G^T lambda (scaled by F) and G^T (a p): p = lambda F / a.
            ps.append(lam * F / m.contact_area if nc else np.zeros(0))
        return QPSolution(u=np.array(us), p=np.array(ps), success=np.array(ok), status=status,
                          seconds=time.perf_counter() - t0)
