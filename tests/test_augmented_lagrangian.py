"""The augmented Lagrangian converges for any gamma from 1e-3 to 1e6 times E/l0, in both variants."""

import numpy as np
import pytest

from ddcm_casadi import formulations
from ddcm_casadi import compare
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.validation.fixed_points import check_fixed_points

FACTORS = [1e-3, 1e-1, 1e1, 1e3, 1e6]


@pytest.mark.parametrize("predictor", [True, False])
@pytest.mark.parametrize("factor", FACTORS)
def test_any_gamma_converges_and_is_exact(paper, factor, predictor):
    """With and without the active-set predictor (which ends the loops at their fixed point)."""
    gamma = factor * paper.contact_stiffness
    cmp = compare(paper, {"augmented_lagrangian": {"gamma": gamma, "predictor": predictor}})
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
    it needs about log(tol) / log(k / (k + gamma)) updates; Anderson mixing needs a few. (Without
    the active-set predictor, which would start the loop at its fixed point.)"""
    k = paper.contact_stiffness
    gamma = 0.1 * k
    plain = compare(paper, {"augmented_lagrangian": {"gamma": gamma, "anderson": 0, "max_updates": 2000,
                                                     "predictor": False}},
                    variants=["classical"])["classical", "augmented_lagrangian"]
    fast = compare(paper, {"augmented_lagrangian": {"gamma": gamma, "predictor": False}},
                   variants=["classical"])["classical", "augmented_lagrangian"]
    assert plain.converged and fast.converged
    tol = formulations.get("augmented_lagrangian").options.tol  # the stopping test on the pairs
    predicted = np.log(tol) / np.log(k / (k + gamma))  # from a unit initial multiplier error
    assert 0.5 * predicted <= plain.array("outer_iterations").max() <= 1.5 * predicted
    assert fast.array("outer_iterations").max() <= 10


def test_ddcm_projection_onto_a_tiny_contact_pressure(paper):
    """Dense data: deep in contact, the assigned datum has a tiny stress (the one nearest the origin
    of 1e5 Hookean points). ``Phi`` rounds its corner at the scale of that pressure, so the inner
    Newton stalls above its tolerance after the first multiplier update; the update is finished on
    the contact branch. The result is the exact projection and a fixed point of the multiplier
    update (``Phi = 0``, so ``lam + rho Phi = lam``)."""
    problems = build_problems(paper)
    built = formulations.get("augmented_lagrangian").build(problems.projection)
    eps, sig = -3.00003e-7, -6.00006e4
    free = built.solve(problems.projection_params(0, [eps], [sig]), np.zeros(2), np.zeros(1))
    assert free.converged, free.message
    last = paper.n_steps - 1
    params = problems.projection_params(last, [eps], [sig])
    sol = built.solve(params, free.x, free.p, free.state)
    assert sol.converged, sol.message
    f = problems.fields("mpcc", sol.x, sol.p)
    w = paper.load_parameter[last] - paper.length  # the contact branch is the nearer: u = w, p = -sig
    assert abs(f["u"][0] - w) <= 1e-12 and abs(f["p"][0] + sig) <= 1e-8 * abs(sig)
    z = np.concatenate([sol.x, sol.p, sol.state["eta"], sol.state["theta"], np.zeros(1)])
    system = built.system
    phi = system.phi(z, system.pack(system.base_parameters.pack(params, lam=sol.state["lam"], rho=sol.state["rho"])))
    assert abs(float(phi[0])) <= 1e-12
