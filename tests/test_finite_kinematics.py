"""Finite kinematics through the nonlinear seam: the von Mises truss against its closed form.

Tolerances: exact formulations to 1e-8 relative (their solver tolerances are 1e-9..1e-11 scaled);
the penalty to its penetration ``p / gamma`` (derived in :mod:`ddcm_casadi.validation.finite_rungs`); DDCM
to the data spacing.
"""

from __future__ import annotations

import json
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from ddcm_casadi import formulations
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.errors import InputError
from ddcm_casadi.validation.finite_rungs import contact_status, penalty_tolerances, rung_von_mises, snap_table
from ddcm_casadi.drivers.harness import compare
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.models.von_mises import descent, green_lagrange, plane_force, von_mises_truss

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "cases"
EXAMPLE_CASE = EXAMPLES / "von_mises.toml"


@pytest.fixture(scope="module")
def classical():
    return compare(von_mises_truss(), variants=("classical",))


def test_green_lagrange_strain_is_exact_for_rigid_rotation():
    m = von_mises_truss(steps=4)
    # rotate the apex about support 0 by 30 degrees: member 0 keeps its length, E = 0 exactly
    X = m.nodes[2] - m.nodes[0]
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    u = np.array([[c, -s], [s, c]]) @ X - X
    E = m.strain(u)
    assert abs(E[0]) < 1e-15
    # and the symbolic strain is the numeric one
    sym = ca.SX.sym("u", 2)
    f = ca.Function("E", [sym], [m.strain_expression(sym)])
    np.testing.assert_allclose(np.asarray(f(u)).ravel(), E, rtol=0, atol=1e-16)


def test_closed_form_matches_green_lagrange_and_force():
    m = von_mises_truss(steps=4)
    w = 0.05
    E = m.strain(np.array([0.0, -w]))
    np.testing.assert_allclose(E, green_lagrange(w, 1.0, 0.1), rtol=1e-14)
    # F is the derivative of the strain energy 2 A L0 E_mod E^2 / 2 in the descent w
    L0 = np.hypot(1.0, 0.1)
    energy = lambda w: 2 * 1e-4 * L0 * 200e9 * green_lagrange(w, 1.0, 0.1) ** 2 / 2  # noqa: E731
    h = 1e-7
    assert plane_force(w, half_span=1.0, rise=0.1, area=1e-4, youngs_modulus=200e9) == pytest.approx(
        (energy(w + h) - energy(w - h)) / (2 * h), rel=1e-7)


def test_problems_are_nonlinear_and_affine_ones_unchanged():
    pair = build_problems(von_mises_truss(dataset=MaterialDataset.hookean(200e9, -0.01, 0.01, 11, c=200e9)))
    assert not pair.classical.affine and not pair.projection.affine
    small = von_mises_truss(steps=4)
    assert small.kinematics == "finite"


@pytest.mark.parametrize("formulation", formulations.available())
def test_classical_accepted_steps_match_closed_form(classical, formulation):
    m = classical.model
    r = classical["classical", formulation]
    ok = np.array([s.converged for s in r.steps])
    u_ref = np.array([m.closed_form(k)[0] for k in range(m.n_steps)])
    p_ref = np.array([m.closed_form(k)[1] for k in range(m.n_steps)])
    assert ok.sum() >= m.n_steps - 5  # at most the snap steps fail, and they are flagged
    # exact formulations: their solver tolerances (1e-9..1e-11 scaled); the penalty: its
    # penetration p / gamma in u, and the force's slope times it in p (derived in finite_rungs)
    tol_u, tol_p = penalty_tolerances(classical, u_ref, p_ref) if formulation == "penalty" else (1e-8, 1e-8)
    assert np.max(np.abs(r.array("u") - u_ref)[ok]) <= tol_u * np.max(np.abs(u_ref))
    assert np.max(np.abs(r.array("p") - p_ref)[ok]) <= tol_p * np.max(np.abs(p_ref))
    status = contact_status(m, r.array("p"))
    assert np.all(status[ok] == contact_status(m, p_ref)[ok])


def test_fischer_burmeister_crosses_the_snap(classical):
    r = classical["classical", "fischer_burmeister"]
    assert all(s.converged for s in r.steps)
    w = -r.array("u")[:, 1]
    np.testing.assert_allclose(w, descent(classical.model.load_parameter, 0.1), rtol=1e-12, atol=1e-14)
    table = snap_table(classical)
    assert "C" in table and "-" in table


def test_unstable_equilibrium_is_flagged(classical):
    """The augmented Lagrangian reaches the unstable equilibrium w = h at the step before the
    snap: it solves the equations but is not reported as converged."""
    r = classical["classical", "augmented_lagrangian"]
    flagged = [s for s in r.steps if "unstable equilibrium" in s.message]
    for s in flagged:
        assert not s.converged
        assert -s.u[1] == pytest.approx(0.1, rel=1e-6)


def test_load_step_on_grazing_equilibrium_is_refused():
    with pytest.raises(InputError, match="not unique"):
        von_mises_truss(steps=25)


def test_rung_passes():
    checks = rung_von_mises(sizes=(101, 201, 401, 801))
    failed = [c for c in checks if not c.passed]
    assert not failed, failed


def test_case_file_kinematics_key(tmp_path):
    """``kinematics = "finite"`` from a case file gives the von Mises truss of the module."""
    from ddcm_casadi.casefiles.config import load_case
    from ddcm_casadi.run import run_case

    case = load_case(EXAMPLE_CASE)
    assert case.model.kinematics == "finite"
    reference = von_mises_truss()
    np.testing.assert_allclose(case.model.gap_offsets, reference.gap_offsets, atol=1e-6)
    run = run_case(case, tmp_path / "out", formulations=["fischer_burmeister"], variants=["classical"], figures=False)
    u = run.comparison["classical", "fischer_burmeister"].array("u")
    np.testing.assert_allclose(-u[:, 1], descent(reference.load_parameter, 0.1), rtol=1e-5, atol=1e-7)
    document = json.loads((tmp_path / "out" / "results.json").read_text())
    assert document["parameters"]["kinematics"] == "finite" and document["parameters"]["contact_law"] == "signorini"


@pytest.mark.parametrize("value, message", [
    ('"large"', "kinematics must be one of 'small', 'finite', got 'large'"),
    ("1", "kinematics must be one of 'small', 'finite', got 1"),
])
def test_bad_kinematics_is_refused(tmp_path, value, message):
    from ddcm_casadi.casefiles.config import load_case

    path = tmp_path / "case.toml"
    path.write_text(EXAMPLE_CASE.read_text().replace('kinematics = "finite"', f"kinematics = {value}"))
    with pytest.raises(InputError) as err:
        load_case(path)
    assert str(err.value) == message


def test_finite_kinematics_refused_where_unavailable(tmp_path):
    from ddcm_casadi.casefiles.config import load_case

    path = tmp_path / "bar.toml"
    path.write_text('kinematics = "finite"\n' + (EXAMPLES / "bar_stops.toml").read_text())
    with pytest.raises(InputError, match=r"kinematics = 'finite' is not available for \[bar\] cases"):
        load_case(path)


def test_restoration_start_closes_violated_gaps_unloaded():
    """After the snap the previous state has passed the plane: the restart is the unloaded
    state on the plane (its gap closed exactly, stresses and pressures zero)."""
    data = MaterialDataset.hookean(200e9, -0.006, 0.008, 201, c=200e9)
    pair = build_problems(von_mises_truss(dataset=data))
    problem = pair.projection
    x, p = pair.scaled_start("mpcc", np.array([0.0, -0.09375]), np.array([1.2e7]), np.array([-9.9e8, -9.9e8]))
    params = pair.projection_params(10, [-0.00495] * 2, [-9.9e8] * 2)
    assert problem.penetrates(x, params)
    xr, pr = problem.restoration_start(x, params)
    assert not problem.penetrates(xr, params)
    f = pair.fields("mpcc", xr, pr)
    t = pair.model.load_parameter[10]
    np.testing.assert_allclose(f["u"], [0.0, -t], atol=1e-15)
    assert np.all(f["stress"] == 0) and np.all(pr == 0)


def test_ddcm_fischer_burmeister_crosses_the_snap_from_the_restart():
    """With 201 data points DDCM Fischer-Burmeister converges at every step, the snap included:
    the projections after it start from the unloaded state on the plane (they failed from the
    previous state)."""
    data = MaterialDataset.hookean(200e9, -0.006, 0.008, 201, c=200e9)
    r = compare(von_mises_truss(dataset=data), ["fischer_burmeister"], variants=("ddcm",))["ddcm", "fischer_burmeister"]
    assert all(s.converged for s in r.steps)
    p_ref = np.array([von_mises_truss().closed_form(k)[1] for k in range(25)])
    assert np.max(np.abs(r.array("p") - p_ref)) <= 200e9 * 0.014 / 200  # the data's stress spacing
