r"""FCLIB frictional contact problems: reading, writing, the natural-map error, and a reference
solver (``docs/maths.md``, section 15).

FCLIB (Acary et al., INRIA RT-0444, 2014) stores discrete 3-D frictional contact problems in HDF5:

- **local** (``/fclib_local``: ``W``, ``q``, ``mu``): find the local velocities ``u`` and
  reactions ``r`` (three per contact, normal component first) with

  .. math::  u = W r + q,\qquad \hat u = u + [\mu |u_T|, 0, 0],\qquad
             K^* \ni \hat u \perp r \in K,\qquad K = \{ |r_T| \le \mu r_N \};

- **global** (``/fclib_global``: ``M``, ``H``, ``f``, ``w``, ``mu``; optional ``G``, ``b``):
  ``M v = H r + f``, ``u = H^T v + w``, the same cone conditions. Without ``G`` it reduces to the
  local problem ``W = H^T M^{-1} H``, ``q = H^T M^{-1} f + w`` (:meth:`GlobalProblem.local`,
  by one sparse factorisation of ``M``).

A sparse matrix is stored as ``m, n, nz, nzmax, p, i, x`` (CSparse's layout): ``nz = -2``
compressed rows, ``nz = -1`` compressed columns, ``nz >= 0`` triplets (``i`` the rows, ``p`` the
columns, as the sample files' index ranges show).

The error of a candidate ``r`` is the natural map of the De Saxce modified velocity,

.. math::  e(r) = \sqrt{\sum_c |r_c - P_K(r_c - \hat u_c)|^2} \,/\, |q| ,

the measure of the FCLIB benchmarks (solved at ``1e-4`` and ``1e-8``) (:func:`natural_map_error`).
:func:`solve_projected_gauss_seidel` is an independent reference (projected Gauss-Seidel with
the De Saxce fixed point per contact, as Siconos' NSGS), not one of the project's formulations.

HDF5 is read with ``h5py`` (the ``fclib`` extra), imported where a file is read or written.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ddcm_casadi.errors import InputError
from ddcm_casadi.models.coulomb import modified_slip, natural_map


# --------------------------------------------------------------------------------- problems
@dataclass(frozen=True)
class LocalProblem:
    """``u = W r + q`` with Coulomb's law at ``nc`` contacts (see the module).

    Attributes
    ----------
    W : sparse (3 nc, 3 nc)
        The Delassus operator.
    q : (3 nc,)
    mu : (nc,)
        Friction coefficients.
    title : str
    """

    W: sp.csr_matrix
    q: np.ndarray
    mu: np.ndarray
    title: str = ""

    def __post_init__(self) -> None:
        W = sp.csr_matrix(self.W, dtype=float)
        q = np.asarray(self.q, float).ravel()
        mu = np.atleast_1d(np.asarray(self.mu, float)).ravel()
        if W.shape != (q.size, q.size) or q.size != 3 * mu.size:
            raise InputError(f"an FCLIB local problem needs W (3 nc x 3 nc), q (3 nc) and mu (nc); got W {W.shape}, "
                             f"q {q.size}, mu {mu.size}")
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(W.data)) and np.all(mu >= 0)):
            raise InputError("an FCLIB local problem needs finite W and q and friction coefficients >= 0")
        object.__setattr__(self, "W", W)
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "mu", mu)

    @property
    def n_contacts(self) -> int:
        return self.mu.size

    def local(self) -> "LocalProblem":
        return self


@dataclass(frozen=True)
class GlobalProblem:
    """``M v = H r + f``, ``u = H^T v + w`` with Coulomb's law (see the module).

    Attributes
    ----------
    M : sparse (n, n)
    H : sparse (n, 3 nc)
    f : (n,)
    w : (3 nc,)
    mu : (nc,)
    title : str
    """

    M: sp.csr_matrix
    H: sp.csr_matrix
    f: np.ndarray
    w: np.ndarray
    mu: np.ndarray
    title: str = ""

    @property
    def n_contacts(self) -> int:
        return np.atleast_1d(self.mu).size

    def local(self) -> LocalProblem:
        """The local problem: ``W = H^T M^{-1} H``, ``q = H^T M^{-1} f + w`` (one sparse LU of ``M``;
        ``W`` is dense in ``3 nc x 3 nc``, kept sparse in type)."""
        M = sp.csc_matrix(self.M, dtype=float)
        H = sp.csc_matrix(self.H, dtype=float)
        try:
            lu = spla.splu(M)
        except RuntimeError as err:
            raise InputError(f"the global problem's M is singular ({err}); it cannot be reduced to a local one") from None
        MiH = lu.solve(H.toarray())
        W = H.T @ MiH
        q = H.T @ lu.solve(np.asarray(self.f, float)) + np.asarray(self.w, float)
        return LocalProblem(sp.csr_matrix(W), q, self.mu, self.title)


# ------------------------------------------------------------------------------- HDF5 files
def _read_matrix(group) -> sp.csr_matrix:
    m, n, nz = (int(np.asarray(group[k]).ravel()[0]) for k in ("m", "n", "nz"))
    p, i, x = (np.asarray(group[k]).ravel() for k in ("p", "i", "x"))
    if nz == -2:
        return sp.csr_matrix((x, i, p), shape=(m, n))
    if nz == -1:
        return sp.csc_matrix((x, i, p), shape=(m, n)).tocsr()
    if nz >= 0:
        return sp.coo_matrix((x[:nz], (i[:nz], p[:nz])), shape=(m, n)).tocsr()  # CSparse triplets: i rows, p columns
    raise InputError(f"an FCLIB matrix has nz = {nz}: expected -2 (rows), -1 (columns) or >= 0 (triplets)")


def _write_matrix(group, A: sp.spmatrix) -> None:
    A = sp.csr_matrix(A)
    for key, value in dict(m=[A.shape[0]], n=[A.shape[1]], nz=[-2], nzmax=[A.nnz]).items():
        group.create_dataset(key, data=np.asarray(value, dtype=np.int32))
    group.create_dataset("p", data=A.indptr.astype(np.int32))
    group.create_dataset("i", data=A.indices.astype(np.int32))
    group.create_dataset("x", data=A.data.astype(float))


def _h5py():
    try:
        import h5py
    except ImportError:
        raise InputError("FCLIB files are HDF5: install h5py (pip install 'ddcm-casadi[fclib]')") from None
    return h5py


def read_fclib(path: str | os.PathLike) -> LocalProblem | GlobalProblem:
    """The local or global problem of an FCLIB file (``/fclib_local`` or ``/fclib_global``)."""
    h5py = _h5py()
    path = Path(path)
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise InputError(f"{path}: not a readable HDF5 file ({err})") from None
    with f:
        title = ""
        for kind in ("fclib_local", "fclib_global"):
            if kind in f:
                g = f[kind]
                if "info" in g and "title" in g["info"]:
                    raw = g["info"]["title"][()]
                    title = raw.decode(errors="replace") if isinstance(raw, bytes) else str(raw)
                spacedim = int(np.asarray(g["spacedim"]).ravel()[0]) if "spacedim" in g else 3
                if spacedim != 3:
                    raise InputError(f"{path}: a {spacedim}-D FCLIB problem; 3-D only")
                v = g["vectors"]
                if kind == "fclib_local":
                    return LocalProblem(_read_matrix(g["W"]), np.asarray(v["q"]), np.asarray(v["mu"]), title)
                if "G" in g:
                    raise InputError(f"{path}: a global problem with equality constraints (G, b) is not supported")
                return GlobalProblem(_read_matrix(g["M"]), _read_matrix(g["H"]), np.asarray(v["f"], float),
                                     np.asarray(v["w"], float), np.atleast_1d(np.asarray(v["mu"], float)), title)
        raise InputError(f"{path}: neither /fclib_local nor /fclib_global: not an FCLIB problem")


def write_fclib(path: str | os.PathLike, problem: LocalProblem | GlobalProblem) -> Path:
    """Write ``problem`` as an FCLIB file (atomically: a temporary file, then a rename)."""
    h5py = _h5py()
    path = Path(path)
    fd, tmp = tempfile.mkstemp(suffix=".hdf5", dir=path.parent)
    os.close(fd)
    try:
        with h5py.File(tmp, "w") as f:
            local = isinstance(problem, LocalProblem)
            g = f.create_group("fclib_local" if local else "fclib_global")
            g.create_dataset("spacedim", data=np.array([3], dtype=np.int32))
            g.create_group("info").create_dataset("title", data=np.bytes_(problem.title))
            v = g.create_group("vectors")
            v.create_dataset("mu", data=np.atleast_1d(np.asarray(problem.mu, float)))
            if local:
                _write_matrix(g.create_group("W"), problem.W)
                v.create_dataset("q", data=problem.q)
            else:
                _write_matrix(g.create_group("M"), problem.M)
                _write_matrix(g.create_group("H"), problem.H)
                v.create_dataset("f", data=np.asarray(problem.f, float))
                v.create_dataset("w", data=np.asarray(problem.w, float))
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


# ------------------------------------------------------------------------- cones and errors
def modified_velocity(problem: LocalProblem, r: np.ndarray) -> np.ndarray:
    """``u_hat = W r + q + [mu |u_T|, 0, 0]`` per contact, ``(nc, 3)``."""
    return modified_slip((problem.W @ np.asarray(r, float).ravel() + problem.q).reshape(-1, 3), problem.mu)


def natural_map_error(problem: LocalProblem, r: np.ndarray) -> float:
    """``sqrt(sum_c |r_c - P_K(r_c - u_hat_c)|^2) / |q|`` (``|q| = 0``: not divided)."""
    r = np.asarray(r, float).reshape(-1, 3)
    res = natural_map((problem.W @ r.ravel() + problem.q).reshape(-1, 3), r, problem.mu)
    scale = float(np.linalg.norm(problem.q))
    return float(np.linalg.norm(res)) / (scale if scale > 0 else 1.0)


@dataclass(frozen=True)
class FrictionSolution:
    """A solve of an FCLIB problem (:func:`~ddcm_casadi.drivers.fclib.solve_fclib`, :func:`solve_projected_gauss_seidel`).

    Attributes
    ----------
    r, u : ndarray (nc, 3)
        Reactions and velocities ``u = W r + q`` (a global problem's ``H^T v + w``), normal first.
    error : float
        :func:`natural_map_error` of ``r``.
    iterations : int
        Newton iterations (summed over every solve); projected Gauss-Seidel's sweeps for ``pgs``.
    seconds : float
        Wall time of the solve (reading and reducing the problem excluded).
    converged : bool
        ``error <= tol``.
    method : str
    sweeps : int
        Projected Gauss-Seidel sweeps (summed over every stage).
    log : tuple of dict
        The stages in order: ``stage``, ``iterations``, ``error`` after it, ``seconds``.
    message : str
    """

    r: np.ndarray
    u: np.ndarray
    error: float
    iterations: int
    seconds: float
    converged: bool
    method: str = "pgs"
    sweeps: int = 0
    log: tuple = ()
    message: str = ""


def _project_one(rn: float, r1: float, r2: float, mu: float) -> tuple[float, float, float]:
    """:func:`~ddcm_casadi.models.coulomb.project_cone` of one 3-vector, in scalars (the sweep's
    inner loop: numpy's per-call cost on 3-vectors is most of a sweep)."""
    t = math.hypot(r1, r2)
    if t <= mu * rn:
        return rn, r1, r2
    if mu * t <= -rn:
        return 0.0, 0.0, 0.0
    s = (rn + mu * t) / (1.0 + mu * mu)
    f = mu * s / t
    return s, f * r1, f * r2


def solve_projected_gauss_seidel(problem: LocalProblem | GlobalProblem, *, tol: float = 1e-8,
                                 max_sweeps: int = 10_000, r0: np.ndarray | None = None) -> FrictionSolution:
    """Projected Gauss-Seidel (an independent reference): sweep the contacts, each updated by the
    De Saxce fixed point ``r_c <- P_K(r_c - rho_c u_hat_c)`` with ``rho_c = 1 / max eig(W_cc)``
    and its own block of ``u`` refreshed, until :func:`natural_map_error` is below ``tol``. Not
    guaranteed to converge (Coulomb friction is not a potential); ``converged`` says."""
    t0 = time.perf_counter()
    local = problem.local()
    W = sp.csr_matrix(local.W)
    nc = local.n_contacts
    blocks = [W[3 * c:3 * c + 3, 3 * c:3 * c + 3].toarray() for c in range(nc)]
    rho = [1.0 / max(float(np.max(np.linalg.eigvalsh(0.5 * (B + B.T)))), 1e-300) for B in blocks]
    r = np.zeros(3 * nc) if r0 is None else np.asarray(r0, float).ravel().copy()
    # dense rows where W is dense (a reduced global problem): one BLAS product per contact
    dense = W.nnz > 0.25 * W.shape[0] ** 2
    rows = [W[3 * c:3 * c + 3].toarray() if dense else W[3 * c:3 * c + 3] for c in range(nc)]
    q, mu = local.q, [float(m) for m in local.mu]
    error = natural_map_error(local, r)
    sweep = 0
    while error > tol and sweep < max_sweeps:
        for c in range(nc):
            un, u1, u2 = rows[c] @ r + q[3 * c:3 * c + 3]
            un += mu[c] * math.hypot(u1, u2)
            k, rc = 3 * c, rho[c]
            r[k], r[k + 1], r[k + 2] = _project_one(r[k] - rc * un, r[k + 1] - rc * u1, r[k + 2] - rc * u2, mu[c])
        sweep += 1
        error = natural_map_error(local, r)
    return FrictionSolution(r.reshape(-1, 3), (W @ r + local.q).reshape(-1, 3), error, sweep,
                            time.perf_counter() - t0, bool(error <= tol), "pgs", sweep,
                            (dict(stage="pgs", iterations=sweep, error=error, seconds=time.perf_counter() - t0),))


# ------------------------------------------------------------------ as the project's problems
def _component_major(nc: int) -> np.ndarray:
    """Indices taking FCLIB's contact-major vectors (``3 c + j``) to component-major (``j nc + c``)."""
    return (3 * np.arange(nc)[None, :] + np.arange(3)[:, None]).ravel()


@dataclass(frozen=True, eq=False)
class FclibComplementarity:
    """An FCLIB problem as the project's frictional :class:`~ddcm_casadi.problems.contract.ComplementarityProblem`
    (``mcp``, three components per contact), built by :func:`as_complementarity_problem`.

    Attributes
    ----------
    problem : ComplementarityProblem
    source : LocalProblem or GlobalProblem
    params : ndarray
        The parameter values (``friction``, ``traction0 = 0``, the data vector ``q`` or
        ``f, w``, and with a proximal term the centre ``r_c = 0``: :meth:`centred`).
    velocity_ref, reaction_ref : float
        The physical size of one scaled unit of ``x`` (``u`` or ``v``) and of ``r``.
    proximal : float
        ``eta`` of the proximal term (0: none).
    """

    problem: object
    source: object
    params: np.ndarray
    velocity_ref: float
    reaction_ref: float
    proximal: float = 0.0

    def reactions(self, p: np.ndarray) -> np.ndarray:
        """FCLIB's contact-major reactions ``r`` from the scaled pressures ``p``."""
        r = np.empty(p.size)
        r[_component_major(p.size // 3)] = self.reaction_ref * np.asarray(p, float)
        return r

    def start(self) -> tuple[np.ndarray, np.ndarray]:
        """The cold start ``x = 0, r = 0``."""
        return np.zeros(self.problem.n_x), np.zeros(self.problem.n_pairs)

    def point(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The scaled ``(x, p)`` of the contact-major reactions ``r``: ``x`` the velocities
        ``u = W r + q`` (local) or ``v = M^-1 (H r + f)`` (global; one sparse solve with ``M``), so a warm start satisfies the linear equations and only Coulomb's law is off
        (at the centre, the proximal term vanishes)."""
        r = np.asarray(r, float).ravel()
        order = _component_major(r.size // 3)
        src = self.source
        if isinstance(src, LocalProblem):
            x = (src.W @ r + src.q)[order]
        else:
            x = spla.spsolve(sp.csc_matrix(src.M, dtype=float), sp.csr_matrix(src.H) @ r + np.asarray(src.f, float))
        return x / self.velocity_ref, r[order] / self.reaction_ref

    def centred(self, r: np.ndarray) -> np.ndarray:
        """The parameters with the proximal centre at the contact-major reactions ``r``."""
        if not self.proximal:
            raise InputError("this FCLIB complementarity problem has no proximal term (proximal = 0)")
        params = np.array(self.params)
        params[self.problem.parameters.slice("center")] = np.asarray(r, float).ravel()[_component_major(
            self.source.n_contacts)]
        return params

    def error(self, x: np.ndarray, p: np.ndarray, local: LocalProblem | None = None) -> float:
        """FCLIB's natural-map error of the reactions (:func:`natural_map_error`) in the problem
        itself (without a proximal term). A global problem's velocities are those at equilibrium
        with the reactions, ``u = H^T M^-1 (H r + f) + w = W r + q`` (its local reduction; pass
        ``local`` to reuse it), not ``H^T v + w`` of the iterate's ``v``: an iterate off
        equilibrium is not credited. ``x`` is not needed (kept for the solution's pair)."""
        return natural_map_error(self.source.local() if local is None else local, self.reactions(p).reshape(-1, 3))


def as_complementarity_problem(source: LocalProblem | GlobalProblem, *, proximal: float = 0.0) -> FclibComplementarity:
    r"""An FCLIB problem as a frictional complementarity problem that every formulation solves.

    Local: unknowns ``x = u``, residual ``x - W r - q``, "gaps" ``x`` (so ``(g_N, s_T) = u``).
    Global: unknowns ``x = v``, residual ``M v - H r - f``, "gaps" ``H^T v + w``. Vectors are
    reordered component-major. Scales: velocities by ``|q|_inf`` (local; global ``|w|_inf`` or the
    size of ``H^T M^{-1} f``), reactions so that ``W`` (or ``M``, ``H``) is O(1).

    ``proximal = eta > 0`` adds the proximal-point term ``eta (r - r_c)`` to the velocities,
    ``u = W r + q + eta (r - r_c)`` (global ``u = H^T v + w + eta (r - r_c)``), with the centre
    ``r_c`` a parameter (:meth:`FclibComplementarity.centred`): the Delassus operator becomes
    ``W + eta I``, positive definite where ``W`` is only semidefinite (more reactions than the
    bodies' freedoms), and a solution with ``r = r_c`` solves the problem itself
    (:func:`~ddcm_casadi.drivers.fclib.solve_fclib`).
    """
    from ddcm_casadi.problems.contract import ComplementarityProblem
    from ddcm_casadi.problems.maps import Affine
    from ddcm_casadi.problems.parameters import Parameters

    eta = float(proximal)
    if not (np.isfinite(eta) and eta >= 0):
        raise InputError(f"proximal must be a finite number >= 0, got {proximal!r}")
    nc = source.n_contacts
    m = 3 * nc
    order = _component_major(nc)
    mu = np.atleast_1d(np.asarray(source.mu, float))
    tiny = np.finfo(float).tiny
    center = dict(center=m) if eta else {}
    if isinstance(source, LocalProblem):
        W = source.W[order][:, order].tocsr()
        q = source.q[order]
        u_ref = max(float(np.max(np.abs(q), initial=0.0)), tiny)
        d = W.diagonal()
        r_ref = u_ref / max(float(np.mean(d[d > 0])) if np.any(d > 0) else 1.0, tiny)
        P = Parameters(friction=nc, traction0=2 * nc, q=m, **center)
        blocks = [sp.csr_matrix((m, 3 * nc)), -sp.identity(m) / u_ref] + ([eta * sp.identity(m) / u_ref] if eta else [])
        residual = Affine(sp.hstack([sp.identity(m), -(r_ref / u_ref) * (W + eta * sp.identity(m))]), sp.hstack(blocks))
        gap = Affine(sp.hstack([sp.identity(m), sp.csr_matrix((m, m))]), sp.csr_matrix((m, P.size)))
        params = P.pack(friction=mu, traction0=0.0, q=q, **{k: 0.0 for k in center})
        unknowns, x_ref, g_ref = (("u", m),), u_ref, u_ref
    else:
        M, H = sp.csr_matrix(source.M, dtype=float), sp.csr_matrix(source.H, dtype=float)[:, order].tocsr()
        f, w = np.asarray(source.f, float), np.asarray(source.w, float)[order]
        n = M.shape[0]
        f_ref = max(float(np.max(np.abs(f), initial=0.0)), tiny)
        h = max(float(abs(H).max()) if H.nnz else 1.0, tiny)
        m_ref = max(float(np.max(np.abs(M.diagonal()), initial=0.0)), tiny)
        g_ref = max(float(np.max(np.abs(w), initial=0.0)), f_ref * h / m_ref, tiny)
        x_ref, r_ref = g_ref / h, f_ref / h
        P = Parameters(friction=nc, traction0=2 * nc, f=n, w=m, **center)
        residual = Affine(sp.hstack([(x_ref / f_ref) * M, -(r_ref / f_ref) * H]),
                          sp.hstack([sp.csr_matrix((n, 3 * nc)), -sp.identity(n) / f_ref, sp.csr_matrix((n, P.size - n - 3 * nc))]))
        blocks = [sp.csr_matrix((m, 3 * nc + n)), sp.identity(m) / g_ref] + ([-eta * sp.identity(m) / g_ref] if eta else [])
        prox = (eta * r_ref / g_ref) * sp.identity(m) if eta else sp.csr_matrix((m, m))
        gap = Affine(sp.hstack([(x_ref / g_ref) * H.T, prox]), sp.hstack(blocks))
        params = P.pack(friction=mu, traction0=0.0, f=f, w=w, **{k: 0.0 for k in center})
        unknowns = (("v", n),)
    problem = ComplementarityProblem(
        kind="mcp", parameters=P, unknowns=unknowns, residual_map=residual, gap_map=gap, distance=None,
        gap_ref=g_ref, pressure_ref=r_ref, contact_stiffness=r_ref / g_ref, fb_alpha=1.0 / g_ref,
        fb_beta=1.0 / r_ref, contact_law="coulomb", kinematics="small", block=3)
    return FclibComplementarity(problem, source, params, x_ref, r_ref, eta)
