"""``ddcm-validate`` rung for finite kinematics: the von Mises truss's snap-through
(:mod:`ddcm_casadi.models.von_mises`) against its closed form, classical and DDCM.

Checks, per formulation:

- every *accepted* (converged) classical step matches the closed form: exact formulations to
  :data:`EXACT_TOL`, the penalty to its derived bound (penetration ``p / gamma`` in ``u``; in ``p``
  the force's slope times that penetration, over the area);
- the contact status of every accepted step (contact, then lost at the snap, then regained) is the
  closed form's;
- Fischer-Burmeister, the paper's method, converges at every step, the snap included;
- DDCM on Hookean ``(E, S)`` data converges to the closed form at the data-spacing rate (fitted
  log-log slope against the number of points, expected ``-1``), with the formulation that crosses
  the snap; every formulation's converged DDCM steps are within the data's stress spacing.

Steps a formulation does not converge at are reported (counts in the notes and in
:func:`snap_table`), never counted as right.
"""

from __future__ import annotations

import numpy as np

from ddcm_casadi import formulations as registry

from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.drivers.harness import compare
from ddcm_casadi.validation.verification import Check, fitted_rate
from ddcm_casadi.models.von_mises import plane_force, von_mises_truss

#: Solver tolerances are 1e-9..1e-11 (scaled); results must agree to 1e-8 relative (as the ladder).
EXACT_TOL = 1e-8

#: Data for the DDCM runs: Hookean (E, S) pairs over the strains of the whole path.
STRAIN_RANGE = (-0.006, 0.008)
MODULUS = 200e9


def _closed_form(model) -> tuple[np.ndarray, np.ndarray]:
    u, p = zip(*(model.closed_form(k) for k in range(model.n_steps)))
    return np.array(u), np.array(p)


def _accepted_error(r, ref: np.ndarray, name: str) -> float:
    """Max over converged steps of ``|value - closed form|``, relative to the largest reference."""
    ok = np.array([s.converged for s in r.steps])
    if not ok.any():
        return float("nan")
    return float(np.max(np.abs(r.array(name) - ref)[ok])) / float(np.max(np.abs(ref)))


def contact_status(model, p: np.ndarray) -> np.ndarray:
    """Per step, whether the plane carries a pressure (the model's one rule)."""
    return np.asarray(model.active_contacts(np.asarray(p)), bool).reshape(model.n_steps, -1).any(axis=1)


def snap_table(cmp) -> str:
    """A step table of the path: travel, the closed form's descent and status, and per
    formulation the status it found (``C`` contact, ``-`` free, ``x`` not converged)."""
    m = cmp.model
    u_ref, p_ref = _closed_form(m)
    ref_status = contact_status(m, p_ref)
    runs = [(v, f) for (v, f) in cmp.results]
    head = "step  travel t   w closed  closed | " + " ".join(f"{v[:4]}/{f[:6]:<6}" for v, f in runs)
    lines = [head, "-" * len(head)]
    statuses = {key: contact_status(m, cmp.results[key].array("p")) for key in runs}
    for k in range(m.n_steps):
        cells = []
        for key in runs:
            s = cmp.results[key].steps[k]
            cells.append(f"{('x' if not s.converged else 'C' if statuses[key][k] else '-'):^11}")
        lines.append(f"{k:4d}  {m.load_parameter[k]:8.5f}  {-u_ref[k, 1]:8.5f}  {'C' if ref_status[k] else '-':^6} | "
                     + " ".join(cells))
    return "\n".join(lines)


def penalty_tolerances(cmp, u_ref: np.ndarray, p_ref: np.ndarray) -> tuple[float, float]:
    """Relative bounds of the penalty's error: penetration ``max p / gamma`` in ``u``, and
    ``max |F'(w)| max p / (gamma a)`` in ``p`` (10 % allowance for the penalty's own pressure)."""
    m = cmp.model
    gamma = next(f for f in cmp.formulations if f.name == "penalty").penalty_stiffness(cmp.problems.classical)
    a = float(m.contact_area[0])
    penetration = float(np.max(p_ref)) / gamma
    w = np.linspace(0.0, float(np.max(m.load_parameter)), 4001)
    F = plane_force(w, half_span=m.half_span, rise=m.rise, area=a, youngs_modulus=float(m.youngs_modulus[0]))
    slope = float(np.max(np.abs(np.gradient(F, w))))
    return (1.1 * penetration / float(np.max(np.abs(u_ref))),
            1.1 * slope * penetration / a / float(np.max(np.abs(p_ref))))


def _classical_checks(cmp) -> list[Check]:
    m = cmp.model
    u_ref, p_ref = _closed_form(m)
    tol_u, tol_p = penalty_tolerances(cmp, u_ref, p_ref)
    ref_status = contact_status(m, p_ref)
    out = []
    for f in registry.available():
        r = cmp["classical", f]
        ok = np.array([s.converged for s in r.steps])
        failed = [s.step for s in r.steps if not s.converged]
        note = (f"{len(failed)} of {m.n_steps} steps not converged: {failed} ({r.steps[failed[0]].message})"
                if failed else "every step converged, the snap included")
        tu, tp = (tol_u, tol_p) if f == "penalty" else (EXACT_TOL, EXACT_TOL)
        name = f"von Mises truss / classical / {f}"
        out.append(Check.make(name, "max rel. error of u vs closed form (converged steps)",
                              _accepted_error(r, u_ref, "u"), 0.0, tu, note=note))
        out.append(Check.make(name, "max rel. error of p vs closed form (converged steps)",
                              _accepted_error(r, p_ref, "p"), 0.0, tp,
                              note="penalty: derived bound, penetration p / gamma" if f == "penalty" else ""))
        status = contact_status(m, r.array("p"))
        out.append(Check.make(name, "converged steps with the wrong contact status",
                              int(np.sum(ok & (status != ref_status))), 0, 0))
    fb = cmp["classical", "fischer_burmeister"]
    lost = int(np.argmax(~ref_status[1:])) + 1
    regained = lost + int(np.argmax(ref_status[lost:]))
    out.append(Check.make("von Mises truss / classical / fischer_burmeister", "converged steps (snap included)",
                          sum(s.converged for s in fb.steps), m.n_steps, 0,
                          note=f"closed form: contact lost at step {lost}, regained at step {regained}"))
    return out


def _ddcm_rate(sizes, formulation: str) -> list[Check]:
    errors, notes = [], []
    for n in sizes:
        data = MaterialDataset.hookean(MODULUS, *STRAIN_RANGE, n, c=MODULUS)
        model = von_mises_truss(dataset=data, youngs_modulus=None)
        u_ref, p_ref = _closed_form(von_mises_truss())
        r = compare(model, [formulation], variants=("ddcm",))["ddcm", formulation]
        converged = sum(s.converged for s in r.steps)
        errors.append(max(_accepted_error(r, u_ref, "u"), _accepted_error(r, p_ref, "p")))
        notes.append(f"N={n}: {errors[-1]:.2e} ({converged}/{model.n_steps} steps)")
    slope, se = fitted_rate(sizes, errors)
    name = f"von Mises truss / ddcm / {formulation}"
    return [Check.make(name, "fitted rate d log(error) / d log(N)", slope, -1.0, 0.3,
                       note="; ".join(notes) + f"; standard error of the slope {se:.2f}. Expected -1: the "
                       "error is set by the data spacing (proportional to 1/N)"),
            Check.make(name, "converged steps at the largest N (snap included)", converged, model.n_steps, 0)]


def _ddcm_accepted(n: int) -> list[Check]:
    """Every formulation's converged DDCM steps against the closed form: the pressure within the
    data's stress spacing ``E_mod dE`` (it is a member stress times ``2 |h - w| / L0 < 1``)."""
    data = MaterialDataset.hookean(MODULUS, *STRAIN_RANGE, n, c=MODULUS)
    model = von_mises_truss(dataset=data, youngs_modulus=None)
    reference = von_mises_truss()
    u_ref, p_ref = _closed_form(reference)
    de = (STRAIN_RANGE[1] - STRAIN_RANGE[0]) / (n - 1)
    spacing = MODULUS * de
    # A strain off by dE moves the apex by dE / |dE/dw| = dE L0^2 / |h - w|, at most dE L0^2 / h on
    # the path's free and tension states; ten times that marks a fixed point on another branch.
    far = 10 * de * (reference.half_span**2 + reference.rise**2) / reference.rise
    cmp = compare(model, variants=("ddcm",))
    out = []
    for f in registry.available():
        r = cmp["ddcm", f]
        ok = np.array([s.converged for s in r.steps])
        failed = [s.step for s in r.steps if not s.converged]
        error = float(np.max(np.abs(r.array("p") - p_ref)[ok])) if ok.any() else float("nan")
        other = [int(k) for k in np.flatnonzero(ok & (np.abs(r.array("u")[:, 1] - u_ref[:, 1]) > far))]
        out.append(Check.make(f"von Mises truss / ddcm / {f}", f"max |p - closed form| (Pa) of converged steps, N={n}",
                              error, 0.0, spacing,
                              note=(f"{len(failed)} of {model.n_steps} steps not converged: {failed}" if failed
                                    else "every step converged, the snap included")
                              + f"; tolerance: the data's stress spacing {spacing:.3g} Pa"
                              + (f"; local DDCM minima (apex more than {far:.2g} m from the closed form, members "
                                 f"unloaded at the plane): steps {other}" if other else "")))
    return out


def rung_von_mises(*, sizes=(101, 201, 401, 801, 1601)) -> list[Check]:
    """The von Mises truss's snap-through: classical against the closed form, DDCM's rate and
    every formulation's converged DDCM steps."""
    cmp = compare(von_mises_truss(), variants=("classical",))
    return _classical_checks(cmp) + _ddcm_rate(sizes, "mpcc") + _ddcm_accepted(sizes[-1])
