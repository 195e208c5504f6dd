"""The verification ladder run by ``ddcm-validate``: each rung checks one claim against an
independent reference, with a tolerance derived from the method.

Every check is a :class:`Check` with ``name``, ``quantity``, ``value``, ``reference``,
``tolerance`` and ``passed = |value - reference| <= tolerance``. Errors are relative to the largest
reference magnitude along the load path.

Rungs
-----
1. The paper's bar against its closed form (every formulation, both variants).
2. A bar with stops that close one after another against its closed form (upper concave envelope).
3. Classical 2-D and 3-D truss contact against an independent convex QP (qpOASES through
   ``casadi.conic``); the penalty against the QP of the penalised problem.
4. DDCM converging to the classical solution as the data set grows: fitted log-log rate.
5. A 4-member truss without contact, DDCM with 5 000 and 10 000 Hookean points, to 1e-2.
6. Active sets (<= 12 contacts) against enumeration of all of them; the DDCM projections against
   enumeration of all branches of ``Z_E``, reporting every local minimum.
9. DDCM search quality on noisy 1-D data: restarts + greedy at the enumerated global optimum at
   >= 95 % of the steps for <= 5x the projections of plain alternating.
10. Finite kinematics: the von Mises truss pushed through its snap by a rigid plane against its
    closed form (every formulation's converged steps, contact lost and regained; DDCM's
    data-spacing rate), :mod:`ddcm_casadi.validation.finite_rungs`.
11. Finite-strain continua: homogeneous compression against its closed form, the small-load limit
    of Hertz, a sphere to 0.3 R on a coarse mesh, DDCM's rate on Neo-Hookean data,
    :mod:`ddcm_casadi.validation.finite_strain_rungs` (its mesh sequence: ``python -m`` it).
12. Prescribed displacements (a hard device), classical and DDCM, every formulation: the tutorial
    bar (E = 1, u = 1) against ``sigma = E u / L``, a bar pulled onto a stop, a truss against the
    stiffness method, a stretched continuum patch (:mod:`ddcm_casadi.validation.hard_device_rungs`).
"""

from __future__ import annotations

import functools
import time
from typing import Callable

import numpy as np

from ddcm_casadi import formulations as registry

from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.problems.exact import ExactEnumerator
from ddcm_casadi.drivers.harness import compare
from ddcm_casadi.models.bar import paper_bar
from ddcm_casadi.validation.reference import ContactQP
from ddcm_casadi.models import truss
from ddcm_casadi.models.truss import Obstacle, bar_chain, truss_model
from ddcm_casadi.validation import continuum as continuum_rungs
from ddcm_casadi.validation.quality_rungs import rung_search_quality
from ddcm_casadi.validation.fixed_points import check_fixed_points
from ddcm_casadi.validation.finite_rungs import rung_von_mises
from ddcm_casadi.validation import finite_strain_rungs, friction_rungs, hard_device_rungs, mindlin, two_body_rungs
from ddcm_casadi.validation.verification import (  # noqa: F401 - as_records, markdown: ddcm-validate's API
    Check, as_records, fitted_rate, markdown,
)

EXACT = ("augmented_lagrangian", "fischer_burmeister", "mpcc")
#: Solver tolerances are 1e-9..1e-11 (scaled); results must agree to 1e-8 relative.
EXACT_TOL = 1e-8


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    scale = float(np.max(np.abs(b), initial=0.0)) or 1.0
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b)), initial=0.0)) / scale


# --------------------------------------------------------------------------- models of the ladder
def stops_bar(*, n_data: int = 2000) -> "bar_chain":
    """10-element bar, tip obstacle 1.0 -> 0.98 m, stops behind nodes 3, 6 and 8."""
    return bar_chain(length=1.0, elements=10, youngs_modulus=200e9, tip_positions=np.linspace(1.0, 0.98, 11),
                     stops={3: 0.004, 6: 0.006, 8: 0.01},
                     dataset=MaterialDataset.hookean(200e9, -0.05, 0.01, n_data, c=300e9))


def warren_truss(*, n_data: int = 2001, panels: int = 4, steps: int = 7):
    """2-D Warren truss on a pin and a roller, loaded from above onto a plane under its bottom chord."""
    return truss.warren_truss(panels=panels, gap=0.002, contact_nodes=range(1, panels),
                              load_factors=np.linspace(0.5, 3.0, steps),
                              dataset=MaterialDataset.hookean(200e9, -0.004, 0.004, n_data, c=200e9),
                              name="2-D Warren truss")


def tower_3d(*, n_data: int = 2001):
    """3-D truss hanging from four fixed top nodes; a rising plane z >= d closes on its five
    bottom nodes (at different heights) one after another."""
    top = [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
    bottom = [(0, 0, 0.0), (1, 0, 0.002), (1, 1, 0.004), (0, 1, 0.006), (0.5, 0.5, 0.003)]
    X = np.array(top + bottom, dtype=float)
    b = [4, 5, 6, 7]
    members = ([(b[i], i) for i in range(4)] + [(b[i], (i + 1) % 4) for i in range(4)]
               + [(b[i], (i + 3) % 4) for i in range(4)] + [(b[i], b[(i + 1) % 4]) for i in range(4)]
               + [(8, bi) for bi in b] + [(8, 0), (8, 2)])
    data = MaterialDataset.hookean(200e9, -0.01, 0.01, n_data, c=200e9)
    return truss_model(nodes=X, members=np.array(members), area=1e-4, youngs_modulus=200e9,
                       supports=[(i, "xyz") for i in range(4)],
                       obstacles=[Obstacle(normal=[0, 0, 1], offset=np.linspace(-0.001, 0.008, 10), nodes=b + [8])],
                       dataset=data, name="3-D tower on a plane")


def four_member_truss(*, n_data: int):
    """A free node tied by four members to fixed nodes, loaded obliquely (no contact)."""
    X = np.array([(0.0, 0.0), (-1.0, 1.0), (-0.3, 1.0), (0.4, 1.0), (1.0, 1.0)])
    members = np.array([(0, 1), (0, 2), (0, 3), (0, 4)])
    loads = np.zeros_like(X)
    loads[0] = (2e4, -1e5)
    data = MaterialDataset.hookean(200e9, -0.005, 0.005, n_data, c=200e9)
    return truss_model(nodes=X, members=members, area=1e-4, youngs_modulus=200e9,
                       supports=[(i, "xy") for i in range(1, 5)], loads=loads, load_factors=[0.5, 1.0],
                       dataset=data, name="4-member truss")


def many_stops_bar():
    """20-element bar with stops behind 11 nodes: 12 contact pairs."""
    stops = {2 * j: 0.0015 * j for j in range(1, 10)} | {19: 0.016, 1: 0.0005}
    return bar_chain(length=1.0, elements=20, youngs_modulus=200e9, tip_positions=np.linspace(1.0, 0.975, 11),
                     stops=stops, name="bar with 11 stops")


# --------------------------------------------------------------------------------------- rungs
@functools.lru_cache(maxsize=None)
def _compare(builder: Callable, variants: tuple = ("classical", "ddcm")):
    """One comparison per ladder model, shared by the rungs (cleared by :func:`run_ladder`)."""
    return compare(builder(), variants=variants)


def _classical_against(name: str, cmp, ref_u, ref_p, reference: str) -> list[Check]:
    out = []
    for f in EXACT:
        r = cmp["classical", f]
        out.append(Check.make(f"{name} / classical / {f}", f"max rel. error of u vs {reference}",
                              _rel(r.array("u"), ref_u), 0.0, EXACT_TOL))
        out.append(Check.make(f"{name} / classical / {f}", f"max rel. error of p vs {reference}",
                              _rel(r.array("p"), ref_p), 0.0, EXACT_TOL))
    return out


def _gamma(cmp, name: str = "penalty") -> float:
    """The physical penalty stiffness (Pa/m) a comparison used for formulation ``name``."""
    return next(f for f in cmp.formulations if f.name == name).penalty_stiffness(cmp.problems.classical)


def _penalty_against_qp(name: str, cmp) -> list[Check]:
    gamma = _gamma(cmp)
    ref = ContactQP(cmp.model, penalty=gamma).solve()
    r = cmp["classical", "penalty"]
    return [Check.make(f"{name} / classical / penalty", "max rel. error of u vs penalised QP",
                       _rel(r.array("u"), ref.u), 0.0, EXACT_TOL, note=f"gamma = {gamma:.3g} Pa/m"),
            Check.make(f"{name} / classical / penalty", "max rel. error of p vs penalised QP",
                       _rel(r.array("p"), ref.p), 0.0, EXACT_TOL)]


def _penalty_bound(cmp) -> float:
    """Penalty error bound ``max diag(K) / (gamma min a)``: the contact point's stiffness (per
    unit contact area) over the penalty, as ``k / (k + gamma)`` for the paper's bar."""
    gamma = _gamma(cmp)
    k = float(cmp.model.stiffness().diagonal().max())
    return k / (gamma * float(np.min(cmp.model.contact_area)))


def _penalty_tilt(cmp, name: str) -> float:
    """A penalty projection's distance from the exact one: ``c / (gamma l_e)`` (scaled), the tilt
    of its contact branch in the (strain, stress) plane, ``l_e = 1 / max |B|`` the shortest element."""
    m = cmp.model
    gamma = _gamma(cmp, name)
    l_e = 1.0 / float(abs(m.strain_operator).max())
    return float(np.max(m.metric)) / (gamma * l_e)


def _ddcm_fixed_points(name: str, cmp) -> list[Check]:
    out = []
    m = cmp.model
    exact = ExactEnumerator(cmp.problems.projection)  # one set of factorisations for every formulation
    for f in registry.available():
        r = cmp["ddcm", f]
        out.append(Check.make(f"{name} / ddcm / {f}", "converged steps", sum(s.converged for s in r.steps),
                              m.n_steps, 0))
        rep = check_fixed_points(cmp.problems, r, exact=exact)
        tol = EXACT_TOL
        note = "exact projection (branch enumeration) of the assigned data"
        if f == "penalty":
            # Penalty projections tilt the contact branch (docs/maths.md, Sec. 4).
            tol = _penalty_tilt(cmp, f)
            note = "penalty: tolerance c / (gamma l_e), the tilt of its contact branch"
        out.append(Check.make(f"{name} / ddcm / {f}", "max projection error (u, p), scaled",
                              max(np.max(rep.projection_error_u), np.max(rep.projection_error_p)), 0.0, tol, note))
        out.append(Check.make(f"{name} / ddcm / {f}", "steps whose datum is not the nearest (brute force)",
                              int(np.sum(~rep.nearest)), 0, 0))
    return out


def rung_paper() -> list[Check]:
    cmp = _compare(paper_bar)
    m = cmp.model
    ref_u, ref_p = (np.array(v) for v in zip(*(m.closed_form(k) for k in range(m.n_steps))))
    out = _classical_against("paper bar", cmp, ref_u, ref_p, "closed form")
    gamma = registry.get("penalty").penalty_stiffness(cmp.problems.classical)
    pen = [m.penalty_closed_form(k, gamma) for k in range(m.n_steps)]
    r = cmp["classical", "penalty"]
    out.append(Check.make("paper bar / classical / penalty", "max rel. error of u vs penalty closed form",
                          _rel(r.array("u"), np.array([a for a, _ in pen])), 0.0, EXACT_TOL))
    out.append(Check.make("paper bar / classical / penalty", "max rel. error of p vs penalty closed form",
                          _rel(r.array("p"), np.array([b for _, b in pen])), 0.0, EXACT_TOL))
    out += _ddcm_fixed_points("paper bar", cmp)
    summary = {(s["variant"], s["formulation"]): s for s in cmp.summary()}
    loc = summary["ddcm", "fischer_burmeister"]["local_minimum_h"]
    out.append(Check.make("paper bar / ddcm", "steps at a local (not global) DDCM minimum, by data enumeration",
                          len(loc), len(loc), 0,
                          note="reported, not a failure: alternating projections find local minima; "
                               + ("at h = " + ", ".join(f"{h:.4g}" for h in loc) if loc else "none")))
    return out


def rung_stops() -> list[Check]:
    cmp = _compare(stops_bar)
    m = cmp.model
    ref = [m.closed_form(k) for k in range(m.n_steps)]
    ref_u, ref_p = np.array([a for a, _ in ref]), np.array([b for _, b in ref])
    out = _classical_against("bar with 3 stops", cmp, ref_u, ref_p, "closed form")
    r = cmp["classical", "penalty"]
    bound = _penalty_bound(cmp)
    out.append(Check.make("bar with 3 stops / classical / penalty", "max rel. error of u vs closed form",
                          _rel(r.array("u"), ref_u), 0.0, bound, note="tolerance max diag(K) / (gamma a)"))
    out += _penalty_against_qp("bar with 3 stops", cmp)
    out += _ddcm_fixed_points("bar with 3 stops", cmp)
    return out


def rung_trusses() -> list[Check]:
    out = []
    for cmp in (_compare(warren_truss), _compare(tower_3d, ("classical",))):
        m = cmp.model
        ref = ContactQP(m).solve()
        out.append(Check.make(f"{m.name} / QP reference", "QP steps solved", int(ref.success.sum()), m.n_steps, 0,
                              note="qpOASES via casadi.conic"))
        out += _classical_against(m.name, cmp, ref.u, ref.p, "QP")
        out += _penalty_against_qp(m.name, cmp)
    return out


def rung_data_convergence(*, sizes=(250, 500, 1000, 2000, 4000, 8000, 16000)) -> list[Check]:
    """DDCM error against the classical solution as the data set grows (2-D truss with contact)."""
    fb = "fischer_burmeister"
    exact_u = compare(warren_truss(n_data=sizes[0], steps=6), [fb], variants=("classical",))["classical", fb].array("u")
    errs = [_rel(compare(warren_truss(n_data=n, steps=6), [fb], variants=("ddcm",))["ddcm", fb].array("u"), exact_u)
            for n in sizes]
    slope, se = fitted_rate(sizes, errs)
    note = ("errors " + ", ".join(f"N={n}: {e:.2e}" for n, e in zip(sizes, errs))
            + f"; standard error of the slope {se:.2f}. Expected -1: the error is set by the data spacing "
              "(proportional to 1/N); at one N it varies within about 2x with the alignment of the data, "
              "which bounds the slope's uncertainty over this range by about 0.1 (tolerance 3x that)")
    return [Check.make("2-D Warren truss / ddcm / fischer_burmeister", "fitted rate d log(error u) / d log(N)",
                       slope, -1.0, 0.3, note=note)]


def rung_no_contact() -> list[Check]:
    out = []
    for n in (5000, 10000):
        m = four_member_truss(n_data=n)
        cmp = compare(m, variants=("ddcm",))
        ref = compare(m, ["fischer_burmeister"], variants=("classical",))["classical", "fischer_burmeister"]
        for f in registry.available():
            r = cmp["ddcm", f]
            out.append(Check.make(f"4-member truss, {n} points / ddcm / {f}", "max rel. error of u vs classical",
                                  _rel(r.array("u"), ref.array("u")), 0.0, 1e-2,
                                  note="converged" if r.converged else "NOT CONVERGED"))
            out.append(Check.make(f"4-member truss, {n} points / ddcm / {f}", "max rel. error of stress vs classical",
                                  _rel(r.array("stress"), ref.array("stress")), 0.0, 1e-2))
    return out


def rung_active_sets() -> list[Check]:
    out = []
    for cmp in (_compare(many_stops_bar, ("classical",)), _compare(warren_truss), _compare(tower_3d, ("classical",))):
        m, problems = cmp.model, cmp.problems
        ex = ExactEnumerator(problems.classical, max_pairs=12)
        solutions = [ex.solutions(problems.step_params(k)) for k in range(m.n_steps)]
        out.append(Check.make(f"{m.name} ({m.n_contacts} contacts) / enumeration", "steps without exactly one "
                              f"solution among {2 ** m.n_contacts} active sets",
                              sum(len(s) != 1 for s in solutions), 0, 0,
                              note="a convex problem has exactly one; more would mean a local solution"))
        # Active: a pressure above 1e-8 of its scale, in the enumeration (scaled) and the solvers;
        # a step without a solution counts as differing.
        exact_active = np.array([s[0].z[m.n_dofs:] > 1e-8 if s else np.full(m.n_contacts, np.nan)
                                 for s in solutions])
        for f in EXACT:
            active = cmp["classical", f].array("p") > 1e-8 * m.scales["stress"]
            out.append(Check.make(f"{m.name} / classical / {f}", "steps whose active set differs from enumeration",
                                  int(np.sum(np.any(active != exact_active, axis=1))), 0, 0))
    for cmp in (_compare(stops_bar), _compare(warren_truss)):
        m, problems = cmp.model, cmp.problems
        ex = ExactEnumerator(problems.projection)
        for f in registry.available():
            # The same tolerances as the fixed-point checks: exact formulations 1e-8, penalty its tilt.
            tol = EXACT_TOL if f != "penalty" else _penalty_tilt(cmp, f)
            not_global, several = 0, []
            for s in cmp["ddcm", f].steps:
                minima = ex.local_minima(problems.projection_params(s.step, s.strain_star, s.stress_star))
                if len(minima) > 1:
                    several.append(s.step)
                if not minima:
                    not_global += 1
                    continue
                x, p = problems.scaled_start("mpcc", s.u, s.p, s.stress)
                best = minima[0].z
                not_global += int(np.max(np.abs(np.concatenate([x, p]) - best))
                                  > tol * max(1.0, float(np.max(np.abs(best)))))
            out.append(Check.make(f"{m.name} / ddcm / {f}", f"projections not at the global minimum of Z_E "
                                  f"(enumeration of {3 ** m.n_contacts} branches)", not_global, 0, 0,
                                  note=("steps with several local minima of the projection: "
                                        + (", ".join(map(str, several)) if several else "none"))))
    return out


RUNGS: dict[str, Callable] = {
    "paper bar (closed form)": rung_paper,
    "bar with stops (closed form)": rung_stops,
    "2-D and 3-D trusses (QP)": rung_trusses,
    "DDCM convergence with data size": rung_data_convergence,
    "4-member truss without contact": rung_no_contact,
    "active sets (enumeration)": rung_active_sets,
    "Hertz contact in plane strain": continuum_rungs.rung_hertz,
    "Hertz contact in 3-D (recovered pressure)": continuum_rungs.rung_hertz_3d,
    "DDCM on a continuum with data size": continuum_rungs.rung_continuum_ddcm,
    "DDCM search quality on noisy data": rung_search_quality,
    "von Mises truss snap-through (finite kinematics)": rung_von_mises,
    **finite_strain_rungs.RUNGS,
    **hard_device_rungs.RUNGS,
    **two_body_rungs.RUNGS,
    **friction_rungs.RUNGS,
    **mindlin.RUNGS,
}


def run_ladder(*, progress: Callable[[str], None] | None = None) -> list[Check]:
    """Run every rung; returns the checks (nothing is raised for a failed check)."""
    checks: list[Check] = []
    _compare.cache_clear()  # the rungs share comparisons within one run, never across runs
    for title, rung in RUNGS.items():
        t0 = time.perf_counter()
        new = rung()
        checks += new
        if progress is not None:
            failed = sum(not c.passed for c in new)
            progress(f"{title}: {len(new) - failed}/{len(new)} passed ({time.perf_counter() - t0:.1f} s)")
    _compare.cache_clear()
    return checks
