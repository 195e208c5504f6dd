"""The sparse build of problems and Newton systems (``ddcm_casadi.problems.contract``,
``formulations/pairs.py``) against CasADi's own symbolic derivatives of the same expressions."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from ddcm_casadi import formulations, paper_bar
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.models.truss import warren_truss
from ddcm_casadi.data.dataset import MaterialDataset

#: Agreement of two evaluations of the same sums in another order: a few ulps of the largest term.
ROUNDOFF = 1e-12


def _truss():
    data = MaterialDataset.hookean(200e9, -0.01, 0.01, 50, c=200e9)
    return warren_truss(panels=12, gap=[0.0, 1e-4, 2e-4], contact_nodes=[2, 6, 10], load_factors=[0.5, 1.0],
                        dataset=data)


def _systems(problem):
    """Every Newton system the formulations build for ``problem``: ``(label, rj, parameters)``
    (their published systems, and the FB piece systems)."""
    out = []
    for name in ("penalty", "augmented_lagrangian", "fischer_burmeister"):
        built = formulations.get(name).build(problem)
        system = built.newton_system()
        out.append((name, system.functions.rj, system.parameters.size))
        if name == "fischer_burmeister":
            rj, _, _, _ = built.system.branch_system()
            out.append((f"{name} pieces", rj, built.system.piece_parameters.size))
    return out


@pytest.mark.parametrize("model", [paper_bar, _truss], ids=["paper bar", "truss"])
@pytest.mark.parametrize("kind", ["classical", "projection"])
def test_jacobians_are_casadi_derivatives_of_the_residuals(model, kind):
    """``J = J0 + T d`` (constant part and per-pair derivatives scattered) equals CasADi's
    derivative of the same residual graph, at random unknowns and parameters (the formulations'
    own ones, selectors and ``rho`` included, in [0.5, 1.5]: any values, the identity is exact)."""
    problem = getattr(build_problems(model()), kind)
    rng = np.random.default_rng(0)
    for label, rj, n_params in _systems(problem):
        f = rj.function
        z, P = ca.MX.sym("z", f.nnz_in(0)), ca.MX.sym("P", n_params)
        r, J = f(z, P)
        check = ca.Function("check", [z, P], [J, ca.jacobian(r, z)])
        for _ in range(3):
            zv, Pv = rng.standard_normal(f.nnz_in(0)), rng.uniform(0.5, 1.5, n_params)
            Pv[: problem.parameters.size] = rng.standard_normal(problem.parameters.size)
            mine, ad = (np.asarray(ca.densify(v), float) for v in check(zv, Pv))
            assert np.all(np.isfinite(mine))
            assert np.max(np.abs(mine - ad)) <= ROUNDOFF * max(1.0, np.max(np.abs(ad))), label


@pytest.mark.parametrize("kind", ["classical", "projection"])
def test_numeric_evaluation_is_the_symbolic_problem(kind):
    """The metrics' sparse products and the ``SX`` expressions (rendered for IPOPT and the exact
    enumeration) are the same residual, terms, gaps and objective."""
    problem = getattr(build_problems(_truss()), kind)
    rng = np.random.default_rng(1)
    x, p, P = (rng.standard_normal(n) for n in (problem.n_x, problem.n_pairs, problem.parameters.size))
    objective = problem.objective if problem.objective is not None else ca.SX(0)
    f = ca.Function("f", [problem.x, problem.p, problem.params],
                    [problem.residual, problem.residual_terms, problem.gap, objective])
    for symbolic, numeric in zip(f(x, p, P), problem.evaluate(x, p, P)):
        symbolic = np.asarray(symbolic, float).ravel()
        assert np.max(np.abs(symbolic - numeric)) <= ROUNDOFF * max(1.0, np.max(np.abs(symbolic)))


def test_piece_systems_of_a_linear_model_are_linear():
    """The piece systems' Jacobians depend on the pieces only (one factorisation per active set),
    the FB system's on the unknowns."""
    problems = build_problems(_truss())
    for problem in (problems.classical, problems.projection):
        system = formulations.get("fischer_burmeister").build(problem).system
        assert system.branch_system()[3]
        f = system.rj.function
        z, P = ca.MX.sym("z", f.nnz_in(0)), ca.MX.sym("P", f.nnz_in(1))
        assert ca.depends_on(f(z, P)[1], z)


def test_problems_are_built_on_first_use_and_once():
    """A DDCM run builds the projection only, once; the classical problem is built when asked for,
    once (``ProblemPair`` builds lazily; ``has`` answers without building)."""
    from ddcm_casadi.drivers.ddcm_reduced import build_projection
    from ddcm_casadi.drivers.path import DDCMSolver

    pair = build_problems(_truss())
    assert pair.has("classical") and pair.has("projection")
    assert "classical" not in vars(pair) and "projection" not in vars(pair)
    result = DDCMSolver(pair, build_projection(formulations.get("fischer_burmeister"), pair)).solve()
    assert result.converged
    assert "classical" not in vars(pair)
    projection = pair.projection
    assert pair.projection is projection and pair.classical is pair.classical
    assert pair.classical.kind == "mcp" and projection.kind == "mpcc"


def test_a_problem_the_model_has_not_is_none():
    """A problem without a builder (no Young's modulus, no data set) is ``None``, as before the
    problems were lazy."""
    from ddcm_casadi.problems.build import ProblemPair

    pair = ProblemPair(model=_truss(), builders={})
    assert not pair.has("classical") and pair.classical is None and pair.projection is None


def test_a_ddcm_run_records_its_options_without_the_classical_problem():
    """``results.json``'s resolved options (the penalty's ``gamma_used``, from the contact stiffness
    both problems share) come from a problem the runs built: a DDCM-only run's record builds no
    classical problem, and gives the same ``gamma_used`` as a run of both variants."""
    from ddcm_casadi import compare, run
    from ddcm_casadi.casefiles.config import Case

    model = _truss()
    both = run.parameters(Case(model=model, source="t"), compare(model, ["penalty"]))
    ddcm = compare(_truss(), ["penalty"], variants=["ddcm"])
    params = run.parameters(Case(model=ddcm.model, source="t"), ddcm)
    assert "classical" not in vars(ddcm.problems)
    assert params["formulations"]["penalty"]["gamma_used"] == both["formulations"]["penalty"]["gamma_used"] > 0
