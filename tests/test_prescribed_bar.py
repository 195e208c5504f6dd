"""Prescribed displacements (a hard device) on bars: the tutorial bar (E = 1, u = 1), a bar pulled
onto a stop, the ``[bar] tip_displacement`` case file, refusals, the step parameter and sub-steps."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi import compare, formulations
from ddcm_casadi.casefiles.config import load_case
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.drivers.substeps import interpolate, unloaded
from ddcm_casadi.errors import InputError, PhysicsWarning
from ddcm_casadi.models.bar import paper_bar
from ddcm_casadi.models.truss import HardDeviceBarModel, bar_chain
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.run import run_case
from ddcm_casadi.validation.hard_device_rungs import ddcm_bound, stop_bar, stop_closed_form, tutorial_bar

ALL = formulations.available()
EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "cases" / "hard_device_bar.toml"


def _compare(model, formulation, variant):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsWarning)
        return compare(model, [formulation], variants=[variant])


@pytest.mark.parametrize("variant", ["classical", "ddcm"])
@pytest.mark.parametrize("formulation", ALL)
def test_tutorial_bar_stress_is_E_u_over_L(formulation, variant):
    """E = A = L = 1, the tip displaced to 1: classical exactly E u / L; DDCM within the
    fixed-point bound E de (1 + (E/c)^2) / 2 of the data spacing."""
    m = tutorial_bar(points=121)
    run = _compare(m, formulation, variant)[variant, formulation]
    U = m.load_parameter
    assert all(s.converged for s in run.steps)
    stress = run.array("stress")
    force = _compare(m, formulation, variant).fields(variant, formulation)["hard_device_force"][:, 0, 0]
    if variant == "classical":
        np.testing.assert_allclose(stress, np.repeat(U[:, None], 4, axis=1), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(run.array("u"), U[:, None] * np.array([0.25, 0.5, 0.75]), rtol=1e-12)
        np.testing.assert_allclose(force, U, rtol=1e-12)
    else:
        bound = ddcm_bound(1.0, 1.2 / 120, 1.0) * (1 + 1e-9)
        assert np.max(np.abs(stress - U[:, None])) <= bound
        assert np.max(np.abs(force - U)) <= bound


def test_stretch_to_strain_one_warns_and_runs():
    """The check that refused the tutorial bar ('pushed past a fixed end or through the body')
    now warns about the large strain of a stretch; a compression to -1 is still refused."""
    m = tutorial_bar(points=121)
    messages = m.path_warnings()
    assert len(messages) == 1 and "prescribed displacements impose a strain of about 1" in messages[0]
    assert "pushed" not in messages[0]
    with pytest.raises(InputError, match="compress the body to a strain of about -1") as err:
        bar_chain(length=1.0, elements=4, youngs_modulus=1.0, tip_displacements=[-0.5, -1.0]).path_warnings()
    assert "\n" not in str(err.value)
    # a compression short of inverting the bar is a warning
    assert "strain of about 0.5" in bar_chain(length=1.0, elements=4, youngs_modulus=1.0,
                                               tip_displacements=[-0.5]).path_warnings()[0]


@pytest.mark.parametrize("variant", ["classical", "ddcm"])
@pytest.mark.parametrize("formulation", ALL)
def test_bar_pulled_onto_a_stop(formulation, variant):
    """Contact and a prescribed displacement together, against the two-segment closed form."""
    m = stop_bar()
    assert isinstance(m, HardDeviceBarModel)
    cmp = _compare(m, formulation, variant)
    run = cmp[variant, formulation]
    assert all(s.converged for s in run.steps)
    uj, p_ref, F_ref = stop_closed_form(200e9, 1.0, 0.5, 0.004, m.load_parameter)
    # the model's own closed form (convex minorant) agrees with the two-segment formula
    closed = [m.closed_form(k) for k in range(m.n_steps)]
    np.testing.assert_allclose([c[0][4] for c in closed], uj, rtol=1e-12)
    np.testing.assert_allclose([c[1][0] for c in closed], p_ref, rtol=1e-9, atol=1e-3)
    force = cmp.fields(variant, formulation)["hard_device_force"][:, 0, 0]
    if variant == "classical" and formulation != "penalty":
        np.testing.assert_allclose(run.array("p")[:, 0], p_ref, rtol=1e-9, atol=1e-3)
        np.testing.assert_allclose(force, F_ref, rtol=1e-9)
    else:  # penalty: its penetration; DDCM: the data spacing's bound
        bound = ddcm_bound(200e9, 0.06 / 600, 200e9) * (1 + 1e-9)
        assert np.max(np.abs(force - F_ref)) <= bound
        assert np.max(np.abs(run.array("p")[:, 0] - p_ref)) <= 2 * bound


def test_hard_device_bar_example_case(tmp_path):
    """examples/cases/hard_device_bar.toml: the device force per step in results.csv and
    results.json, named so; the large strain a warning."""
    case = load_case(EXAMPLE)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsWarning)
        run = run_case(case, tmp_path, formulations=["fischer_burmeister"], figures=False)
    rows = [r for r in run.rows if r["variant"] == "classical"]
    assert [r["hard_device_force_x(node 4)"] for r in rows] == pytest.approx(np.linspace(0.1, 1.0, 10), rel=1e-12)
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["parameters"]["hard_device"]["supports"] == ["node 4"]
    assert doc["parameters"]["hard_device"]["column_names"] == ["hard_device_force_x(node 4)"]
    force = np.array(doc["fields"]["classical/fischer_burmeister"]["hard_device_force"])
    assert force.shape == (10, 1, 1)
    assert any("strain of about 1" in w for w in doc["warnings"])
    nodal = np.array(doc["fields"]["classical/fischer_burmeister"]["nodal_displacement"])
    np.testing.assert_allclose(nodal[-1, :, 0], [0.0, 0.25, 0.5, 0.75, 1.0], rtol=1e-12)
    header = (tmp_path / "results.csv").read_text().splitlines()[0]
    assert "hard_device_force_x(node 4)" in header


@pytest.mark.parametrize("text, message", [
    ("tip_displacement = [0.1, 0.2]\n[obstacle]\npositions = [1.0, 0.9]\n", "both act on the bar's tip"),
    ("tip_displacement = []\n", "non-empty list"),
    ("tip_displacement = [0.1, \"a\"]\n", "[bar] tip_displacement"),
])
def test_bar_case_errors_are_one_line(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text("[bar]\nlength = 1.0\nyoungs_modulus = 1.0\nelements = 2\n" + text)
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")) as err:
        load_case(path)
    assert "\n" not in str(err.value)


def test_one_element_hard_device_bar_is_refused_in_one_line(tmp_path):
    path = tmp_path / "one.toml"
    path.write_text("[bar]\nlength = 1.0\nyoungs_modulus = 1.0\ntip_displacement = [0.1]\n")
    with pytest.raises(InputError, match="elements >= 2"):
        load_case(path)


def test_stops_ahead_in_a_case_file(tmp_path):
    path = tmp_path / "stop.toml"
    path.write_text("[bar]\nlength = 1.0\nyoungs_modulus = 200e9\nelements = 10\n"
                    "tip_displacement = [0.002, 0.01, 0.02]\n"
                    "[[stops]]\nnode = 5\nclearance = 0.004\nside = \"ahead\"\n")
    m = load_case(path).model
    cmp = _compare(m, "fischer_burmeister", "classical")
    _, p_ref, F_ref = stop_closed_form(200e9, 1.0, 0.5, 0.004, m.load_parameter)
    np.testing.assert_allclose(cmp.fields("classical", "fischer_burmeister")["hard_device_force"][:, 0, 0], F_ref,
                               rtol=1e-9)
    path.write_text(path.read_text().replace('"ahead"', '"above"'))
    with pytest.raises(InputError, match='side must be "behind" or "ahead"'):
        load_case(path)


# ------------------------------------------------------------------------- the step parameter
def test_prescribed_values_are_a_load_entry_interpolated_by_substeps():
    m = tutorial_bar(points=121)
    assert m.load_names() == ("gap0", "f", "u_prescribed")
    problems = build_problems(m)
    P = problems.classical.parameters
    target = problems.step_params(3)
    assert P.get(target, "u_prescribed") == pytest.approx([0.4])
    assert P.get(unloaded(P, target, m.load_names()), "u_prescribed") == pytest.approx([0.0])
    start = problems.step_params(2)
    assert P.get(interpolate(P, start, target, 0.5, m.load_names()), "u_prescribed") == pytest.approx([0.35])


def test_no_device_leaves_the_problems_as_they_were():
    """Without prescribed displacements the parameters and maps are the ones of before."""
    problems = build_problems(paper_bar())
    assert problems.classical.parameters.names == ("gap0", "f")
    assert problems.projection.parameters.names == ("gap0", "f", "strain_star", "stress_star")


def test_fields_of_a_device_need_the_parameters():
    m = tutorial_bar(points=121)
    problems = build_problems(m)
    x = np.zeros(problems.classical.n_x)
    with pytest.raises(ValueError, match="need the step's parameters"):
        problems.fields("mcp", x, np.zeros(0))
    f = problems.fields("mcp", x, np.zeros(0), problems.step_params(9))
    np.testing.assert_allclose(f["strain"], [0, 0, 0, 4.0])  # the last element takes the whole 1 m


def test_a_bisected_step_reaches_the_device_value(monkeypatch):
    """A step that fails is bisected, the prescribed values interpolated from the last converged
    step (or from zero before the first): its sub-steps end at the step's own value."""
    from ddcm_casadi.drivers import path

    m = bar_chain(length=1.0, elements=3, youngs_modulus=1.0, tip_displacements=[0.03, 0.06])
    reference = compare(m, ["fischer_burmeister"], variants=["classical"])["classical", "fischer_burmeister"]
    real, calls = path.accepted, []

    def reject_full_steps(step, *args):  # every full step fails once: bisected from the start
        calls.append(step.step)
        return real(step, *args) and calls.count(step.step) > 1

    monkeypatch.setattr(path, "accepted", reject_full_steps)
    run = compare(m, ["fischer_burmeister"], variants=["classical"], min_substep=0.25)["classical", "fischer_burmeister"]
    assert all(s.converged and s.substeps > 1 for s in run.steps)
    np.testing.assert_allclose(run.array("u"), reference.array("u"), rtol=1e-12)
    np.testing.assert_allclose(run.array("stress"), reference.array("stress"), rtol=1e-12)
