"""Property-based checks (hypothesis) of single projections and classical steps of the bar."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ddcm_casadi import formulations
from ddcm_casadi import MaterialDataset, bar_model
from ddcm_casadi.problems.build import build_problems

from .conftest import EXACT

MODEL = bar_model(length=1.0, youngs_modulus=200e9, positions=np.linspace(1.01, 0.99, 5),
                  dataset=MaterialDataset.hookean(200e9, -0.05, 0.01, 50, c=300e9))
PROBLEMS = build_problems(MODEL)
BUILT = {n: (formulations.get(n).build(PROBLEMS.classical), formulations.get(n).build(PROBLEMS.projection))
         for n in EXACT}
SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _params(w):
    return np.array([w, 0.0])


def _tolerances(name):
    """``(complementarity, residual)`` tolerances the formulation itself declares converged at."""
    opts = formulations.get(name).options
    return (opts.comp_tol if hasattr(opts, "comp_tol") else opts.tol), opts.residual_tol


@pytest.mark.parametrize("name", EXACT)
@SETTINGS
@given(w=st.floats(-0.02, 0.02))
def test_classical_step_matches_closed_form(name, w):
    built = BUILT[name][0]
    sol = built.solve(_params(w), np.zeros(1), np.zeros(1))
    assert sol.converged
    f = PROBLEMS.fields("mcp", sol.x, sol.p)
    u_ex = min(0.0, w)
    assert abs(f["u"][0] - u_ex) <= 1e-8 * 0.02  # relative to the range of w
    assert abs(f["p"][0] + 200e9 * u_ex) <= 1e-8 * 200e9 * 0.02
    # KKT within the formulation's own tolerances: equilibrium, signs, complementarity
    comp_tol, residual_tol = _tolerances(name)
    assert sol.residual <= residual_tol and sol.penetration <= comp_tol and sol.complementarity <= comp_tol


@pytest.mark.parametrize("name", EXACT)
@SETTINGS
@given(w=st.floats(-0.02, 0.02), eps=st.floats(-0.05, 0.01), sig=st.floats(-1e10, 2e9))
def test_projection_is_exact(name, w, eps, sig):
    """Any data point, any obstacle: converged and equal to the closed-form projection, or flagged."""
    built = BUILT[name][1]
    m = bar_model(length=1.0, youngs_modulus=200e9, positions=[1.0 + w], dataset=MODEL.dataset)
    params = np.array([w, 0.0, eps, sig])
    sol = built.solve(params, np.zeros(2), np.zeros(1))
    assert np.all(np.isfinite(sol.x)) and np.all(np.isfinite(sol.p))
    u_ex, p_ex, _ = m.projection_closed_form(0, eps, sig)
    f = PROBLEMS.fields("mpcc", sol.x, sol.p)
    if sol.converged:
        # A converged local solve is the minimum of one branch (the DDCM driver restarts on the
        # global one): free, u = min(L eps, w), p = 0, or contact, u = w, p = max(0, -sig).
        branches = [(u_ex, p_ex), (min(eps, w), 0.0), (w, max(0.0, -sig))]
        assert any(abs(f["u"][0] - u) <= 1e-8 * 0.02 and abs(f["p"][0] - p) <= 1e-8 * 6e9 for u, p in branches)
        comp_tol, residual_tol = _tolerances(name)
        assert sol.complementarity <= comp_tol and sol.residual <= residual_tol


@pytest.mark.parametrize("name", formulations.available())
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(log_E=st.floats(6, 12), log_L=st.floats(-3, 2), travel=st.floats(1e-4, 2e-2))
def test_any_units_classical_exact_and_ddcm_fixed_points(name, log_E, log_L, travel):
    """Moduli 1e6..1e12 Pa, lengths 1e-3..1e2 m: classical matches the closed form to 1e-8 and every
    DDCM step is a converged, valid fixed point (KKT within the reported tolerance)."""
    from ddcm_casadi import compare
    from ddcm_casadi.validation.fixed_points import check_fixed_points

    E, L = 10.0**log_E, 10.0**log_L
    h = L * (1.0 + travel * np.array([1.0, 0.5, 0.0, -0.5, -1.0, 0.0]))
    data = MaterialDataset.hookean(E, -2 * travel, travel, 200, c=1.5 * E)
    model = bar_model(length=L, youngs_modulus=E, positions=h, dataset=data)
    cmp = compare(model, [name])
    classical, ddcm = cmp["classical", name], cmp["ddcm", name]
    assert classical.converged and ddcm.converged
    err = cmp.errors("classical", name)
    assert max(err["u"].max(), err["p"].max()) <= 1e-8
    report = check_fixed_points(cmp.problems, ddcm)
    tol = 1e-8 if formulations.get(name).exact else \
        data.c / (formulations.get(name).gamma(cmp.problems.classical) * L)
    assert report.projection_error_u.max() <= tol and report.projection_error_p.max() <= tol
    assert report.nearest.all()
