"""Beyond the first fixed point of a load step: restarts and the greedy global improvement
(:class:`~ddcm_casadi.drivers.ddcm_options.DDCMOptions` ``restarts``, ``restart_neighbours``,
``improve``), for schemes that assign one datum per point.

Each function takes the driver (:class:`~ddcm_casadi.drivers.ddcm.DDCMSolver`) and reruns its
alternation (:meth:`~ddcm_casadi.drivers.ddcm.DDCMSolver.alternate`) from other assignments,
keeping the best run (fixed points first, then the lowest objective).
"""

from __future__ import annotations

import numpy as np

from ddcm_casadi.drivers.ddcm_search import (
    assignment_projection, descent_threshold, point_ranges, random_assignment, screened_moves, tolerant_argsort,
)
from ddcm_casadi.drivers.records import Run, count

#: Single-point moves screened per sweep of the greedy search (points x candidates).
SCREEN_SIZE = 1_000_000


def restart_assignment(solver, k: int, r: int, best: Run) -> np.ndarray:
    """The start of restart ``r`` of step ``k``, seeded by ``(seed, k, r)``: uniform over each
    point's data set, or (``restart_neighbours = K``) a kick from the best state so far, each point
    at one of its ``K`` nearest data."""
    opts, model = solver.options, solver.problems.model
    rng = np.random.default_rng((opts.seed, k, r))
    if not opts.restart_neighbours:
        return random_assignment(model, rng)
    f = best.fields
    near = model.dataset.k_nearest(f["strain"], f["stress"], opts.restart_neighbours)
    return near[np.arange(near.shape[0]), rng.integers(0, near.shape[1], near.shape[0])]


def restart(solver, k: int, best: Run, best_warm: tuple, warm: tuple, visited: set, tally: dict):
    """``restarts`` more runs of step ``k``, each warm-started from the previous step (``warm``);
    returns the best run and the ``(x, p, state)`` it ended at."""
    for r in range(1, solver.options.restarts + 1):
        start = restart_assignment(solver, k, r, best)
        run, state = solver.alternate(k, solver.scheme.states(start), *warm)
        count(tally, run)
        visited |= {start.tobytes(), run.index.tobytes()}
        if run.better_than(best):
            best, best_warm = run, state
            tally["improvements"] += 1
    return best, best_warm


def _next_nearest_moves(solver, best: Run, order: np.ndarray) -> list[np.ndarray]:
    """The worst points (``order``) moved to their ``greedy_neighbours`` next-nearest data (as
    Datasolver.jl)."""
    opts, data, f = solver.options, solver.problems.model.dataset, best.fields
    near = data.k_nearest(f["strain"], f["stress"], opts.greedy_neighbours + 1)
    moves = []
    for i in order:
        for j in [j for j in near[i] if j != best.index[i]][:opts.greedy_neighbours]:
            trial = best.index.copy()
            trial[i] = j
            moves.append(trial)
    return moves


def _screened_moves(solver, k: int, best: Run, order: np.ndarray) -> list[np.ndarray]:
    """Every move of a point of ``order`` to another datum of its set (or, past
    :data:`SCREEN_SIZE` moves, to one of its nearest data), screened by the exact objective of
    its projection (closed forms, :func:`~ddcm_casadi.drivers.ddcm_search.screened_moves`): the
    moves that lower the objective, best first."""
    model, f = solver.problems.model, best.fields
    data = model.dataset
    offset, size = point_ranges(model)
    per_point = SCREEN_SIZE // len(order)
    sizes, offsets = size[order], offset[order]
    if sizes[0] <= per_point and np.all(sizes == sizes[0]):
        cand = offsets[0] + np.arange(sizes[0])[None, :]  # every point's own set: one row where they share it
        if np.any(offsets != offsets[0]):
            cand = offsets[:, None] + np.arange(sizes[0])[None, :]
    else:
        pts = f["strain"].reshape(model.n_points, -1)[order], f["stress"].reshape(model.n_points, -1)[order]
        cand = data.k_nearest(pts[0].ravel(), pts[1].ravel(), max(2, per_point))
    a, b, obj, mine = screened_moves(solver.problems, solver.exact, k, best.index, order, cand)
    # Row-major, so the sort keeps the order of a sort of every move; moves whose objectives agree to
    # the descent test's tolerance (mirror-symmetric moves) in that order.
    limit = descent_threshold(mine)
    descending = np.flatnonzero(obj < limit)
    moves = []
    for j in descending[tolerant_argsort(obj[descending], mine - limit)]:
        i = a[j]
        trial = best.index.copy()
        trial[order[i]] = cand[i % cand.shape[0], b[j]]
        moves.append(trial)
        if len(moves) == solver.options.greedy_neighbours:
            break
    return moves


def greedy_moves(solver, k: int, best: Run) -> list[np.ndarray]:
    """Candidate assignments of one greedy sweep, most promising first: the ``greedy_points``
    points with the largest ``w_i d_i^2``, moved by :func:`_screened_moves` where the exact branch
    enumeration is available (affine problems, few contact pairs) and ``greedy_screen`` is set,
    else by :func:`_next_nearest_moves`."""
    opts, model = solver.options, solver.problems.model
    f = best.fields
    local = model.volumes * model.dataset.distance2(f["strain"], f["stress"], best.index)
    # Mirror-symmetric points have equal distances but for roundoff: taken by position.
    order = tolerant_argsort(-local, 1e-9 * float(np.sum(local)))[:opts.greedy_points or model.n_points]
    if solver.exact is None or not opts.greedy_screen:
        return _next_nearest_moves(solver, best, order)
    return _screened_moves(solver, k, best, order)


def greedy(solver, k: int, best: Run, warm: tuple, visited: set, tally: dict):
    """Greedy global improvement after a fixed point (``improve = "greedy"``): rerun the
    alternation from the candidate moves of :func:`greedy_moves`, accept only a strictly lower
    objective and start over from it; at most ``greedy_budget`` reruns. The objective never
    increases. Returns the best run and the ``(x, p, state)`` it ended at."""
    budget = solver.options.greedy_budget
    # Trials from the screen (exact objectives in closed form) start from their exact projection
    # where that is the formulation's answer.
    reuse = solver.exact is not None and solver.options.greedy_screen and solver.projection.enumerated
    trials = 0
    while trials < budget:
        improved = False
        for trial in greedy_moves(solver, k, best):
            key = trial.tobytes()
            if key in visited:
                continue
            visited.add(key)
            # The screen evaluated the trial's exact projection in closed form: no formulation
            # solve for it (where the exact projection is the formulation's answer), its state
            # from the same closed forms where the step's directions are kept.
            known = assignment_projection(solver.problems, solver.exact, k, trial) if reuse else None
            run, state = solver.alternate(k, solver.scheme.states(trial), *warm, exact_first=reuse, known=known)
            trials += 1
            count(tally, run)
            visited.add(run.index.tobytes())
            if run.converged and run.better_than(best):
                best, warm, improved = run, state, True
                tally["improvements"] += 1
                break
            if trials >= budget:
                break
        if not improved:
            break
    return best, warm
