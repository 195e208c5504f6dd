"""The augmented Lagrangian converges for any gamma from 1e-3 to 1e6 times E/l0, in both variants."""

import numpy as np
import pytest

from ddcm_casadi import compare
from ddcm_casadi.validate import check_fixed_points

FACTORS = [1e-3, 1e-1, 1e1, 1e3, 1e6]


@pytest.mark.parametrize("factor", FACTORS)
def test_any_gamma_converges_and_is_exact(paper, factor):
    gamma = factor * paper.contact_stiffness
    cmp = compare(paper, {"augmented_lagrangian": {"gamma": gamma}})
    classical = cmp["classical", "augmented_lagrangian"]
    assert classical.converged
    err = cmp.errors("classical", "augmented_lagrangian")
    assert np.max(err["u"]) <= 1e-8 and np.max(err["p"]) <= 1e-8
    ddcm = cmp["ddcm", "augmented_lagrangian"]
    assert ddcm.converged
    report = check_fixed_points(cmp.problems, ddcm)
    assert np.max(report.projection_error_u) <= 1e-8 and np.max(report.projection_error_p) <= 1e-8
    assert report.nearest.all()


def test_plain_uzawa_follows_its_contraction_rate(paper):
    """Plain Uzawa contracts the multiplier error by k / (k + gamma), k = E/l0, per update:
    it needs about log(tol) / log(k / (k + gamma)) updates; Anderson mixing needs a few."""
    k = paper.contact_stiffness
    gamma = 0.1 * k
    plain = compare(paper, {"augmented_lagrangian": {"gamma": gamma, "anderson": 0, "max_updates": 2000}},
                    variants=["classical"])["classical", "augmented_lagrangian"]
    fast = compare(paper, {"augmented_lagrangian": {"gamma": gamma}},
                   variants=["classical"])["classical", "augmented_lagrangian"]
    assert plain.converged and fast.converged
    predicted = np.log(1e-11) / np.log(k / (k + gamma))  # from a unit initial multiplier error
    assert 0.5 * predicted <= plain.array("outer_iterations").max() <= 1.5 * predicted
    assert fast.array("outer_iterations").max() <= 10
