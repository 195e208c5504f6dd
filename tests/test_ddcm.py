"""DDCM variant: every step is a true fixed point, and the paper's local minimum is reported.

Reference values come from the closed forms of docs/maths.md, Sec. 3 (BarModel methods), not from
the branch enumeration the solver itself consults.
"""

import numpy as np
import pytest

from ddcm_casadi import formulations
from ddcm_casadi.drivers.path import DDCMSolver
from ddcm_casadi.problems.build import build_problems

from .conftest import ALL

# Exact formulations: the projection is the exact one up to solver tolerances (1e-9 .. 1e-11).
EXACT_PROJECTION_RTOL = 1e-8


def _projection_tolerance(paper, name, problems):
    """Relative tolerance of the Z_E projection, from the method.

    The penalty replaces the contact branch u = w by the line sigma = -gamma (u - w). In the metric's
    normalised coordinates (sqrt(c) eps, sigma / sqrt(c)) that line is tilted from the vertical by an
    angle ~ c / (gamma l0), which moves the foot of the projection by at most that fraction of the
    path's scale.
    """
    if formulations.get(name).exact:
        return EXACT_PROJECTION_RTOL
    gamma = formulations.get(name).gamma(problems.classical)
    return paper.dataset.c / (gamma * paper.length)


@pytest.mark.parametrize("name", ALL)
def test_every_step_is_a_fixed_point(paper, paper_comparison, name):
    r = paper_comparison["ddcm", name]
    assert r.converged, [(s.step, s.message) for s in r.steps if not s.converged]
    data = paper.dataset
    rtol = _projection_tolerance(paper, name, paper_comparison.problems)
    u_scale, p_scale = paper.scales["displacement"], paper.scales["stress"]
    for s in r.steps:
        j = int(s.data_index[0])
        # (u, p) is the exact projection onto Z_E of the assigned data point ...
        u_ex, p_ex, _ = paper.projection_closed_form(s.step, data.strain[j], data.stress[j])
        assert abs(s.u[0] - u_ex) <= rtol * u_scale, (s.step, s.u[0], u_ex)
        assert abs(s.p[0] - p_ex) <= rtol * p_scale, (s.step, s.p[0], p_ex)
        # ... and that data point is the nearest datum to (strain, stress), by brute force.
        d2 = data.c * (s.strain[0] - data.strain) ** 2 + (s.stress[0] - data.stress) ** 2 / data.c
        assert d2[j] <= d2.min() * (1 + 1e-12) + 1e-300
        # Mechanical admissibility and complementarity, as reported.
        assert s.complementarity <= (1e-9 if formulations.get(name).exact else rtol)
        assert s.projection_global is True


@pytest.mark.parametrize("name", ALL)
def test_local_minimum_reported_at_the_papers_step(paper, paper_comparison, name):
    """docs/maths.md, Sec. 3: the alternating scheme stops at a local minimum at h = 0.992 m only."""
    r = paper_comparison["ddcm", name]
    local = [s.load_parameter for s in r.steps if s.global_optimum is False]
    assert local == [pytest.approx(0.992)]
    assert all(s.global_optimum is not None for s in r.steps)


def test_global_optimum_by_independent_enumeration(paper, paper_comparison):
    """The solver's global distance equals a brute-force minimum over closed-form projections."""
    r = paper_comparison["ddcm", "fischer_burmeister"]
    data, vol = paper.dataset, paper.volumes[0]
    # The enumerator expands the quadratic, so terms as large as w/2 (c eps*^2 + sigma*^2/c) cancel:
    # its roundoff is a few machine epsilons of that size, not of the (small) distance itself.
    roundoff = 8 * np.finfo(float).eps * 0.5 * vol * np.max(data.c * data.strain**2 + data.stress**2 / data.c)
    for s in r.steps:
        d2 = [paper.projection_closed_form(s.step, e, q)[2] for e, q in zip(data.strain, data.stress)]
        best = 0.5 * vol * min(d2)
        assert s.global_distance == pytest.approx(best, rel=1e-12, abs=roundoff)
        assert (s.distance <= best * (1 + 1e-9) + 1e-9) == s.global_optimum


@pytest.mark.parametrize("name", ALL)
def test_ddcm_accuracy_follows_the_data_spacing(paper, paper_comparison, name):
    """u is exact in contact; before contact it is l0 eps* of the datum nearest the origin; at global
    optima p is off by at most E * (strain spacing) / 2."""
    r = paper_comparison["ddcm", name]
    data = paper.dataset
    E = paper.youngs_modulus[0]
    spacing = np.max(np.diff(np.sort(data.strain)))
    j0 = data.nearest([0.0], [0.0])[0]
    rtol = _projection_tolerance(paper, name, paper_comparison.problems)
    for s in r.steps:
        u_ex, p_ex = (v[0] for v in paper.closed_form(s.step))
        w = paper.gap_offsets[s.step, 0]
        if w < 0:
            assert s.u[0] == pytest.approx(w, abs=rtol * paper.scales["displacement"])
        elif w > paper.length * data.strain[j0]:
            assert s.u[0] == pytest.approx(paper.length * data.strain[j0], rel=1e-9)
        if s.global_optimum:
            assert abs(s.p[0] - p_ex) <= E * spacing / 2 * (1 + 1e-9) + rtol * paper.scales["stress"]


def test_first_step_starts_from_datum_nearest_origin(paper):
    problems = build_problems(paper)
    built = formulations.get("fischer_burmeister").build(problems.projection)
    r = DDCMSolver(problems, built).solve()
    j0 = int(paper.dataset.nearest([0.0], [0.0])[0])
    assert int(r.steps[0].data_index[0]) == j0
    assert r.steps[0].outer_iterations == 1  # already a fixed point: free bar, datum nearest origin
