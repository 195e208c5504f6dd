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

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ddcm_casadi.problems.exact import BorderedFamily, ExactEnumerator, move_terms
from ddcm_casadi.linalg import SingularMatrix, factorize
from ddcm_casadi.data.metric import block_diagonal


def point_ranges(model) -> tuple[np.ndarray, np.ndarray]:
    """Per material point: where its data set starts in the global index, and its size
    (remembered per model: the greedy screen asks every sweep)."""
    cached = model._cache.get("point_ranges")
    if cached is None:
        data = model.dataset
        _, material = data.point_materials(model.n_points)
        sizes = np.array([len(d) for d in data.datasets], dtype=np.intp)
        cached = model._cache["point_ranges"] = (np.asarray(data.offsets, dtype=np.intp)[material], sizes[material])
    return cached[0].copy(), cached[1].copy()


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
    family, cur_e, cur_s, _ = _family_columns(problems, exact, step, index, points)
    return family, cur_e, cur_s


def _family_columns(problems, exact: ExactEnumerator, step: int, index: np.ndarray, points: np.ndarray | None):
    """:func:`assignment_family` and ``cols``: the family's columns of the points' directions
    (their strains, then their stresses). Where the step's directions are kept the family is that
    of every direction, its quadratic terms the step's (no per-call gathers or products); else
    that of the points' directions alone."""
    model = problems.model
    data = model.dataset
    m, k = model.n_points, model.strain_components
    cur_e = data.strain[index].reshape(m, k)
    cur_s = data.stress[index].reshape(m, k)
    pts = np.arange(m) if points is None else np.asarray(points)
    comps = (pts[:, None] * k + np.arange(k)).ravel()
    cols = np.concatenate([comps, m * k + comps])  # their strains, then their stresses
    solved = _all_directions(problems, exact, step) if exact.bordered else None
    if solved is None:
        return exact.affine_family(problems.projection_params(step, cur_e.ravel(), cur_s.ravel()),
                                   _directions(problems, step, cols)), cur_e, cur_s, np.arange(cols.size)
    # P(index) = P(0) + D c(index): the imposed solutions of index and of the directions by linearity.
    c = np.concatenate([cur_e.ravel(), cur_s.ravel()])
    family = exact.family(solved.dz + solved.E @ c, solved.wz + solved.W @ c, solved.E, solved.W, A2=solved.A2,
                          relaxed_A2=solved.relaxed_A2)
    return family, cur_e, cur_s, cols


def assignment_projection(problems, exact: ExactEnumerator, step: int,
                          index: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The exact projection ``(x, p, objective)`` (scaled) of the data assignment ``index`` at
    ``step`` from the step's solved directions (:func:`_all_directions`, by linearity, as
    :func:`assignment_family`): what :meth:`~ddcm_casadi.problems.exact.ExactEnumerator.solve`
    gives for its parameters, to roundoff, without a solve. None where the directions are not
    kept (no bordered form, a large model) or no branch is sign-feasible."""
    solved = _all_directions(problems, exact, step) if exact.bordered else None
    if solved is None:
        return None
    data = problems.model.dataset
    return _directions_projection(exact, solved, np.concatenate([data.strain[index].ravel(),
                                                                 data.stress[index].ravel()]))


def params_projection(problems, exact: ExactEnumerator, step: int,
                      params: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    r"""The exact projection ``(x, p, objective)`` (scaled) of the parameter vector ``params``
    of ``step`` from the step's solved directions (:func:`_all_directions`), as
    :func:`assignment_projection` for any assigned states ``c`` (the ``strain_star`` and
    ``stress_star`` entries of ``params``): ``z = z_0 + Z c`` and the best branch, a product with
    ``2 m k`` columns instead of a solve with the bordered matrix. Only where ``params`` is
    ``P(0) + D c`` of the step's directions (not for a sub-step's interpolated load or another
    history), else None; None also where the directions are not kept or no branch is
    sign-feasible."""
    solved = _all_directions(problems, exact, step) if exact.bordered else None
    if solved is None:
        return None
    P = problems.projection.parameters
    c = np.concatenate([P.get(params, "strain_star"), P.get(params, "stress_star")])
    # the directions' parameters are exact copies of c (Parameters.pack): equal but for roundoff
    if np.max(np.abs(solved.P0 + solved.D @ c - params)) > 1e-14 * max(1.0, float(np.max(np.abs(params)))):
        return None
    return _directions_projection(exact, solved, c)


def _directions_projection(exact: ExactEnumerator, solved: "_Directions",
                           c: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The exact projection ``(x, p, objective)`` of the assigned states ``c`` by linearity from
    the step's directions ``solved``, or None where no branch is sign-feasible."""
    ex = exact.from_imposed((solved.zz + solved.Z @ c)[:, None], (solved.dz + solved.E @ c)[:, None],
                            (solved.wz + solved.W @ c)[:, None])
    if not ex.found[0]:
        return None
    return ex.x[:, 0], ex.p[:, 0], float(ex.objective[0])


def _directions(problems, step: int, columns: np.ndarray) -> np.ndarray:
    """The columns ``D`` of :func:`assignment_family`'s ``P = P(0) + D c`` at ``step`` (``c``:
    every point's strains, then stresses), one per entry of ``columns``."""
    model = problems.model
    mk = model.n_points * model.strain_components
    zero = problems.projection_params(step, np.zeros(mk), np.zeros(mk))
    unit = np.zeros((2 * mk, len(columns)))
    unit[columns, np.arange(len(columns))] = 1.0
    return problems.projection_params(step, unit[:mk], unit[mk:]) - zero[:, None]


@dataclass(frozen=True)
class _Directions:
    """The projection with every constraint imposed for the zero assignment (``zz``, ``dz``,
    ``wz``: unknowns, distance, multipliers) and for every direction of :func:`_directions`
    (``Z``, ``E``, ``W``, one column each), the directions' quadratic term ``A2 = E^T W E`` and
    that of the projection without contact constraints (``relaxed_A2``,
    :meth:`~ddcm_casadi.problems.exact.BorderedFamily.relaxed`; None where it is singular), and
    the parameters they solved: ``P(c) = P0 + D c``."""

    zz: np.ndarray
    dz: np.ndarray
    wz: np.ndarray
    Z: np.ndarray
    E: np.ndarray
    W: np.ndarray
    A2: np.ndarray
    P0: np.ndarray
    D: np.ndarray
    relaxed_A2: np.ndarray | None


def _all_directions(problems, exact: ExactEnumerator, step: int) -> _Directions | None:
    """The :class:`_Directions` of ``step``, solved once per problem and step (the greedy search
    screens sweep after sweep, :meth:`~ddcm_casadi.problems.exact.ExactEnumerator.imposed`), or
    None where they would exceed :data:`DIRECTION_CACHE_VALUES` floats."""
    model = problems.model
    n = 2 * model.n_points * model.strain_components
    n_params = problems.projection.parameters.size
    if (n + 1) * (n + 2 * exact.nc + exact.nz + n_params) + 2 * n * n > DIRECTION_CACHE_VALUES:
        return None

    def solve():
        P = np.column_stack([problems.projection_params(step, np.zeros(n // 2), np.zeros(n // 2)),
                             _directions(problems, step, np.arange(n))])
        z, d, w = exact.imposed(P)
        family = exact.family(d[:, 0], w[:, 0], d[:, 1:], w[:, 1:])
        relaxed = family.relaxed()
        return _Directions(zz=z[:, 0], dz=d[:, 0], wz=w[:, 0], Z=z[:, 1:], E=d[:, 1:], W=w[:, 1:], A2=family.A2,
                           P0=P[:, 0], D=np.ascontiguousarray(P[:, 1:]),
                           relaxed_A2=None if relaxed is None else relaxed[2])

    return problems.projection.shared(("assignment_directions", step), solve)


def tolerant_argsort(values: np.ndarray, tol: float) -> np.ndarray:
    """The indices that sort ``values`` ascending, values within ``tol`` of their neighbour in
    the sorted order (chains of them) in the order of their indices: ties of roundoff (mirror-
    symmetric points and moves) are broken by position, not by the last bits of the values, so
    the order does not depend on which solver computed them."""
    values = np.asarray(values, dtype=float).ravel()
    idx = np.argsort(values, kind="stable")
    apart = np.diff(values[idx]) > tol
    if apart.all():  # no near-ties (the usual case): the plain order
        return idx
    group = np.cumsum(np.concatenate([[False], apart]))
    return idx[np.lexsort((idx, group))]


def descent_threshold(mine: float) -> float:
    """The objective a move must beat to descend from ``mine`` (past roundoff)."""
    return mine - 1e-12 - 1e-9 * abs(mine)


#: A move is left out by its lower bound only when the bound exceeds the descent threshold by this
#: share of the terms that make it (far above the roundoff of the closed forms).
PRUNE_MARGIN = 1e-6


def single_moves(problems, exact: ExactEnumerator, step: int, index: np.ndarray, points: np.ndarray,
                 candidates: np.ndarray, *, prune: bool = False) -> tuple[np.ndarray, float]:
    r"""The exact projection's objective (scaled) of every assignment that differs from ``index``
    at one point: ``points[a]`` moved to datum ``candidates[a, b]`` (``candidates`` with one row:
    the same for every point); returns ``(objectives, objective of index)``, ``objectives``
    ``(len(points), candidates.shape[1])``. Only the moving points
    enter the closed forms (``2 n k`` directions for ``n`` points, not ``2 m k``), and each move's
    ``c`` has ``2 k`` nonzeros.

    ``prune``: a move whose lower bound, the projection without contact constraints
    (:meth:`~ddcm_casadi.problems.exact.BorderedFamily.relaxed`, one quadratic in the move's ``2 k``
    numbers), is above :func:`descent_threshold` is reported as ``inf`` without its branches:
    it cannot descend (:func:`screened_moves`). The moves that can are exactly those of the full screen.
    """
    shape = (len(points), candidates.shape[1])
    if prune:
        a, b, values, mine = screened_moves(problems, exact, step, index, points, candidates)
        obj = np.full(shape, np.inf)
        obj[a, b] = values
        return obj, mine
    family, cur, rows, pairs = _move_family(problems, exact, step, index, points)
    return family.best_moves(rows, pairs(np.broadcast_to(candidates, shape)) - cur[:, None, :]), family.base()


def _move_family(problems, exact: ExactEnumerator, step: int, index: np.ndarray, points: np.ndarray):
    """The family of the moves of ``points`` from ``index`` (:func:`assignment_family`), their
    current data ``(n, 2 k)``, their directions' rows ``(n, 2 k)`` and ``pairs(indices)``: data
    indices to their strains and stresses side by side."""
    family, cur_e, cur_s, cols = _family_columns(problems, exact, step, index, points)
    data, k = problems.model.dataset, problems.model.strain_components
    strain = data.strain.reshape(len(data), k)
    stress = data.stress.reshape(len(data), k)
    n = len(points)

    def pairs(indices):
        return np.concatenate([strain[indices], stress[indices]], axis=-1)

    cur = np.concatenate([cur_e[points], cur_s[points]], axis=1)
    rows = cols.reshape(2, n, k).transpose(1, 0, 2).reshape(n, 2 * k)  # each point's strain, then stress, directions
    return family, cur, rows, pairs


def screened_moves(problems, exact: ExactEnumerator, step: int, index: np.ndarray, points: np.ndarray,
                   candidates: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    r"""The moves of :func:`single_moves` (``prune``) that its bound leaves in, with their exact
    objectives: ``(a, b, objectives, objective of index)`` for the moves of ``points[a]`` to
    ``candidates[a, b]`` (row-major order). Every move that can descend is among them."""
    family, cur, rows, pairs = _move_family(problems, exact, step, index, points)
    n, n_c = len(points), candidates.shape[1]
    shared = candidates.shape[0] == 1 or bool(np.all(candidates == candidates[:1]))  # one data set for every point
    mine = family.base()
    relaxed = family.relaxed() if isinstance(family, BorderedFamily) else None
    if relaxed is None:  # no bound: every move
        a, b = np.divmod(np.arange(n * n_c), n_c)
    else:
        limit = descent_threshold(mine)
        # the bound's test: bound <= limit + PRUNE_MARGIN (size + |limit|), far above its roundoff
        if shared:
            margin_bound = _shared_bound(*relaxed, rows, _monomials(problems, candidates[0], pairs), cur)
        else:
            linear, quadratic = move_terms(relaxed[1], relaxed[2], rows, pairs(candidates) - cur[:, None, :])
            margin_bound = (relaxed[0] + linear + quadratic
                            - PRUNE_MARGIN * (abs(relaxed[0]) + np.abs(linear) + np.abs(quadratic)))
        # row-major, as np.nonzero, at a third of its cost on the screen's 8 x 2001 moves
        a, b = np.divmod(np.flatnonzero(margin_bound <= limit + PRUNE_MARGIN * abs(limit)), n_c)
    chosen = candidates[0, b] if shared else candidates[a, b]
    return a, b, family.best_moves(rows[a], (pairs(chosen) - cur[a])[:, None, :])[:, 0], mine


def _monomials(problems, candidates: np.ndarray, pairs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""``(x0, Y, |Y|max)`` of the data ``x = pairs(candidates)`` (``(N, j)``) for
    :func:`_shared_bound`: their centre ``x0`` (their mean, inside the data's range), per datum
    (column) the monomials ``Y = [1, y, y y^T]`` (``y = x - x0``; ``1 + j + j^2`` rows), and the
    largest absolute value of each monomial over the data. Remembered per problem for a
    contiguous range of data (a whole data set, screened sweep after sweep)."""
    def build():
        x = pairs(candidates)
        centre = np.mean(x, axis=0)
        y = x - centre
        Y = np.vstack([np.ones((1, len(y))), y.T, (y[:, :, None] * y[:, None, :]).reshape(len(y), -1).T])
        return centre, Y, np.max(np.abs(Y), axis=1)  # one row per monomial: contiguous for the product

    n = candidates.size
    if n and candidates[-1] - candidates[0] == n - 1 and np.all(np.diff(candidates) == 1):
        return problems.projection.shared(("screen_monomials", int(candidates[0]), n), build)
    return build()


def _shared_bound(a0: float, a1: np.ndarray, A2: np.ndarray, rows: np.ndarray,
                  monomials: tuple[np.ndarray, np.ndarray, np.ndarray], cur: np.ndarray) -> np.ndarray:
    r"""The quadratic ``a0 + a1^T c + c^T A2 c / 2`` of every move of point ``g`` (rows ``rows[g]``)
    from ``cur[g]`` to a datum ``x[i]`` of one shared set ``x`` (``(N, j)``), less
    :data:`PRUNE_MARGIN` times a bound of the size of its terms: a ``(G, N)`` array. About the
    data's centre ``x0`` (``x = x0 + y``, ``c = y + delta_g``, ``delta_g = x0 - cur[g]``) it is
    ``k_g + l_g^T y + y^T A_g y / 2``: one product of the coefficients ``[k_g, l_g, A_g / 2]``
    with the data's monomials ``Y = [1, y, y y^T]`` (:func:`_monomials`, once per data set)
    instead of per-move arithmetic; the size of the terms of point ``g``'s moves is at most
    ``|[k_g, l_g, A_g / 2]|`` times the monomials' largest absolute values over the data (one
    number per point, no second product: a margin at least the per-move one, so it leaves in
    every move that one did and a few more, 103 against 101 a sweep on the quick benchmark)."""
    centre, Y, largest = monomials
    g, A = a1[rows], A2[rows[:, :, None], rows[:, None, :]]  # (G, j), (G, j, j)
    delta = centre - cur
    Ad = np.einsum("gpq,gq->gp", A, delta)
    const = a0 + np.einsum("gp,gp->g", g + 0.5 * Ad, delta)
    coef = np.hstack([const[:, None], g + Ad, 0.5 * A.reshape(len(A), -1)])
    bound = coef @ Y
    bound -= (PRUNE_MARGIN * (np.abs(coef) @ largest))[:, None]
    return bound


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
