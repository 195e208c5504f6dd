"""Hard load paths, extreme units and awkward data: every formulation, both variants.

Exact formulations must reproduce the closed form to 1e-8 (their solver tolerances are 1e-9 and
below); DDCM steps must be converged, true fixed points (see ddcm_casadi.validate).
"""

import numpy as np
import pytest

import formulations
from ddcm_casadi import MaterialDataset, bar_model, compare
from ddcm_casadi.problem import build_problems
from ddcm_casadi.validate import check_fixed_points

from .conftest import ALL

RNG = np.random.default_rng(20261123)
STRAINS = np.linspace(-0.05, 0.01, 500)


def _case(L=1.0, E=200e9, h=None, data=None):
    h = L + L * 0.01 * np.linspace(1, -1, 21) if h is None else np.asarray(h)
    data = MaterialDataset.hookean(E, -0.05, 0.01, 500, c=1.5 * E) if data is None else data
    return bar_model(length=L, area=1.0, youngs_modulus=E, positions=h, dataset=data)


CASES = {
    "rubber_mm": lambda: _case(L=1e-3, E=1e6),
    "steel_100m": lambda: _case(L=1e2, E=1e12),
    "start_in_contact_then_unload": lambda: _case(h=1.0 + 0.01 * np.linspace(-1, 1, 21)),
    "random_jumps": lambda: _case(h=1.0 + 0.01 * RNG.uniform(-1, 1, 20)),
    "repeatedly_grazing": lambda: _case(h=[1.0, 0.995, 1.0, 1.0, 1.005, 1.0, 1.0]),
    "sparse_20_points": lambda: _case(data=MaterialDataset.hookean(200e9, -0.05, 0.01, 20, c=300e9)),
    "noisy_data": lambda: _case(data=MaterialDataset(STRAINS, 200e9 * STRAINS + RNG.normal(0, 2e8, 500), 300e9)),
    "nonlinear_data": lambda: _case(data=MaterialDataset(STRAINS, 4e9 * np.tanh(STRAINS / 0.02), 300e9)),
    "dense_1e5_points": lambda: _case(h=1.0 + 0.01 * np.linspace(1, -1, 7),
                                      data=MaterialDataset.hookean(200e9, -0.05, 0.01, 100_000, c=300e9)),
}


@pytest.fixture(scope="module", params=list(CASES))
def case(request):
    model = CASES[request.param]()
    return request.param, model, compare(model)


@pytest.mark.parametrize("name", ALL)
def test_classical_matches_closed_form(case, name):
    _, model, cmp = case
    r = cmp["classical", name]
    assert r.converged, [(s.step, s.message) for s in r.steps if not s.converged]
    err = cmp.errors("classical", name)  # penalty: against its own closed form
    assert np.max(err["u"]) <= 1e-8 and np.max(err["p"]) <= 1e-8


@pytest.mark.parametrize("name", ALL)
def test_ddcm_steps_are_converged_fixed_points(case, name):
    _, model, cmp = case
    r = cmp["ddcm", name]
    assert r.converged, [(s.step, s.message) for s in r.steps if not s.converged]
    report = check_fixed_points(cmp.problems, r)
    if formulations.get(name).exact:
        tol = 1e-8
    else:  # penalty: the tilt c / (gamma l0) of its contact branch (see test_ddcm.py)
        tol = model.dataset.c / (formulations.get(name).gamma(cmp.problems.classical) * model.length)
    assert np.max(report.projection_error_u) <= tol
    assert np.max(report.projection_error_p) <= tol
    assert report.nearest.all()


def test_results_are_deterministic(paper):
    """Same input, same solution columns, bit for bit."""
    a = compare(paper, ["fischer_burmeister", "mpcc"])
    b = compare(paper, ["fischer_burmeister", "mpcc"])
    for key in a.results:
        for field in ("u", "p", "iterations", "data_index", "converged"):
            arr_a, arr_b = a.arrays(*key).get(field), b.arrays(*key).get(field)
            if arr_a is not None:
                assert np.array_equal(arr_a, arr_b), (key, field)


@pytest.mark.parametrize("name", ALL)
def test_converges_from_any_start(paper, name):
    """Grazing (h = l0), the corner just after it, and a step deep in contact, from far-away starts:
    never NaN, always converged (merit line search, smoothing, corner polish)."""
    problems = build_problems(paper)
    built = formulations.get(name).build(problems.projection)
    classical = formulations.get(name).build(problems.classical)
    data = paper.dataset
    for step, j in ((10, 416), (11, 416), (15, 374)):
        params = problems.projection_params(step, data.strain[[j]], data.stress[[j]])
        for x0 in ([0.0, 0.0], [5.0, -3.0], [-5.0, 7.0], [1e3, 1e3]):
            sol = built.solve(params, np.array(x0), np.array([2.0]))
            assert np.all(np.isfinite(sol.x)) and np.all(np.isfinite(sol.p))
            assert np.isfinite(sol.residual) and np.isfinite(sol.complementarity)
            assert sol.converged, (step, x0, sol.message)
            c = classical.solve(problems.step_params(step), np.array(x0[:1]), np.array([2.0]))
            assert c.converged and np.all(np.isfinite(c.x)), (step, x0, c.message)
