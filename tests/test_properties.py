"""Property-based checks (hypothesis) of single projections and classical steps of the bar."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import formulations
from ddcm_casadi import MaterialDataset, bar_model
from ddcm_casadi.problem import build_problems

from .conftest import EXACT

MODEL = bar_model(length=1.0, youngs_modulus=200e9, positions=np.linspace(1.01, 0.99, 5),
                  dataset=MaterialDataset.hookean(200e9, -0.05, 0.01, 50, c=300e9))
PROBLEMS = build_problems(MODEL)
BUILT = {n: (formulations.get(n).build(PROBLEMS.classical), formulations.get(n).build(PROBLEMS.projection))
         for n in EXACT}
SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _params(w):
    return np.array([w, 0.0])


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
    # KKT within the reported tolerances: equilibrium, signs, complementarity
    assert sol.residual <= 1e-9 and sol.penetration <= 1e-9 and sol.complementarity <= 1e-9


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
        # A converged local solve is a stationary point on some branch; the DDCM driver restarts on
        # the global branch. Either it is the exact projection, or its distance is not smaller.
        d2 = 300e9 * (f["u"][0] - eps) ** 2 + (-f["p"][0] - sig) ** 2 / 300e9
        d2_ex = 300e9 * (u_ex - eps) ** 2 + (-p_ex - sig) ** 2 / 300e9
        close = abs(f["u"][0] - u_ex) <= 1e-8 * 0.02 and abs(f["p"][0] - p_ex) <= 1e-8 * 6e9
        assert close or d2 >= d2_ex * (1 - 1e-9)
        assert sol.complementarity <= 1e-9 and sol.residual <= 1e-9
