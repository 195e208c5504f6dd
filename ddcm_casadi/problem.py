"""Symbolic complementarity problems built from a :class:`~ddcm_casadi.model.ContactModel`.

Two kinds arise from one model (see ``formulations.md``):

``mcp`` (classical)
    Find ``x, p`` with ``F(x, p) = 0`` and ``g(x) >= 0, p >= 0, g p = 0``.
``mpcc`` (DDCM projection onto ``Z_E``)
    ``min_x f(x)`` subject to ``h(x, p) = 0`` and ``g(x) >= 0, p >= 0, g p = 0``.

Everything is nondimensional: unknowns, residual rows, gaps, pressures and the objective are divided
by the model's reference scales, so formulations and solvers see O(1) numbers for any units. A
formulation only sees a :class:`ComplementarityProblem`; it never needs the mechanical model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import casadi as ca
import numpy as np
import scipy.sparse as sp

from .model import ContactModel


def to_casadi(A: sp.spmatrix) -> ca.DM:
    """A scipy sparse matrix as a sparse CasADi ``DM`` (same pattern, no densification)."""
    A = sp.csc_matrix(A)
    A.sort_indices()
    sparsity = ca.Sparsity(A.shape[0], A.shape[1], A.indptr.tolist(), A.indices.tolist())
    return ca.DM(sparsity, A.data.tolist())


@dataclass(frozen=True, eq=False)
class ComplementarityProblem:
    """A nondimensional complementarity problem, the contract between models and formulations.

    Attributes
    ----------
    kind : {"mcp", "mpcc"}
    x : casadi.SX
        Smooth unknowns (scaled).
    p : casadi.SX
        One multiplier per pair: the scaled contact pressures.
    params : casadi.SX
        Parameters (load step, assigned data), in physical units.
    residual : casadi.SX
        ``mcp``: ``F(x, p)``, as many rows as ``x``. ``mpcc``: equality constraints ``h(x, p)``.
    objective : casadi.SX or None
        ``mpcc`` only: the scaled squared distance.
    gap : casadi.SX
        Scaled gaps ``g(x)``.
    gap_ref, pressure_ref : float
        Physical size of one unit of scaled gap (m) and of scaled pressure (Pa).
    contact_stiffness : float
        Reference stiffness (Pa/m) in which penalty parameters are given.
    fb_alpha, fb_beta : float
        Default Fischer-Burmeister scalings (1/m and 1/Pa), as in the paper.
    """

    kind: Literal["mcp", "mpcc"]
    x: ca.SX
    p: ca.SX
    params: ca.SX
    residual: ca.SX
    objective: ca.SX | None
    gap: ca.SX
    gap_ref: float
    pressure_ref: float
    contact_stiffness: float
    fb_alpha: float
    fb_beta: float

    @property
    def n_x(self) -> int:
        return self.x.numel()

    @property
    def n_pairs(self) -> int:
        return self.p.numel()

    def scaled_penalty(self, gamma: float) -> float:
        """A physical contact stiffness (Pa/m) in the problem's scaled units."""
        return gamma * self.gap_ref / self.pressure_ref


@dataclass(frozen=True, eq=False)
class ProblemPair:
    """Both problems of one model, with the maps between scaled unknowns and physical fields."""

    model: ContactModel
    classical: ComplementarityProblem | None
    projection: ComplementarityProblem | None

    def step_params(self, step: int) -> np.ndarray:
        return np.concatenate([self.model.gap_offsets[step], self.model.loads[step]])

    def projection_params(self, step: int, strain_star: np.ndarray, stress_star: np.ndarray) -> np.ndarray:
        """Parameters of the ``Z_E`` projection; with ``(m, k)`` data arrays, a ``(n_params, k)`` matrix."""
        strain_star, stress_star = np.asarray(strain_star, float), np.asarray(stress_star, float)
        if strain_star.ndim == 2:
            k = strain_star.shape[1]
            return np.vstack([np.repeat(self.step_params(step)[:, None], k, axis=1), strain_star, stress_star])
        return np.concatenate([self.step_params(step), strain_star, stress_star])

    def fields(self, kind: str, x: np.ndarray, p: np.ndarray) -> dict[str, np.ndarray]:
        """Physical displacement, contact pressure, strain and stress from scaled unknowns."""
        s = self.model.scales
        n = self.model.n_dofs
        u = s["displacement"] * np.asarray(x[:n])
        pressure = s["stress"] * np.asarray(p)
        strain = self.model.strain(u)
        if kind == "mpcc":
            stress = s["stress"] * np.asarray(x[n:n + self.model.n_points])
        else:
            stress = self.model.youngs_modulus * strain
        return dict(u=u, p=pressure, strain=strain, stress=stress)

    def scaled_start(self, kind: str, u: np.ndarray, p: np.ndarray, stress: np.ndarray | None = None):
        """Scaled unknowns ``(x, p)`` from physical fields (for warm starts)."""
        s = self.model.scales
        x = [np.asarray(u) / s["displacement"]]
        if kind == "mpcc":
            x.append(np.asarray(stress) / s["stress"])
        return np.concatenate(x), np.asarray(p) / s["stress"]


def build_problems(model: ContactModel) -> ProblemPair:
    """Build the classical MCP and the DDCM projection MPCC of ``model`` (each symbolically, once)."""
    s = model.scales
    n, m, nc = model.n_dofs, model.n_points, model.n_contacts
    B = to_casadi(model.strain_operator)
    G = to_casadi(model.gap_operator)
    a = ca.DM(model.contact_area)
    w = ca.DM(model.volumes)

    gap0 = ca.SX.sym("gap0", nc)
    load = ca.SX.sym("f", n)
    u_hat = ca.SX.sym("u", n)
    p_hat = ca.SX.sym("p", nc)
    u = s["displacement"] * u_hat
    p = s["stress"] * p_hat
    gap = (ca.mtimes(G, u) + gap0) / s["displacement"]
    contact_force = ca.mtimes(G.T, a * p)
    common = dict(
        gap=gap,
        gap_ref=s["displacement"],
        pressure_ref=s["stress"],
        contact_stiffness=model.contact_stiffness,
        fb_alpha=1.0 / (0.01 * model.length_scale),
        fb_beta=1.0 / s["metric"],
    )

    classical = None
    if model.youngs_modulus is not None:
        K = to_casadi(model.stiffness())
        F = (ca.mtimes(K, u) - contact_force - load) / s["force"]
        classical = ComplementarityProblem(kind="mcp", x=u_hat, p=p_hat, params=ca.vertcat(gap0, load),
                                           residual=F, objective=None, **common)

    projection = None
    if model.dataset is not None:
        c = ca.DM(model.metric)
        eps_star = ca.SX.sym("strain_star", m)
        sig_star = ca.SX.sym("stress_star", m)
        sig_hat = ca.SX.sym("stress", m)
        sig = s["stress"] * sig_hat
        strain = ca.mtimes(B, u)
        d2 = c * (strain - eps_star) ** 2 + (sig - sig_star) ** 2 / c
        objective = 0.5 * ca.dot(w, d2) / s["energy"]
        h = (ca.mtimes(B.T, w * sig) - contact_force - load) / s["force"]
        projection = ComplementarityProblem(
            kind="mpcc", x=ca.vertcat(u_hat, sig_hat), p=p_hat,
            params=ca.vertcat(gap0, load, eps_star, sig_star),
            residual=h, objective=objective, **common)
    return ProblemPair(model=model, classical=classical, projection=projection)
