"""Prescribed displacements (a hard device) on continua: ``[[supports]] displacement``, the
homogeneous patch (every formulation, both variants), outputs, refusals and one-line errors."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi import compare, formulations
from ddcm_casadi.casefiles.config import load_case
from ddcm_casadi.data.metric import isotropic_elasticity
from ddcm_casadi.errors import InputError, PhysicsWarning
from ddcm_casadi.models.continuum import mesh as meshes
from ddcm_casadi.models.continuum.model import Contact, Material, Support, continuum_model
from ddcm_casadi.models.continuum.obstacles import Plane
from ddcm_casadi.run import run_case
from ddcm_casadi.validation.hard_device_rungs import stretched_block

ALL = formulations.available()
EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "cases" / "hard_device_block.toml"
E, NU = 200e9, 0.3


@pytest.fixture(scope="module")
def block():
    return stretched_block(points=21)


@pytest.mark.parametrize("variant", ["classical", "ddcm"])
@pytest.mark.parametrize("formulation", ALL)
def test_stretched_block_is_homogeneous(block, formulation, variant):
    cmp = compare(block, [formulation], variants=[variant])
    r = cmp[variant, formulation]
    assert all(s.converged for s in r.steps)
    exx = 1e-3 * np.asarray(block.load_parameter)
    sxx = E / (1 - NU ** 2) * exx
    stress = r.array("stress").reshape(block.n_steps, -1, 3)
    force = cmp.fields(variant, formulation)["hard_device_force"][:, 0]
    if variant == "classical":
        strain = r.array("strain").reshape(block.n_steps, -1, 3)
        np.testing.assert_allclose(strain[..., 0], np.repeat(exx[:, None], strain.shape[1], axis=1), rtol=1e-9)
        np.testing.assert_allclose(strain[..., 1], -NU / (1 - NU) * np.repeat(exx[:, None], strain.shape[1], axis=1),
                                   rtol=1e-9)
        np.testing.assert_allclose(stress[..., 0], np.repeat(sxx[:, None], stress.shape[1], axis=1), rtol=1e-9)
        np.testing.assert_allclose(force[:, 0], sxx * 0.01, rtol=1e-9)
    else:
        C = isotropic_elasticity(E, NU, 2)[0]
        bound = float(np.linalg.norm(C, 2)) * (0.004 / 20) * np.sqrt(3)
        assert np.max(np.abs(stress[..., 0] - sxx[:, None])) <= bound
        assert np.max(np.abs(force[:, 0] - sxx * 0.01)) <= bound * 0.01


def test_example_case_writes_the_device_force_and_the_moved_boundary(tmp_path):
    case = load_case(EXAMPLE)
    run = run_case(case, tmp_path, formulations=["fischer_burmeister"], figures=False)
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["parameters"]["hard_device"]["supports"] == ["xmax"]
    force = np.array(doc["fields"]["classical/fischer_burmeister"]["hard_device_force"])
    assert force.shape == (4, 1, 2)
    np.testing.assert_allclose(force[:, 0, 0], E / (1 - NU ** 2) * 1e-3 * np.array([0.25, 0.5, 0.75, 1.0]) * 0.01,
                               rtol=1e-9)
    rows = [r for r in run.rows if r["variant"] == "classical"]
    assert rows[-1]["hard_device_force_x(xmax)"] == pytest.approx(force[-1, 0, 0])
    # the VTU displacement of the device's boundary is the prescribed one
    import meshio

    last = sorted((tmp_path / "vtu").rglob("*classical*fischer_burmeister*.vtu"))
    mesh_files = [p for p in last if "points" not in p.name]
    data = meshio.read(mesh_files[-1])
    x = data.points[:, 0]
    right = np.isclose(x, 0.02)
    np.testing.assert_allclose(data.point_data["displacement"][right, 0], 2e-5, rtol=1e-12)


def _model(supports, **kw):
    return continuum_model(meshes.rectangle(2.0, 1.0, nx=4, ny=2),
                           materials=[Material(youngs_modulus=1.0, poisson_ratio=0.3)], supports=supports, **kw)


ROLLERS = [Support("xmin", "x"), Support("ymin", "y")]


def test_a_stretch_to_strain_one_warns_a_compression_to_minus_one_is_refused():
    m = _model(ROLLERS + [Support("xmax", "x", [2.0, 0.0])])
    messages = m.path_warnings()
    assert len(messages) == 1 and "prescribed displacements impose a strain of about 1" in messages[0]
    with pytest.raises(InputError, match="compress the body to a strain of about -1"):
        _model(ROLLERS + [Support("xmax", "x", [-2.0, 0.0])]).path_warnings()


@pytest.mark.parametrize("supports, kw, message", [
    ([Support("xmax", "x", [0.1])], {}, r"\[supports 2\] displacement must have 2 components"),
    ([Support("xmax", "x", [[0.1, 0.0], [0.2, 0.0]])], dict(load_factors=[0.5, 1.0, 1.5]),
     r"\[supports 2\] displacement has 2 steps but \[loading\] load_factors has 3"),
    ([Support("xmax", "x", [0.1, 0.1])], {}, "has a y component but the support does not fix y"),
    ([Support("xmax", "x", [0.1, 0.0]), Support("xmax", "x", [0.2, 0.0])], {}, "prescribe different x displacements"),
    ([Support("ymin", "x", [0.1, 0.0])], {}, r"\[supports 0\] \(fixed at 0\) and \[supports 2\] prescribe different x"),
])
def test_continuum_device_errors_are_one_line(supports, kw, message):
    with pytest.raises(InputError, match=message) as err:
        _model(ROLLERS + supports, **kw)
    assert "\n" not in str(err.value)


def test_per_step_displacements_set_the_number_of_steps():
    m = _model(ROLLERS + [Support("xmax", "x", [[0.01, 0.0], [0.02, 0.0], [0.03, 0.0]])])
    assert m.n_steps == 3 and m.load_parameter_name == "load step"
    cmp = compare(m, ["fischer_burmeister"], variants=["classical"])
    force = cmp.fields("classical", "fischer_burmeister")["hard_device_force"][:, 0, 0]
    np.testing.assert_allclose(force, np.array([0.01, 0.02, 0.03]) / 2 / (1 - 0.09) * 1.0, rtol=1e-9)


def test_finite_kinematics_with_a_device_is_refused_in_one_line(tmp_path):
    text = EXAMPLE.read_text().replace("[mesh]", 'kinematics = "finite"\n\n[mesh]').replace(
        "poisson_ratio = 0.3", 'poisson_ratio = 0.3\nlaw = "saint_venant_kirchhoff"')
    text = text[:text.index("[data]")]
    path = tmp_path / "finite.toml"
    path.write_text(text)
    with pytest.raises(InputError, match='not supported with kinematics = "finite"') as err:
        load_case(path)
    assert "\n" not in str(err.value)


def test_device_and_obstacle_together():
    """A block pressed down by a rigid plane while a hard device pulls its right edge sideways:
    homogeneous (frictionless plane, rollers), eps_xx = U / L, eps_yy = -travel / H; the device
    carries sigma_xx H, the plane -sigma_yy L."""
    plane = Plane(point=[0.0, 1.0], normal=[0.0, -1.0], direction=(0.0, -1.0), travel=[0.0, 0.01, 0.02])
    m = _model([Support("ymin", "y"), Support("xmin", "x"), Support("xmax", "x", [[0.0, 0.0], [0.005, 0.0],
                                                                                  [0.01, 0.0]])],
               contacts=[Contact(plane, "ymax")])
    for formulation in ALL:
        cmp = compare(m, [formulation], variants=["classical"])
        r = cmp["classical", formulation]
        assert all(s.converged for s in r.steps), formulation
        force = cmp.fields("classical", formulation)["hard_device_force"][:, 0, 0]
        lam, mu = 0.3 / (1.3 * 0.4), 1.0 / 2.6
        exx, eyy = np.array([0.0, 0.0025, 0.005]), np.array([0.0, -0.01, -0.02])
        sxx, syy = (lam + 2 * mu) * exx + lam * eyy, lam * exx + (lam + 2 * mu) * eyy
        tol = 1e-9 if formulation != "penalty" else 1e-3  # a penalty lets the plane in by p / gamma
        np.testing.assert_allclose(force, sxx * 1.0, rtol=tol, atol=1e-15)
        contact = np.sum(m.contact_area * r.array("p"), axis=1)
        np.testing.assert_allclose(contact, -syy * 2.0, rtol=tol, atol=1e-15)
