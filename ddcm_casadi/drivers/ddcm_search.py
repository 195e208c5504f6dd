r"""Initial data assignments of the DDCM driver and the exact global optimum by enumeration.

Starts (:class:`~ddcm_casadi.drivers.ddcm_options.DDCMOptions` ``start``):

- ``origin``: every point at the datum nearest the zero state;
- ``elastic``: every point at the datum nearest the state of the *linear* contact problem whose
  material law is the metric, ``sigma_i = C_i eps_i``:

  .. math::  \min_u \tfrac12 u^T K_C u - f^T u \quad\text{s.t.}\quad G u + g_0 \ge 0,
             \qquad K_C = B^T (W \otimes C) B .

  It is solved through its dual, a bound-constrained least-squares problem in the contact forces
  ``lambda = a p``: with ``S = G K_C^{-1} G^T`` and ``q = G K_C^{-1} f + g_0`` the conditions
  ``lambda >= 0, S lambda + q >= 0, lambda . (S lambda + q) = 0`` are those of
  ``min_{lambda >= 0} ||L^T lambda + L^{-1} q||^2`` (``S = L L^T``; non-negative least squares),
  then ``K_C u = f + G^T lambda``. A ``K_C`` that is singular (a body held only by its obstacles)
  is regularised by ``1e-9 max diag(K_C)`` on its diagonal: the start is a guess, not a result.
- ``random``: every point at a datum drawn uniformly from its own data set.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ddcm_casadi.problems.exact import BorderedFamily, ExactEnumerator, move_terms
from ddcm_casadi.linalg import SingularMatrix, factorize
from ddcm_casadi.data.metric import block_diagonal


def point_ranges(model) -> tuple[np.ndarray, np.ndarray]:
    """Per material point: where its data set starts in the global index, and its size."""
    data = model.dataset
    _, material = data.point_materials(model.n_points)
    sizes = np.array([len(d) for d in data.datasets], dtype=np.intp)
    return np.asarray(data.offsets, dtype=np.intp)[material], sizes[material]


def origin_assignment(model, search: str = "kdtree") -> np.ndarray:
    """Every point at the datum nearest the zero state (by the data search ``search``)."""
    origin = np.zeros(model.n_points * model.strain_components)
    return model.dataset.nearest(origin, origin, search=search)


def random_assignment(model, rng: np.random.Generator) -> np.ndarray:
    """Every point at a datum drawn uniformly from its own data set."""
    offset, size = point_ranges(model)
    return offset + rng.integers(0, size).astype(np.intp)


def _metric_blocks(model) -> np.ndarray:
    """``(m, k, k)``: each point's metric ``C``."""
    metrics, material = model.dataset.point_materials(model.n_points)
    return np.stack([mt.matrix for mt in metrics])[material]


def _elastic_operator(model):
    """``(C, lu, KG, S)`` of the metric's linear problem: the point metrics, the factorised
    ``K_C = B^T W C B``, ``K_C^-1 G^T`` and the contact compliance ``G K_C^-1 G^T``; the same at
    every load step, so computed once per model."""
    cached = model._cache.get("elastic_start")
    if cached is None:
        C = _metric_blocks(model)
        B, G = model.strain_operator, model.gap_operator
        K = (B.T @ block_diagonal(C * model.volumes[:, None, None]) @ B).tocsc()
        try:
            lu = factorize(K)
        except SingularMatrix:
            lu = factorize(K + 1e-9 * float(K.diagonal().max()) * sp.identity(K.shape[0], format="csc"))
        KG = S = None
        if model.n_contacts:
            KG = lu.solve(G.T.toarray())  # K^-1 G^T, one column per pair
            S = np.asarray(G @ KG)
            S = 0.5 * (S + S.T)
        cached = model._cache["elastic_start"] = (C, lu, KG, S)
    return cached


def elastic_state(model, step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(u, strain, stress)`` of the linear contact problem with the metric as material law
    (see the module's docstring), at load step ``step``."""
    C, lu, KG, S = _elastic_operator(model)
    k = model.strain_components
    f, offset, g0 = model.loads[step], None, model.gap_offsets[step]
    if model.prescribed is not None:  # a hard device: strains B u + B_D u_D, gaps + G_D u_D
        u_D = model.prescribed.values[step]
        offset = model.prescribed.strain_operator @ u_D
        sigma0 = np.einsum("ijk,ik->ij", C * model.volumes[:, None, None], offset.reshape(-1, k)).reshape(-1)
        f = f - model.strain_operator.T @ sigma0
        if model.n_contacts:
            g0 = g0 + model.prescribed.gap_operator @ u_D
    u = lu.solve(f)
    if model.n_contacts:
        q = model.gap_operator @ u + g0
        if np.any(q < 0):  # some pair would penetrate: solve the dual
            from scipy.optimize import nnls  # scipy.optimize costs a first run 0.08 s to import

            scale = float(np.max(np.diag(S))) or 1.0
            Sn = S / scale + 1e-12 * np.eye(S.shape[0])
            L = np.linalg.cholesky(Sn)
            lam, _ = nnls(L.T, -np.linalg.solve(L, q / scale), maxiter=50 * S.shape[0] + 100)
            u = u + KG @ lam
    strain = model.strain_operator @ u
    if offset is not None:
        strain = strain + offset
    stress = np.einsum("ijk,ik->ij", C, strain.reshape(-1, k)).reshape(-1)
    return u, strain, stress


def start_assignment(model, start: str, step: int, rng: np.random.Generator, search: str = "kdtree") -> np.ndarray:
    """The initial assignment ``start`` ("origin", "elastic" or "random") at load step ``step``
    (the nearest data by the data search ``search``: an exact one, so any gives the same)."""
    if start == "origin":
        return origin_assignment(model, search)
    if start == "elastic":
        _, strain, stress = elastic_state(model, step)
        return model.dataset.nearest(strain, stress, search=search)
    return random_assignment(model, rng)


#: The solved directions of :func:`assignment_family` are remembered per problem and step where
#: they take at most this many floats (8 MB).
DIRECTION_CACHE_VALUES = 1_000_000


def assignment_family(problems, exact: ExactEnumerator, step: int, index: np.ndarray,
                      points: np.ndarray | None = None):
    r"""The exact projections of every assignment near ``index``, as closed forms.

    The projection's parameters are affine in the assigned data, ``P = P(index) + D c`` with
    ``c`` the data's strain and stress minus those of ``index`` at the material points ``points``
    (default: all; ``2 n k`` numbers for ``n`` points, point-major strains then stresses), so
    ``Z_E`` is solved once for ``2 n k + 1`` right-hand sides
    (:meth:`~ddcm_casadi.problems.exact.ExactEnumerator.affine_family`; in the bordered form, for a
    small model, once per step for every direction, :func:`_all_directions`) and the objective of any
    assignment that differs from ``index`` only at ``points`` is a closed-form quadratic in
    ``c``. Centring ``c`` on ``index`` keeps the terms small near the assignment found, where
    comparisons matter.

    Returns ``(family, strain, stress)``: the :class:`~ddcm_casadi.problems.exact.BorderedFamily`
    (:class:`~ddcm_casadi.problems.exact.AffineFamily` where the bordered form is singular) and the
    assigned data of ``index`` as ``(m, k)`` arrays.
    """
    model = problems.model
    data = model.dataset
    m, k = model.n_points, model.strain_components
    cur_e = data.strain[index].reshape(m, k)
    cur_s = data.stress[index].reshape(m, k)
    pts = np.arange(m) if points is None else np.asarray(points)
    comps = (pts[:, None] * k + np.arange(k)).ravel()
    cols = np.concatenate([comps, m * k + comps])  # their strains, then their stresses

    def directions(columns) -> np.ndarray:
        zero = problems.projection_params(step, np.zeros(m * k), np.zeros(m * k))
        unit = np.zeros((2 * m * k, len(columns)))
        unit[columns, np.arange(len(columns))] = 1.0
        return problems.projection_params(step, unit[:m * k], unit[m * k:]) - zero[:, None]  # one column each

    solved = _all_directions(problems, exact, step, directions) if exact.bordered else None
    if solved is None:
        return exact.affine_family(problems.projection_params(step, cur_e.ravel(), cur_s.ravel()), directions(cols)), \
            cur_e, cur_s
    # P(index) = P(0) + D c(index): the imposed solutions of index and of the directions by linearity.
    dz, wz, E, W = solved
    c = np.concatenate([cur_e.ravel(), cur_s.ravel()])
    return exact.family(dz + E @ c, wz + W @ c, E[:, cols], W[:, cols]), cur_e, cur_s


def _all_directions(problems, exact: ExactEnumerator, step: int, directions):
    """``(d, mu)`` of the projection with every constraint imposed (:meth:`~ddcm_casadi.problems.exact.ExactEnumerator.imposed`)
    for the zero assignment and for every direction of :func:`assignment_family` at ``step``,
    solved once per problem and step (the greedy search screens sweep after sweep), or None
    where they would exceed :data:`DIRECTION_CACHE_VALUES` floats."""
    model = problems.model
    n = 2 * model.n_points * model.strain_components
    if n * (n + 2 * exact.nc + 2) > DIRECTION_CACHE_VALUES:  # d has 2 m k rows
        return None

    def solve():
        d, w = exact.imposed(np.column_stack([problems.projection_params(step, np.zeros(n // 2), np.zeros(n // 2)),
                                              directions(np.arange(n))]))
        return d[:, 0], w[:, 0], d[:, 1:], w[:, 1:]

    return problems.projection.shared(("assignment_directions", step), solve)


def descent_threshold(mine: float) -> float:
    """The objective a move must beat to descend from ``mine`` (past roundoff)."""
    return mine - 1e-12 - 1e-9 * abs(mine)


#: A move is left out by its lower bound only when the bound exceeds the descent threshold by this
#: share of the terms that make it (far above the roundoff of the closed forms).
PRUNE_MARGIN = 1e-6


def single_moves(problems, exact: ExactEnumerator, step: int, index: np.ndarray, points: np.ndarray,
                 candidates: np.ndarray, *, prune: bool = False) -> tuple[np.ndarray, float]:
    r"""The exact projection's objective (scaled) of every assignment that differs from ``index``
    at one point: ``points[a]`` moved to datum ``candidates[a, b]``; returns ``(objectives,
    objective of index)`` with ``objectives`` shaped like ``candidates``. Only the moving points
    enter the closed forms (``2 n k`` directions for ``n`` points, not ``2 m k``), and each move's
    ``c`` has ``2 k`` nonzeros.

    ``prune``: a move whose lower bound, the projection without contact constraints
    (:meth:`~ddcm_casadi.problems.exact.BorderedFamily.relaxed`, one quadratic in the move's ``2 k``
    numbers), is above :func:`descent_threshold` is reported as ``inf`` without its branches:
    it cannot descend. The moves that can are exactly those of the full screen.
    """
    family, cur_e, cur_s = assignment_family(problems, exact, step, index, points)
    data, k = problems.model.dataset, problems.model.strain_components
    strain = data.strain.reshape(len(data), k)
    stress = data.stress.reshape(len(data), k)
    n, n_c = len(points), candidates.shape[1]
    points = np.asarray(points)

    def pairs(indices):  # the data's strains and stresses, side by side
        return np.concatenate([strain[indices], stress[indices]], axis=-1)

    cur = np.concatenate([cur_e[points], cur_s[points]], axis=1)  # (n, 2 k)
    rows = np.concatenate([np.arange(k) + k * np.arange(n)[:, None], n * k + np.arange(k) + k * np.arange(n)[:, None]],
                          axis=1)  # (n, 2 k): each point's strain, then stress, directions
    mine = family.base()
    relaxed = family.relaxed() if prune and isinstance(family, BorderedFamily) else None
    if relaxed is None:
        return family.best_moves(rows, pairs(candidates) - cur[:, None, :]), mine
    if np.all(candidates == candidates[:1]):  # one data set for every point
        bound, size = _shared_bound(*relaxed, rows, pairs(candidates[0]), cur)
    else:
        linear, quadratic = move_terms(relaxed[1], relaxed[2], rows, pairs(candidates) - cur[:, None, :])
        bound, size = relaxed[0] + linear + quadratic, abs(relaxed[0]) + np.abs(linear) + np.abs(quadratic)
    limit = descent_threshold(mine)
    a, b = np.nonzero(bound <= limit + PRUNE_MARGIN * (size + abs(limit)))  # far above the bound's roundoff
    obj = np.full((n, n_c), np.inf)
    obj[a, b] = family.best_moves(rows[a], (pairs(candidates[a, b]) - cur[a])[:, None, :])[:, 0]
    return obj, mine


def _shared_bound(a0: float, a1: np.ndarray, A2: np.ndarray, rows: np.ndarray, x: np.ndarray,
                  cur: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""The quadratic ``a0 + a1^T c + c^T A2 c / 2`` of every move of point ``g`` (rows ``rows[g]``)
    from ``cur[g]`` to a datum ``x[i]`` of one shared set ``x`` (``(N, j)``), and the size of its
    terms: two ``(G, N)`` arrays. About a centre ``x0`` (``x = x0 + y``,
    ``c = y + delta_g``, ``delta_g = x0 - cur[g]``) it is ``k_g + l_g^T y + y^T A_g y / 2``: two
    products with the data's monomials instead of per-move arithmetic (``x0``: the mean of the
    current data, inside the data's range)."""
    g, A = a1[rows], A2[rows[:, :, None], rows[:, None, :]]  # (G, j), (G, j, j)
    centre = np.mean(cur, axis=0)
    y, delta = x - centre, centre - cur
    Ad = np.einsum("gpq,gq->gp", A, delta)
    const = a0 + np.einsum("gp,gp->g", g + 0.5 * Ad, delta)
    lin = g + Ad
    M = (y[:, :, None] * y[:, None, :]).reshape(len(y), -1)  # (N, j^2)
    Ag = A.reshape(len(A), -1)
    bound = const[:, None] + lin @ y.T + 0.5 * (Ag @ M.T)
    size = np.abs(const)[:, None] + np.abs(lin) @ np.abs(y).T + 0.5 * (np.abs(Ag) @ np.abs(M).T)
    return bound, size


def global_optimum(problems, exact: ExactEnumerator, step: int, index: np.ndarray, *,
                   chunk: int = 1 << 20) -> tuple[float, float]:
    """The exact global DDCM optimum of load step ``step`` by enumerating every one of the
    ``N^m`` data assignments with the closed forms of :func:`assignment_family`, and the exact
    projection's objective of the assignment ``index`` (both scaled)."""
    model = problems.model
    data = model.dataset
    m, k = model.n_points, model.strain_components
    family, cur_e, cur_s = assignment_family(problems, exact, step, index)
    mine = family.base()
    offset, size = point_ranges(model)
    total = int(np.prod(size.astype(float)))
    best = np.inf
    strain = data.strain.reshape(len(data), k)
    stress = data.stress.reshape(len(data), k)
    for a in range(0, total, chunk):
        flat = np.arange(a, min(total, a + chunk))
        local = np.unravel_index(flat, tuple(size)) if m > 1 else (flat,)
        glob = [offset[i] + local[i] for i in range(m)]
        c = np.vstack([(strain[glob[i]] - cur_e[i]).T for i in range(m)]
                      + [(stress[glob[i]] - cur_s[i]).T for i in range(m)])
        best = min(best, float(np.min(family.best(c, chunk=chunk))))
    return best, mine
