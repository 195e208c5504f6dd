"""Contact between two deformable bodies (mortar, dual multipliers): the coupling operators, the
patch test across non-matching meshes, NAFEMS benchmark 1, the case files and their errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi import compare, formulations
from ddcm_casadi.casefiles.config import load_case
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.continuum import fem
from ddcm_casadi.models.continuum import mesh as meshes
from ddcm_casadi.models.continuum.bodies import join
from ddcm_casadi.models.continuum.inputs import BodyContact, Material, Support, Traction
from ddcm_casadi.models.continuum.model import continuum_model
from ddcm_casadi.models.continuum.mortar import Surface, candidate_facets, mortar_coupling
from ddcm_casadi.validation import two_body_rungs

from .test_bad_input import assert_input_error, run_cli

CASES = Path(__file__).resolve().parent.parent / "examples" / "cases"
#: Round-off of sums over a few dozen O(1) terms.
ROUNDOFF = 1e-13


def _blocks(d: int):
    """Two blocks on top of each other with non-matching meshes (punch above, block below)."""
    if d == 2:
        bodies = dict(block=meshes.rectangle(1.0, 0.5, nx=7, ny=3, origin=(0.0, -0.5)),
                      punch=meshes.rectangle(1.0, 0.5, nx=5, ny=3, origin=(0.0, 0.0)))
        return join(bodies), "punch/ymin", "block/ymax"
    bodies = dict(block=meshes.box(1.0, 1.0, 0.5, nx=5, ny=4, nz=2, origin=(0.0, 0.0, -0.5)),
                  punch=meshes.box(1.0, 1.0, 0.5, nx=3, ny=3, nz=2, origin=(0.0, 0.0, 0.0)))
    return join(bodies), "punch/zmin", "block/zmax"


def _coupling(mesh, slave, master, reach=0.1):
    s, m = mesh.boundaries[slave], mesh.boundaries[master]
    return mortar_coupling(mesh.p.T, Surface.of(mesh, s), Surface.of(mesh, m), reach)


@pytest.mark.parametrize("d", [2, 3])
def test_mortar_weights_are_means_and_transmit_a_uniform_pressure(d):
    """Rows of D/m and M/m sum to one (the weighted gap is a difference of means); a uniform
    pressure puts exactly the consistent loads int N on both sides of non-matching meshes."""
    mesh, slave, master = _blocks(d)
    c = _coupling(mesh, slave, master)
    assert c.dropped == 0
    assert np.allclose(c.slave_weights.sum(axis=1), 1.0, atol=ROUNDOFF)
    assert np.allclose(c.master_weights.sum(axis=1), 1.0, atol=ROUNDOFF)
    disc = fem.Discretisation.create(mesh, 1)
    for weights, boundary in ((c.master_weights, master), (c.slave_weights, slave)):
        loads = np.asarray(weights.T @ c.area).ravel()  # uniform p = 1
        dofs, area = fem.tributary_areas(disc, mesh.boundaries[boundary])  # P1: int N per node
        assert np.max(np.abs(loads[dofs] - area)) < ROUNDOFF
    assert np.max(np.abs(c.gaps(mesh.p.T))) < ROUNDOFF  # the blocks touch
    lifted = mesh.p.T.copy()
    lifted[np.unique(mesh.t[:, mesh.subdomains["punch"]]), -1] += 0.01
    assert np.allclose(c.gaps(lifted), 0.01, atol=ROUNDOFF)


def test_contact_search_finds_overlapping_facets_only():
    centres = np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 0.0]])
    s, m = candidate_facets(np.array([[0.0, 0.1]]), np.array([0.5]), centres, np.full(3, 0.5), 0.2)
    assert s.tolist() == [0, 0] and sorted(m.tolist()) == [0, 1]


def test_join_names_bodies_and_their_boundaries():
    mesh, _, _ = _blocks(2)
    assert set(mesh.subdomains) == {"block", "punch"}
    assert {"block/ymax", "punch/ymin", "block", "punch"} <= set(mesh.boundaries)
    top = mesh.p[:, mesh.facets[:, mesh.boundaries["block/ymax"]]]
    assert np.allclose(top[1], 0.0)


def test_patch_test_every_formulation_and_variant():
    checks = two_body_rungs.rung_patch_test()
    assert len(checks) == 2 * 2 * len(formulations.available())
    failed = [(c.name, c.value) for c in checks if not c.passed]
    assert not failed, failed


def test_nafems_exact_formulations_agree_and_penalty_within_its_bound():
    """On one coarse grading every formulation solves NAFEMS 1; the exact ones agree to their
    stopping tests (1e-8 relative) and penalty's pressures differ by its O(1/gamma) share."""
    model = two_body_rungs.nafems_model(2, steps=2)
    cmp = compare(model, variants=("classical",))
    p = {name: np.asarray(r.steps[-1].p) for (_, name), r in cmp.results.items()}
    assert all(s.converged for r in cmp.results.values() for s in r.steps)
    scale = float(np.max(p["fischer_burmeister"]))
    for name in ("augmented_lagrangian", "mpcc"):
        assert np.max(np.abs(p[name] - p["fischer_burmeister"])) < 1e-8 * scale, name
    assert np.max(np.abs(p["penalty"] - p["fischer_burmeister"])) < 0.05 * scale
    m = model.reference.measure(model, p["fischer_burmeister"])
    assert m["force"] == pytest.approx(two_body_rungs.NAFEMS["load"], rel=1e-9)  # the load, all of it
    assert m["p0_hertz"] == pytest.approx(two_body_rungs.NAFEMS_REFERENCE["p0"], rel=1e-3)
    assert m["a_hertz"] == pytest.approx(two_body_rungs.NAFEMS_REFERENCE["a"], rel=1e-2)


def test_nafems_example_case_runs(tmp_path, capsys):
    code, out, err = run_cli(["--config", str(CASES / "nafems1.toml"), "--formulations", "fischer_burmeister",
                              "--variants", "classical", "--out", str(tmp_path / "out"), "--no-plots"], capsys)
    assert code == 0, err
    model = load_case(CASES / "nafems1.toml").model
    assert model.n_contacts > 10 and {ob.kind for ob in model.obstacles} == {"surface"}


def _case(tmp_path, contact: str, degree: int = 1, extra: str = "") -> Path:
    path = tmp_path / "two.toml"
    path.write_text(f"""{extra}
[mesh]
degree = {degree}
[[mesh.body]]
name = "punch"
shape = "rectangle"
size = [1.0, 0.5]
divisions = [3, 2]
[[mesh.body]]
name = "block"
shape = "rectangle"
size = [1.0, 0.5]
divisions = [4, 2]
origin = [0.0, -0.5]
[material]
youngs_modulus = 1e9
poisson_ratio = 0.3
[[supports]]
boundary = "block/ymin"
fix = "xy"
[[supports]]
boundary = "punch/ymax"
fix = "x"
[[loads]]
boundary = "punch/ymax"
traction = [0.0, -1e6]
[[contact]]
{contact}
""")
    return path


@pytest.mark.parametrize("contact, degree, extra, expected", [
    ('slave = "punch/ymin"', 1, "", "needs 'master'"),
    ('slave = "punch/ymin"\nmaster = "block/nowhere"', 1, "", "nowhere"),
    ('slave = "punch/ymin"\nmaster = "block/ymax"\nobstacle = "plane"', 1, "", "takes no 'obstacle'"),
    ('slave = "punch/ymin"\nmaster = "block/ymax"\nsearch_distance = -1', 1, "", "search_distance"),
    ('slave = "punch/ymin"\nmaster = "block/ymax"', 2, "", "degree = 1"),
    ('slave = "punch/ymin"\nmaster = "punch/ymin"', 1, "", "share nodes"),
    ('slave = "punch/ymin"\nmaster = "block/ymax"', 1, 'kinematics = "finite"\n', "finite kinematics"),
])
def test_bad_two_body_cases_are_one_line_errors(tmp_path, capsys, contact, degree, extra, expected):
    if "finite" in extra:
        path = _case(tmp_path, contact, degree, extra)
        path.write_text(path.read_text().replace('poisson_ratio = 0.3', 'poisson_ratio = 0.3\nlaw = "neo_hookean"'))
    else:
        path = _case(tmp_path, contact, degree, extra)
    code, _, err = run_cli(["--config", str(path), "--out", str(tmp_path / "out")], capsys)
    assert_input_error(code, err, expected)


def test_a_body_held_only_by_a_contact_it_does_not_touch_is_refused_with_a_hint():
    mesh = join(dict(block=meshes.rectangle(1.0, 0.5, nx=3, ny=2, origin=(0.0, -0.5)),
                     punch=meshes.rectangle(1.0, 0.5, nx=2, ny=2, origin=(0.0, 0.001))))
    with pytest.raises(InputError, match=r"smallest gap is 0\.001 m"):
        continuum_model(mesh, materials=[Material(None, 1e9, 0.3)],
                        supports=[Support("block/ymin", "xy"), Support("punch/ymax", "x")],
                        tractions=[Traction("punch/ymax", (0.0, -1e6))],
                        contacts=[BodyContact("punch/ymin", "block/ymax")])


#: The examples' discretisation errors against Hertz (a, p0), from the mesh sequences of
#: ``python -m ddcm_casadi.validation.two_body_rungs`` at the examples' element sizes (NAFEMS
#: level 4: 1.2 % and 6.3 %; two spheres level 4: 1.7 % and 3.8 %; the Gmsh mesh, 0.5 mm at the
#: contact: 0.1 % and 0.01 %), rounded up: a regression bound, not the method's accuracy.
EXAMPLE_ERRORS = {"nafems1.toml": (0.02, 0.07), "two_spheres.toml": (0.02, 0.05),
                  "gmsh_cylinder_on_block.toml": (0.01, 0.01)}


@pytest.mark.parametrize("case", sorted(EXAMPLE_ERRORS))
def test_two_body_examples_against_hertz(case):
    """The two-body examples run and agree with Hertz for the measured force within what their
    meshes resolve (:data:`EXAMPLE_ERRORS`)."""
    model = load_case(CASES / case).model
    r = compare(model, ["fischer_burmeister"], variants=("classical",))["classical", "fischer_burmeister"]
    assert all(s.converged for s in r.steps)
    m = model.reference.measure(model, r.steps[-1].p, r.steps[-1].stress)
    bound_a, bound_p0 = EXAMPLE_ERRORS[case]
    assert m["error_a"] < bound_a and m["error_p0"] < bound_p0, m
    full = r.steps[-1]
    assert model.step_summary(full.u, full.p, full.stress)["hertz_force"] == pytest.approx(m["force"])


def test_ddcm_on_two_bodies_every_formulation():
    """NAFEMS 1 on a coarse mesh with Hookean data of each material: every formulation reaches a
    DDCM fixed point that carries the whole load through the contact."""
    from ddcm_casadi.data.dataset import MaterialDataset
    from ddcm_casadi.data.metric import isotropic_elasticity

    data = [MaterialDataset.hookean_grid(isotropic_elasticity(E, 0.3, 2)[0], -0.03, 0.03, 15, c="estimated")
            for E in (210e9, 70e9)]
    model = two_body_rungs.nafems_model(1, datasets=data)
    cmp = compare(model, variants=("ddcm",))
    for (_, name), r in cmp.results.items():
        last = r.steps[-1]
        assert last.converged, (name, last.message)
        m = model.reference.measure(model, last.p)
        assert m["force"] == pytest.approx(two_body_rungs.NAFEMS["load"], rel=1e-6), name


@pytest.mark.parametrize("formulation", sorted(formulations.available()))
def test_two_blocks_squeezed_by_a_hard_device(formulation):
    """Displacement control across a mortar interface: the punch's top moved down by ``delta``
    over two blocks in series (rollers elsewhere). Uniform uniaxial stress in plane strain, lateral
    faces free: ``sigma = -delta / sum(h_i (1 - nu_i^2) / E_i)``, the pairs' pressure ``-sigma``
    and the device's force ``sigma`` times the width; penalty within its O(1/gamma) share."""
    h, delta = 0.5, 1e-3
    laws = dict(block=(1e9, 0.3), punch=(2e9, 0.25))
    mesh = join(dict(block=meshes.rectangle(1.0, h, nx=7, ny=4, origin=(0.0, -h)),
                     punch=meshes.rectangle(1.0, h, nx=5, ny=3, origin=(0.0, 0.0))))
    model = continuum_model(
        mesh, materials=[Material(b, E, nu) for b, (E, nu) in laws.items()],
        supports=[Support("block/ymin", "y"), Support("block/xmin", "x"), Support("punch/xmin", "x"),
                  Support("punch/ymax", "y", displacement=(0.0, -delta))],
        contacts=[BodyContact("punch/ymin", "block/ymax")], load_factors=[0.5, 1.0])
    compliance = sum(h * (1 - nu ** 2) / E for E, nu in laws.values())  # m/Pa, the two blocks in series
    sigma = -delta / compliance
    cmp = compare(model, [formulation], variants=("classical",))
    r = cmp["classical", formulation]
    last = r.steps[-1]
    assert all(s.converged for s in r.steps)
    stress = np.asarray(last.stress).reshape(-1, 3)
    # exact formulations: their stopping tests (1e-9); penalty: the spring 1/gamma in series adds
    # to the compliance, a relative error 1/(gamma compliance), to first order
    gamma = next(f for f in cmp.formulations if f.name == formulation).penalty_stiffness(cmp.problems.classical)
    rel = 1e-9 if gamma is None else 2.0 / (gamma * compliance)
    assert np.max(np.abs(stress[:, 1] - sigma)) < rel * abs(sigma)
    assert np.max(np.abs(np.asarray(last.p) + sigma)) < rel * abs(sigma)
