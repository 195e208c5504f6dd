"""The Kirchdoerfer-Ortiz reduction of the DDCM projection (docs/maths.md, section 17): the same
projections as the full saddle-point problem, hence the same DDCM fixed points, for every
formulation, with and without contact; selected by default where it applies, reported."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ddcm_casadi import MaterialDataset, compare, formulations, paper_bar
from ddcm_casadi.casefiles.base import read_document
from ddcm_casadi.casefiles.config import case_from_dict
from ddcm_casadi.drivers.ddcm_options import DDCMOptions
from ddcm_casadi.drivers.path import DDCMSolver
from ddcm_casadi.drivers.ddcm_reduced import ReducedProjection, build_projection, path_description
from ddcm_casadi.models.truss import bar_chain, warren_truss
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.problems.exact import ExactEnumerator
from ddcm_casadi.problems.reduction import (
    MAX_CONDITION, NEWTON_TOL, Reduction, block_inverse, condition_limit, refusal,
)
from ddcm_casadi.validation.continuum import EXAMPLE
from ddcm_casadi.validation.hard_device_rungs import stretched_block

ALL = formulations.available()
#: Round-off of a projection: the scaled unknowns are O(1), the systems well conditioned
#: (K_C of a few hundred dofs); the brief's 1e-10.
PROJECTION_TOL = 1e-10


def stopped_bar():
    data = MaterialDataset.hookean(200e9, -0.05, 0.01, 60, c=300e9)
    return bar_chain(length=1.0, elements=6, youngs_modulus=200e9, tip_positions=[0.999, 0.997, 0.995],
                     stops={2: 0.0006, 4: 0.0012}, dataset=data, name="stopped bar")


def truss():
    data = MaterialDataset.hookean(200e9, -0.01, 0.01, 60, c=200e9)
    return warren_truss(panels=16, gap=1e-4 * (np.arange(4) % 3), contact_nodes=[2, 6, 10, 14],
                        load_factors=[0.6, 0.8, 1.0], dataset=data, name="truss on a stepped ground")


def hertz_block(divisions: int = 3):
    doc = read_document(EXAMPLE)
    doc["mesh"]["divisions"] = [divisions, divisions]
    doc["mesh"].pop("refine_near", None)
    doc["data"]["hookean"]["points"] = 11
    return case_from_dict(doc, base_dir=EXAMPLE.parent, source="hertz block").model


MODELS = {"bar": lambda: paper_bar(n_data=100), "stopped bar": stopped_bar, "truss": truss,
          "continuum": hertz_block, "continuum without contact": lambda: stretched_block(points=11)}


@pytest.fixture(scope="module", params=list(MODELS))
def problems(request):
    return build_problems(MODELS[request.param]())


def _assigned(problems, seed: int = 0):
    """Parameters of the last step's projection for a random data assignment."""
    model = problems.model
    index = np.random.default_rng(seed).integers(0, len(model.dataset), model.n_points)
    data = model.dataset
    strain, stress = data.strain[index], data.stress[index]
    return problems.projection_params(model.n_steps - 1, strain, stress)


def test_block_inverse_is_the_inverse():
    rng = np.random.default_rng(1)
    blocks = [rng.standard_normal((k, k)) + 4 * np.eye(k) for k in (1, 3, 2, 3)]
    M = sp.block_diag(blocks).tocsr()
    perm = rng.permutation(M.shape[0])
    M = M[perm][:, perm]
    np.testing.assert_allclose((block_inverse(M) @ M).toarray(), np.eye(M.shape[0]), atol=1e-13)


def test_reduction_applies_to_every_small_strain_projection(problems):
    assert refusal(problems.projection) == ""
    reduction = Reduction(problems.projection)
    assert reduction.factorizations == 1  # Hookean metric: K_s = alpha K_u, one factor
    assert reduction.condensed.n_pairs == problems.projection.n_pairs


def test_without_contact_the_projection_is_the_kkt_solution():
    """No pairs: the reduced projection (two solves) is the equality-constrained QP's solution,
    here from the full KKT matrix ``[H J^T; J 0]`` by a sparse direct solve."""
    problems = build_problems(stretched_block(points=11))
    problem = problems.projection
    P = _assigned(problems)
    H, H_P = problem.distance.hessian
    nx = problem.n_x
    J, J_P = problem.residual_map.z[:, :nx], problem.residual_map.params
    K = sp.bmat([[H[:nx, :nx], J.T], [J, None]], format="csc")
    x = spla.spsolve(K, -np.concatenate([H_P[:nx] @ P, J_P @ P]))[:nx]
    sol = build_projection(formulations.get("fischer_burmeister"), problems).solve(P, np.zeros(nx), np.zeros(0))
    assert sol.converged
    assert np.max(np.abs(sol.x - x)) <= PROJECTION_TOL * max(1.0, np.max(np.abs(x)))


@pytest.mark.parametrize("name", ALL)
def test_condensed_projection_is_the_full_one(problems, name):
    """From the exact projection (branch enumeration), every formulation on the condensed
    problem and on the full one return the same projection (an inexact formulation its own)."""
    problem = problems.projection
    if not problem.n_pairs:
        pytest.skip("no contact pairs: nothing condensed")
    P = _assigned(problems, seed=2)
    ex = ExactEnumerator(problem, max_pairs=problem.n_pairs).solve(P)
    xe, pe = ex.x[:, 0], ex.p[:, 0]
    full = formulations.get(name).build(problem).solve(P, xe, pe, {"on_branch": True})
    reduced = build_projection(formulations.get(name), problems)
    assert isinstance(reduced, ReducedProjection)
    sol = reduced.solve(P, xe, pe, {"on_branch": True})
    assert full.converged and sol.converged
    scale = max(1.0, float(np.max(np.abs(np.concatenate([full.x, full.p])))))
    assert np.max(np.abs(sol.x - full.x)) <= PROJECTION_TOL * scale
    assert np.max(np.abs(sol.p - full.p)) <= PROJECTION_TOL * scale
    if formulations.get(name).exact:
        assert np.max(np.abs(sol.x - xe)) <= PROJECTION_TOL * scale
        assert sol.objective == pytest.approx(float(ex.objective[0]), rel=PROJECTION_TOL, abs=PROJECTION_TOL)


@pytest.mark.parametrize("model", list(MODELS))
def test_ddcm_fixed_points_equal_the_full_path(model):
    """Every formulation: the same data assignment at every step, and the same fields to the
    formulations' own tolerance (Newton and IPOPT stop at 1e-9 relative increments)."""
    m = MODELS[model]()
    full = compare(m, variants=["ddcm"], ddcm=DDCMOptions(reduce=False))
    reduced = compare(m, variants=["ddcm"], ddcm=DDCMOptions())
    for key, a in full.results.items():
        b = reduced.results[key]
        assert a.projection_path.startswith("full") and b.projection_path.startswith("reduced")
        assert a.converged and b.converged
        for s, t in zip(a.steps, b.steps, strict=True):
            np.testing.assert_array_equal(s.data_index, t.data_index)
        for field in ("u", "stress", "p"):
            x, y = a.array(field), b.array(field)
            assert np.max(np.abs(x - y), initial=0.0) <= 1e-9 * max(np.max(np.abs(x), initial=0.0), 1e-300)


def test_reduction_is_reported_and_can_be_switched_off():
    m = stopped_bar()
    on = compare(m, ["fischer_burmeister"], variants=["ddcm"])
    row = on.summary()[0]
    assert row["projection_path"].startswith("reduced (Kirchdoerfer-Ortiz: 1 factorisation(s) of K_C, 3 condensed")
    problems = build_problems(m)
    off = build_projection(formulations.get("fischer_burmeister"), problems, reduce=False)
    assert path_description(off) == "full saddle point (reduction off)"
    assert refusal(problems.projection, max_pairs=1) == "3 contact pairs (the condensed problem is assembled up to 1)"
    assert refusal(problems.classical) == "not a DDCM projection"


def test_finite_kinematics_keep_the_full_path():
    from ddcm_casadi.models.von_mises import von_mises_truss

    data = MaterialDataset.hookean(200e9, -0.05, 0.05, 41, c=200e9)
    problems = build_problems(von_mises_truss(steps=4, dataset=data))
    assert refusal(problems.projection) == "the projection is not affine with a quadratic distance"
    built = build_projection(formulations.get("fischer_burmeister"), problems)
    assert not isinstance(built, ReducedProjection)
    assert path_description(built).startswith("full saddle point (the projection is not affine")


def test_a_body_held_only_by_its_contacts_keeps_the_full_path():
    """The 2-D patch test's punch floats on its contacts: ``K_C`` is singular, the Delassus
    matrix's condition number near ``1 / eps``; the full path is kept, and says why."""
    from ddcm_casadi.validation.two_body_rungs import patch_model

    problems = build_problems(patch_model(2, data=True))
    built = build_projection(formulations.get("fischer_burmeister"), problems)
    assert not isinstance(built, ReducedProjection)
    assert "a Delassus matrix's condition" in path_description(built)


@pytest.mark.parametrize("panels, reduced", [(100, True), (300, False)])
def test_a_slender_truss_whose_delassus_condition_exceeds_the_roundoff_limit_keeps_the_full_path(panels, reduced):
    """The condensed solve's roundoff floor is about ``cond(D_u) eps``: the limit keeps it a decade
    below Newton's tolerance. A Warren truss's Delassus condition grows like its length to the
    fourth (1.2e5 at 100 panels, 1.2e9 at 1000, where the piece solves stalled at 2.5e-7): the
    300-panel one is past the limit and keeps the full path, saying why; both converge."""
    assert MAX_CONDITION * np.finfo(float).eps == pytest.approx(0.1 * NEWTON_TOL)
    nodes = np.arange(2, panels - 1, 4)
    model = warren_truss(panels=panels, gap=1e-4 * (np.arange(nodes.size) % 3), contact_nodes=nodes,
                         load_factors=(0.5, 1.0), dataset=MaterialDataset.hookean(200e9, -0.01, 0.01, 2001, c=200e9))
    problems = build_problems(model)
    built = build_projection(formulations.get("fischer_burmeister"), problems)
    assert isinstance(built, ReducedProjection) == reduced
    if not reduced:
        assert "a Delassus matrix's condition" in path_description(built)
    path = DDCMSolver(problems, built).solve()
    assert path.converged


@pytest.mark.parametrize("name", ["penalty", "augmented_lagrangian", "fischer_burmeister", "mpcc"])
def test_a_formulation_with_a_tighter_residual_tolerance_gets_a_tighter_condition_limit(name):
    """The limit is ``0.1 residual_tol / eps``, each formulation's own: the 100-panel truss
    (condition 1.2e5) is reduced for the penalty and FB (1e-9: 4.5e5), not for the augmented
    Lagrangian and the MPCC (1e-10: 4.5e4), which keep the full path and say why."""
    nodes = np.arange(2, 99, 4)
    model = warren_truss(panels=100, gap=1e-4 * (np.arange(nodes.size) % 3), contact_nodes=nodes,
                         load_factors=(0.5, 1.0), dataset=MaterialDataset.hookean(200e9, -0.01, 0.01, 2001, c=200e9))
    problems = build_problems(model)
    formulation = formulations.get(name)
    tol = formulation.resolved_options(problems.projection)["residual_tol"]
    built = build_projection(formulation, problems)
    condition = Reduction(problems.projection).condition
    assert condition == pytest.approx(1.2e5, rel=0.1)
    assert isinstance(built, ReducedProjection) == (condition <= condition_limit(tol))
    assert isinstance(built, ReducedProjection) == (name in ("penalty", "fischer_burmeister"))
    if not isinstance(built, ReducedProjection):
        assert f"for the residual tolerance {tol:g}" in path_description(built)


def block_3d(divisions: int, contact: bool):
    """The 3-D Hertz example's block (P1 tetrahedra) on a uniform mesh, pressed by its sphere
    (pairs on the top face within 5 mm of the axis) or, without contact, by a hard device on its top."""
    from ddcm_casadi.validation.continuum import EXAMPLE_3D

    doc = read_document(EXAMPLE_3D)
    doc["mesh"]["divisions"] = [divisions] * 3
    doc["mesh"].pop("refine_near", None)
    if contact:
        doc["contact"][0]["boundary"] = {"min": [0.0, 0.0, 0.0], "max": [5e-3, 5e-3, 0.0]}
    else:
        doc.pop("contact")
        doc.pop("hertz", None)
        doc["supports"].append({"boundary": "zmax", "fix": "z", "displacement": [0.0, 0.0, -4e-5]})
        doc["loading"] = {"load_factors": [0.5, 1.0]}
    return case_from_dict(doc, base_dir=EXAMPLE_3D.parent, source="3-D block").model


@pytest.mark.parametrize("contact", [False, True])
def test_amg_solves_of_k_c_give_the_direct_fixed_points(contact):
    """K_C by AMG-preconditioned CG (``use_definite_solver("amg")``) against its direct factor,
    on a 3-D block: the same data assignment at every step, and fields within the forward error
    of a solve to relative residual ``tol`` (twice DEFINITE_TOL, as accepted):
    ``|e| / |x| <= cond(K_C) tol`` in the 2-norm, ``sqrt(n)`` more in the max-norm; with contact
    the condensed solve amplifies a Delassus error by ``cond(D_u)`` more."""
    pytest.importorskip("pyamg")
    from ddcm_casadi import linalg

    runs = {}
    try:
        for solver in ("direct", "amg"):
            linalg.use_definite_solver(solver)
            problems = build_problems(block_3d(4, contact))
            built = build_projection(formulations.get("fischer_burmeister"), problems)
            assert isinstance(built, ReducedProjection) and built.reduction.solver == solver
            runs[solver] = (DDCMSolver(problems, built).solve(), built.reduction)
    finally:
        linalg.use_definite_solver("direct")
    (direct, red), (amg, red_amg) = runs["direct"], runs["amg"]
    factor = red_amg.factor.lu if red_amg.shared else red_amg.factor  # the scales' factor, over a number
    assert isinstance(factor, linalg.AMGFactor) and red.nc == red_amg.nc == (9 if contact else 0)
    assert direct.converged and amg.converged
    eig = np.linalg.eigvalsh(red.K_u.toarray())
    bound = eig[-1] / eig[0] * 2 * linalg.DEFINITE_TOL * np.sqrt(red.n)
    if contact:
        eig_d = np.linalg.eigvalsh(red.D_u)
        bound *= eig_d[-1] / eig_d[0]
    for s, t in zip(direct.steps, amg.steps, strict=True):
        np.testing.assert_array_equal(s.data_index, t.data_index)
    for field in ("u", "stress", "p"):
        x, y = direct.array(field), amg.array(field)
        assert np.max(np.abs(x - y), initial=0.0) <= bound * max(np.max(np.abs(x), initial=0.0), 1e-300)
