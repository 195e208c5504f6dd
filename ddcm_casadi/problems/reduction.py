r"""The Kirchdoerfer-Ortiz reduction of an affine DDCM projection (``docs/maths.md``, section 17).

The projection (:func:`~ddcm_casadi.problems.build.build_problems`, kind ``"mpcc"``) is, in the
problem's scaled unknowns ``z = [u; sigma; p]`` and parameters ``P``,

.. math::  \min\ \tfrac12 |A_u u + a|^2_{W_e} + \tfrac12 |S\sigma + s|^2_{W_s}
           \ \text{s.t.}\ R_\sigma \sigma + R_p p + r = 0,\quad 0 \le G u + g \perp p \ge 0,

``a, s, r, g`` affine in ``P``. With a constant metric (no strain-stress cross term, ``S``
invertible) its stationarity eliminates the stresses and the displacements:

- ``K_u u = b + G^T lambda``, ``K_u = A_u^T W_e A_u``, ``b = -A_u^T W_e a``;
- ``K_s eta = c + R_p p``, ``K_s = R_sigma M^-1 R_sigma^T``, ``M = S^T W_s S``,
  ``c = R_sigma sigma_0 + r``, ``sigma_0 = -S^-1 s``; then ``sigma = sigma_0 - M^-1 R_sigma^T eta``.

A Hookean metric (``C`` on the strains, ``C^-1`` on the stresses, point by point) makes both
matrices multiples of ``K_C = B^T (W (x) C) B``: ``K_s = alpha K_u``, one factorisation for the
whole load path. What is left is a problem on the contact pairs alone (the condensed problem,
:attr:`Reduction.condensed`), with the Delassus matrices ``D_u = G K_u^-1 G^T`` and
``D_p = R_p^T K_s^-1 R_p`` (``nc x nc``, assembled by ``nc`` back-solves):

.. math::  \min_{\lambda, p}\ \tfrac12 \lambda^T D_u \lambda + \tfrac12 (p + t)^T D_p (p + t)
           \ \text{s.t.}\ 0 \le D_u \lambda + g_c \perp p \ge 0,

``g_c = G K_u^-1 b + g`` the gaps at ``lambda = 0`` and ``D_p t = R_p^T K_s^-1 c``. Its objective
differs from the projection's by a constant only, and its stationary points are the
projection's (``lambda`` is the gap multiplier), so every formulation solves it unchanged. It is
posed in the gaps ``w = D_u lambda + g_c`` (objective ``1/2 (w - g_c)^T D_u^-1 (w - g_c) + ...``,
constraint ``0 <= w _|_ p >= 0``): one row per pair, so a pair switching piece is a low-rank
update of a formulation's factor. ``u``, ``eta`` and ``sigma`` follow from the solve pair
``K_u^-1 [b, c]`` and the kept columns ``K_u^-1 G^T`` of the closed pairs.
"""

from __future__ import annotations

import time
from functools import cached_property

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ddcm_casadi.linalg import (
    SingularMatrix, definite_solver_name, factorize_definite, factorize_with_delassus, numerically_symmetric,
    solved_columns,
)
from ddcm_casadi.heap import release_heap
from ddcm_casadi.models.stiffness import MAX_CLASSICAL_PAIRS, StiffnessFactor, condensation_size_refusal
from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.problems.maps import Affine, Distance
from ddcm_casadi.problems.parameters import Parameters

#: Contact pairs up to which the condensed problem is assembled (``nc`` back-solves, an ``n x nc``
#: dense block kept); above, the projection keeps the full saddle-point path.
MAX_PAIRS = 500
#: Relative size (Frobenius) of ``K_s - alpha K_u`` up to which the two share one factor.
PROPORTIONAL = 1e-12
#: The formulations' Newton tolerance (relative increment and scaled residual, their default).
NEWTON_TOL = 1e-9
#: Largest condition number of a Delassus matrix. The condensed solve's roundoff floor is about
#: ``cond(D_u) eps`` relative (backward-stable solves of the ``D_u^-1`` block), and Newton must
#: resolve ``NEWTON_TOL`` above it: ``cond <= 0.1 NEWTON_TOL / eps`` (4.5e5). Measured: the
#: 1000-panel Warren truss (cond 1.2e9) stalls its piece solves at 2.5e-7 (``cond eps`` = 2.6e-7)
#: and Newton took 219 steps where the full path takes 2; the 100-panel one (1.2e5) and the
#: continua (1e2-3e2) converge as on the full path. A body held only by its contacts (a rigid
#: mode, ``B r = 0``) shows as ``1 / eps``. Above the limit the full path is kept; a formulation
#: whose own residual tolerance is tighter gets the tighter :func:`condition_limit`.
MAX_CONDITION = 0.1 * NEWTON_TOL / np.finfo(float).eps


def condition_limit(residual_tol: float) -> float:
    """The largest Delassus condition a condensed solve to ``residual_tol`` carries with a decade
    to spare above its roundoff floor ``cond eps``: ``0.1 residual_tol / eps``, at most
    :data:`MAX_CONDITION`."""
    return min(MAX_CONDITION, 0.1 * residual_tol / np.finfo(float).eps)


#: Largest dense ``n x nc`` block kept (bytes); above, the full path is kept.
MAX_DENSE_BYTES = 2 * 1024**3


class NotReducible(ValueError):
    """The reduction does not apply to a problem (the message says why, one line)."""


def _rows(A: sp.csr_matrix, columns: slice) -> np.ndarray:
    """Whether each row of ``A`` has a nonzero in ``columns``."""
    return np.diff(sp.csr_matrix(A[:, columns]).indptr) > 0


def _frobenius(A: sp.spmatrix) -> float:
    return float(np.sqrt(abs(A).power(2).sum())) if A.nnz else 0.0


def block_inverse(M: sp.spmatrix) -> sp.csr_matrix:
    """The inverse of a block-diagonal sparse matrix (blocks: the connected components of its
    pattern, in any order), block by block."""
    M = sp.csr_matrix(M)
    count, label = connected_components(abs(M) + abs(M.T), directed=False)
    order = np.argsort(label, kind="stable")
    sizes = np.bincount(label, minlength=count)
    rows, cols, vals = [], [], []
    start = np.concatenate([[0], np.cumsum(sizes)])
    for size in np.unique(sizes):  # one batched inverse per block size
        blocks = np.flatnonzero(sizes == size)
        idx = order[start[blocks][:, None] + np.arange(size)]  # (nb, size)
        r, c = np.broadcast_arrays(idx[:, :, None], idx[:, None, :])
        inv = np.linalg.inv(np.asarray(M[r.ravel(), c.ravel()]).reshape(len(blocks), size, size))
        rows.append(np.repeat(idx, size, axis=1).ravel())
        cols.append(np.tile(idx, (1, size)).ravel())
        vals.append(inv.ravel())
    n = M.shape[0]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))


#: Entries of ``lambda`` or ``p`` below this fraction of the largest are round-off of an open pair
#: (exactly zero in exact arithmetic): their kept columns are skipped in the recovery.
ROUND_OFF = 64 * np.finfo(float).eps


def _significant(v: np.ndarray, condition: float = 1.0) -> np.ndarray:
    """The indices of the entries of ``v`` above :data:`ROUND_OFF` times its largest (times the
    ``condition`` number of the system ``v`` was solved from: its round-off)."""
    a = np.abs(v)
    return np.flatnonzero(a > ROUND_OFF * condition * np.max(a, initial=0.0))


def _columns_times(Z: np.ndarray, v: np.ndarray, on: np.ndarray) -> np.ndarray:
    """``Z[:, on] @ v[on]``: the selected columns when they are few, else one product with the
    others' entries zeroed (selecting many columns copies them: 640 MB at 1e6 unknowns)."""
    if 8 * on.size <= v.size:
        return Z[:, on] @ v[on]
    kept = np.zeros_like(v)
    kept[on] = v[on]
    return Z @ kept


def _times_kept(A: sp.spmatrix, Z: np.ndarray) -> np.ndarray:
    """``A @ Z`` for a sparse ``A`` whose columns are mostly empty (the contact rows ``G``,
    ``R_p^T``) and kept columns ``Z`` (column-major): from the rows of ``Z`` that ``A`` uses only
    (scipy's product would copy all of ``Z`` to row-major first: 640 MB and 7 s at 1e6 unknowns)."""
    A = sp.csr_matrix(A)  # row by row, in the order of the full product: the same sums
    used = np.unique(A.indices)
    return np.asarray(A[:, used] @ np.ascontiguousarray(Z[used]))


def column_ratio(G: sp.spmatrix, R: sp.spmatrix) -> np.ndarray | None:
    """``r`` with ``R = G^T diag(r)`` (to :data:`PROPORTIONAL`), or ``None``: the contact forces
    ``G^T (a p)`` are the gap rows' transposes scaled pair by pair."""
    Gt, R = sp.csc_matrix(G).T.tocsc(), sp.csc_matrix(R)
    r = np.asarray(Gt.multiply(R).sum(axis=0)).ravel() / np.maximum(
        np.asarray(Gt.multiply(Gt).sum(axis=0)).ravel(), 1e-300)
    if _frobenius(R - Gt @ sp.diags(r)) <= PROPORTIONAL * max(_frobenius(R), 1e-300):
        return r
    return None


def delassus_condition(D: np.ndarray) -> float:
    """The condition number of a Delassus matrix ``D`` (symmetric), or :class:`NotReducible`
    above :data:`MAX_CONDITION` (the condensed solve's round-off would exceed Newton's tolerance)."""
    eig = np.linalg.eigvalsh(D)
    if not eig[0] > eig[-1] / MAX_CONDITION:
        raise NotReducible(
            f"a Delassus matrix's condition {eig[-1] / max(eig[0], 1e-300):.1e} is above"
            f" {MAX_CONDITION:.1e}: the condensed solve's roundoff would exceed Newton's tolerance"
            " (a slender structure, a body held only by its contacts, or dependent contact rows)")
    return float(eig[-1] / eig[0])


def refusal(problem: ComplementarityProblem, *, max_pairs: int | None = None) -> str:
    """Why the reduction does not apply to ``problem`` (one line), or ``""``: it needs an affine
    projection whose objective separates strains (of ``u``) from stresses (of ``sigma``), whose
    equilibrium does not involve ``u``, whose gaps involve ``u`` only, and at most ``max_pairs``
    contact pairs (default :data:`MAX_PAIRS`)."""
    max_pairs = MAX_PAIRS if max_pairs is None else max_pairs
    if problem.kind != "mpcc":
        return "not a DDCM projection"
    if not problem.affine or problem.distance is None:
        return "the projection is not affine with a quadratic distance"
    if problem.frictional:  # the condensed problem would need the law's blocks and parameters
        return "Coulomb friction (the condensed problem carries Signorini pairs only, for now)"
    if [name for name, _ in problem.unknowns] != ["u", "stress"]:
        return "the projection's unknowns are not (u, stress)"
    if problem.n_pairs > max_pairs:
        return f"{problem.n_pairs} contact pairs (the condensed problem is assembled up to {max_pairs})"
    n, mk = (size for _, size in problem.unknowns)
    if 8 * n * problem.n_pairs > MAX_DENSE_BYTES:
        return (f"the kept columns K_C^-1 G^T would take {8 * n * problem.n_pairs / 1024**3:.1f} GB "
                f"(at most {MAX_DENSE_BYTES / 1024**3:.0f})")
    h, g, d = problem.residual_map.z, problem.gap_map.z, problem.distance.d.z
    if _rows(h, slice(0, n)).any():
        return "the equilibrium involves the displacements"
    if problem.n_pairs and _rows(g, slice(n, None)).any():
        return "the gaps involve more than the displacements"
    on_u, on_s, on_p = (_rows(d, s) for s in (slice(0, n), slice(n, n + mk), slice(n + mk, None)))
    if on_p.any() or (on_u & on_s).any() or on_s.sum() != mk:
        return "the distance does not separate strains and stresses"
    W = sp.csr_matrix(problem.distance.weight)
    if W[np.flatnonzero(~on_s)][:, np.flatnonzero(on_s)].count_nonzero():
        return "the metric couples strains and stresses"
    return ""


def _displacement_stiffness(problem: ComplementarityProblem, n: int, mk: int) -> sp.csc_matrix:
    """``K_u = A_u^T W_e A_u`` from the distance's strain rows (those without stress entries;
    constant where no free dof moves a point)."""
    d, W = problem.distance.d, sp.csr_matrix(problem.distance.weight)
    e_rows = np.flatnonzero(~_rows(d.z, slice(n, n + mk)))
    A_u = d.z[e_rows][:, :n].tocsc()
    return (A_u.T @ W[e_rows][:, e_rows] @ A_u).tocsc()


def _operators(problem: ComplementarityProblem, n: int, mk: int) -> tuple:
    r"""The sparse operators of the reduction of ``problem`` (module docstring): ``(K_u, K_s,
    sigma0_P, M^-1 R_sigma^T, R_p, G, g_P)``, ``sigma_0 = sigma0_P P`` and ``g = g_P P``. In a
    function of its own so that the slices of the projection's maps it takes (``A_u``, ``W_e``,
    ``S``, ``W_s``, ``A_u^T W_e``, ``M^-1``, ``R_sigma``: about 0.15 GB at 1e5 points) are freed
    before ``K_u`` is factorised, not held through the factorisation."""
    R, Gm, dist = problem.residual_map, problem.gap_map, problem.distance
    d, W = dist.d, sp.csr_matrix(dist.weight)
    K_u = _displacement_stiffness(problem, n, mk)
    s_rows = np.flatnonzero(_rows(d.z, slice(n, n + mk)))
    S_inv = block_inverse(d.z[s_rows][:, n:n + mk])
    sigma0 = (-(S_inv @ d.params[s_rows])).tocsr()  # sigma_0 = -S^-1 s, s = s_P P
    M_inv = (S_inv @ block_inverse(W[s_rows][:, s_rows]) @ S_inv.T).tocsr()  # (S^T W_s S)^-1
    del S_inv, W
    R_s = R.z[:, n:n + mk].tocsr()
    MRt = (M_inv @ R_s.T).tocsr()
    del M_inv
    K_s = (R_s @ MRt).tocsc()
    return K_u, K_s, sigma0, MRt, R.z[:, n + mk:].tocsc(), Gm.z[:, :n].tocsr(), Gm.params.tocsr()


class Reduction:
    r"""The reduction of one affine projection (module docstring), built once per model.

    Parameters
    ----------
    problem : ComplementarityProblem
        The projection (kind ``"mpcc"``, :func:`refusal` empty; else, or with a singular
        Delassus matrix, :class:`NotReducible`).
    near_null : ndarray, optional
        The near-null space of ``K_u`` (a body's rigid-body modes in the free dofs), for an
        algebraic multigrid solver (:func:`~ddcm_casadi.linalg.use_definite_solver`); a direct
        solver ignores it.
    known : StiffnessFactor, optional
        The model's kept factor of its reference scales' stiffness
        (:meth:`~ddcm_casadi.models.base.ContactModel.stiffness_factor`): ``K_u``'s where
        ``K_u`` is a multiple of that stiffness
        (:meth:`~ddcm_casadi.models.stiffness.StiffnessFactor.scaled`), else let go before ``K_u``
        is factorised.

    Attributes
    ----------
    alpha : float or None
        ``K_s = alpha K_u`` when the metric is Hookean (one factor), else ``None`` (two).
    factorizations : int
        Sparse factorisations made (1 with a Hookean metric).
    factor : Factor
        The kept factor of ``K_u`` (:func:`~ddcm_casadi.linalg.factorize_definite`: a direct
        factor, or an AMG hierarchy whose solves are CG iterations to
        :data:`~ddcm_casadi.linalg.DEFINITE_TOL`).
    solver : str
        Which (:func:`~ddcm_casadi.linalg.definite_solver_name` when built).
    back_solves : int
        Solves with the kept factor made for the Delassus matrices (``nc`` or ``2 nc``).
    factor_seconds, back_solve_seconds : float
        Wall time of the factorisation (or AMG set-up; the reference scales' where shared, with
        the check that recognises ``K_u``) and of the back-solves.
    shared : bool
        Whether the factor of ``K_u`` is the reference scales' (``K_u`` a multiple of their stiffness).
    K_u : scipy.sparse.csc_matrix
        ``A_u^T W_e A_u`` (a multiple of ``K_C``; assembled on use, not held).
    Z_u : ndarray
        ``K_u^-1 G^T`` (``n x nc``, column-major), the kept columns.
    D_u, D_p : ndarray
        The Delassus matrices ``G K_u^-1 G^T`` and ``R_p^T K_s^-1 R_p`` (``nc x nc``).
    condition : float
        The larger of their condition numbers (at most :data:`MAX_CONDITION`; 1 without pairs).
    """

    def __init__(self, problem: ComplementarityProblem, near_null: np.ndarray | None = None,
                 known: StiffnessFactor | None = None) -> None:
        why = refusal(problem, max_pairs=np.iinfo(np.int64).max)
        if why:
            raise NotReducible(why)
        self.problem = problem
        n, mk = (size for _, size in problem.unknowns)
        nc = problem.n_pairs
        self.n, self.mk, self.nc = n, mk, nc
        K_u, K_s, self._sigma0, self._MRt, self.R_p, self.G, self._g = _operators(problem, n, mk)
        self.factorizations, self.back_solves = 1, 0
        self.solver = definite_solver_name()
        # K_s against K_u before any factorisation: the check's copies are not held beside a factor
        scale = float((K_s.multiply(K_u)).sum()) / max(float(K_u.multiply(K_u).sum()), 1e-300)
        self.alpha = scale if _frobenius(K_s - scale * K_u) <= PROPORTIONAL * _frobenius(K_s) else None
        if self.alpha is not None:
            del K_s  # a copy of K_u's size, not needed with one factor
        start = time.perf_counter()
        scaled = None if known is None else known.adopted(K_u, self.G)
        if scaled is not None:
            known.hand_over()  # the classical stiffness it kept: not this problem's to hold
            start -= known.seconds  # its factorisation's time counted as this one's
        self.shared = scaled is not None
        release_heap()  # the temporaries of the operators and of the check, before the factor's pages
        self._factor_s = None
        try:
            self.factor = scaled[0] if scaled is not None else factorize_definite(K_u, near_null=near_null)
        except SingularMatrix:
            raise NotReducible("K_C is singular (a body held only by its contacts)") from None
        del K_u  # the factor holds what it needs (K_u on demand: :attr:`K_u`)
        if self.alpha is None:
            try:
                self._factor_s = factorize_definite(K_s, near_null=near_null)
            except SingularMatrix:
                raise NotReducible("the stress block K_s is singular") from None
            self.factorizations = 2
        self.factor_seconds = time.perf_counter() - start
        start = time.perf_counter()
        if nc:
            # nc back-solves: the columns K_u^-1 G^T and K_s^-1 R_p (shared when R_p is a
            # multiple of G^T column by column, as the contact forces G^T (a p) are)
            self.Z_u = self._back_solves(self.factor.solve, self.G.T)
            ratio = column_ratio(self.G, self.R_p)
            if ratio is not None and self.alpha is not None:  # K_s^-1 R_p = Z_u diag(r) / alpha
                self._p_scale, self.Z_p = ratio / self.alpha, None
                self.D_p = _times_kept(self.R_p.T, self.Z_u) * self._p_scale
            else:
                self._p_scale = None
                self.Z_p = self._back_solves(self._solve_s, self.R_p)
                self.D_p = _times_kept(self.R_p.T, self.Z_p)
            self.D_u = _times_kept(self.G, self.Z_u)
            self.D_u, self.D_p = 0.5 * (self.D_u + self.D_u.T), 0.5 * (self.D_p + self.D_p.T)
            self._condition_u = delassus_condition(self.D_u)
            self.condition = max(self._condition_u, delassus_condition(self.D_p))
            self._D_p, self._D_u = sla.cho_factor(self.D_p), sla.cho_factor(self.D_u)
        else:
            self.Z_u = self.Z_p = np.zeros((n, 0))
            self._p_scale = None
            self.D_u = self.D_p = np.zeros((0, 0))
            self.condition = 1.0
        self.back_solve_seconds = time.perf_counter() - start
        self.description = (f"reduced (Kirchdoerfer-Ortiz: {self.factorizations} factorisation(s) of K_C, "
                            f"{nc} condensed contact pairs)")
        release_heap()  # the factorisation's working memory

    def _back_solves(self, solve, columns: sp.spmatrix) -> np.ndarray:
        """``solve`` applied to the columns of ``columns``, :data:`~ddcm_casadi.linalg.SOLVE_BLOCK` at a time, into one
        column-major ``n x nc`` array (the recovery takes whole columns)."""
        self.back_solves += columns.shape[1]
        out = np.empty((self.n, columns.shape[1]), order="F")
        for cols, X in solved_columns(solve, columns):
            out[:, cols] = X
        return out

    def _solve_s(self, rhs: np.ndarray) -> np.ndarray:
        """``K_s^-1 rhs``."""
        if self._factor_s is None:
            return self.factor.solve(rhs) / self.alpha
        return self._factor_s.solve(rhs)

    # ------------------------------------------------------------------ the condensed problem
    @cached_property
    def condensed(self) -> ComplementarityProblem:
        """The condensed problem (module docstring), in the gaps ``w = D_u lambda + g_c``: unknowns
        ``w`` and the pressures ``p``, gaps ``w`` (one entry per pair, so that a pair switching
        piece changes few rows of a formulation's system, and its factor is updated, not
        remade), objective ``1/2 (w - g_c)^T D_u^-1 (w - g_c) + 1/2 (p + t)^T D_p (p + t)``;
        parameters ``gap_offset = g_c`` and ``pressure_offset = t``; no equality constraint.
        Scales, contact law and Fischer-Burmeister scalings are the projection's."""
        nc, full = self.nc, self.problem
        P = Parameters(gap_offset=nc, pressure_offset=nc)
        I, Z = sp.identity(nc, format="csr"), sp.csr_matrix((nc, nc))
        gap = Affine(sp.hstack([I, Z]), sp.csr_matrix((nc, P.size)))
        d = Affine(sp.bmat([[I, None], [None, I]], format="csr"), sp.bmat([[-I, None], [None, I]], format="csr"))
        D_u_inv = sla.cho_solve(self._D_u, np.eye(nc)) if nc else np.zeros((0, 0))
        weight = sp.bmat([[sp.csr_matrix(0.5 * (D_u_inv + D_u_inv.T)), None], [None, sp.csr_matrix(self.D_p)]])
        return ComplementarityProblem(
            kind="mpcc", parameters=P, unknowns=(("gap", nc),),
            residual_map=Affine(sp.csr_matrix((0, 2 * nc)), sp.csr_matrix((0, P.size))), gap_map=gap,
            distance=Distance(d, sp.csr_matrix(weight)), gap_ref=full.gap_ref, pressure_ref=full.pressure_ref,
            contact_stiffness=full.contact_stiffness, fb_alpha=full.fb_alpha, fb_beta=full.fb_beta,
            contact_law=full.contact_law, kinematics=full.kinematics)

    def particular(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(u_0, eta_0) = (K_u^-1 b, K_s^-1 c)`` at the projection's parameter values: the
        projection without contact forces, by one solve with two right-hand sides (two solves
        without a shared factor)."""
        params = np.asarray(params, float)
        b, c = self._right_hand_sides(params)
        if self._factor_s is None:
            both = np.asarray(self.factor.solve(np.column_stack([b, c])), float).reshape(self.n, 2)
            return both[:, 0], both[:, 1] / self.alpha
        return self.factor.solve(b), self._factor_s.solve(c)

    def _right_hand_sides(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(b, c)`` at the parameter values, from the projection's own maps (no matrix of
        their own: ``b_P`` and ``c_P`` took 25 MB at 1e5 points): ``b = -A_u^T W_e a`` is the
        displacement block of ``-Z^T W (Q P)`` (the distance ``d = Z z + Q P``, whose stress rows
        have no displacement entries and whose metric does not couple strains and stresses,
        :func:`refusal`), and ``c = R_sigma sigma_0 + r`` the equilibrium residual at ``sigma_0``
        with no displacements and no pressures."""
        d, R = self.problem.distance.d, self.problem.residual_map
        b = -(d.z.T @ (self.problem.distance.weight @ (d.params @ params)))[:self.n]
        z = np.zeros(R.z.shape[1])
        z[self.n:self.n + self.mk] = self._sigma0 @ params
        return b, R.value(z, params)

    @property
    def K_u(self) -> sp.csc_matrix:
        """``A_u^T W_e A_u`` (a multiple of ``K_C``), assembled again on each use: not held
        beside its factor (14 MB at 1e5 points)."""
        return _displacement_stiffness(self.problem, self.n, self.mk)

    def condensed_params(self, params: np.ndarray, u0: np.ndarray, eta0: np.ndarray) -> np.ndarray:
        """The condensed problem's parameter vector: ``g_c = G u_0 + g`` and
        ``t = D_p^-1 R_p^T eta_0`` (sparse products and an ``nc x nc`` solve)."""
        if not self.nc:
            return np.zeros(0)
        gap_offset = self.G @ u0 + self._g @ np.asarray(params, float)
        t = sla.cho_solve(self._D_p, self.R_p.T @ eta0)
        return self.condensed.parameters.pack(gap_offset=gap_offset, pressure_offset=t)

    def condensed_start(self, params: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The condensed start of a projection start ``x``: its gaps ``G u + g`` (a formulation
        sees the same pairs at the start, and picks the same pieces, as on the full problem)."""
        if not self.nc:
            return np.zeros(0)
        return self.G @ np.asarray(x, float)[:self.n] + self._g @ np.asarray(params, float)

    def recover(self, params: np.ndarray, u0: np.ndarray, eta0: np.ndarray, w: np.ndarray,
                p: np.ndarray) -> np.ndarray:
        """The projection's ``x = [u; sigma]`` from the condensed ``(w, p)``: the gap multipliers
        ``lambda = D_u^-1 (w - g_c)``, ``u = u_0 + K_u^-1 G^T lambda`` and
        ``eta = eta_0 + K_s^-1 R_p p`` from the kept columns (only those of the nonzero ``lambda``
        and ``p``: the closed pairs), then ``sigma = sigma_0 - M^-1 R_sigma^T eta``."""
        u, eta = u0, eta0
        if self.nc:
            lam = sla.cho_solve(self._D_u, w - self.G @ u0 - self._g @ np.asarray(params, float))
            u = u0 + _columns_times(self.Z_u, lam, _significant(lam, self._condition_u))
            on = _significant(p)
            if self._p_scale is not None:
                eta = eta0 + _columns_times(self.Z_u, self._p_scale * p, on)
            else:
                eta = eta0 + _columns_times(self.Z_p, p, on)
        return np.concatenate([u, self._sigma0 @ np.asarray(params, float) - self._MRt @ eta])


# ---------------------------------------------------------------------- the classical problem
def classical_refusal(problem: ComplementarityProblem, *, max_pairs: int | None = None) -> str:
    """Why the Delassus condensation (:class:`ClassicalReduction`) does not apply to the classical
    ``problem`` (one line), or ``""``: it needs an affine problem ``K u + R_p p + f = 0`` in the
    displacements ``u`` alone with a symmetric ``K``, gaps in ``u`` alone, contact forces
    ``-R_p p = G^T diag(r) p`` (Signorini pairs, no friction), and sizes it is made for
    (:func:`~ddcm_casadi.models.stiffness.condensation_size_refusal`: 1 to ``max_pairs`` pairs,
    default :data:`MAX_CLASSICAL_PAIRS`, and a Schur complement (MUMPS's or PARDISO's) above
    :data:`~ddcm_casadi.linalg.SCHUR_MIN_SIZE` unknowns)."""
    if problem.kind != "mcp":
        return "not a classical problem"
    if not problem.affine:
        return "the classical problem is not affine (finite kinematics)"
    if problem.frictional:
        return "Coulomb friction (the condensed problem carries Signorini pairs only, for now)"
    if [name for name, _ in problem.unknowns] != ["u"]:
        return "the classical problem's unknowns are not the displacements alone"
    n = problem.n_x
    why = condensation_size_refusal(n, problem.n_pairs, max_pairs)
    if why:
        return why
    # once per problem (asked by build_classical, then by ClassicalReduction: 0.45 s at 3e5 unknowns)
    return problem.shared("classical_structure", lambda: _classical_structure(problem, n))


def _classical_structure(problem: ComplementarityProblem, n: int) -> str:
    """The structural part of :func:`classical_refusal`: gaps in ``u`` alone, a symmetric ``K``,
    contact forces the gap rows' transposes scaled pair by pair."""
    F, g = problem.residual_map.z, problem.gap_map.z
    if _rows(g, slice(n, None)).any():
        return "the gaps involve more than the displacements"
    if not numerically_symmetric(F[:, :n]):
        return "the stiffness is not symmetric"
    if column_ratio(g[:, :n], -F[:, n:]) is None:
        return "the contact forces are not the gap rows' transposes scaled pair by pair"
    return ""


class ClassicalReduction:
    r"""The Delassus condensation of an affine classical problem (``docs/maths.md``, section 17),
    built once per model: the stationarity ``K u - G^T diag(r) p + f_P P = 0`` of
    ``min 1/2 u^T K u + u^T f_P P`` subject to ``G u + g >= 0`` (multipliers ``diag(r) p``) gives
    ``u = u_0 + K^-1 G^T diag(r) p`` with ``u_0 = -K^-1 f_P P``, and the gaps

    .. math::  w = G u + g_P P = g_c + D_u \operatorname{diag}(r)\, p, \qquad
               g_c = G u_0 + g_P P,\quad D_u = G K^{-1} G^T,

    a linear complementarity problem ``0 <= w _|_ p >= 0`` on the pairs alone
    (:attr:`condensed`, a classical problem in the unknowns ``w``, so every formulation solves it
    unchanged). ``u`` follows by one solve with the kept factor of ``K``
    (:meth:`recover`). ``K`` is factorised once and ``D_u`` assembled with it
    (:func:`~ddcm_casadi.linalg.factorize_with_delassus`: MUMPS's or PARDISO's Schur complement, or ``nc``
    back-solves); nothing of size ``n x nc`` is kept.

    Parameters
    ----------
    problem : ComplementarityProblem
        The classical problem (:func:`classical_refusal` empty for any number of pairs; else, or
        with a singular ``K`` or an ill-conditioned ``D_u``, :class:`NotReducible`).
    near_null : ndarray, optional
        The near-null space of ``K``, for an algebraic multigrid solver.
    known : StiffnessFactor, optional
        The model's factor of its reference scales' stiffness with its Delassus matrix
        (:meth:`~ddcm_casadi.models.base.ContactModel.stiffness_factor`): where ``K`` is a
        multiple ``c`` of that stiffness (the nondimensional problem's, ``c = s_d / s_f``) and the
        gap rows are its rows, ``K^-1`` and ``D_u`` are its own over ``c``
        (:meth:`~ddcm_casadi.models.stiffness.StiffnessFactor.scaled`): no factorisation here;
        else it is let go (:meth:`~ddcm_casadi.models.stiffness.StiffnessFactor.release`) first.

    Attributes
    ----------
    factor : Factor
        The kept factor of ``K``.
    D_u : ndarray
        ``G K^-1 G^T`` (``nc x nc``).
    condition : float
        The condition number of ``D_u`` (at most :data:`MAX_CONDITION`).
    ratio : ndarray
        ``r``: the contact forces ``-R_p p = G^T diag(r) p``.
    factorizations, solver, factor_seconds, description
        One factorisation (of ``K``), the definite solver's name, its wall time (with ``D_u``; the
        reference scales' where shared), and the one-line description of the path.
    shared : bool
        Whether the factor of ``K`` is the reference scales'
        (:class:`~ddcm_casadi.models.stiffness.StiffnessFactor`).
    """

    def __init__(self, problem: ComplementarityProblem, near_null: np.ndarray | None = None,
                 known: StiffnessFactor | None = None) -> None:
        why = classical_refusal(problem, max_pairs=np.iinfo(np.int64).max)
        if why:
            raise NotReducible(why)
        self.problem = problem
        self.n = n = problem.n_x
        self.nc = problem.n_pairs
        F, gap = problem.residual_map, problem.gap_map
        K = F.z[:, :n]  # not kept: a copy of the problem's (0.27 GB at 1e6 dofs), in its format
        self._R_p = F.z[:, n:].tocsr()
        self._f = F.params.tocsr()  # F = K u + R_p p + f_P P
        self.G = gap.z[:, :n].tocsr()
        self._g = gap.params.tocsr()
        self.ratio = column_ratio(self.G, -self._R_p)
        self.factorizations, self.solver = 1, definite_solver_name()
        start = time.perf_counter()
        scaled = None if known is None else known.adopted(K, self.G)
        self.shared = scaled is not None
        if self.shared:  # its factorisation's time counted as this one's
            (self.factor, self.D_u), start = scaled, start - known.seconds
        else:
            release_heap()
            try:
                self.factor, self.D_u = factorize_with_delassus(K, self.G, near_null=near_null)
            except SingularMatrix:
                raise NotReducible("the stiffness is singular (a body held only by its contacts)") from None
        self.factor_seconds = time.perf_counter() - start
        self.condition = delassus_condition(self.D_u)
        whose = ", K's factor the reference scales'" if self.shared else ""
        self.description = (f"condensed (Delassus: 1 factorisation of K, {self.nc} contact pairs, "
                            f"D_u condition {self.condition:.1e}{whose})")

    @cached_property
    def condensed(self) -> ComplementarityProblem:
        """The condensed problem: unknowns the gaps ``w``, residual ``w - D_u diag(r) p - g_c``
        (parameter ``gap_offset = g_c``), gaps ``w``. Scales, contact law and Fischer-Burmeister
        scalings are the classical problem's."""
        nc, full = self.nc, self.problem
        P = Parameters(gap_offset=nc)
        I = sp.identity(nc, format="csr")
        residual = Affine(sp.hstack([I, sp.csr_matrix(-self.D_u * self.ratio[None, :])]).tocsr(), -I)
        gap = Affine(sp.hstack([I, sp.csr_matrix((nc, nc))]).tocsr(), sp.csr_matrix((nc, P.size)))
        return ComplementarityProblem(
            kind="mcp", parameters=P, unknowns=(("gap", nc),), residual_map=residual, gap_map=gap, distance=None,
            gap_ref=full.gap_ref, pressure_ref=full.pressure_ref, contact_stiffness=full.contact_stiffness,
            fb_alpha=full.fb_alpha, fb_beta=full.fb_beta, contact_law=full.contact_law,
            kinematics=full.kinematics)

    def _solve(self, rhs: np.ndarray) -> np.ndarray:
        """``K^-1 rhs``; zero without a solve for a zero right-hand side (no load on the free dofs)."""
        if not np.any(rhs):
            return np.zeros(self.n)
        return np.asarray(self.factor.solve(rhs), float).reshape(self.n)

    def particular(self, params: np.ndarray) -> tuple[np.ndarray]:
        """``(u_0,)``: the displacements without contact forces, ``-K^-1 f_P P``."""
        return (self._solve(-(self._f @ np.asarray(params, float))),)

    def condensed_params(self, params: np.ndarray, u0: np.ndarray) -> np.ndarray:
        """The condensed problem's parameters: ``g_c = G u_0 + g_P P``."""
        return self.condensed_start(params, u0)

    def condensed_start(self, params: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The gaps ``G u + g_P P`` of a classical start ``x`` (the condensed start)."""
        return self.G @ np.asarray(x, float)[:self.n] + self._g @ np.asarray(params, float)

    def recover(self, params: np.ndarray, u0: np.ndarray, w: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``u`` from the pressures: ``K u = -(R_p p + f_P P)``, one solve (``u_0`` without contact
        forces). ``w`` is not used: ``u`` satisfies the equilibrium to the factor's backward
        error, and its gaps ``G u + g_P P`` are ``w`` to the condensed residual."""
        p = np.asarray(p, float)
        if not np.any(p):
            return np.asarray(u0, float)
        return self._solve(-(self._R_p @ p + self._f @ np.asarray(params, float)))
