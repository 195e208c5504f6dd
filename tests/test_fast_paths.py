"""The fast paths change the cost, never the answer.

- The active-set predictor of the FB systems (``active_set_predictor``) against plain semismooth
  Newton, on every model kind, for every formulation that has it, in both variants.
- The warm-started data search against the cold KD-tree query, along whole DDCM paths.
- The buffer evaluation of CasADi Functions against CasADi's own call.

Tolerances. Both solves stop when the relative Newton increment is below ``tol`` (1e-9) and the
scaled residual below ``residual_tol``; the last Newton step is quadratically smaller than the one
before, so each solution is within ``tol * max(1, |z|)`` of the root and two of them within
twice that. DDCM paths must reach the same data assignment (an exact search is exact).
"""

import casadi as ca
import numpy as np
import pytest

from ddcm_casadi import formulations
from ddcm_casadi import MaterialDataset, compare, paper_bar
from ddcm_casadi.errors import InputError
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.evaluate import NumericFunction
from ddcm_casadi.drivers.path import DDCMSolver
from ddcm_casadi.models.truss import bar_chain, warren_truss

WITH_PREDICTOR = ["fischer_burmeister", "penalty"]


def _bar_with_stops():
    data = MaterialDataset.hookean(200e9, -0.02, 0.01, 3001, c=300e9)
    return bar_chain(length=1.0, elements=20, youngs_modulus=200e9, tip_positions=np.linspace(1.0, 0.985, 6),
                     stops={5: 0.002, 10: 0.004, 15: 0.008}, dataset=data)


def _warren():
    return warren_truss(panels=8, gap=0.004, contact_nodes=[2, 4, 6], load_factors=np.linspace(0.2, 1.0, 5),
                        dataset=MaterialDataset.hookean(200e9, -0.01, 0.01, 4001, c=200e9))


MODELS = {"paper bar": paper_bar, "bar with stops": _bar_with_stops, "Warren truss": _warren}


@pytest.fixture(scope="module", params=list(MODELS))
def model(request):
    return MODELS[request.param]()


def _scaled(model, r):
    s = model.scales
    return np.concatenate([r.array("u").ravel() / s["displacement"], r.array("p").ravel() / s["stress"]])


@pytest.mark.parametrize("variant", ["classical", "ddcm"])
@pytest.mark.parametrize("name", WITH_PREDICTOR)
def test_predictor_gives_the_newton_solution(model, name, variant):
    tol = formulations.get(name).options.tol
    on = compare(model, {name: {}}, variants=[variant])[variant, name]
    off = compare(model, {name: {"active_set_predictor": False}}, variants=[variant])[variant, name]
    assert on.converged and off.converged
    z_on, z_off = _scaled(model, on), _scaled(model, off)
    assert np.max(np.abs(z_on - z_off)) <= 2 * tol * max(1.0, float(np.max(np.abs(z_off))))
    if variant == "ddcm":
        assert np.array_equal(on.array("data_index"), off.array("data_index"))


def test_predictor_is_used_along_a_path():
    """Between DDCM iterations only the data change: the active set mostly stays, and the
    projection is one cached factorisation's triangular solves."""
    model = _bar_with_stops()
    problems = build_problems(model)
    built = formulations.get("fischer_burmeister").build(problems.projection)
    path = DDCMSolver(problems, built).solve()
    assert path.converged
    stats = built.stats
    outer = sum(s.outer_iterations for s in path.steps)
    assert stats["predicted"] + stats["newton"] == outer
    assert stats["predicted"] >= outer // 2, stats
    for s in path.steps:
        assert 0 < s.projection_seconds and 0 < s.search_seconds
        assert s.projection_seconds + s.search_seconds <= s.seconds


@pytest.mark.parametrize("name", formulations.available())
def test_warm_search_gives_the_same_path(model, name):
    cold = compare(model, [name], variants=["ddcm"])["ddcm", name]
    warm = compare(model, [name], variants=["ddcm"], ddcm_search="warm")["ddcm", name]
    assert cold.converged and warm.converged
    for a, b in zip(cold.steps, warm.steps):
        assert a.outer_iterations == b.outer_iterations
        assert np.array_equal(a.data_index, b.data_index)
        assert np.array_equal(a.u, b.u)


def test_bad_fast_path_options():
    with pytest.raises(InputError, match="data search"):
        compare(paper_bar(), ["fischer_burmeister"], ddcm_search="fast")
    with pytest.raises(InputError, match="active_set_predictor"):
        formulations.get("fischer_burmeister", active_set_predictor="yes")


def test_numeric_function_matches_casadi():
    x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    sparse_vector = ca.vertcat(x[0] * p[0], ca.SX(1, 1), x[2] ** 2)  # a structural zero
    f = ca.Function("f", [x, p], [sparse_vector, ca.jacobian(sparse_vector, x), ca.dot(x, x)])
    fast = NumericFunction(f)
    xv, pv = np.array([1.0, 2.0, 3.0]), np.array([4.0, 5.0])
    v, J, s = fast(xv, pv)
    ref = f(xv, pv)
    assert np.array_equal(v, np.asarray(ca.densify(ref[0])).ravel())
    assert np.array_equal(J, np.asarray(ref[1].nonzeros()))
    assert s.shape == (1,) and s[0] == 14.0
    v[:] = 0  # results are copies
    assert np.array_equal(fast(xv, pv)[0], [4.0, 0.0, 9.0])
    with pytest.raises(ValueError, match="expected 3"):
        fast(np.zeros(4), pv)
