"""Hard load paths, extreme units and awkward data: every formulation, both variants.

Exact formulations must reproduce the closed form to 1e-8 (their solver tolerances are 1e-9 and
below); DDCM steps must be converged, true fixed points (see ddcm_casadi.validation.fixed_points).
"""

import numpy as np
import pytest

from ddcm_casadi import formulations
from ddcm_casadi import MaterialDataset, bar_model, compare
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.models.truss import bar_chain
from ddcm_casadi.validation.fixed_points import nearest_by_brute_force, check_fixed_points

from .conftest import ALL
from .test_examples import _load

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


# ------------------------------------------------------------------ many contact pairs (DDCM)
def _floor_grid(load_factors):
    """The 3-D double-layer grid of ``examples/truss_3d_plane.py`` on its floor at its 10 inner
    bottom nodes, with a gentler load gradient in y and data up to |strain| 2e-3."""
    grid = _load("truss_3d_plane")
    inner = [(i, j) for j in range(1, grid.NY) for i in range(1, grid.NX)]
    return grid.build_model(contact=inner, gradient=(0.5, 1.0, 0.7, 0.6), strain_limit=2e-3,
                            load_factors=load_factors)


@pytest.mark.parametrize("name", ["penalty", "augmented_lagrangian", "fischer_burmeister"])
def test_ddcm_with_ten_contact_pairs(name):
    """Ten pairs, several near a tiny-stress datum: FB-based Newton stalls at its roundoff floor
    there and only converged with smoothing before the branch finish (formulations/ncp.py)."""
    model = _floor_grid(np.linspace(0, 1, 31)[21:26])
    cmp = compare(model, [name], variants=["ddcm"])
    r = cmp["ddcm", name]
    assert r.converged, [(s.step, s.message) for s in r.steps if not s.converged]
    opts = formulations.get(name).options
    comp_tol = opts.tol if name == "augmented_lagrangian" else opts.comp_tol
    for s in r.steps:
        assert nearest_by_brute_force(model.dataset, s)
        assert s.residual <= opts.residual_tol  # the equilibrium rows of the converged Newton system
        if name != "penalty":
            assert s.complementarity <= comp_tol and s.penetration <= comp_tol


@pytest.mark.parametrize("name", ["fischer_burmeister", "penalty"])
def test_ddcm_with_nine_stops_at_their_corner(name):
    """3000 elements, nine stops touching with zero pressure, 1e5 data: a projection from the
    warm multipliers failed at the last step (the active-set iteration cycles among 2^9 pieces
    and Newton needs smoothing); restarting without the multipliers converges."""
    stops = {300 * j: 0.002 * j for j in range(1, 10)}
    data = MaterialDataset.hookean(200e9, -0.05, 0.01, 100_000, c=300e9)
    model = bar_chain(length=1.0, elements=3000, youngs_modulus=200e9,
                      tip_positions=[0.99, 0.9875, 0.985, 0.9825, 0.98], stops=stops, dataset=data)
    r = compare(model, [name], variants=["ddcm"])["ddcm", name]
    assert r.converged, [(s.step, s.message) for s in r.steps if not s.converged]
    for s in r.steps:
        assert nearest_by_brute_force(model.dataset, s)
