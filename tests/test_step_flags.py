"""Honest per-step flags (issue 14): states beyond the data, physical checks of converged steps,
roundoff of the reported fields, and table notes that stay short.

- Beyond the data: a DDCM fixed point whose states leave the data's range is flagged per step
  (``extrapolated``), per run (``extrapolated_steps``), in the table, the CSV, the figures and a
  final warning of ``ddcm-compare``; a flag, not a convergence failure.
- Physical checks: a step is never converged with a penetration, an equilibrium residual or a
  negative contact pressure beyond the tolerances of :func:`~ddcm_casadi.drivers.path.physical_check`.
- Roundoff: pressures of the wrong sign within roundoff of the step's scale, and displacements
  within roundoff of it, are zero; a pressure negative beyond roundoff is kept.
- Notes: a long list of steps is summarised as a count and the first values, with enough digits.
"""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi import bar_model, compare, formulations
from ddcm_casadi.data.dataset import MaterialDataset, PointData
from ddcm_casadi.data.extrapolation import FAR_SPACINGS, DataCoverage, neighbourhood
from ddcm_casadi.formulations.base import LocalSolution, Metrics
from ddcm_casadi.drivers.harness import NOTE_VALUES, Comparison
from ddcm_casadi.data.metric import isotropic_elasticity
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.drivers.ddcm_options import DDCMOptions
from ddcm_casadi.drivers.path import (PENALTY_PRESSURE_BOUND, PHYSICAL_TOL, ROUNDOFF, PathResult, StepResult,
                                      clip_roundoff, solve_classical)

from .test_bad_input import run_cli

E = 200e9
FB = "fischer_burmeister"
CASES = Path(__file__).resolve().parent.parent / "examples" / "cases"


def _beyond_bar(formulation_names=(FB,)):
    """The issue's bar: data strain within +-0.005 (200 points), a path to strain -0.05 (31 steps)."""
    data = MaterialDataset.hookean(E, -0.005, 0.005, 200, c=E)
    model = bar_model(length=1.0, area=1.0, youngs_modulus=E, positions=np.linspace(1.0, 0.95, 31), dataset=data)
    return model, compare(model, list(formulation_names), variants=["ddcm"])


BAR_CASE = """[bar]
length = 1.0
area = 1.0
youngs_modulus = 200e9

[obstacle]
positions = {positions}

[data]
hookean = {{ strain_min = -0.005, strain_max = 0.005, points = 200 }}

[ddcm]
c = 200e9
"""


# ------------------------------------------------------------------ states beyond the data
def test_bar_beyond_the_data_is_flagged_at_every_step_past_its_range():
    """Steps whose imposed strain ``h - 1`` is past the data's -0.005 by more than half a spacing
    are flagged (one state each), the others not; the steps stay fixed points (a flag, not a
    failure), and the table, the summary and the rows say so."""
    model, cmp = _beyond_bar()
    r = cmp["ddcm", FB]
    strain = model.load_parameter - 1.0
    spacing = 0.01 / 199
    expected = (strain < -0.005 - spacing).astype(int)
    assert expected.sum() == 27
    assert r.array("extrapolated").tolist() == expected.tolist()
    assert r.converged  # every step a fixed point, and still flagged
    assert np.all(r.array("data_spacings")[expected == 0] < 1.0)  # within the data: < 1 spacing along it
    rec = next(s for s in cmp.summary() if s["variant"] == "ddcm")
    assert rec["extrapolated_steps"] == 27 and rec["max_extrapolated_states"] == 1
    assert rec["max_error_p"] > 0.5  # what the flag is about: the stresses stop at the data's edge
    line = next(ln for ln in cmp.table().splitlines() if ln.startswith("ddcm"))
    assert "DATA RANGE EXCEEDED at 27 steps (max 1 of 1 states; h=0.9933, 0.9917, 0.99, ...)" in line
    rows = cmp.rows()
    assert [row["extrapolated"] for row in rows] == expected.tolist()


def _truss(points: int, strain_max: float):
    from ddcm_casadi.casefiles.config import load_case_with_overrides

    case, _ = load_case_with_overrides(CASES / "truss2d.toml", [
        f"data.hookean.strain_min={-strain_max}", f"data.hookean.strain_max={strain_max}",
        f"data.hookean.points={points}"])
    return case.model, compare(case.model, [FB])


def test_truss_members_beyond_the_data_are_flagged():
    """truss2d with data stresses up to 6e7 Pa while members carry up to 1.8e8 Pa: every loaded
    step has states beyond the data, the unloaded one none; the example's own data (+-0.01) none."""
    model, cmp = _truss(61, 3e-4)
    r = cmp["ddcm", FB]
    classical = np.max(np.abs(cmp["classical", FB].array("stress")), axis=1)
    data_max = E * 3e-4
    flagged = r.array("extrapolated")
    assert flagged[0] == 0 and classical[0] == 0.0
    assert np.all(flagged[classical > data_max] > 0), (flagged, classical)
    assert flagged.max() >= model.n_points - 1
    force = cmp.fields("ddcm", FB)["contact_force"].sum(axis=1)
    exact = cmp.fields("classical", FB)["contact_force"].sum(axis=1)
    assert np.max(np.abs(force - exact)[1:] / exact[1:]) > 0.1  # the shift the flag warns about
    _, plain = _truss(2001, 0.01)
    assert not plain["ddcm", FB].array("extrapolated").any()
    assert np.nanmax(plain["ddcm", FB].array("data_spacings")) < 1.0


def test_no_flags_inside_the_data(paper_comparison):
    """The paper's example (every formulation; a local minimum at h = 0.992 included) stays
    within the data: nothing flagged, states within one spacing of their datum along the data."""
    for f in formulations.available():
        r = paper_comparison["ddcm", f]
        assert not r.array("extrapolated").any()
        assert np.nanmax(r.array("data_spacings")) < 1.0
    assert "DATA RANGE" not in paper_comparison.table()


@pytest.mark.parametrize("variant", ["plain", "lcdd"])
def test_random_noisy_samples_are_not_flagged(variant):
    """Random, noisy samples of a Hookean line have pairs of data far closer than their spacing,
    and states off the line by the noise: along the data the states stay well within
    :data:`FAR_SPACINGS` (measured at most 2.4 over seeds, noise levels and variants)."""
    rng = np.random.default_rng(3)
    e = np.sort(rng.uniform(-0.05, 0.01, 500))
    data = MaterialDataset(e * (1 + 0.01 * rng.standard_normal(500)), E * e * (1 + 0.01 * rng.standard_normal(500)),
                           300e9)
    model = bar_model(length=1.0, area=1.0, youngs_modulus=E, positions=np.linspace(1.01, 0.99, 21), dataset=data)
    r = compare(model, [FB], variants=["ddcm"], ddcm=DDCMOptions(variant=variant))["ddcm", FB]
    assert not r.array("extrapolated").any()
    assert np.nanmax(r.array("data_spacings")) < FAR_SPACINGS / 2


def test_coverage_criteria():
    """The two criteria on hand-made states: past the range by more than half a spacing, and far
    along the data (a hole); across the data (the DDCM mismatch) is never a flag."""
    strain = np.concatenate([np.linspace(-0.01, -0.006, 41), np.linspace(0.006, 0.01, 41)])  # a hole in [-0.006, 0.006]
    data = MaterialDataset(strain, E * strain, E)
    cov = DataCoverage(data, 5)
    d = 1e-4  # the spacing in strain
    states_e = np.array([-0.008, 0.01 + 0.4 * d, 0.01 + 2 * d, 0.0, -0.009])
    states_s = E * states_e + np.array([0.0, 0.0, 0.0, 0.0, 20 * E * d])  # the last one 14 spacings across
    beyond, along = cov.check(states_e, states_s)
    assert beyond.tolist() == [False, False, True, True, False]
    h, tangent = neighbourhood(data, np.array([20]))
    assert h[0] == pytest.approx(np.sqrt(2 * E) * d, rel=1e-9)  # sqrt(c d^2 + (E d)^2 / c) with c = E
    assert along[3] > FAR_SPACINGS and along[4] < 1.0


def test_coverage_of_mandel_grids_and_per_point_data():
    """Several components (the grid's box in scaled coordinates) and per-point data sets."""
    D = isotropic_elasticity(E, 0.3, 2)[0]
    data = MaterialDataset.hookean_grid(D, -0.01, 0.01, 11, c=D)
    inside = np.array([[0.001, -0.002, 0.003], [0.004, 0.0, -0.001]])
    outside = np.array([[0.02, 0.0, 0.0]])
    states = np.vstack([inside, outside])
    beyond, _ = DataCoverage(data, 3).check(states.ravel(), (states @ D.T).ravel())
    assert beyond.tolist() == [False, False, True]
    narrow, wide = (MaterialDataset.hookean(E, -s, s, 101, c=E) for s in (0.001, 0.01))
    per_point = PointData([narrow, wide], [0, 1])
    e = np.array([0.005, 0.005])  # beyond the first point's data, within the second's
    beyond, _ = DataCoverage(per_point, 2).check(e, E * e)
    assert beyond.tolist() == [True, False]


def test_cli_reports_states_beyond_the_data(tmp_path, capsys):
    positions = "[" + ", ".join(repr(float(h)) for h in np.linspace(1.0, 0.95, 31)) + "]"
    case = tmp_path / "beyond.toml"
    case.write_text(BAR_CASE.format(positions=positions))
    out = tmp_path / "out"
    code, stdout, err = run_cli(["--config", str(case), "--variants", "ddcm", "--formulations", FB, "-q",
                                 "--out", str(out)], capsys)
    assert code == 0, err
    assert "DATA RANGE EXCEEDED at 27 steps" in stdout
    assert "WARNING: states beyond the material data" in err and "ddcm/fischer_burmeister at 27 steps" in err
    with open(out / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert sum(int(row["extrapolated"]) for row in rows) == 27
    summary = json.loads((out / "results.json").read_text())["summary"]
    assert summary[0]["extrapolated_steps"] == 27


def test_figures_mark_steps_beyond_the_data():
    from ddcm_casadi.outputs.plots import figure_contact_history, figure_displacement

    _, cmp = _beyond_bar()
    for fig in (figure_displacement(cmp), figure_contact_history(cmp)):
        labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
        assert "DATA RANGE EXCEEDED" in labels
        assert "NOT CONVERGED" not in labels


# ------------------------------------------------------------------------- physical checks
def test_penalty_projection_with_a_metric_far_from_the_data_is_not_converged():
    """DDCM penalty with c = 3e17 on the paper's bar: fixed points with up to 1 cm of penetration
    (the penalty expects p / gamma < 10 S / gamma = 1e-5 m) and absurd pressures. Every step in
    contact is not converged and says by how much; the free steps stay converged."""
    data = MaterialDataset.hookean(E, -0.05, 0.01, 500, c=3e17)
    model = bar_model(length=1.0, area=1.0, youngs_modulus=E, positions=np.linspace(1.01, 0.99, 21), dataset=data)
    cmp = compare(model, ["penalty"], variants=["ddcm"])
    r = cmp["ddcm", "penalty"]
    contact = model.load_parameter <= 1.0 + 1e-12
    conv = r.array("converged")
    assert conv[~contact].all() and not conv[contact].any()
    for s in r.steps:
        if not s.converged:
            assert s.message.startswith("fixed point, but physical check failed: penetration"), s.message
    last = r.steps[-1]
    gamma = formulations.get("penalty").penalty_stiffness(cmp.problems.projection)
    allowed = PHYSICAL_TOL * cmp.problems.projection.gap_ref + PENALTY_PRESSURE_BOUND * \
        cmp.problems.projection.pressure_ref / gamma
    assert last.penetration * cmp.problems.projection.gap_ref > 100 * allowed
    assert "NOT CONVERGED at 11 steps" in cmp.table()


def test_penalty_penetration_is_expected(paper, paper_comparison):
    """A penalty's own O(1 / gamma) penetration is no failure: the paper's example with the
    default gamma, and a soft penalty gamma = 10 E / l0 whose penetration is |w| / 11."""
    assert all(r.converged for r in paper_comparison.results.values())
    soft = compare(paper, {"penalty": {"gamma": 10 * paper.contact_stiffness}}, variants=["classical"])
    r = soft["classical", "penalty"]
    assert r.converged
    assert r.steps[-1].penetration * soft.problems.classical.gap_ref == pytest.approx(0.01 / 11, rel=1e-6)


class _Claims:
    """A formulation that claims convergence for a given answer ``(u, p)`` (physical units): what a
    solver stopping on a degenerate scaled test reports."""

    def __init__(self, problems, u, p):
        self.problem = problems.classical
        self.metrics = Metrics(self.problem)
        self.x = np.asarray(u, float) / self.problem.gap_ref
        self.p = np.asarray(p, float) / self.problem.pressure_ref

    def solve(self, params, x0, p0, state=None):
        residual, comp, pen, _ = self.metrics(self.x, self.p, params)
        return LocalSolution(x=self.x, p=self.p, converged=True, iterations=1, outer_iterations=0, residual=residual,
                             complementarity=comp, penetration=pen, objective=float("nan"), message="converged")


def test_classical_nonsense_is_not_converged():
    """What formulations reported converged on degenerate scales: u = -1000 m with no contact
    pressure (equilibrium fails), and half a centimetre of penetration carrying the pressure that
    balances it (the penetration fails). Neither step is converged, and each says which check
    failed and by how much."""
    model = bar_model(length=1.0, area=1.0, youngs_modulus=E, positions=[0.99])
    problems = build_problems(model)
    s = solve_classical(problems, _Claims(problems, [-1000.0], [0.0]), "claims").steps[0]
    assert not s.converged
    assert s.message.startswith("converged, but physical check failed: equilibrium residual 1 > 1e-06"), s.message
    s = solve_classical(problems, _Claims(problems, [-0.005], [E * 0.005]), "claims").steps[0]
    assert not s.converged
    assert "physical check failed: penetration 0.005 m > 1e-08 m allowed (5e+05 times)" in s.message, s.message
    assert "equilibrium" not in s.message and "contact pressure" not in s.message


def test_negative_pressure_beyond_roundoff_is_kept_and_fails():
    model = bar_model(length=1.0, area=1.0, youngs_modulus=E, positions=[1.01])
    problems = build_problems(model)
    S = problems.classical.pressure_ref
    bad = solve_classical(problems, _Claims(problems, [0.0], [-1e-3 * S]), "claims").steps[0]
    assert not bad.converged and "contact pressure" in bad.message
    assert bad.p[0] == pytest.approx(-1e-3 * S)  # visible, not clipped
    tiny = solve_classical(problems, _Claims(problems, [1e-40], [-10 * np.finfo(float).eps * S]), "claims").steps[0]
    assert tiny.converged and tiny.p[0] == 0.0 and tiny.u[0] == 0.0


# -------------------------------------------------------------------------------- roundoff
def test_reported_fields_carry_no_roundoff_of_the_wrong_sign(paper_comparison):
    """Today's example had p = -9.3e-7 Pa (DDCM augmented Lagrangian, h = 1.009) and
    u = -3.1e-35 m (DDCM Fischer-Burmeister, h = 1.0): zero now. A negative pressure beyond
    roundoff stays (-0.015 Pa at h = 1.01, 7.6e-12 of the stress scale: the augmented
    Lagrangian's own tolerance, not roundoff)."""
    cmp = paper_comparison
    for (variant, _), r in cmp.results.items():
        problem = cmp.problems.classical if variant == "classical" else cmp.problems.projection
        p, u = r.array("p"), r.array("u")
        assert not np.any((p < 0) & (p > -ROUNDOFF * problem.pressure_ref))
        assert not np.any((u != 0) & (np.abs(u) < ROUNDOFF * problem.gap_ref))
    assert cmp["ddcm", FB].steps[10].u[0] == 0.0
    assert cmp["ddcm", "augmented_lagrangian"].steps[1].p[0] == 0.0


def test_clip_roundoff_threshold_is_relative_to_the_step():
    model = bar_model(length=1.0, area=1.0, youngs_modulus=E, positions=[0.99, 0.98])
    problem = build_problems(model).classical
    S = problem.pressure_ref
    step = StepResult(step=0, load_parameter=0.99, u=np.array([-1e-3, 1e-20]), p=np.array([1e3 * S, -1e-12 * S]),
                      converged=True, iterations=1, outer_iterations=0, residual=0.0, complementarity=0.0,
                      penetration=0.0, seconds=0.0)
    clip_roundoff(step, problem)
    # -1e-12 S is roundoff next to a pressure of 1e3 S (64 eps x 1e3 S = 1.4e-11 S), 1e-20 m next to 1 mm
    assert step.p.tolist() == [1e3 * S, 0.0] and step.u.tolist() == [-1e-3, 0.0]


# ----------------------------------------------------------------------------------- notes
def test_long_lists_of_steps_are_summarised_with_distinct_values():
    """1000 local minima: one short note with the count and the first values, each distinct
    value printed distinctly (0.99 and 0.990001 are not both '0.99')."""
    n = 1000
    h = 0.99 + 1e-6 * np.arange(n)
    model = bar_model(length=1.0, area=1.0, youngs_modulus=E, positions=h,
                      dataset=MaterialDataset.hookean(E, -0.05, 0.01, 50, c=E))
    steps = [StepResult(step=k, load_parameter=float(h[k]), u=np.zeros(1), p=np.zeros(1), converged=k >= 5,
                        iterations=1, outer_iterations=1, residual=0.0, complementarity=0.0, penetration=0.0,
                        seconds=0.0, global_optimum=False, projection_error=0.0, extrapolated=int(k % 2))
             for k in range(n)]
    cmp = Comparison(model=model, problems=build_problems(model), formulations=[formulations.get(FB)],
                     results={("ddcm", FB): PathResult("ddcm", FB, steps=steps)})
    line = next(ln for ln in cmp.table().splitlines() if ln.startswith("ddcm"))
    assert len(line) < 400, len(line)
    assert "NOT CONVERGED at 5 steps (0, 1, 2, ...)" in line
    assert "local minimum at 1000 steps (h=0.99, 0.990001, 0.990002, ...)" in line
    assert "DATA RANGE EXCEEDED at 500 steps (max 1 of 1 states; h=0.990001, 0.990003, 0.990005, ...)" in line
    short = bar_model(length=1.0, area=1.0, youngs_modulus=E, positions=h[5:5 + NOTE_VALUES], dataset=model.dataset)
    kept = [dataclasses.replace(s, step=i) for i, s in enumerate(steps[5:5 + NOTE_VALUES])]
    few = Comparison(model=short, problems=build_problems(short), formulations=cmp.formulations,
                     results={("ddcm", FB): PathResult("ddcm", FB, steps=kept)})
    assert "local minimum at h=0.990005, 0.990006, 0.990007" in few.table()


def test_remembered_neighbourhoods_are_the_computed_ones(monkeypatch):
    """Many points' neighbourhoods are remembered datum by datum: a second call, a call with some
    new data and a call past the memory's bound (emptied and computed afresh) give what
    :func:`neighbourhood` computes, point by point."""
    from ddcm_casadi.data import extrapolation

    D = isotropic_elasticity(E, 0.3, 2)[0]
    data = MaterialDataset.hookean_grid(D, -0.01, 0.01, 9, c=D)
    cov = DataCoverage(data, 1)
    rng = np.random.default_rng(7)
    for bound in (10**6, 150):
        monkeypatch.setattr(extrapolation, "_REMEMBERED_DATA", bound)
        for size in (100, 300, 300):
            index = rng.integers(0, len(data), size)
            h, tangent = cov._neighbourhood(0, data, index)
            h_direct, t_direct = neighbourhood(data, index)
            assert np.array_equal(h, h_direct) and np.array_equal(tangent, t_direct)
        assert cov._data_neighbourhoods[0][0].size <= max(bound, 300)


def test_the_check_takes_the_runs_own_search():
    """Given the datum nearest each state (what the run's last search found), the check agrees
    with its own search; a plain DDCM run hands the step's checks that search only for the
    states it searched."""
    data = MaterialDataset.hookean(E, -0.005, 0.005, 200, c=E)
    cov = DataCoverage(data, 3)
    e = np.array([-0.004, 0.0049, 0.0071])
    s = E * e
    nearest = data.nearest(e, s)
    for own, given in zip(cov.check(e, s), cov.check(e, s, nearest)):
        assert np.array_equal(own, given)
    from ddcm_casadi.drivers.nearest_datum import NearestDatum

    model, _ = _beyond_bar()
    scheme = NearestDatum(model, DDCMOptions())
    m = model.n_points
    scheme.begin(scheme.states(np.zeros(m, dtype=np.intp)))
    strain, stress = np.full(m, -0.001), np.full(m, -0.001 * E)
    scheme.update(strain, stress)
    assert np.array_equal(scheme.nearest_index(strain.copy(), stress.copy()), model.dataset.nearest(strain, stress))
    assert scheme.nearest_index(strain + 1e-6, stress) is None
