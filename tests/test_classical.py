"""Classical variant against the closed forms of the paper's bar (docs/maths.md, Sec. 3)."""

import numpy as np
import pytest

from ddcm_casadi import formulations
from ddcm_casadi import bar_model, compare
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.drivers.path import solve_classical

from .conftest import ALL, EXACT

# Exact formulations solve the same complementarity problem as the closed form; their only error is
# the solver tolerance (1e-9 on the increment, 1e-10..1e-12 on residuals), so 1e-8 is a real bound.
EXACT_RTOL = 1e-8


def _check_close(values, reference, rtol):
    """Relative error per step; where the reference is 0 (before contact), relative to the path's max."""
    values, reference = np.asarray(values), np.asarray(reference)
    scale = np.where(reference != 0, np.abs(reference), np.max(np.abs(reference)))
    err = np.abs(values - reference) / scale
    assert np.all(err <= rtol), f"max relative error {err.max():.3e} > {rtol:g} at step {int(err.argmax())}"


@pytest.mark.parametrize("name", EXACT)
def test_exact_formulations_match_closed_form(paper, paper_comparison, name):
    r = paper_comparison["classical", name]
    assert r.converged, [s.message for s in r.steps if not s.converged]
    ref = [paper.closed_form(k) for k in range(paper.n_steps)]
    _check_close(r.array("u")[:, 0], [u[0] for u, _ in ref], EXACT_RTOL)
    _check_close(r.array("p")[:, 0], [p[0] for _, p in ref], EXACT_RTOL)


def test_penalty_matches_its_own_closed_form(paper, paper_comparison):
    r = paper_comparison["classical", "penalty"]
    gamma = formulations.get("penalty").gamma(paper_comparison.problems.classical)
    ref = [paper.penalty_closed_form(k, gamma) for k in range(paper.n_steps)]
    assert r.converged
    _check_close(r.array("u")[:, 0], [u[0] for u, _ in ref], EXACT_RTOL)
    _check_close(r.array("p")[:, 0], [p[0] for _, p in ref], EXACT_RTOL)


def test_penalty_converges_at_rate_one_over_gamma(paper):
    """Fit the log-log slope of the penalty error against gamma: it must be -1."""
    k = paper.contact_stiffness
    gammas = k * np.logspace(1, 6, 6)
    problems = build_problems(paper)
    exact_u = np.array([paper.closed_form(s)[0][0] for s in range(paper.n_steps)])
    errors = []
    for g in gammas:
        built = formulations.get("penalty", gamma=g).build(problems.classical)
        r = solve_classical(problems, built, "penalty")
        assert r.converged
        errors.append(np.max(np.abs(r.array("u")[:, 0] - exact_u)) / np.max(np.abs(exact_u)))
        # the closed form of the error, (E/l0) / (E/l0 + gamma), is a bound to solver precision
        assert errors[-1] <= k / (k + g) * (1 + 1e-8)
    slope = np.polyfit(np.log(gammas), np.log(errors), 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.02)


@pytest.mark.parametrize("name", ALL)
@pytest.mark.parametrize("length, youngs_modulus, travel", [
    (1e-3, 1e6, 2e-5),    # a millimetre rubber bar
    (50.0, 210e9, 0.05),  # a 50 m steel bar
])
def test_units_do_not_matter(name, length, youngs_modulus, travel):
    """Nondimensionalisation: the same relative accuracy in any units."""
    h = length + np.linspace(travel, -travel, 7)
    model = bar_model(length=length, area=2.5e-3, youngs_modulus=youngs_modulus, positions=h)
    r = compare(model, [name], variants=["classical"])["classical", name]
    assert r.converged
    ref = np.array([model.closed_form(k)[0][0] for k in range(model.n_steps)])
    if name == "penalty":
        gamma = formulations.get("penalty").gamma(build_problems(model).classical)
        ref = np.array([model.penalty_closed_form(k, gamma)[0][0] for k in range(model.n_steps)])
    _check_close(r.array("u")[:, 0], ref, EXACT_RTOL)
