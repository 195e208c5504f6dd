"""Finite-strain continua against closed forms and limits (:mod:`ddcm_casadi.validation.finite_strain_rungs`):
homogeneous compression of blocks (both laws, 2-D P1/P2, 3-D P1 by a rigid plane, 3-D P2 by a dead
load), the small-load limit of Hertz, the Richardson order, and DDCM's data-spacing rate.

Tolerances come from the rungs: exact formulations to the bound their stopping tests allow
(``||J^-1|| |r|``), the penalty to its own (penalised) closed form with the same bound and to the
exact one within ``O(1/gamma)``.
"""

from __future__ import annotations

import numpy as np
import pytest

from ddcm_casadi.data.hyperelastic import neo_hookean_stress, second_piola
from ddcm_casadi.errors import InputError
from ddcm_casadi.validation import finite_strain_rungs as fs

FORMULATIONS = list(fs.FORMULATIONS)


def _failed(checks):
    return [f"{c.name} | {c.quantity}: {c.value:.3e} vs {c.reference:g} +- {c.tolerance:.1e} ({c.note})"
            for c in checks if not c.passed]


# ------------------------------------------------------------------------ closed forms
@pytest.mark.parametrize("law, dimension, force", [("neo_hookean", 2, 0.45842392321403),
                                                    ("saint_venant_kirchhoff", 2, 0.19615384615384),
                                                    ("saint_venant_kirchhoff", 3, 0.1785)])
def test_closed_form_values(law, dimension, force):
    """The independent closed form at 30 % compression: the nominal forces measured before the
    rung existed (2-D), and for 3-D Saint Venant-Kirchhoff the hand value ``Y a (a^2 - 1) / 2``
    (uniaxial stress: ``S = Y E``, Young's modulus ``Y = 1``)."""
    state = fs.uniaxial(law, 0.7, dimension)
    assert abs(state.nominal) == pytest.approx(force, rel=1e-12)
    if law == "saint_venant_kirchhoff" and dimension == 3:
        assert state.nominal == pytest.approx(0.7 * (0.49 - 1) / 2, rel=1e-14)


@pytest.mark.parametrize("dimension", [2, 3])
def test_closed_form_is_the_packages_law(dimension):
    """The principal-stretch formulas against the package's textbook Neo-Hookean stress and its
    stress by automatic differentiation: lateral stress zero, axial stress the closed form's."""
    state = fs.uniaxial("neo_hookean", 0.75, dimension)
    l, a = state.lateral, state.axial
    if dimension == 2:
        E = np.array([[(l**2 - 1) / 2, (a**2 - 1) / 2, 0.0]])
        lateral, axial = [0], 1
    else:
        E = np.array([[(l**2 - 1) / 2, (l**2 - 1) / 2, (a**2 - 1) / 2, 0.0, 0.0, 0.0]])
        lateral, axial = [0, 1], 2
    for S in (neo_hookean_stress(E, fs.YOUNG, fs.POISSON, dimension),
              second_piola("neo_hookean", E, fs.YOUNG, fs.POISSON, dimension)):
        assert np.max(np.abs(S[0, lateral])) < 1e-14
        assert S[0, axial] == pytest.approx(state.second_piola, rel=1e-13)


def test_dead_load_inverts_the_closed_form():
    for law in fs.LAWS:
        target = fs.uniaxial(law, 0.8, 3)
        assert fs.dead_load(law, target.nominal, 3).axial == pytest.approx(0.8, rel=1e-13)


# -------------------------------------------------------------- homogeneous compression
@pytest.fixture(scope="module")
def homogeneous_rows():
    """Every law x block x formulation of the rung, computed once (about 15 s)."""
    return fs.homogeneous_table()


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_homogeneous_compression(homogeneous_rows, formulation):
    rows = [r for r in homogeneous_rows if r["formulation"] == formulation]
    assert len(rows) == len(fs.LAWS) * len(fs.BLOCKS)
    checks = fs.rung_homogeneous_compression(rows)
    assert checks and not _failed(checks), _failed(checks)


def test_homogeneous_errors_are_round_off(homogeneous_rows):
    """The errors are round-off (measured <= 5e-12), far below the derived bounds (1e-9..1e-6)."""
    for r in homogeneous_rows:
        e = r.get("errors_own", r["errors"])
        assert e["stretch"] < 1e-10, r
        assert e["force"] < 1e-10, r


def test_penalty_error_is_order_one_over_gamma(homogeneous_rows):
    """Against the exact closed form the penalty is off by its penetration: within the
    first-order bound ``1.1 max|dF/dt| max p / gamma``, and not round-off (above a tenth of it; the
    slope at the last step is the largest for Neo-Hookean, a third of the largest for Saint
    Venant-Kirchhoff, which softens in compression)."""
    for r in homogeneous_rows:
        if "errors_own" in r:
            assert 0.1 * r["exact_bound"] < r["errors"]["force"] <= r["exact_bound"], r


def test_contact_on_quadratic_tetrahedra_is_refused():
    with pytest.raises(InputError, match="quadratic tetrahedra"):
        fs.compression_block(3, 2, "neo_hookean")


# ---------------------------------------------------------------------- small-load limit
def test_small_load_limit():
    """Hertz 2-D, P1: while the active set stays (two gradings), the relative force difference
    between finite and small kinematics is O(delta) (slope 1); with a contact zone of several
    elements (five gradings) it is O(a/R) (slope 1 against a/R, about 1/2 against delta)."""
    checks = fs.rung_small_load_limit(fs.SMALL_LOADS[:4], levels=2)
    assert not _failed(checks), _failed(checks)
    slope = next(c for c in checks if "fixed active set" in c.quantity)
    assert slope.value == pytest.approx(1.0, abs=1e-3)
    assert any("Hertz regime" in c.quantity for c in checks)


def test_hertz_regime_is_half_order_in_the_load():
    """In the Hertz regime the relative difference follows the strain a/R, so against the
    indentation (2-D: the load, up to a logarithm) its slope is near 1/2, not 1."""
    t = fs.small_load_table(fs.HERTZ_LOADS, levels=fs.HERTZ_LEVELS)
    rel = np.abs(t["relative"])
    assert np.all(np.sign(t["relative"]) == np.sign(t["relative"][0]))
    assert 0.4 < fs.fitted_rate(t["travel"], rel)[0] < 0.7
    assert 0.75 < fs.fitted_rate(t["a_over_R"], rel)[0] < 1.25


# -------------------------------------------------------------------------- Richardson
def test_richardson_recovers_order_and_limit():
    h = np.array([0.4, 0.25, 0.1])
    q, limit, err = fs.richardson(h, 2.0 + 0.3 * h**1.5)
    assert q == pytest.approx(1.5, rel=1e-9)
    assert limit == pytest.approx(2.0, rel=1e-12)
    assert err == pytest.approx(0.3 * 0.1**1.5, rel=1e-9)
    assert np.isnan(fs.richardson(h, [1.0, 2.0, 1.5])[0])  # oscillating: no order


# ------------------------------------------------------------------------------- DDCM
def test_ddcm_rate_and_fixed_points():
    checks = fs.rung_ddcm_rate(metrics=())
    assert not _failed(checks), _failed(checks)
