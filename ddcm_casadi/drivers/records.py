"""Records of a load path: one step (:class:`StepResult`), one path (:class:`PathResult`), and
one alternating-projection run of the DDCM driver (:class:`Run`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ddcm_casadi.errors import ConvergenceError


@dataclass
class StepResult:
    """Everything known about one load step of one variant and formulation (physical units)."""

    step: int
    load_parameter: float
    u: np.ndarray
    p: np.ndarray
    converged: bool
    iterations: int
    outer_iterations: int
    residual: float
    complementarity: float
    penetration: float
    seconds: float
    message: str = ""
    #: With Coulomb friction: the tangential tractions (Pa, component-major) and the slips of the step
    #: (m) per contact and tangent (:mod:`ddcm_casadi.models.coulomb`).
    traction: np.ndarray | None = None
    slip: np.ndarray | None = None
    # DDCM only
    strain: np.ndarray | None = None
    stress: np.ndarray | None = None
    strain_star: np.ndarray | None = None
    stress_star: np.ndarray | None = None
    data_index: np.ndarray | None = None
    distance: float = float("nan")
    projection_error: float = float("nan")
    projection_global: bool | None = None
    global_optimum: bool | None = None
    global_distance: float = float("nan")
    global_gap: float = float("nan")
    projections: int = 0
    runs: int = 0
    improvements: int = 0
    projection_seconds: float = 0.0
    search_seconds: float = 0.0
    #: Material points whose state is beyond the data (:mod:`ddcm_casadi.data.extrapolation`): a flag,
    #: not a convergence failure.
    extrapolated: int = 0
    #: The largest offset of a state from its nearest datum along the data, in local data spacings.
    data_spacings: float = float("nan")
    #: Coarse data (:meth:`~ddcm_casadi.data.extrapolation.DataCoverage.coarseness`): the share of the
    #: material points on the most used datum, how far their states spread (in data spacings), and
    #: the states' size (the largest distance from zero of a state, in data spacings at its datum); ``coarse_data`` says why the data are
    #: too coarse for this step (:func:`~ddcm_casadi.data.extrapolation.coarse_data`), ``""`` if not.
    datum_share: float = float("nan")
    datum_spread: float = float("nan")
    state_spacings: float = float("nan")
    coarse_data: str = ""
    #: Automatic step bisection (:mod:`ddcm_casadi.drivers.substeps`): the sub-steps that converged
    #: on the way to this step (1 when it was solved at once or not bisected; for a step that failed
    #: under bisection, those that converged before it gave up, possibly 0) and the smallest
    #: fraction of the step used (1.0 without bisection; for a step that failed under bisection, the
    #: smallest fraction tried). The costs (``iterations``, ``outer_iterations``, ``projections``,
    #: ``seconds``, ...) of a bisected step are the totals over every attempt, the failed ones included.
    substeps: int = 1
    smallest_substep: float = 1.0
    #: What the driver left out at this step and why (e.g. the exact enumeration of a problem
    #: that is not affine), ``"; "``-separated; ``""`` when nothing was.
    notes: str = ""

    @property
    def bisected(self) -> bool:
        """Whether the step was bisected (reached through sub-steps, or failed at the smallest)."""
        return self.smallest_substep < 1.0

    def diagnostics(self) -> dict:
        d = asdict(self)
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in d.items()}


@dataclass
class PathResult:
    """The steps of one variant x formulation along the load path."""

    variant: str
    formulation: str
    steps: list[StepResult] = field(default_factory=list)
    build_seconds: float = 0.0
    solve_seconds: float = 0.0
    #: What the driver left out for the whole path and why (one line each).
    warnings: list[str] = field(default_factory=list)
    #: How the DDCM projections were solved: reduced (Kirchdoerfer-Ortiz) or the full saddle point,
    #: and why; for a classical path, condensed on the contact pairs (Delassus) or full, and why
    #: (:func:`~ddcm_casadi.drivers.ddcm_reduced.path_description`; ``""`` if not built by its builders).
    projection_path: str = ""

    @property
    def converged(self) -> bool:
        return all(s.converged for s in self.steps)

    def array(self, name: str) -> np.ndarray:
        """Per-step values of a field, stacked (``u`` and ``p`` give ``(n_steps, n)`` arrays)."""
        return np.array([getattr(s, name) for s in self.steps])


def check_convergence(step: StepResult, raise_on_failure: bool, label: str) -> None:
    """Raise :class:`ConvergenceError` for a step that did not converge, if asked to."""
    if raise_on_failure and not step.converged:
        raise ConvergenceError(f"{label}: step {step.step} did not converge ({step.message})",
                               step.diagnostics())


@dataclass
class MaterialStates:
    """The material states ``z*`` the ``Z_E`` projection is given: per point strain and stress
    (as :meth:`~ddcm_casadi.problems.build.ProblemPair.projection_params` takes them) and, for a scheme
    that assigns data, the global data indices (``None`` otherwise)."""

    strain: np.ndarray
    stress: np.ndarray
    index: np.ndarray | None = None

    @property
    def key(self) -> bytes:
        """A hashable identity of an assignment (visited sets of restarts and greedy moves)."""
        return self.index.tobytes() if self.index is not None else self.strain.tobytes() + self.stress.tobytes()


@dataclass
class Run:
    """One alternating-projection run of one load step from one start.

    ``star`` are the last material states (the ones the run stopped at), ``sol`` the last ``Z_E``
    projection and ``fields`` its physical fields; ``distance`` the objective
    ``1/2 sum_i w_i d^2(z_i, z*_i)`` (``inf`` when the projection failed)."""

    star: MaterialStates
    sol: object
    fields: dict
    distance: float
    converged: bool
    message: str
    outer: int
    inner: int
    t_project: float
    t_search: float
    error: float
    is_global: bool | None

    @property
    def index(self) -> np.ndarray | None:
        return self.star.index

    def better_than(self, other: "Run") -> bool:
        """Fixed points before anything else, then a strictly lower objective (beyond roundoff)."""
        if self.converged != other.converged:
            return self.converged
        return self.distance < other.distance - 1e-12 * abs(other.distance)


def new_tally() -> dict:
    """The cost of one load step, summed over its runs (:func:`count`)."""
    return dict(projections=0, inner=0, runs=0, improvements=0, t_project=0.0, t_search=0.0)


def count(tally: dict, run: Run) -> None:
    """Add one run's cost to a step's tally."""
    tally["projections"] += run.outer
    tally["inner"] += run.inner
    tally["runs"] += 1
    tally["t_project"] += run.t_project
    tally["t_search"] += run.t_search
