"""The Delassus condensation of the classical problem (docs/maths.md, section 17): every
formulation on the contact pairs' linear complementarity problem, ``u`` by one solve with the kept
factor of ``K``, gives the full problem's path; selected automatically where it applies, the
full path kept (and the reason reported) where not."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ddcm_casadi import compare, formulations, linalg
from ddcm_casadi.drivers.ddcm_reduced import ReducedProjection, build_classical, path_description
from ddcm_casadi.drivers.path import solve_classical
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.problems.reduction import NEWTON_TOL, ClassicalReduction, classical_refusal

from tests.test_reduction import MODELS

ALL = formulations.available()
EPS = np.finfo(float).eps
#: The classical models with contact pairs (the projection-only ones and the one without pairs
#: are the DDCM reduction's).
CLASSICAL = ["bar", "stopped bar", "truss", "continuum"]


@pytest.fixture(scope="module", params=CLASSICAL)
def problems(request):
    return build_problems(MODELS[request.param]())


def test_condensation_applies_to_every_small_strain_classical_problem(problems):
    assert classical_refusal(problems.classical) == ""
    reduction = ClassicalReduction(problems.classical)
    D = reduction.D_u
    assert D.shape == (problems.classical.n_pairs,) * 2
    # D_u = G K^-1 G^T, by a sparse solve of its own
    n = problems.classical.n_x
    G, K = reduction.G, problems.classical.residual_map.z[:, :n]
    direct = G @ spla.spsolve(K.tocsc(), G.T.toarray()).reshape(K.shape[0], -1)
    assert np.max(np.abs(D - direct)) <= 1e3 * EPS * reduction.condition * np.max(np.abs(D))


@pytest.mark.parametrize("name", ALL)
def test_condensed_path_is_the_full_one(problems, name):
    """Both paths converge to Newton's tolerance (:data:`NEWTON_TOL`, relative increments of the
    scaled unknowns; IPOPT's own 1e-9 for ``mpcc``), on the same complementarity problem: they
    differ by at most that, amplified by the condensed system's condition (its round-off floor
    ``cond(D_u) eps``) and the scales between scaled and physical fields (O(1) by construction:
    a factor 10 margin)."""
    form = formulations.get(name)
    full = solve_classical(problems, form.build(problems.classical), name)
    built = build_classical(form, problems)
    assert isinstance(built, ReducedProjection)
    condensed = solve_classical(problems, built, name)
    assert condensed.projection_path.startswith("condensed (Delassus: 1 factorisation of K")
    assert full.converged and condensed.converged
    tol = 10 * (NEWTON_TOL + built.reduction.condition * EPS)
    for field in ("u", "p", "stress"):
        a, b = full.array(field), condensed.array(field)
        assert np.max(np.abs(a - b), initial=0.0) <= tol * max(np.max(np.abs(a), initial=0.0), 1e-300), field
    for step in condensed.steps:  # the full problem's residual and complementarity, not the condensed ones
        assert step.residual <= tol and step.complementarity <= max(tol, full.steps[step.step].complementarity * 10)


def test_the_path_is_reported_and_can_be_switched_off():
    from tests.test_reduction import stopped_bar

    on = compare(stopped_bar(), ["fischer_burmeister"], variants=["classical"])
    assert on.summary()[0]["projection_path"].startswith("condensed (Delassus: 1 factorisation of K, 3 contact")
    problems = build_problems(stopped_bar())
    off = build_classical(formulations.get("fischer_burmeister"), problems, reduce=False)
    assert path_description(off) == "full (condensation off)"
    assert classical_refusal(problems.classical, max_pairs=1) == (
        "3 contact pairs (the condensed problem is assembled up to 1)")
    assert classical_refusal(problems.projection) == "not a classical problem"


def test_large_problems_need_the_schur_complement(monkeypatch):
    """Above ``SCHUR_MIN_SIZE`` unknowns, ``nc`` back-solves with SuperLU cost more than the full
    path: without a Schur complement (MUMPS's or PARDISO's) the full path is kept, and says why."""
    import ddcm_casadi.models.stiffness as stiffness

    problems = build_problems(MODELS["continuum"]())
    monkeypatch.setattr(stiffness, "SCHUR_MIN_SIZE", 10)
    previous = linalg.solver_name()
    try:
        linalg.use_solver("superlu")
        why = classical_refusal(problems.classical)
    finally:
        linalg.use_solver(previous)
    assert why.startswith(f"{problems.classical.n_x} unknowns without a Schur complement")


def test_finite_kinematics_keep_the_full_path():
    from ddcm_casadi.models.von_mises import von_mises_truss

    problems = build_problems(von_mises_truss(steps=4))
    built = build_classical(formulations.get("fischer_burmeister"), problems)
    assert not isinstance(built, ReducedProjection)
    assert path_description(built) == "full (the classical problem is not affine (finite kinematics))"
    assert solve_classical(problems, built, "fischer_burmeister").projection_path == path_description(built)


def test_a_body_held_only_by_its_contacts_keeps_the_full_path():
    """The 2-D patch test's punch floats on its contacts: ``K`` is singular; the full path is
    kept and says why."""
    from ddcm_casadi.validation.two_body_rungs import patch_model

    problems = build_problems(patch_model(2, data=True))
    built = build_classical(formulations.get("fischer_burmeister"), problems)
    assert not isinstance(built, ReducedProjection)
    why = path_description(built)
    assert "the stiffness is singular" in why or "a Delassus matrix's condition" in why


@pytest.mark.parametrize("storage", ["csc", "csr"])
@pytest.mark.parametrize("solver", linalg.SCHUR_SOLVERS)
def test_schur_complement_is_the_back_solved_delassus_matrix(solver, storage):
    """MUMPS's and PARDISO's Schur complement of ``[[K, G^T], [G, 0]]`` and their solves with
    ``K`` alone (the Schur part zeroed) against SuperLU's factor and back-solves: equal to
    round-off, ``cond(K) eps`` relative at most (``cond(K)`` of a few-hundred-dof continuum:
    below 1e6), with ``K`` stored either way; each solve's backward error at most
    ``linalg.BACKWARD_ERROR``, the bound the factor is checked to."""
    if solver not in linalg.available_solvers():
        pytest.skip(f"{solver} does not load here: {linalg.unavailable_solvers().get(solver, 'not installed')}")
    model = MODELS["continuum"]()
    K, G = sp.csc_matrix(model.stiffness()), sp.csr_matrix(model.gap_operator)
    previous = linalg.solver_name()
    try:
        linalg.use_solver("superlu")
        lu, D = linalg.factorize_with_delassus(K, G)
        linalg.use_solver(solver)
        assert linalg.delassus_solver(K.shape[0]) == solver
        schur, S = linalg.factorize_with_delassus(K.asformat(storage), G)
    finally:
        linalg.use_solver(previous)
    assert np.max(np.abs(S - D)) <= 1e6 * EPS * np.max(np.abs(D))
    b = np.cos(np.arange(K.shape[0]))
    B = np.column_stack([b, np.sin(np.arange(K.shape[0]))])
    for rhs in (b, B):
        x, y = schur.solve(rhs), lu.solve(rhs)
        assert x.shape == rhs.shape
        assert np.max(np.abs(x - y)) <= 1e6 * EPS * np.max(np.abs(y))
        assert linalg.backward_error(K, x, rhs) <= linalg.BACKWARD_ERROR


def test_the_case_file_key_condense():
    """The top-level ``condense`` of a case file reaches every classical run (``false``: the full
    problem, which says so), is recorded in ``results.json``'s parameters, and a value that is not
    a boolean is refused in one line."""
    from ddcm_casadi.casefiles.config import case_from_dict
    from ddcm_casadi.errors import InputError
    from ddcm_casadi.run import compare_case, parameters

    doc = {"bar": {"length": 1.0, "area": 1e-4, "youngs_modulus": 200e9}, "obstacle": {"positions": [1.01, 0.99]}}
    for condense, path in ((True, "condensed (Delassus"), (False, "full (condensation off)")):
        case = case_from_dict({**doc, "condense": condense})
        assert case.condense is condense
        cmp = compare_case(case, ["fischer_burmeister", "mpcc"], ["classical"])
        assert all(row["projection_path"].startswith(path) for row in cmp.summary())
        assert parameters(case, cmp)["condense"] is condense
    assert case_from_dict(dict(doc)).condense is True
    with pytest.raises(InputError, match=r"^condense must be true or false, not 'no'$"):
        case_from_dict({**doc, "condense": "no"})
