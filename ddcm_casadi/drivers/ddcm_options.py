"""Options of the DDCM driver: iterations, data search, where each load step starts, restarts,
global improvement, certificates and the noise-robust variants (one frozen, keyword-only
dataclass, validated on construction).

>>> from ddcm_casadi.drivers.ddcm_options import DDCMOptions
>>> opts = DDCMOptions(restarts=4, improve="greedy", seed=1)
>>> opts.describe()["restarts"]
4

The same keys are read from a case file's ``[ddcm]`` section (:meth:`DDCMOptions.from_mapping`);
every value is checked by its type and range (:func:`ddcm_casadi.inputs.check_fields`), and a bad
one is a one-line :class:`~ddcm_casadi.errors.InputError` naming the key.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any, Literal, Mapping, get_args

from ddcm_casadi import inputs as check
from ddcm_casadi.errors import InputError
from ddcm_casadi.data.search import search_name
from ddcm_casadi.data import ann  # noqa: F401  (registers the certified searches)

#: The initial data assignment of a load step (see :class:`DDCMOptions`).
Start = Literal["origin", "elastic", "random"]
#: What is done after a fixed point.
Improvement = Literal["none", "greedy"]
#: The data-driven scheme: plain distance minimisation, or a noise-robust variant.
Variant = Literal["plain", "lcdd", "maxent"]
STARTS, IMPROVEMENTS, VARIANTS = get_args(Start), get_args(Improvement), get_args(Variant)

#: Integer options: their inclusive ranges (the other fields are checked by their type).
_INTS = {"seed": (0, 2**63 - 1), "restarts": (0, 10_000), "restart_neighbours": (0, 10**6), "greedy_neighbours": (1, 1000),
         "greedy_points": (0, 10**9), "greedy_budget": (1, 10**6), "exact_max": (0, 10**9),
         "lcdd_neighbours": (2, 64), "maxent_neighbours": (2, 4096), "maxent_steps": (1, 200),
         # One alternating projection cannot confirm a fixed point (an unchanged assignment).
         "max_outer": (2, 10**6)}
#: Alternating projections per step.
MAX_OUTER_RANGE = _INTS["max_outer"]


#: The fields whose type and name say too little (see :func:`ddcm_casadi.inputs.check_fields`).
_RULES: dict[str, check.Rule] = {
    **{name: functools.partial(check.integer, low=lo, high=hi) for name, (lo, hi) in _INTS.items()},
    "maxent_beta_growth": functools.partial(check.in_range, low=1.0, high=1e6, low_open=True),
    "search": lambda value, where: search_name(value),  # a one-line error listing the registered backends
    "initial": functools.partial(check.number_list, integers=True, nonempty=True),  # data indices
}


@dataclass(frozen=True, kw_only=True)
class DDCMOptions:
    """How the DDCM driver searches for the double minimum ``min_{z in Z_E} min_{z* in Z_D} F``.

    Parameters
    ----------
    max_outer : int
        Alternating projections per run of a load step (2..1e6: one projection cannot confirm a
        fixed point).
    search : str
        The data search backend (:data:`ddcm_casadi.data.search.SEARCHES`): ``"kdtree"``, a cold
        KD-tree query, ``"graph"`` (alias ``"warm"``), the exact walk on the data's
        neighbour graph from the previous assignment, ``"strips"`` (one-component data at
        scale) or ``"ann"`` (faiss, the extra ``ann``), certified partition searches
        (:mod:`ddcm_casadi.data.ann`). All are exact: the path is the same.
    start : {"origin", "elastic", "random"}
        The data assignment the first load step starts from (and every step when ``warm`` is
        False). ``origin``: every point at the datum nearest the zero state (the historical
        default). ``elastic``: every point at the datum nearest the solution of the *linear*
        contact problem whose material law is the metric, ``sigma = C eps``,
        ``min_u 1/2 u^T K_C u - f^T u`` s.t. ``G u + g0 >= 0`` with ``K_C = B^T W C B``
        (:func:`~ddcm_casadi.drivers.ddcm_search.elastic_state`). ``random``: every point at a
        datum drawn uniformly from its data set, seeded by ``(seed, step)``.
    initial : tuple of int, optional
        An explicit initial assignment (global data indices, one per material point); it replaces
        ``start`` at the first step.
    warm : bool
        Later steps start from the previous step's assignment (the default); False starts every
        step from ``start``.
    seed : int
        Seed of the random start and of the restarts: the draws of step ``k`` and restart ``r`` use
        ``numpy.random.default_rng((seed, k, r))``, so a run is reproducible and does not depend
        on what other steps did.
    restarts : int
        Additional runs per load step from random assignments; the lowest objective is kept
        (fixed points before non-converged runs). Each run is warm-started from the same previous
        step, so the result is deterministic.
    restart_neighbours : int
        0: a restart draws every point's datum uniformly from its whole data set. ``K > 0``: from
        the ``K`` data nearest the best state found so far at that step (a kick, as in iterated
        local search: cheaper, and more effective when the data cover far more than the states).
    improve : {"none", "greedy"}
        ``greedy`` (after the greedy local search of Datasolver.jl): after the fixed point, take
        the ``greedy_points`` points with the largest local distance ``w_i d_i^2`` (worst first),
        move one to another datum and rerun the alternating scheme from there; accept the new
        fixed point only if its objective is strictly lower, and start over from it; assignments
        already visited are skipped; stop when no move improves or after ``greedy_budget`` reruns.
        A descent method: the objective never increases. The moves tried per sweep (at most
        ``greedy_neighbours``): with the exact branch enumeration (few contact pairs) the single-
        point moves whose exact projection lowers the objective, best first, screened in closed
        form over each point's data set (so a rerun is paid only for a move known to descend; on
        a one-element problem this reaches the enumerated optimum); otherwise each point's
        next-nearest data, as in Datasolver.jl.
    greedy_neighbours, greedy_points, greedy_budget : int
        See ``improve`` (``greedy_points = 0``: every point).
    greedy_screen : bool
        Screen the greedy moves in closed form where the branch enumeration is available (see
        ``improve``); False always uses the next-nearest data (Datasolver.jl's moves).
    exact_max : int
        Compute the exact global optimum (a certificate; ``global_optimum``, ``global_gap``) by
        enumerating every data assignment when there are at most this many (``N^m`` for ``m``
        points); one-element problems are always enumerated (cheap closed forms). 0: one element only.
    variant : {"plain", "lcdd", "maxent"}
        The data-driven scheme; ``lcdd`` (local convexity, He & Chen 2020) and ``maxent``
        (maximum entropy with annealing, Kirchdoerfer & Ortiz 2017) are noise-robust and change
        the solution, not only the search (:mod:`ddcm_casadi.drivers.noise_robust`). Neither has a
        data assignment to restart or improve: with ``restarts`` or ``improve`` they are refused.
    lcdd_neighbours : int
        LCDD: the local convex hull is that of the ``k`` nearest data (He & Chen 2020 use 5-6).
    maxent_neighbours : int
        Max-ent: the Boltzmann weights ``p_j ~ exp(-beta d_j^2 / 2)`` and their mean run over the
        ``K`` data nearest each state (the KD-tree), not over all data. ``K`` also sets the
        temperature scale (``beta_0`` below), hence how many data are averaged: more smooths more
        noise, and on curved data biases the mean towards the inside of the curve.
    maxent_steps : int
        Max-ent: annealing stages per load step, ``beta_s = beta_0 g^s`` for ``s < maxent_steps``,
        ``beta_0 = 1 / <d^2>`` over the first state's neighbourhoods; the scheme settles at each
        stage and stops early once the weights concentrate on the nearest datum (then it is at a
        fixed point of plain DDCM). The default, one stage, is the measured best on noisy data
        (README): a second stage costs about 3x the projections for no lower error, and annealing
        to concentration returns to a plain DDCM fixed point (a better one, still noisy).
    maxent_beta_growth : float
        Max-ent: the factor ``g > 1`` of ``beta`` from one annealing stage to the next.
    reduce : bool
        Solve each projection through the Kirchdoerfer-Ortiz reduction where it applies (an affine
        projection with a constant metric and at most
        :data:`~ddcm_casadi.problems.reduction.MAX_PAIRS` contact pairs): ``K_C = B^T (W (x) C) B``
        factorised once per model, the formulation on the contact pairs' condensed problem
        (:mod:`ddcm_casadi.drivers.ddcm_reduced`; the same projections to round-off). False: the
        formulation on the full saddle-point problem.
    """

    max_outer: int = 100
    search: str = "kdtree"
    start: Start = "origin"
    initial: tuple[int, ...] | None = None
    warm: bool = True
    seed: int = 0
    restarts: int = 0
    restart_neighbours: int = 0
    improve: Improvement = "none"
    greedy_neighbours: int = 3
    greedy_points: int = 8
    greedy_budget: int = 40
    greedy_screen: bool = True
    exact_max: int = 0
    variant: Variant = "plain"
    lcdd_neighbours: int = 5
    maxent_neighbours: int = 32
    maxent_steps: int = 1
    maxent_beta_growth: float = 2.0
    reduce: bool = True

    def __post_init__(self) -> None:
        check.check_dataclass(self, "ddcm option", rules=_RULES)
        if self.variant != "plain" and (self.restarts or self.improve != "none"):
            # checked here, before any work: LCDD and max-ent have no data assignment to restart or improve
            raise InputError(f"ddcm variant {self.variant!r} does not combine with restarts or improve "
                             f"(it has no data assignment)")

    @classmethod
    def from_mapping(cls, table: Mapping[str, Any], *, where: str = "[ddcm]") -> "DDCMOptions":
        """Options from a case file's ``[ddcm]`` table (other keys, such as ``c``, are ignored
        here); every value is checked and a bad one is a one-line error naming ``where key``."""
        values = {k: v for k, v in table.items() if k in KEYS}
        return cls(**check.check_fields(cls, values, where, rules=_RULES))

    def describe(self) -> dict:
        """The options as plain values, for ``results.json``."""
        d = dataclasses.asdict(self)
        d["initial"] = None if self.initial is None else list(self.initial)
        return d


#: The keys of ``[ddcm]`` read by :meth:`DDCMOptions.from_mapping` (``c`` is read by the case
#: file itself).
KEYS = frozenset(f.name for f in dataclasses.fields(DDCMOptions))
