"""The DDCM projection through the Kirchdoerfer-Ortiz reduction, and the classical problem through
its Delassus condensation (:mod:`ddcm_casadi.problems.reduction`, ``docs/maths.md`` section 17),
behind the interface of a built formulation.

:func:`build_projection` is how drivers build the projection's formulation: reduced where the
reduction applies and is asked for (the default), the formulation built on the full saddle-point
problem otherwise. A reduced projection is the chosen formulation built on the condensed problem
(the contact pairs only; none without contact), with the displacements and stresses recovered by
one solve with the kept factor; its solutions, residuals and objectives are the full projection's.
:func:`build_classical` does the same for the classical problem (:class:`ClassicalReduction`:
the formulation on the pairs' linear complementarity problem, ``u`` by one solve with the kept
factor of ``K``).
"""

from __future__ import annotations

import numpy as np

from ddcm_casadi.formulations.base import BuiltFormulation, LocalSolution
from ddcm_casadi.heap import release_heap
from ddcm_casadi.linalg import definite_solver_name, solver_name
from ddcm_casadi.parallel import limited_blas
from ddcm_casadi.problems.build import ProblemPair
from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.problems.reduction import (
    ClassicalReduction, NotReducible, Reduction, classical_refusal, condition_limit, refusal,
)

#: How a path's projection was solved (``PathResult.projection_path``).
FULL = "full saddle point ({why})"
#: How a classical path was solved, when not condensed.
CLASSICAL_FULL = "full ({why})"


class ReducedProjection(BuiltFormulation):
    """A formulation solving the condensed problem of a projection (or of a classical problem),
    returning the full problem's solutions (:class:`~ddcm_casadi.formulations.base.LocalSolution`
    of the full unknowns).

    Parameters
    ----------
    problem : ComplementarityProblem
        The full problem (residuals, gaps and objectives are evaluated on it).
    reduction : Reduction or ClassicalReduction
        Its reduction (the kept factor, the condensed problem; ``particular(params)`` a tuple
        passed on to ``condensed_params`` and ``recover``).
    inner : BuiltFormulation or None
        The formulation built on :attr:`Reduction.condensed` (``None`` without contact pairs:
        the projection is then the solve with the kept factor alone).
    """

    def __init__(self, problem: ComplementarityProblem, reduction: Reduction, inner: BuiltFormulation | None,
                 full=None) -> None:
        super().__init__(problem)
        self.reduction, self.inner = reduction, inner
        #: Builds the formulation on the full problem: where a condensed solve fails, this and every
        #: later projection take the full path (measured: the 1000-panel Warren truss's condensed
        #: FB solves failed and bisected for minutes where the full path converged in 0.4 s).
        self._full_factory, self._full = full, None
        self._full_path = FULL if problem.kind == "mpcc" else CLASSICAL_FULL
        self.penalty_stiffness = None if inner is None else inner.penalty_stiffness
        self.path = reduction.description
        #: Without contact pairs the projection is the closed form of the exact one (no branch to
        #: enumerate): the driver skips the enumeration's check.
        self.closed_form = inner is None

    def reset(self) -> None:
        """Forget the condensed formulation's caches (the reduction's factor is the model's: kept)."""
        if self.inner is not None:
            self.inner.reset()

    @property
    def stats(self) -> dict:
        inner = dict(self.inner.stats) if self.inner is not None else {}
        return {**inner, "reduced": 1, "reduction_factorizations": self.reduction.factorizations,
                "condensed_pairs": self.reduction.nc}

    def solve(self, params: np.ndarray, x0: np.ndarray, p0: np.ndarray, state: dict | None = None) -> LocalSolution:
        """The projection at ``params`` from ``(x0, p0)`` (scaled): the condensed problem from
        the gaps of ``x0`` (:meth:`Reduction.condensed_start`) and ``p0``, then ``x`` recovered."""
        if self._full is not None:
            return self._full.solve(params, x0, p0, state)
        red = self.reduction
        params = np.asarray(params, float)
        base = red.particular(params)
        if self.inner is None:
            w, p, converged, iterations, outer, state, message = np.zeros(0), np.zeros(0), True, 1, 0, None, ""
        else:
            sol = self.inner.solve(red.condensed_params(params, *base), red.condensed_start(params, x0),
                                   np.asarray(p0, float), state)
            w, p, converged, iterations = sol.x, sol.p, sol.converged, sol.iterations
            outer, state, message = sol.outer_iterations, sol.state, sol.message
            if not converged and self._full_factory is not None:
                self._full = self._full_factory()
                self.path = self.projection_path = self._full_path.format(why=f"a condensed solve failed ({message})")
                full = self._full.solve(params, x0, p0, None)
                full.iterations += iterations
                return full
        x = red.recover(params, *base, w, p)
        return self._finish(x, p, params, converged=converged, iterations=iterations, outer=outer, state=state,
                            message=message)


@limited_blas
def build_projection(formulation, problems: ProblemPair, *, reduce: bool = True) -> BuiltFormulation:
    """The projection's formulation, built: reduced (:class:`ReducedProjection`) when ``reduce``
    and the reduction applies (:func:`~ddcm_casadi.problems.reduction.refusal`), else built on the
    full problem. ``path_description(built)`` says which and why."""
    problem = problems.projection
    formulation.check_supports(problem)
    return _built(formulation, problems, problem, refusal(problem) if reduce else "reduction off", Reduction, FULL)


@limited_blas
def build_classical(formulation, problems: ProblemPair, *, reduce: bool = True) -> BuiltFormulation:
    """The classical problem's formulation, built: condensed on the contact pairs
    (:class:`~ddcm_casadi.problems.reduction.ClassicalReduction`, in a :class:`ReducedProjection`)
    when ``reduce`` and the condensation applies
    (:func:`~ddcm_casadi.problems.reduction.classical_refusal`, a well-conditioned Delassus
    matrix), else built on the full problem. ``path_description(built)`` says which and why."""
    problem = problems.classical
    formulation.check_supports(problem)
    why = classical_refusal(problem) if reduce else "condensation off"
    return _built(formulation, problems, problem, why, ClassicalReduction, CLASSICAL_FULL)


def _built(formulation, problems: ProblemPair, problem: ComplementarityProblem, why: str, kind: type,
           full: str) -> BuiltFormulation:
    """``formulation`` built on the condensed problem of ``problem``'s reduction (a ``kind``,
    made once per problem and solvers of ``K``), in a :class:`ReducedProjection`; on ``problem``
    itself if ``why`` says why not, or the reduction refuses (its ``projection_path``: ``full``
    with the reason). The model's kept factor of its scales' stiffness
    (:meth:`~ddcm_casadi.models.base.ContactModel.stiffness_factor`) goes to the reduction, which
    shares it or lets it go; on the full path it is let go."""
    if not why:
        reduction = problem.shared((kind.__name__, definite_solver_name(), solver_name()),
                                   lambda: _reduction(problem, problems.model, kind))
        why = reduction if isinstance(reduction, str) else _too_ill_conditioned(formulation, problem, reduction)
    if why:
        _let_go(problems.model.stiffness_factor())  # the full path makes its own
        built = formulation.build(problem)
        built.projection_path = full.format(why=why)
        return built
    inner = formulation.build(reduction.condensed) if reduction.nc else None
    built = ReducedProjection(problem, reduction, inner, full=lambda: formulation.build(problem))
    built.projection_path = built.path
    # the build's temporaries, before the solves' pages (the Hertz body's classical run of 95 485
    # unknowns: its peak 364 -> 355 MiB, docs/performance.md)
    release_heap()
    return built


def _too_ill_conditioned(formulation, problem: ComplementarityProblem, reduction) -> str:
    """Why ``formulation``'s own residual tolerance is too tight for the condensed solve
    (:func:`~ddcm_casadi.problems.reduction.condition_limit`: the augmented Lagrangian and the
    MPCC accept at 1e-10, a decade below the shared limit's 1e-9), or ``""``."""
    tol = formulation.resolved_options(problem).get("residual_tol")
    if tol is None or reduction.condition <= condition_limit(tol):
        return ""
    return (f"a Delassus condition of {reduction.condition:.1e}, above {condition_limit(tol):.1e} for the residual "
            f"tolerance {tol:g}: the condensed solve's roundoff would exceed it")


def _reduction(problem: ComplementarityProblem, model, kind: type):
    """The reduction of ``problem`` (a ``kind``), or why it does not apply (a singular or
    ill-conditioned Delassus matrix). It takes the model's kept factor of its scales' stiffness
    (:meth:`~ddcm_casadi.models.base.ContactModel.stiffness_factor`): its own where it is a
    multiple of it, else let go before a factorisation of its own."""
    try:
        return kind(problem, model.near_null_space(), known=model.stiffness_factor())
    except NotReducible as exc:
        return str(exc)


def _let_go(factor) -> None:
    """Release the model's kept factor (a :class:`~ddcm_casadi.models.stiffness.StiffnessFactor`), if any."""
    if factor is not None:
        factor.release()


def path_description(built) -> str:
    """How ``built`` solves the projection (set by :func:`build_projection`; ``""`` if not built by it)."""
    return getattr(built, "projection_path", "")
