"""Automatic step bisection along load paths (:mod:`ddcm_casadi.drivers.substeps`), classical and
DDCM: the interpolation of a step's parameters, the walk through the sub-steps, a real step that
fails whole and converges in halves, the option that turns it off, and what the records, the
table, ``results.csv`` and ``results.json`` say."""

from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pytest

from ddcm_casadi import MaterialDataset, compare, formulations
from ddcm_casadi.casefiles.base import Case, TOP_LEVEL_KEYS
from ddcm_casadi.casefiles.config import case_from_dict, load_case_with_overrides
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.truss import truss_model
from ddcm_casadi.models.truss_assembly import Obstacle
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.problems.parameters import Parameters
from ddcm_casadi.drivers.ddcm import DDCMSolver
from ddcm_casadi.drivers.path import solve_classical
from ddcm_casadi.drivers.substeps import (
    DEFAULT_MIN_SUBSTEP, bisect, bisection_enabled, check_min_substep, fraction_text, interpolate, unloaded,
    unloaded_start,
)
from ddcm_casadi.run import run_case

FB = "fischer_burmeister"
#: The apex load of the steep two-bar truss below: Newton (Fischer-Burmeister) needs 6 iterations
#: for the whole load from rest and 5 for each half (measured), so with ``max_iter = 5`` the full
#: step fails and its halves converge.
LOAD = 2e6


def steep_truss(load_factors=(1.0,), dataset=None, kinematics="finite"):
    """Two steel members from ``(+-1, 0)`` to the apex ``(0, 1)``, the apex pushed down by
    ``LOAD`` times the load factor (members strained by several per cent: geometrically
    nonlinear); a floor far below that it never reaches."""
    return truss_model(nodes=[[-1.0, 0.0], [1.0, 0.0], [0.0, 1.0]], members=[[0, 2], [1, 2]], area=1e-4,
                       youngs_modulus=200e9, supports=[(0, "xy"), (1, "xy")], loads=[[0, 0], [0, 0], [0.0, -LOAD]],
                       obstacles=[Obstacle(normal=[0.0, 1.0], offset=-5.0, nodes=[2])],
                       load_factors=list(load_factors), dataset=dataset, kinematics=kinematics)


# ------------------------------------------------------------------------------ interpolation
def test_interpolation_is_exact_at_the_ends_and_linear_between():
    """Only ``gap0`` and ``f`` move, linearly; history and data entries are the target's; the
    ends are exact (bit for bit)."""
    P = Parameters(gap0=2, f=3, strain_star=2, stress_star=2, tip_previous=1)
    rng = np.random.default_rng(0)
    start, target = rng.normal(size=P.size), rng.normal(size=P.size)
    kept = start.copy(), target.copy()
    np.testing.assert_array_equal(interpolate(P, start, target, 1.0), target)
    at0 = interpolate(P, start, target, 0.0)
    for name in ("gap0", "f"):
        np.testing.assert_array_equal(P.get(at0, name), P.get(start, name))
    for t in (0.25, 0.5, 0.8125):
        v = interpolate(P, start, target, t)
        for name in ("gap0", "f"):
            np.testing.assert_allclose(P.get(v, name), (1 - t) * P.get(start, name) + t * P.get(target, name),
                                       rtol=0, atol=1e-15)
        for name in ("strain_star", "stress_star", "tip_previous"):  # data and history: the target's
            np.testing.assert_array_equal(P.get(v, name), P.get(target, name))
    # linear: the midpoint of two fractions is the fraction of the midpoint
    a, b = interpolate(P, start, target, 0.25), interpolate(P, start, target, 0.75)
    np.testing.assert_allclose(interpolate(P, start, target, 0.5), (a + b) / 2, rtol=0, atol=1e-15)
    assert interpolate(P, start, target, 1.0) is not target  # a new vector; the inputs are unchanged
    np.testing.assert_array_equal(start, kept[0])
    np.testing.assert_array_equal(target, kept[1])


def test_unloaded_start_has_no_load_and_no_penetration():
    """Before any converged step: ``f = 0``, the obstacles drawn back to at most touching, the
    rest (data, history) untouched."""
    P = Parameters(gap0=3, f=2, strain_star=1, stress_star=1)
    target = P.pack(gap0=[-0.01, 0.0, 0.02], f=[5.0, -3.0], strain_star=[0.1], stress_star=[7.0])
    v = unloaded(P, target)
    np.testing.assert_array_equal(P.get(v, "gap0"), [0.0, 0.0, 0.02])
    np.testing.assert_array_equal(P.get(v, "f"), [0.0, 0.0])
    np.testing.assert_array_equal(P.get(v, "strain_star"), [0.1])
    np.testing.assert_array_equal(P.get(v, "stress_star"), [7.0])


def test_unloaded_zeroes_a_model_s_other_load_entries_and_refuses_a_penetrating_start():
    """A model kind's own load entry (an obstacle's travel) starts at zero; where the undeformed
    body would then penetrate, there is no clean start (``None``: the step is not bisected)."""
    P = Parameters(gap0=1, f=1, travel=2, history=1)
    target = P.pack(gap0=[-0.5], f=[3.0], travel=[0.2, 0.3], history=[9.0])
    v = unloaded(P, target, ("gap0", "f", "travel"))
    np.testing.assert_array_equal(v, P.pack(gap0=[0.0], f=[0.0], travel=[0.0, 0.0], history=[9.0]))

    class Stub:
        parameters, n_x = P, 2

        def __init__(self, penetrating):
            self.penetrating, self.seen = penetrating, None

        def penetrates(self, x, params):
            self.seen = (np.asarray(x).copy(), np.asarray(params).copy())
            return self.penetrating

    ok = Stub(False)
    np.testing.assert_array_equal(unloaded_start(ok, target, ("gap0", "f", "travel")), v)
    np.testing.assert_array_equal(ok.seen[0], [0.0, 0.0])  # the undeformed body is what is checked
    assert unloaded_start(Stub(True), target, ("gap0", "f", "travel")) is None


def test_interpolation_of_a_real_projection_leaves_the_data_alone():
    data = MaterialDataset.hookean(200e9, -0.08, 0.02, 101, c=200e9)
    pair = build_problems(steep_truss(dataset=data))
    P = pair.projection.parameters
    target = pair.projection_params(0, [-0.01, -0.01], [-2e9, -2e9])
    v = interpolate(P, unloaded(P, target), target, 0.5)
    np.testing.assert_array_equal(P.get(v, "f"), 0.5 * P.get(target, "f"))
    np.testing.assert_array_equal(P.get(v, "gap0"), P.get(target, "gap0"))  # a floor 6 m away: unchanged
    np.testing.assert_array_equal(P.get(v, "strain_star"), [-0.01, -0.01])
    np.testing.assert_array_equal(P.get(v, "stress_star"), [-2e9, -2e9])


# ------------------------------------------------------------------------------ the walk
def _walk(limit: float, min_substep: float):
    """Bisection of a step whose sub-steps converge when at most ``limit`` of it."""
    seen = []

    def attempt(t0, t1, state):
        seen.append((t0, t1))
        assert state == t0  # warm-started from the last converged sub-state
        return t1 - t0 <= limit, t1

    return bisect(attempt, 0.0, min_substep), seen


def test_bisect_halves_then_grows_in_powers_of_two():
    b, seen = _walk(0.25, 1 / 16)
    assert b.converged and b.state == 1.0 and b.reached == 1.0
    assert b.substeps == 4 and b.smallest == 0.25
    # 1/2 fails, 1/4 converges, then 1/2 is tried again after each success
    assert seen[:3] == [(0.0, 0.5), (0.0, 0.25), (0.25, 0.75)]
    for t0, t1 in seen:
        dt = t1 - t0
        assert dt == 2.0 ** round(np.log2(dt)) and 0 < t1 <= 1.0
    assert fraction_text(b.smallest) == "1/4" and b.message() == "reached in 4 sub-steps (smallest 1/4)"


def test_bisect_stops_at_the_minimum():
    b, seen = _walk(1 / 64, 1 / 16)
    assert not b.converged and b.reached == 0.0 and b.substeps == 0
    assert b.smallest == 1 / 16 and min(t1 - t0 for t0, t1 in seen) == 1 / 16
    assert "1/16" in b.message()
    b, _ = _walk(1 / 64, 1 / 64)
    assert b.converged and b.smallest == 1 / 64


@pytest.mark.parametrize("value, on", [(0, False), (1, False), (0.75, False), (0.5, True), (DEFAULT_MIN_SUBSTEP, True)])
def test_which_values_bisect(value, on):
    assert bisection_enabled(check_min_substep(value)) is on


@pytest.mark.parametrize("value, message", [
    (-0.1, "min_substep must be in [0, 1] (a fraction of one load step; 0 or 1 turns bisection off), got -0.1"),
    (1.5, "min_substep must be in [0, 1] (a fraction of one load step; 0 or 1 turns bisection off), got 1.5"),
    (float("nan"), "min_substep must be in [0, 1] (a fraction of one load step; 0 or 1 turns bisection off), got nan"),
    ("half", "min_substep must be in [0, 1] (a fraction of one load step; 0 or 1 turns bisection off), got 'half'"),
    (1e-9, "min_substep = 1e-09 is below 2**-20 (about a million sub-steps per step); use 0 to turn bisection off"),
])
def test_bad_min_substep_is_one_line(value, message):
    with pytest.raises(InputError) as err:
        check_min_substep(value)
    assert str(err.value) == message
    with pytest.raises(InputError):
        compare(steep_truss(), [FB], variants=["classical"], min_substep=value)


# ------------------------------------------------------------------------------ a real failure
def _classical(model, min_substep):
    pair = build_problems(model)
    built = formulations.get(FB, max_iter=5).build(pair.classical)
    return solve_classical(pair, built, FB, min_substep=min_substep)


def test_classical_full_step_fails_and_halves_converge():
    """The full step needs 6 Newton iterations, ``max_iter = 5``: it fails without bisection;
    bisected, it converges in two halves, to the state of the explicit path ``[0.5, 1]``."""
    off = _classical(steep_truss(), 0.0).steps[0]
    assert not off.converged and off.substeps == 1 and off.smallest_substep == 1.0
    assert "bisection" not in off.message
    step = _classical(steep_truss(), DEFAULT_MIN_SUBSTEP).steps[0]
    assert step.converged and step.substeps == 2 and step.smallest_substep == 0.5
    assert step.message.endswith("; reached in 2 sub-steps (smallest 1/2)")
    assert step.iterations >= off.iterations + 2  # every attempt counts: the failed full step as well
    explicit = _classical(steep_truss((0.5, 1.0)), 0.0)
    assert all(s.converged for s in explicit.steps)
    np.testing.assert_allclose(step.u, explicit.steps[-1].u, rtol=1e-9, atol=0)
    np.testing.assert_allclose(step.stress, explicit.steps[-1].stress, rtol=1e-9, atol=0)
    assert step.u[1] < -0.19  # a large displacement: the apex 0.19 m down (the sub-step was not the answer)


def test_ddcm_full_step_fails_and_sub_steps_converge():
    """DDCM Fischer-Burmeister with ``max_iter = 4`` in the projections: the full step's
    projection fails, four quarter sub-steps converge, to the fixed point of the explicit
    path of quarters."""
    data = MaterialDataset.hookean(200e9, -0.08, 0.02, 401, c=200e9)

    def run(load_factors, min_substep):
        pair = build_problems(steep_truss(load_factors, dataset=data))
        built = formulations.get(FB, max_iter=4).build(pair.projection)
        return DDCMSolver(pair, built, min_substep=min_substep).solve(formulation_name=FB)

    off = run((1.0,), 0.0).steps[0]
    assert not off.converged and off.substeps == 1
    step = run((1.0,), DEFAULT_MIN_SUBSTEP).steps[0]
    assert step.converged and step.substeps > 1 and step.smallest_substep < 1.0
    assert f"reached in {step.substeps} sub-steps" in step.message
    n = round(1 / step.smallest_substep)
    assert step.substeps == n  # equal sub-steps here: n of 1/n
    explicit = run(tuple(np.arange(1, n + 1) / n), 0.0)
    assert all(s.converged for s in explicit.steps)
    last = explicit.steps[-1]
    np.testing.assert_array_equal(step.data_index, last.data_index)
    np.testing.assert_allclose(step.u, last.u, rtol=1e-9, atol=0)
    np.testing.assert_allclose(step.stress, last.stress, rtol=1e-9, atol=0)


class _FailsWhole:
    """A built formulation that reports every solve at the step's whole load (``load``, the
    largest ``|f|``) not converged until a sub-step (a smaller load) has been solved; every
    other solve is the real formulation's. (For DDCM every projection of the full step fails,
    the rescue on the exact branch included.)"""

    def __init__(self, built, problem, load: float):
        self.built, self.problem, self.load, self.partial = built, problem, load, False

    def solve(self, params, x0, p0, state=None):
        sol = self.built.solve(params, x0, p0, state)
        self.partial = self.partial or float(np.max(np.abs(self.problem.parameters.get(params, "f")))) < self.load
        return sol if self.partial else dataclasses.replace(sol, converged=False, message="forced failure")


SMALL_LOAD = 1e5


def small_truss(dataset=None):
    """The same truss with small kinematics, loaded until the apex rests on a floor 0.1 mm below
    it: a load, a contact pressure, and a true-equilibrium check that needs the sub-step's load."""
    return truss_model(nodes=[[-1.0, 0.0], [1.0, 0.0], [0.0, 1.0]], members=[[0, 2], [1, 2]], area=1e-4,
                       youngs_modulus=200e9, supports=[(0, "xy"), (1, "xy")],
                       loads=[[0, 0], [0, 0], [0.0, -SMALL_LOAD]],
                       obstacles=[Obstacle(normal=[0.0, 1.0], offset=1.0 - 1e-4, nodes=[2])], load_factors=[1.0],
                       dataset=dataset)


def test_sub_steps_are_checked_at_their_own_load():
    """Small kinematics: the true equilibrium of every sub-step is checked against its own
    (interpolated) load; with the step's load the half step would be rejected. Classical and
    DDCM reach the step in two halves and land where the direct solve does."""
    data = MaterialDataset.hookean(200e9, -0.01, 0.01, 201, c=200e9)
    pair = build_problems(small_truss(data))
    direct = solve_classical(pair, formulations.get(FB).build(pair.classical), FB).steps[0]
    assert direct.converged and direct.p[0] > 0
    failing = _FailsWhole(formulations.get(FB).build(pair.classical), pair.classical, SMALL_LOAD)
    step = solve_classical(pair, failing, FB).steps[0]
    assert step.converged and (step.substeps, step.smallest_substep) == (2, 0.5), step.message
    np.testing.assert_allclose(step.u, direct.u, rtol=1e-9)
    np.testing.assert_allclose(step.p, direct.p, rtol=1e-9)
    built = formulations.get(FB).build(pair.projection)
    direct = DDCMSolver(pair, built).solve().steps[0]
    failing = _FailsWhole(formulations.get(FB).build(pair.projection), pair.projection, SMALL_LOAD)
    step = DDCMSolver(pair, failing).solve().steps[0]
    assert step.converged and (step.substeps, step.smallest_substep) == (2, 0.5), step.message
    np.testing.assert_array_equal(step.data_index, direct.data_index)


class _Nonsense:
    """A formulation that claims convergence for a displacement of a kilometre at every solve."""

    def __init__(self, problem):
        from ddcm_casadi.formulations.base import Metrics
        self.problem, self.metrics = problem, Metrics(problem)

    def solve(self, params, x0, p0, state=None):
        from ddcm_casadi.formulations.base import LocalSolution
        x = np.full(self.problem.n_x, -1000.0 / self.problem.gap_ref)
        p = np.zeros(self.problem.n_pairs)
        residual, comp, pen, _ = self.metrics(x, p, params)
        return LocalSolution(x=x, p=p, converged=True, iterations=1, outer_iterations=0, residual=residual,
                             complementarity=comp, penetration=pen, objective=float("nan"), message="converged")


def test_every_sub_step_is_checked():
    """A solver that claims nonsense at every fraction: no sub-step is accepted (the physical
    checks run on each), and the step is reported as its full attempt, not converged, with
    the smallest fraction tried."""
    pair = build_problems(small_truss())
    step = solve_classical(pair, _Nonsense(pair.classical), "nonsense").steps[0]
    assert not step.converged and step.substeps == 0 and step.smallest_substep == 1 / 16
    assert step.message.startswith("converged, but physical check failed")
    assert "bisection failed down to a fraction of 1/16 of the step" in step.message
    assert "reached 0 in 0 sub-steps" in step.message
    assert step.iterations == 5  # the full step and 1/2, 1/4, 1/8, 1/16


# ------------------------------------------------------------------------------ reports
def _first_row(path) -> dict:
    with open(path, newline="") as f:
        return next(csv.DictReader(f))


def test_min_substep_turns_it_off_and_results_carry_the_sub_steps(tmp_path):
    """``min_substep`` from the case (0: off), and ``results.json``/``results.csv``/the table
    with the sub-steps of a bisected step."""
    model = steep_truss()
    options = {FB: {"max_iter": 5}}
    off = run_case(Case(model=model, formulation_options=options, min_substep=0.0), tmp_path / "off",
                   formulations=[FB], variants=["classical"], figures=False)
    doc = json.loads((tmp_path / "off" / "results.json").read_text())
    assert doc["parameters"]["min_substep"] == 0.0
    assert doc["summary"][0]["non_converged_steps"] == [0] and doc["summary"][0]["bisected_steps"] == []
    assert "substeps" not in _first_row(tmp_path / "off" / "results.csv")
    assert "bisected" not in off.comparison.table()

    on = run_case(Case(model=model, formulation_options=options), tmp_path / "on",
                  formulations=[FB], variants=["classical"], figures=False)
    doc = json.loads((tmp_path / "on" / "results.json").read_text())
    summary = doc["summary"][0]
    assert doc["parameters"]["min_substep"] == DEFAULT_MIN_SUBSTEP
    assert summary["non_converged_steps"] == [] and summary["bisected_steps"] == [0]
    assert summary["substeps"] == [2] and summary["smallest_substep"] == [0.5]
    row = _first_row(tmp_path / "on" / "results.csv")
    assert row["substeps"] == "2" and float(row["smallest_substep"]) == 0.5
    assert "reached in 2 sub-steps (smallest 1/2)" in row["message"]
    assert "bisected at steps 0 (up to 2 sub-steps, smallest 1/2)" in on.comparison.table()


def test_case_file_key():
    """The top-level ``min_substep`` of a case file, checked in one line."""
    assert "min_substep" in TOP_LEVEL_KEYS
    doc = {"bar": {"length": 1.0, "area": 1e-4, "youngs_modulus": 200e9}, "obstacle": {"positions": [1.01, 0.99]}}
    assert case_from_dict(dict(doc)).min_substep == DEFAULT_MIN_SUBSTEP
    assert case_from_dict({**doc, "min_substep": 0.25}).min_substep == 0.25
    assert case_from_dict({**doc, "min_substep": 1}).min_substep == 1.0
    with pytest.raises(InputError, match=r"^min_substep must be in \[0, 1\]"):
        case_from_dict({**doc, "min_substep": 2})


def test_case_file_and_set(tmp_path):
    """``min_substep`` written in a case file (a top-level key, before any section) and from
    ``--set``, which overrides it."""
    path = tmp_path / "case.toml"
    path.write_text("min_substep = 0.125\n\n[bar]\nlength = 1.0\narea = 1e-4\nyoungs_modulus = 200e9\n\n"
                    "[obstacle]\npositions = [1.01, 0.99]\n")
    case, _ = load_case_with_overrides(path, [])
    assert case.min_substep == 0.125
    case, overrides = load_case_with_overrides(path, ["min_substep=0"])
    assert case.min_substep == 0.0 and overrides == {"min_substep": 0}
    with pytest.raises(InputError, match=r"^min_substep = 1e-07 is below 2\*\*-20"):
        load_case_with_overrides(path, ["min_substep=1e-7"])


def test_progress_line_says_so():
    from ddcm_casadi.commands.compare import _bisection

    step = _classical(steep_truss(), DEFAULT_MIN_SUBSTEP).steps[0]
    assert _bisection(step) == "  bisected: 2 sub-steps, smallest 1/2"
    assert _bisection(_classical(steep_truss(), 0.0).steps[0]) == ""
