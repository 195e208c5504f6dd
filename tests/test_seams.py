"""The core's seams: contact laws as kinds, formulations that declare what they support, the
published Newton systems and the steps' history."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ddcm_casadi import formulations
from ddcm_casadi.models.bar import paper_bar
from ddcm_casadi.models.contact_laws import ContactLaw, contact_laws, get_contact_law, register_contact_law
from ddcm_casadi.errors import InputError
from ddcm_casadi.formulations.fischer_burmeister import FischerBurmeister
from ddcm_casadi.drivers.harness import compare
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.models.von_mises import von_mises_truss

NEWTON = ("penalty", "augmented_lagrangian", "fischer_burmeister")


@pytest.fixture(scope="module")
def two_component_law():
    name = "test_two_components"
    if name not in contact_laws():
        register_contact_law(ContactLaw(name, ("normal", "tangential"), "a law no formulation supports"))
    return get_contact_law(name)


def test_signorini_is_the_default_law():
    law = get_contact_law("signorini")
    assert law.block(2) == 1 and law.components == ("normal",)
    pair = build_problems(paper_bar())
    assert pair.classical.contact_law == pair.projection.contact_law == "signorini"
    with pytest.raises(InputError, match="unknown contact law 'coulomb_x'; known: signorini, coulomb"):
        get_contact_law("coulomb_x")


@pytest.mark.parametrize("name", formulations.available())
def test_unsupported_law_is_refused_before_any_work(two_component_law, name, monkeypatch):
    model = dataclasses.replace(paper_bar(), contact_law=two_component_law.name)
    cls = type(formulations.get(name))
    monkeypatch.setattr(cls, "_build", lambda self, problem: pytest.fail("built an unsupported problem"))
    with pytest.raises(InputError) as err:
        compare(model, [name])
    assert str(err.value) == (f"formulation {name!r} does not support the contact law "
                              f"'{two_component_law.name}' (it supports: {', '.join(sorted(cls.supported_contact_laws))})")


def test_unsupported_kinematics_is_refused():
    class SmallOnly(FischerBurmeister):
        supported_kinematics = frozenset({"small"})

    with pytest.raises(InputError, match="does not support finite kinematics"):
        compare(von_mises_truss(steps=4), [SmallOnly()], variants=("classical",))


@pytest.mark.parametrize("variant", ["classical", "ddcm"])
@pytest.mark.parametrize("name", NEWTON)
def test_published_newton_system_vanishes_at_a_solution(name, variant):
    """The published system, by name, is the one the formulation solved: its residual at the
    converged point of the last step is at the solver's tolerance."""
    cmp = compare(paper_bar(), [name], variants=(variant,))
    problems, step = cmp.problems, cmp[variant, name].steps[-1]
    problem = problems.classical if variant == "classical" else problems.projection
    built = formulations.get(name).build(problem)
    system = built.newton_system()
    assert {"x"} <= set(system.unknowns.names) and system.parameters.names[:2] == ("gap0", "f")
    if variant == "classical":
        x, p = problems.scaled_start("mcp", step.u, step.p)
        params = problems.step_params(step.step)
    else:
        x, p = problems.scaled_start("mpcc", step.u, step.p, step.stress)
        params = problems.projection_params(step.step, step.strain_star, step.stress_star)
    sol = built.solve(params, x, p)  # from the converged point: the multipliers come back
    z, P = built.newton_point(params, sol.x, sol.p, sol.state)
    J = system.matrix(z, P)
    assert J.shape == (system.unknowns.size, system.unknowns.size)
    blocks = system.unpack(z)
    np.testing.assert_array_equal(blocks["x"], sol.x)
    if name != "augmented_lagrangian":  # its inner system holds at the multiplier iterate only
        assert np.max(np.abs(system.residual(z, P))) <= 1e-8


def test_mpcc_publishes_no_newton_system():
    built = formulations.get("mpcc").build(build_problems(paper_bar()).classical)
    assert built.newton_system() is None


@dataclasses.dataclass(frozen=True, eq=False)
class _FollowingObstacleBar(type(paper_bar())):
    """The paper's bar whose obstacle, at each step, is placed ``delta`` beyond the tip's previous
    converged position: a step that depends on its history."""

    delta: float = -1e-3

    def history_sizes(self) -> dict[str, int]:
        return {"tip_previous": 1}

    def step_values(self, step, previous=None):
        tip = 0.0 if previous is None else float(previous["u"][0])
        # the obstacle at l0 + tip + delta: gap = (tip + delta) - u >= 0 pushes the tip to tip + delta
        return dict(gap0=np.array([tip + self.delta]), f=self.loads[step], tip_previous=np.array([tip]))


@pytest.mark.parametrize("name", NEWTON + ("mpcc",))
def test_history_reaches_every_step(name):
    """Each step pushes the tip ``delta`` further than the previous converged one: after k
    steps it has moved ``k delta`` (the driver hands every step its predecessor)."""
    base = paper_bar()
    fields = {f.name: getattr(base, f.name) for f in dataclasses.fields(base) if f.init}
    model = _FollowingObstacleBar(**fields)
    pair = build_problems(model)
    assert "tip_previous" in pair.classical.parameters.names
    u = compare(model, [name], variants=("classical",))["classical", name].array("u")[:, 0]
    # penalty: each step's penetration, 1e-4 of its displacement (gamma = 1e4 E / l0), carries into
    # every later step's obstacle: the relative error grows to at most n_steps * 1e-4
    tol = model.n_steps * 1e-4 if name == "penalty" else 1e-9
    np.testing.assert_allclose(u, model.delta * np.arange(1, model.n_steps + 1), rtol=tol, atol=0)
