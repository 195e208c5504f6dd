"""The one-off build's shortcuts (issue 28, item 6) give what the long way gives: the reference
scales of two kinds whose point stiffnesses are proportional share one factorisation, and the
reduction's Delassus products from the rows of the kept columns the contact rows use are the
full products."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

import ddcm_casadi.models.scales as scales
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.problems.reduction import Reduction
from tests.test_reduction import MODELS, hertz_block


def _counting(monkeypatch) -> list:
    """The scales' factorisations: their own (direct, or AMG where selected), or the one shared
    with the classical condensation (:class:`~ddcm_casadi.models.stiffness.StiffnessFactor`)."""
    calls = []
    for name in ("factorize_definite", "StiffnessFactor"):
        original = getattr(scales, name)

        def counted(A, *args, original=original, **kw):
            calls.append(A.shape[0])
            return original(A, *args, **kw)

        monkeypatch.setattr(scales, name, counted)
    return calls


def test_proportional_kinds_share_one_factorisation(monkeypatch):
    """One-component points: the classical law ``E`` and the data's secant modulus on every
    component are proportional laws (a continuum's classical law ``C(E, nu)`` is not)."""
    model = MODELS["truss"]()
    D_c, D_d = (np.broadcast_to(model.point_stiffness(k), (model.n_points,)) for k in ("classical", "ddcm"))
    assert np.allclose(D_d, D_d[0] / D_c[0] * D_c, rtol=4 * np.finfo(float).eps, atol=0)  # the case under test
    calls = _counting(monkeypatch)
    shared = {k: model.scales_for(k) for k in ("classical", "ddcm")}
    assert len(calls) == 1
    # the long way: the data-driven kind alone, on a fresh model (its own factorisation)
    alone = MODELS["truss"]().scales_for("ddcm")
    assert len(calls) == 2
    # Both are backward-stable solves of one system (up to the factor beta), so the solutions,
    # and the maxima the scales are, agree to cond(A) eps, A the stiffness with the pair springs.
    B, G, a, w = model.strain_operator, model.gap_operator, model.contact_area, model.volumes
    K = (B.T @ model.representative_law("classical") @ B).toarray()
    A = K + 1e3 * np.max(np.diag(K)) / np.max(a) * (G.T @ sp.diags(a) @ G).toarray()
    tol = 4 * np.linalg.cond(A) * np.finfo(float).eps
    for name, value in alone.items():
        assert abs(shared["ddcm"][name] - value) <= tol * abs(value), name


def test_model_with_one_kind_factorises_once(monkeypatch):
    model = hertz_block(4)
    calls = _counting(monkeypatch)
    model.scales_for("classical")
    model.scales_for("classical")  # cached
    assert len(calls) == 1


def test_delassus_products_are_the_full_products():
    problem = build_problems(hertz_block(6)).projection
    red = Reduction(problem)
    assert red.nc > 0
    full = red.G @ red.Z_u
    assert np.array_equal(red.D_u, 0.5 * (full + full.T))  # the same sums, not just close
