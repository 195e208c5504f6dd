"""The Python API: registry, options, results, and raising on failure."""

import json

import numpy as np
import pytest

from ddcm_casadi import formulations
from ddcm_casadi import ConvergenceError, InputError, MaterialDataset, bar_model, compare
from ddcm_casadi.problems.build import build_problems

from .conftest import ALL


def test_registry_lists_the_four_formulations():
    assert formulations.available() == ["penalty", "augmented_lagrangian", "fischer_burmeister", "mpcc"]


@pytest.mark.parametrize("name", ALL)
def test_unknown_option_is_rejected(name):
    with pytest.raises(InputError, match="unknown option"):
        formulations.get(name, no_such_option=1)


def test_options_are_copied_not_shared():
    opts = {"ipopt": {"max_iter": 77}}
    a = formulations.get("mpcc", **opts)
    opts["ipopt"]["max_iter"] = 1
    b = formulations.get("mpcc")
    assert a.options.ipopt == {"max_iter": 77}
    assert b.options.ipopt == {}


def test_unknown_formulation():
    with pytest.raises(InputError, match="unknown formulation"):
        formulations.get("lagrange")


@pytest.mark.parametrize("name", ALL)
def test_raise_on_failure_carries_diagnostics(name):
    """A formulation starved of iterations must fail loudly when asked to."""
    model = bar_model(length=1.0, youngs_modulus=200e9, positions=[0.99])
    # (the MPCC's active-set branch NLPs need one IPOPT iteration on a linear model)
    starve = {"mpcc": {"max_homotopy": 1, "active_set": False, "ipopt": {"max_iter": 1}}}.get(name, {"max_iter": 1})
    if name == "augmented_lagrangian":
        starve = {"max_updates": 1, "predictor": False}  # the predictor needs no update at all
    with pytest.raises(ConvergenceError) as info:
        compare(model, {name: starve}, variants=["classical"], raise_on_failure=True)
    d = info.value.diagnostics
    assert d["converged"] is False and d["step"] == 0
    assert {"iterations", "residual", "complementarity", "penetration"} <= set(d)


def test_results_as_arrays_and_rows():
    data = MaterialDataset.hookean(200e9, -0.05, 0.01, 100, c=300e9)
    model = bar_model(length=1.0, youngs_modulus=200e9, positions=[1.005, 0.995], dataset=data)
    r = compare(model, ["fischer_burmeister"])
    a = r.arrays("classical", "fischer_burmeister")
    assert a["u"].shape == (2, 1) and a["converged"].all()
    np.testing.assert_allclose(a["u"][:, 0], [0.0, -0.005], atol=1e-15)
    rows = r.rows()
    assert len(rows) == 4
    assert {"variant", "formulation", "step", "h", "u", "p", "converged", "iterations"} <= set(rows[0])
    ddcm = [row for row in rows if row["variant"] == "ddcm"]
    assert {"strain_star", "stress_star", "global_optimum"} <= set(ddcm[0])


def test_built_formulation_is_reused_across_steps():
    """Build once, solve many: the same CasADi functions serve every load step."""
    model = bar_model(length=1.0, youngs_modulus=200e9, positions=np.linspace(1.01, 0.99, 5))
    problems = build_problems(model)
    built = formulations.get("fischer_burmeister").build(problems.classical)
    f = built.newton_system().functions.rj
    for k in range(model.n_steps):
        built.solve(problems.step_params(k), np.zeros(1), np.zeros(1))
    assert built.newton_system().functions.rj is f


def test_model_rejects_bad_values():
    with pytest.raises(InputError, match="youngs_modulus"):
        bar_model(length=1.0, youngs_modulus=float("nan"), positions=[1.0])
    with pytest.raises(InputError, match="length"):
        bar_model(length=-1.0, youngs_modulus=1e9, positions=[1.0])
    with pytest.raises(InputError, match="metric c"):
        MaterialDataset.hookean(1e9, -0.01, 0.01, 10, c=0.0)


def test_rows_of_a_truss_whose_load_parameter_is_the_step():
    """A moving obstacle without load factors: the load parameter is the step number, and the
    rows must carry it next to ``step`` (a ``step`` keyword twice used to crash ``rows()``)."""
    from ddcm_casadi.models.truss import Obstacle, truss_model

    model = truss_model(nodes=[[0.0], [1.0], [2.0]], members=[[0, 1], [1, 2]], area=1e-4, youngs_modulus=200e9,
                        supports=[(0, "x")], obstacles=[Obstacle([-1.0], [-2.001, -1.999], [2])])
    rows = compare(model, ["fischer_burmeister"], variants=["classical"]).rows()
    assert [r["step"] for r in rows] == [0, 1] and [r["load step"] for r in rows] == [0.0, 1.0]
    assert rows[1]["active_contacts"] == 1 and rows[0]["active_contacts"] == 0


def test_json_outputs_are_strict(tmp_path):
    """NaN (e.g. ``max_projection_error`` where no exact check ran) and infinities become null."""
    from ddcm_casadi.io import write_json_atomic

    path = write_json_atomic(tmp_path / "r.json", {"a": float("nan"), "b": np.array([1.0, np.inf]),
                                                   "c": [np.float64("-inf"), np.int64(3)], "d": np.ones((2, 2))})

    def reject(name):
        raise ValueError(name)

    data = json.loads(path.read_text(), parse_constant=reject)
    assert data == {"a": None, "b": [1.0, None], "c": [None, 3], "d": [[1.0, 1.0], [1.0, 1.0]]}
