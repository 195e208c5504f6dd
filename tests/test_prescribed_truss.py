"""Prescribed displacements (a hard device) on trusses: against the direct stiffness method (every
formulation, both variants), at finite strain, in case files, with contact, and the refusals."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from ddcm_casadi import compare, formulations
from ddcm_casadi.casefiles.config import load_case
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.errors import InputError, PhysicsWarning
from ddcm_casadi.models.truss import Obstacle, truss_model
from ddcm_casadi.validation.hard_device_rungs import (TRUSS_DEVICE, TRUSS_MEMBERS, TRUSS_NODES, ddcm_bound,
                                                      device_truss, stiffness_method)

ALL = formulations.available()


def _reference(m):
    fixed = np.zeros_like(TRUSS_NODES, dtype=bool)
    fixed[1:] = True
    loads = np.zeros_like(TRUSS_NODES)
    loads[0] = (2e4, -1e5)
    out = [stiffness_method(TRUSS_NODES, TRUSS_MEMBERS, np.full(4, 200e9), np.full(4, 1e-4), fixed,
                            {(4, 0): lf * TRUSS_DEVICE[0], (4, 1): lf * TRUSS_DEVICE[1]}, lf * loads)
           for lf in m.load_parameter]
    return (np.array([U[0] for U, _, _ in out]), np.array([N for _, N, _ in out]),
            np.array([R[4] for _, _, R in out]), np.array([U for U, _, _ in out]))


@pytest.mark.parametrize("variant", ["classical", "ddcm"])
@pytest.mark.parametrize("formulation", ALL)
def test_truss_against_the_stiffness_method(formulation, variant):
    m = device_truss()
    cmp = compare(m, [formulation], variants=[variant])
    assert all(s.converged for s in cmp[variant, formulation].steps)
    f = cmp.fields(variant, formulation)
    U, N, R, nodal = _reference(m)
    if variant == "classical":
        np.testing.assert_allclose(f["u"], U, rtol=1e-9)
        np.testing.assert_allclose(f["member_force"], N, rtol=1e-9)
        np.testing.assert_allclose(f["hard_device_force"][:, 0], R, rtol=1e-9)
        np.testing.assert_allclose(f["nodal_displacement"], nodal, rtol=1e-9, atol=1e-15)
    else:
        bound = ddcm_bound(200e9, 0.01 / 2000, 200e9) * (1 + 1e-9)
        assert np.max(np.abs(f["stress"] - N / 1e-4)) <= bound
        assert np.max(np.abs(f["hard_device_force"][:, 0] - R)) <= bound * 1e-4
        # the prescribed node moves by the device, whatever the data
        np.testing.assert_allclose(f["nodal_displacement"][:, 4], nodal[:, 4], rtol=1e-12)


@pytest.mark.parametrize("variant", ["classical", "ddcm"])
def test_finite_strain_bar_pulled_by_a_device(variant):
    """Finite kinematics: a two-member chain pulled to 20 % by its end; Saint Venant-Kirchhoff
    (S = E E_GL): uniform stretch, S = E (U/L + (U/L)^2 / 2), the device force A S (1 + U/L)."""
    U = np.array([0.05, 0.1, 0.2])
    data = MaterialDataset.hookean(1.0, -0.05, 0.3, 3501, c=1.0)
    m = truss_model(nodes=[[0.0], [0.5], [1.0]], members=[[0, 1], [1, 2]], area=1.0, youngs_modulus=1.0,
                    supports=[(0, "x"), (2, "x", U[:, None])], kinematics="finite", dataset=data)
    assert m.path_warnings() == []  # large strains are what finite kinematics model
    cmp = compare(m, ["fischer_burmeister", "mpcc"], variants=[variant])
    S = U + U ** 2 / 2
    for name in ("fischer_burmeister", "mpcc"):
        r = cmp[variant, name]
        assert all(s.converged for s in r.steps)
        force = cmp.fields(variant, name)["hard_device_force"][:, 0, 0]
        if variant == "classical":
            np.testing.assert_allclose(r.array("stress"), np.repeat(S[:, None], 2, axis=1), rtol=1e-9)
            np.testing.assert_allclose(force, S * (1 + U), rtol=1e-9)
        else:
            spacing = 0.35 / 3500
            assert np.max(np.abs(r.array("stress") - S[:, None])) <= 2 * spacing
            np.testing.assert_allclose(force, S * (1 + U), atol=3 * spacing)


def _two_bar_truss(path, device: str):
    """A two-bar truss case file whose node 2 carries the hard device ``device`` (TOML)."""
    path.write_text(f"""
[structure]
nodes = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]
members = [[0, 1], [1, 2]]
area = 1e-4
youngs_modulus = 200e9
supports = [[0, "xy"], [1, "y"], [2, "xy", {device}]]
""")
    return path


def test_truss_case_file_with_a_displacement(tmp_path):
    m = load_case(_two_bar_truss(tmp_path / "truss.toml", "[[0.001, 0.0], [0.002, 0.0]]")).model
    assert m.n_steps == 2 and m.prescribed.size == 2
    cmp = compare(m, ["fischer_burmeister"], variants=["classical"])
    force = cmp.fields("classical", "fischer_burmeister")["hard_device_force"][:, 0]
    np.testing.assert_allclose(force[:, 0], 200e9 * 1e-4 * np.array([0.001, 0.002]) / 2, rtol=1e-9)
    assert force[:, 1] == pytest.approx([0.0, 0.0], abs=1e-6)
    rows = cmp.rows()
    assert set(k for k in rows[0] if k.startswith("hard_device")) == {"hard_device_force_x(node 2)",
                                                                     "hard_device_force_y(node 2)"}


@pytest.mark.parametrize("supports, load_factors, message", [
    ([(0, "xy"), (1, "y"), (2, "x", [0.001])], None, "must have 2 components"),
    ([(0, "xy"), (1, "y"), (2, "x", [[0.001, 0], [0.002, 0]])], [0.5, 1.0, 1.5], "has 2 steps but load_factors has 3"),
    ([(0, "xy"), (1, "y"), (2, "x", [0.001, 0.001])], None, "has a y component but the support does not fix y"),
    ([(0, "xy"), (1, "y"), (2, "x", [0.001, 0.0]), (2, "x", [0.002, 0.0])], None, "two displacements prescribed"),
])
def test_truss_device_errors_are_one_line(supports, load_factors, message):
    with pytest.raises(InputError, match=message) as err:
        truss_model(nodes=[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]], members=[[0, 1], [1, 2]], area=1e-4,
                    youngs_modulus=200e9, supports=supports, load_factors=load_factors)
    assert "\n" not in str(err.value)


def test_case_file_device_of_the_wrong_length(tmp_path):
    with pytest.raises(InputError, match="must have 2 components"):
        load_case(_two_bar_truss(tmp_path / "bad.toml", "[0.001, 0.0, 0.0]"))


def test_contact_on_a_prescribed_node():
    """A node whose x is prescribed rests on a floor along y: fine (the floor holds its free y).
    A device that pushes a node into an obstacle no free dof can leave is refused."""
    X = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0]]
    members = [[0, 1], [1, 2], [0, 2]]
    floor = Obstacle(normal=[0.0, 1.0], offset=-0.001, nodes=[1, 2])
    m = truss_model(nodes=X, members=members, area=1e-4, youngs_modulus=200e9,
                    supports=[(0, "xy"), (2, "x", [0.002, 0.0])], loads=[[0, 0], [0, -1e5], [0, 0]],
                    obstacles=[floor], load_factors=[0.5, 1.0])
    cmp = compare(m, variants=["classical"])
    for r in cmp.results.values():
        assert all(s.converged for s in r.steps)
    with pytest.raises(InputError, match="push contact pair 0 into its obstacle"):
        truss_model(nodes=X, members=members, area=1e-4, youngs_modulus=200e9,
                    supports=[(0, "xy"), (2, "xy", [0.0, -0.002])],
                    obstacles=[Obstacle(normal=[0.0, 1.0], offset=-0.001, nodes=[2])])


def test_a_pure_rigid_motion_of_a_device_has_sane_scales():
    """A device that moves a node along a mechanism-free but strain-free direction (a roller
    perpendicular to its only member): zero strain, no degenerate scales, every step converged."""
    X = np.array([(0.0, 0.0), (-1.0, 1.0), (-0.3, 1.0), (0.4, 1.0), (1.0, 1.0)])
    m = truss_model(nodes=X, members=[(0, 1), (0, 2), (0, 3), (0, 4)], area=1e-4, youngs_modulus=200e9,
                    supports=[(1, "xy"), (2, "xy"), (3, "xy"), (4, "x", [0.001, 0.0])], load_factors=[0.5, 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysicsWarning)
        cmp = compare(m, ["fischer_burmeister"], variants=["classical"])
    r = cmp["classical", "fischer_burmeister"]
    assert all(s.converged for s in r.steps)
    np.testing.assert_allclose(r.array("u")[-1], [0.0, 0.0, -0.001], atol=1e-15)
