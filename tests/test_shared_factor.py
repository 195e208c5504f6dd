"""One factorisation of the stiffness for the reference scales and the classical condensation
(docs/maths.md, section 17, "One factorisation for the scales and the condensation"): the scales
from the condensation's factor (Woodbury for the springs) are the scales from factorisations of
their own, to round-off; the condensation takes that factor, and the model lets it go once taken."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from ddcm_casadi import formulations
from ddcm_casadi.drivers.ddcm_reduced import build_classical, build_projection
from ddcm_casadi.models.base import ContactModel
from ddcm_casadi.models.scales import STIFFNESS_FACTOR
from ddcm_casadi.models.stiffness import StiffnessFactor
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.problems.reduction import ClassicalReduction

from tests.test_reduction import MODELS

EPS = np.finfo(float).eps
CLASSICAL = ["bar", "stopped bar", "truss", "continuum"]


def _roundoff(model) -> float:
    """The relative round-off of the scales' solves either way: ``cond(A) eps`` of a solve with
    ``A = K + kappa G^T A G`` (the pair springs), and ``cond(K) eps`` amplified by Woodbury's
    cancellation, ``|K^-1 r| / |A^-1 r|`` for the deepest penetration's right-hand side ``r``
    (the spring's ``kappa`` cancels between ``K^-1 r`` and its correction)."""
    B, G, a = model.strain_operator, model.gap_operator, model.contact_area
    K = (B.T @ model.representative_law("classical") @ B).toarray()
    kappa = 1e3 * np.max(np.diag(K)) / np.max(a)
    A = K + kappa * (G.T @ sp.diags(a) @ G).toarray()
    r = kappa * (G.T @ (a * np.max(np.maximum(-model.gap_offsets, 0.0), axis=0)))
    x = np.linalg.solve(A, r)
    amplification = np.max(np.abs(np.linalg.solve(K, r))) / np.max(np.abs(x)) if np.any(x) else 1.0
    return (np.linalg.cond(A) + np.linalg.cond(K) * amplification) * EPS


def _own_factors(monkeypatch) -> None:
    """The scales factorise their own (the same stiffness): as if the model kept a factor already
    (a stand-in), which the scales then neither make nor use."""
    monkeypatch.setattr(ContactModel, "stiffness_factor", lambda self: object())


@pytest.mark.parametrize("name", CLASSICAL)
def test_classical_scales_stiffness_is_the_stiffness(name):
    """The classical kind's representative stiffness is the classical problem's (same arithmetic):
    its factor can serve the condensation."""
    model = MODELS[name]()
    B = model.strain_operator
    K = B.T @ model.representative_law("classical") @ B
    assert (K != model.stiffness()).nnz == 0


@pytest.mark.parametrize("name", CLASSICAL)
def test_scales_from_the_shared_factor_are_the_scales_of_their_own(name, monkeypatch):
    """Both ways solve the same systems (``K``, and ``K + G^T S G`` directly or by Woodbury from
    ``K``'s factor and ``D``), so the solutions, and the maxima the scales are, agree to their
    round-off (:func:`_roundoff`); a factor 8 for the few operations between."""
    shared = MODELS[name]()
    new = {k: shared.scales_for(k) for k in ("classical", "ddcm")}
    assert isinstance(shared._cache.get(STIFFNESS_FACTOR), StiffnessFactor)
    _own_factors(monkeypatch)
    alone = MODELS[name]()
    old = {k: alone.scales_for(k) for k in ("classical", "ddcm")}
    assert STIFFNESS_FACTOR not in alone._cache
    tol = 8 * _roundoff(shared)
    for kind in old:
        for key, value in old[kind].items():
            assert abs(new[kind][key] - value) <= tol * abs(value), (kind, key)


def test_woodbury_solves_the_stiffness_with_springs():
    model = MODELS["continuum"]()
    B, G = model.strain_operator, model.gap_operator
    K = (B.T @ model.representative_law("classical") @ B).tocsc()
    S = 1e3 * np.max(K.diagonal()) * np.linspace(1.0, 2.0, G.shape[0])
    A = (K + G.T @ sp.diags(S) @ G).toarray()
    r = np.cos(np.arange(K.shape[0]))
    x = StiffnessFactor(K, G).with_springs(S).solve(r)
    exact = np.linalg.solve(A, r)
    assert np.max(np.abs(x - exact)) <= 8 * np.linalg.cond(A) * EPS * np.max(np.abs(exact))


@pytest.mark.parametrize("name", CLASSICAL)
def test_condensation_takes_the_scales_factor(name):
    """The condensation's factor and ``D_u`` from the scales' factor (over ``c``) equal its own:
    ``D_u`` to ``cond(D_u)``-free round-off of a backward-stable solve, ``cond(K) eps``."""
    model = MODELS[name]()
    problems = build_problems(model)
    known = model._cache[STIFFNESS_FACTOR]
    built = build_classical(formulations.get("fischer_burmeister"), problems)
    assert built.reduction.shared and built.path.endswith("K's factor the reference scales')")
    assert model.stiffness_factor() is known  # kept for the model's next condensation (the same factor)
    own = ClassicalReduction(problems.classical)
    assert not own.shared
    n = problems.classical.n_x
    K = problems.classical.residual_map.z[:, :n].toarray()
    tol = 8 * np.linalg.cond(K) * EPS
    D, D_own = built.reduction.D_u, own.D_u
    assert np.max(np.abs(D - D_own)) <= tol * np.max(np.abs(D_own))
    b = np.cos(np.arange(n))
    x, x_own = built.reduction.factor.solve(b), own.factor.solve(b)
    assert np.max(np.abs(x - x_own)) <= tol * np.max(np.abs(x_own))
    del known


def test_a_stiffness_not_a_multiple_is_refused():
    model = MODELS["truss"]()
    B, G = model.strain_operator, model.gap_operator
    K = (B.T @ model.representative_law("classical") @ B).tocsc()
    factor = StiffnessFactor(K, G)
    assert factor.scaled(3.0 * K, G) is not None
    other = K + sp.csc_matrix(([1.0, 1.0], ([0, 1], [1, 0])), shape=K.shape)  # the same diagonal, another matrix
    assert factor.scaled(other, G) is None
    assert factor.scaled(K + sp.identity(K.shape[0]), G) is None  # another diagonal
    assert factor.scaled(K, 2.0 * G) is None
    # a reduction adopts it where it serves, else lets it go before factorising its own
    assert factor.adopted(2.0 * K, G) is not None and not factor.released
    assert factor.adopted(other, G) is None and factor.released


@pytest.mark.parametrize("name", CLASSICAL)
def test_a_ddcm_run_shares_the_factor_or_lets_it_go(name):
    """The projection's reduction solves with the scales' factor where ``K_C`` is a multiple of
    their stiffness (a metric proportional to the law); otherwise it lets it go before its own
    factorisation, and the model keeps it no longer."""
    model = MODELS[name]()
    problems = build_problems(model)
    known = model.stiffness_factor()
    assert known is not None
    built = build_projection(formulations.get("fischer_burmeister"), problems)
    if built.reduction.shared:
        assert model.stiffness_factor() is known
    else:
        assert known.released and model.stiffness_factor() is None and STIFFNESS_FACTOR not in model._cache


def test_the_full_path_lets_the_factor_go():
    model = MODELS["truss"]()
    problems = build_problems(model)
    known = model.stiffness_factor()
    build_classical(formulations.get("fischer_burmeister"), problems, reduce=False)
    assert known.released and model.stiffness_factor() is None


def _floating_bar():
    """A bar of two nodes and no support, pressed between two stops (node 0 pushed 1 mm in from
    the left, node 1 against a stop on the right): ``K`` is singular (a rigid translation), the
    stops alone hold it."""
    return ContactModel(strain_operator=sp.csr_matrix([[-1.0, 1.0]]), volumes=np.ones(1),
                        gap_operator=sp.csr_matrix([[1.0, 0.0], [0.0, -1.0]]), contact_area=np.ones(2),
                        gap_offsets=np.array([[-1e-3, 0.0]]), loads=np.zeros((1, 2)), load_parameter=np.ones(1),
                        youngs_modulus=np.full(1, 200e9), name="floating bar")


def test_a_body_held_only_by_its_contacts_keeps_the_springs_own_factor(monkeypatch):
    """``K`` singular: the springs' system is factorised itself (no Woodbury from a singular
    factor), so the scales are those of the path without the shared factor, to round-off of a
    well-conditioned 2 x 2 system."""
    new = _floating_bar().scales_for("classical")
    _own_factors(monkeypatch)
    old = _floating_bar().scales_for("classical")
    for key, value in old.items():
        assert abs(new[key] - value) <= 1e-12 * abs(value), key


def test_the_classical_stiffness_is_handed_over_once_and_only_the_classical_one():
    model = MODELS["truss"]()
    model.scales_for("classical")
    K = model.stiffness_factor()._K
    assert K is not None and (model.stiffness() != K).nnz == 0
    assert model.stiffness_factor()._K is None  # handed over: the next one is assembled
    other = MODELS["continuum"]()
    assert not np.array_equal(other.point_stiffness("ddcm"), other.youngs_modulus)
    other.scales_for("ddcm")  # first: the factor's K is the data's secant stiffness, not the classical one
    assert other.stiffness_factor() is not None and other.stiffness_factor().hand_over() is None


def test_without_the_condensation_the_scales_law_is_the_modulus_on_every_component():
    """No contact pair (nothing to condense): the classical scales keep ``E`` on every strain
    component (the continuum's classical law is not factorised for them)."""
    from ddcm_casadi.validation.hard_device_rungs import stretched_block

    model = stretched_block(points=11)
    assert model.delassus_rows() is None
    w, k = model.volumes, model.strain_components
    expected = sp.diags(np.repeat(w * model.point_stiffness("classical"), k))
    assert (model.representative_law("classical") != expected).nnz == 0
