"""Physical checks of a step, in physical units, run by every driver before a step is reported:
roundoff clipped (:func:`clip_roundoff`), penetration, equilibrium and the sign of the contact
pressures checked (:func:`physical_check`), the true equilibrium of the physical fields
(:func:`equilibrium_error`), the data's range (:func:`finish_step`)."""

from __future__ import annotations

import numpy as np

from ddcm_casadi.drivers.records import StepResult


#: Relative tolerance of the physical checks of a step (:func:`physical_check`): at least a thousand
#: times the default stopping tests of every formulation (1e-9 to 1e-11, scaled), so a step that met its
#: solver's own test in well-scaled units always passes; what fails is a step whose scaled test
#: passed while the physical answer is wrong by orders of magnitude (degenerate scales, a metric
#: far from the data's modulus).
PHYSICAL_TOL = 1e-6
#: A penalty formulation penetrates by ``p / gamma``: its allowance is that of a contact pressure of
#: this many times the problem's stress scale. Pressures are O(1) in that scale by construction
#: (measured at most 1.0 over the examples: bars, trusses, Hertz), so ten times is generous for a
#: sound solution and still far below a penetration that carries nonsense pressures.
PENALTY_PRESSURE_BOUND = 10.0
#: Roundoff of a value computed from terms of size ``s``: ``64 eps s``, the floor at which Newton
#: accepts a residual (docs/maths.md, Sec. 6). Below it a displacement or a pressure of the wrong
#: sign is zero (:func:`clip_roundoff`).
ROUNDOFF = 64 * np.finfo(float).eps


def _step_scale(values: np.ndarray, reference: float) -> float:
    """The size of the terms a step's ``values`` are computed from: the problem's reference
    magnitude or the step's largest finite value, whichever is larger."""
    v = np.abs(np.asarray(values, dtype=float))
    return max(reference, float(np.max(v[np.isfinite(v)], initial=0.0)))


def clip_roundoff(step: StepResult, problem) -> None:
    """Zero the roundoff of a step's physical fields, in place (before anything reports them).

    A contact pressure in ``(-t_p, 0)`` and a displacement with ``|u| < t_u`` are zero, with
    ``t = ROUNDOFF x`` the step's scale (:data:`ROUNDOFF`; the scale is the problem's stress or
    displacement unit, ``problem.pressure_ref`` / ``problem.gap_ref``, or the step's largest
    value if larger). Removed on the paper's bar, for example: ``p = -9.3e-7 Pa`` (a free step of
    the DDCM augmented Lagrangian; the stress scale is 2e9 Pa) and ``u = -3.1e-35 m`` (the tip at
    an obstacle that just touches it). A pressure negative beyond roundoff is kept (and
    :func:`physical_check` judges it).
    """
    p = np.array(step.p, dtype=float)
    t_p = ROUNDOFF * _step_scale(p, problem.pressure_ref)
    p[(p < 0) & (p > -t_p)] = 0.0
    u = np.array(step.u, dtype=float)
    u[np.abs(u) < ROUNDOFF * _step_scale(u, problem.gap_ref)] = 0.0
    step.p, step.u = p, u


def physical_check(step: StepResult, problem, length_scale: float, *,
                   penalty_stiffness: float | None = None) -> str:
    """Why a step fails in physical units, or ``""``: the one place a step's physics is checked.

    Checked, with ``tol`` = :data:`PHYSICAL_TOL`:

    - finite displacements and contact pressures;
    - penetration ``max(0, -g)`` (m) at most ``tol min(U, L)`` (``U`` the displacement scale,
      ``problem.gap_ref``; ``L`` the model's length scale), plus, for a penalty formulation of
      stiffness ``gamma`` (Pa/m), its expected penetration ``p / gamma`` for pressures up to
      :data:`PENALTY_PRESSURE_BOUND` times the stress scale ``S = problem.pressure_ref``;
    - equilibrium: the residual (relative to the forces that cancel in it,
      :meth:`~ddcm_casadi.problems.contract.ComplementarityProblem.relative_residual`) at most ``tol``;
    - the sign of the contact pressures: ``p >= -tol max(S, max |p|)``.

    Parameters
    ----------
    step : StepResult
        ``penetration`` and ``residual`` scaled as the formulations report them; ``u``, ``p`` in
        physical units.
    problem : ComplementarityProblem
        The problem the step solved (its scales).
    length_scale : float
        The model's characteristic length (m).
    penalty_stiffness : float, optional
        ``gamma`` of a penalty formulation (:meth:`Formulation.penalty_stiffness`); ``None`` for a
        formulation that enforces contact exactly.

    Returns
    -------
    str
        ``"physical check failed: ..."`` naming each failed check and by how much, or ``""``.
    """
    if not (np.all(np.isfinite(step.u)) and np.all(np.isfinite(step.p))):
        return "physical check failed: non-finite displacements or contact pressures"
    failed = []
    penetration = step.penetration * problem.gap_ref
    allowed = PHYSICAL_TOL * min(problem.gap_ref, length_scale)
    if penalty_stiffness:
        allowed += PENALTY_PRESSURE_BOUND * problem.pressure_ref / penalty_stiffness
    if not penetration <= allowed:
        failed.append(f"penetration {penetration:.3g} m > {allowed:.3g} m allowed ({penetration / allowed:.2g} times)")
    if not step.residual <= PHYSICAL_TOL:
        failed.append(f"equilibrium residual {step.residual:.3g} > {PHYSICAL_TOL:g} (relative to the forces)")
    p_min = float(np.min(step.p, initial=0.0))
    floor = PHYSICAL_TOL * _step_scale(step.p, problem.pressure_ref)
    if p_min < -floor:
        failed.append(f"contact pressure {p_min:.3g} Pa < 0 (beyond -{floor:.3g} Pa, {-p_min / floor:.2g} times)")
    return "physical check failed: " + "; ".join(failed) if failed else ""


#: The true equilibrium error (:func:`equilibrium_error`, at most :data:`PHYSICAL_TOL`, which a
#: singular solve misses by five orders of magnitude) is measured against at least this many
#: times the problem's force unit: the solvers stop at 1e-9 to 1e-11 of their scaled units, so a
#: step whose load is below 1e-6 of the force unit (a step before contact, a zero load) carries
#: only roundoff, and dividing by it would turn roundoff into a failure (measured: 8e-10 N of
#: roundoff against a zero load on the compression patch test, whose force unit is 2e5 N/m).
EQUILIBRIUM_FLOOR = 1e-6


def _force_scale(problem, model) -> float:
    """The force unit of the problem a step solved (its model's classical or DDCM scales)."""
    try:
        return float(model.scales_for("classical" if problem.kind == "mcp" else "ddcm").get("force", 0.0))
    except (AttributeError, KeyError, ValueError):  # a model without scales of that kind: no floor
        return 0.0


def equilibrium_error(step: StepResult, model, force_floor: float = 0.0, load: np.ndarray | None = None
                      ) -> float | None:
    """The true equilibrium error of a step's physical fields relative to its forces, or ``None``
    where it is not defined here.

    ``r = B^T (w sigma) - f - G^T (a p)`` (``B`` the strain operator, ``w`` the point volumes,
    ``sigma`` the step's stress, ``f`` its load, ``G`` the gap operator, ``a`` the contact areas),
    recomputed from the physical fields rather than taken from the solver: a solve of a singular
    system (a body no support holds) can meet its own scaled test while ``r`` is of the order of
    the load (measured: 3 times the load, 0.4 of the element forces). The error is
    ``max |r| / max(max |f|, max |G^T a p|, max |B|^T (w |sigma|), force_floor)``: relative to
    the terms that cancel in ``r`` (the load and the element forces, as in a backward error;
    a slender structure's element forces exceed its load by orders of magnitude, and roundoff
    in ``r`` follows them), ``force_floor`` keeping a step that carries nothing from dividing
    roundoff by zero. ``load``: the step's ``f`` when it is not ``model.loads[step.step]`` (a
    sub-step's, :mod:`~ddcm_casadi.drivers.substeps`).

    Defined for small kinematics, the normal (Signorini) contact law and models whose steps carry
    no history (their load is ``model.loads[step]``), with the step's stress known; ``None`` else.
    """
    if step.stress is None or model.kinematics != "small" or model.contact_law != "signorini" or model.history_sizes():
        return None
    B = model.strain_operator
    stress = np.asarray(step.stress, dtype=float).reshape(-1)
    p = np.asarray(step.p, dtype=float).reshape(-1)
    if stress.size != B.shape[0] or p.size != model.n_contacts or not 0 <= step.step < model.n_steps:
        return None
    weights = np.repeat(model.volumes, model.strain_components)
    contact = model.gap_operator.T @ (model.contact_area * p)
    f = np.asarray(model.loads[step.step] if load is None else load, dtype=float).reshape(-1)
    r = B.T @ (weights * stress) - f - contact
    terms = abs(B).T @ (weights * np.abs(stress))
    forces = max(float(np.max(np.abs(f), initial=0.0)), float(np.max(np.abs(contact), initial=0.0)), force_floor)
    error = float(np.max(np.abs(r), initial=0.0))
    scale = max(forces, float(np.max(terms, initial=0.0)))
    return error / scale if scale > 0 else 0.0


def finish_step(step: StepResult, problem, model, *, penalty_stiffness: float | None = None,
                coverage=None, load: np.ndarray | None = None,
                nearest: np.ndarray | None = None) -> None:
    """What every driver does to a step before reporting it, in place: :func:`clip_roundoff`,
    :func:`physical_check` (a failure makes a converged step not converged and says why in its
    message; so does a true equilibrium error, :func:`equilibrium_error`, above :data:`PHYSICAL_TOL`,
    and a state the model calls inadmissible, :meth:`~ddcm_casadi.models.base.ContactModel.inadmissible`:
    an inverted element at finite strain)
    and, with a :class:`~ddcm_casadi.data.extrapolation.DataCoverage`, the count of states
    beyond the data (``extrapolated``, ``data_spacings``: a flag, not a failure). ``load``: the
    step's ``f`` when it is not the model's (a sub-step's, :mod:`~ddcm_casadi.drivers.substeps`).
    ``nearest``: the datum nearest each of the step's states where the run already searched them
    (:meth:`~ddcm_casadi.drivers.scheme.MaterialScheme.nearest_index`)."""
    clip_roundoff(step, problem)
    failure = physical_check(step, problem, model.length_scale, penalty_stiffness=penalty_stiffness)
    error = (equilibrium_error(step, model, EQUILIBRIUM_FLOOR * _force_scale(problem, model), load)
             if np.all(np.isfinite(step.u)) else None)
    if error is not None and not error <= PHYSICAL_TOL:
        what = (f"true equilibrium error |B^T w sigma - f - G^T a p| {error:.3g} of the forces (load, element forces) "
                f"> {PHYSICAL_TOL:g}")
        failure = f"{failure}; {what}" if failure else f"physical check failed: {what}"
    # a state the equations admit but the body cannot take (finite strain: an inverted element)
    inadmissible = model.inadmissible(step.u) if np.all(np.isfinite(step.u)) else None
    if inadmissible:
        failure = f"{failure}; {inadmissible}" if failure else f"inadmissible state: {inadmissible}"
    if failure and step.converged:
        step.converged = False
        step.message = f"{step.message}, but {failure}" if step.message else failure
    if coverage is not None and step.strain is not None:
        beyond, spacings = coverage.check(step.strain, step.stress, nearest)
        step.extrapolated = int(np.sum(beyond))
        finite = spacings[np.isfinite(spacings)]
        step.data_spacings = float(np.max(finite)) if finite.size else float("nan")
