"""Coulomb friction: the validation rungs as tests, the examples, every formulation on the same
problems, the FCLIB-style problems from models, and bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi import formulations
from ddcm_casadi.casefiles.config import load_case
from ddcm_casadi.drivers.harness import compare
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.continuum.inputs import Contact
from ddcm_casadi.models.continuum.obstacles import Plane, moving
from ddcm_casadi.models.coulomb import blocks, natural_map, project_cone
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.validation import friction_rungs, mindlin

CASES = Path(__file__).resolve().parents[1] / "examples" / "cases"
FRICTIONAL = friction_rungs.frictional_formulations()


def _all_pass(checks):
    failed = [(c.name, c.quantity, c.value, c.note) for c in checks if not c.passed]
    assert not failed, failed


@pytest.mark.parametrize("rung", ["rung_frictionless_limit", "rung_block_stick_slip", "rung_inclined_patch",
                                  "rung_ddcm_rate"])
def test_friction_rungs(rung):
    _all_pass(getattr(friction_rungs, rung)())


def test_every_newton_formulation_enforces_coulomb():
    assert {"penalty", "augmented_lagrangian", "fischer_burmeister"} <= set(FRICTIONAL)


def test_cone_projection_and_natural_map():
    """The projection onto K_mu is idempotent, lands in the cone, and is the identity inside; the
    natural map vanishes on the law's three cases (open, stick, slip) and not off them."""
    rng = np.random.default_rng(0)
    x, mu = rng.normal(size=(200, 3)), rng.uniform(0.0, 1.0, 200)
    px = project_cone(x, mu)
    assert np.allclose(project_cone(px, mu), px)
    assert np.all(np.linalg.norm(px[:, 1:], axis=1) <= mu * px[:, 0] + 1e-12)
    mu1 = np.array([0.3, 0.3, 0.3])
    u = np.array([[1.0, 0.2, 0.0], [0.0, 0.0, 0.0], [0.0, 0.5, 0.0]])      # open, stick, slip
    r = np.array([[0.0, 0.0, 0.0], [1.0, 0.1, 0.1], [1.0, -0.3, 0.0]])
    assert np.max(np.abs(natural_map(u, r, mu1))) < 1e-15
    r_wrong = r.copy()
    r_wrong[2, 1] = 0.3  # the traction along the slip
    assert np.max(np.abs(natural_map(u, r_wrong, mu1))) > 0.1


def test_3d_sphere_pressed_then_sheared_example():
    """The 3-D example (two tangents per contact, semismooth Newton): every step converges, the
    exact formulations agree, the friction never exceeds the cone and the shear makes the contacts
    at the edge slip."""
    case = load_case(CASES / "sphere_shear3d.toml")
    model = case.model
    cmp = compare(model, ["augmented_lagrangian", "fischer_burmeister"], variants=("classical",))
    ac, fb = (cmp["classical", n] for n in ("augmented_lagrangian", "fischer_burmeister"))
    assert all(s.converged for s in ac.steps + fb.steps)
    last_ac, last_fb = ac.steps[-1], fb.steps[-1]
    # two solutions of the same problem to Newton's tolerance (1e-9, relative)
    assert np.max(np.abs(last_ac.u - last_fb.u)) <= 1e-8 * np.max(np.abs(last_ac.u))
    r = blocks(last_ac.traction, 2)
    assert np.all(np.linalg.norm(r, axis=1) <= model.friction * last_ac.p * (1 + 1e-9) + 1e-9 * last_ac.p.max())
    status = model.contact_status(last_ac.p, last_ac.traction, last_ac.slip)[0]
    assert np.any(status == 2) and np.any(status == 1)


def test_mindlin_example_matches_the_rung_model():
    """examples/cases/mindlin2d.toml is the rung's model at level 4."""
    case, model = load_case(CASES / "mindlin2d.toml").model, mindlin.mindlin_model(4)
    assert case.n_dofs == model.n_dofs and case.n_contacts == model.n_contacts
    assert np.allclose(case.friction, model.friction) and np.allclose(case.slip_offsets, model.slip_offsets)


def test_mindlin_closed_form_integrates_to_Q():
    """The force distribution of the closed form: F(a) = Q = mu P (1 - (c/a)^2) with
    P = pi a p0 / 2 (the stick zone's deficit is the same law on c)."""
    a, p0, mu = 1.0, 2.0, 0.3
    for c in (0.0, 0.4, 0.9):
        P = np.pi * a * p0 / 2
        assert mindlin.mindlin_force(np.array([a]), a, c, p0, mu)[0] == pytest.approx(mu * P * (1 - (c / a) ** 2))
        x = np.linspace(-a, a, 20001)
        q = mindlin.mindlin_traction(x, a, c, p0, mu)
        assert np.trapezoid(q, x) == pytest.approx(mu * P * (1 - (c / a) ** 2), rel=1e-4)


def test_classical_mindlin_partial_slip_on_a_coarse_mesh():
    """One coarse Mindlin run: the sideways steps are in partial slip with Q < mu P, and the
    stick zone shrinks as Q grows."""
    model = mindlin.mindlin_model(3)
    r = compare(model, ["augmented_lagrangian"], variants=("classical",))["classical", "augmented_lagrangian"]
    assert all(s.converged for s in r.steps)
    rows = [mindlin.mindlin_measure(model, s) for s in r.steps[2:]]
    assert all(0 < row["ratio"] < 1 for row in rows)
    assert rows[1]["c"] < rows[0]["c"]


def test_problem_blocks_are_component_major():
    """A frictional problem's gaps are ``[g_N; s_T]`` (component-major) and its parameters carry
    the friction coefficients and the history; the 2-D predictor is built for the exact
    formulations."""
    model = friction_rungs.block_model(shear=(1e-4,))
    problems = build_problems(model)
    P = problems.classical.parameters
    assert problems.classical.block == 2 and problems.classical.n_contacts == model.n_contacts
    assert {"friction", "slip_offset", "slip0", "traction0"} <= set(P.names)
    built = formulations.get("augmented_lagrangian").build(problems.classical)
    assert built.pieces is not None
    sol = built.solve(problems.step_params(0), np.zeros(problems.classical.n_x), np.zeros(problems.classical.n_pairs))
    assert sol.converged and built.stats["predicted"] == 1


def test_friction_without_small_kinematics_is_refused():
    from dataclasses import replace

    from ddcm_casadi.models.bar import paper_bar

    bar = paper_bar()
    frictional = dict(tangent_operator=bar.gap_operator, friction=0.3)
    assert replace(bar, **frictional).contact_law == "coulomb"
    with pytest.raises(InputError, match="Coulomb friction needs small kinematics"):
        replace(bar, kinematics="finite", **frictional)


@pytest.mark.parametrize("edit, message", [
    ('friction = -0.1', r"\[contact 0\] friction must be >= 0, got -0.1"),
    ('friction = "a lot"', r"\[contact 0\] friction"),
    ('motion = [[0.0, 1e-4], [0.0]]', r"\[contact 0\] motion\[1\] must be a list of 2 numbers"),
    ('motion = [[0.0, 1e-4]]\ntravel = [0.0]', r"\[contact 0\] give either motion or direction and travel, not both"),
])
def test_bad_friction_input(tmp_path, edit, message):
    text = (CASES / "mindlin2d.toml").read_text()
    text = text.replace("motion = [[0.0, -2e-5], [0.0, -4e-5], [5e-6, -4e-5], [1e-5, -4e-5]]\nfriction = 0.3", edit)
    path = tmp_path / "case.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=message):
        load_case(path)


def test_motion_length_must_match_the_path():
    plane = moving(Plane(point=(0.0, 0.0), normal=(0.0, 1.0)), [[0.0, 1e-3], [0.0, 2e-3]])
    with pytest.raises(InputError, match="motion has 2 displacements"):
        plane.displacements(3)
    assert isinstance(Contact(plane, "ymin", friction=0.2), Contact)


# ------------------------------------------------------------------ trusses
def _triangle(friction, supports_extra=(), obstacle=True, load=(0.3, -1.0)):
    from ddcm_casadi.models.truss import Obstacle, truss_model

    # node 1 also hangs on a thin vertical member to node 3 (a truss held only by contact is
    # refused as a mechanism)
    nodes = [[0.0, 0.0], [1.0, 0.0], [0.5, 1.0], [1.0, -1.0]]
    loads = np.zeros((4, 2))
    loads[2] = load
    obstacles = [Obstacle(normal=[0.0, 1.0], offset=0.0, nodes=[1], friction=friction)] if obstacle else []
    return truss_model(nodes=nodes, members=[[0, 1], [0, 2], [1, 2], [1, 3]], area=[1e-4, 1e-4, 1e-4, 1e-7],
                       youngs_modulus=200e9, supports=[(0, "xy"), (3, "xy"), *supports_extra], loads=loads,
                       obstacles=obstacles, load_factors=[0.5, 1.0])


@pytest.mark.parametrize("name", FRICTIONAL)
def test_truss_node_sticks_like_a_pin_and_slides_like_a_roller(name):
    """A triangle pinned at node 0, node 1 on a plane: with ample friction node 1 sticks and the
    truss deforms as if node 1 were pinned; with mu = 0 as on a roller; in between, node 1 slips
    with its traction on the cone. The load (0.3, -1) N on the apex presses node 1: the horizontal
    member carries 0.15 N where the plane carries 0.5 N, so mu = 5 sticks, mu = 0.1 slips."""
    exact = type(formulations.get(name)).exact
    tol = 1e-8 if exact else 1e-3  # Newton's tolerance; penalty: O(1/gamma) relative
    pinned = compare(_triangle(None, [(1, "xy")], obstacle=False), ["fischer_burmeister"], variants=("classical",))
    roller = compare(_triangle(None, [(1, "y")], obstacle=False), ["fischer_burmeister"], variants=("classical",))
    for mu, ref in ((5.0, pinned), (0.0, roller)):
        model = _triangle(mu)
        run = compare(model, [name], variants=("classical",))["classical", name]
        expected = ref["classical", "fischer_burmeister"]
        for s, e in zip(run.steps, expected.steps):
            assert s.converged
            full = model.nodal_displacements(s.u, s.step)
            reference = ref.model.nodal_displacements(e.u, e.step)
            assert np.max(np.abs(full - reference)) <= tol * np.max(np.abs(reference))
    model = _triangle(0.1)
    last = compare(model, [name], variants=("classical",))["classical", name].steps[-1]
    assert last.converged and abs(abs(last.traction[0]) - 0.1 * last.p[0]) <= tol * last.p[0]
    assert model.contact_status(last.p, last.traction, last.slip)[0][0] == 2
