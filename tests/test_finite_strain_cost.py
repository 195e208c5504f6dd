"""The cost of a finite-strain DDCM iteration (issue 25, item 9; ``benchmarks/finite_strain.py``
measures it): Newton's chord steps reach the same fixed points with fewer factorisations, and the
factors made in the factorising thread do not pile up from projection to projection."""

from __future__ import annotations

import numpy as np
import pytest

import ddcm_casadi.drivers.ddcm_projection as ddcm_projection
import ddcm_casadi.loops.newton as newton
from ddcm_casadi import linalg
from ddcm_casadi.casefiles.config import case_from_dict
from ddcm_casadi.drivers.harness import compare

#: The benchmark's block, coarse: bonded at its base, pressed 1 % a step by a rigid plane, four steps.
BLOCK = {"kinematics": "finite",
         "mesh": {"shape": "rectangle", "size": [1.0, 1.0], "divisions": [6, 6]},
         "material": {"youngs_modulus": 1.0, "poisson_ratio": 0.3, "law": "neo_hookean"},
         "supports": [{"boundary": "ymin", "fix": "xy"}, {"boundary": "xmin", "fix": "x"}],
         "contact": [{"boundary": "ymax", "obstacle": "plane", "point": [0.0, 1.0], "normal": [0.0, -1.0],
                      "direction": [0.0, -1.0], "travel": [0.0, 0.01, 0.02, 0.03, 0.04]}],
         "data": {"law": "neo_hookean", "grid": {"strain_min": -0.3, "strain_max": 0.3, "points": 21,
                                                 "grading": 2}, "c": "estimated"}}


def ddcm_run(monkeypatch, chord_min_size: int, live: list | None = None):
    """DDCM Fischer-Burmeister on :data:`BLOCK`, with chord steps from ``chord_min_size`` unknowns;
    returns the path and the factorisations Newton made. ``live``: every system goes to the
    factorising thread, and the factors it holds are appended after each projection."""
    monkeypatch.setattr(newton, "CHORD_MIN_SIZE", chord_min_size)
    factorisations = []
    factorize = newton.factorize
    monkeypatch.setattr(newton, "factorize", lambda A, **kw: factorisations.append(1) or factorize(A, **kw))
    if live is not None:
        monkeypatch.setattr(linalg, "INTERRUPTIBLE_MIN_SIZE", 0)
        owner, project = linalg._FACTOR_THREAD, ddcm_projection.Projection.project

        def counted(self, *args, **kw):
            out = project(self, *args, **kw)
            live.append(owner.made - owner.released)
            return out

        monkeypatch.setattr(ddcm_projection.Projection, "project", counted)
    model = case_from_dict(BLOCK).model
    return compare(model, ["fischer_burmeister"], variants=["ddcm"])["ddcm", "fischer_burmeister"], len(factorisations)


@pytest.mark.filterwarnings("ignore::ddcm_casadi.errors.PhysicsWarning")  # coarse data, on purpose: a cheap run
def test_chord_steps_reach_the_same_fixed_points_with_fewer_factorisations(monkeypatch):
    """Chord steps (the last factor reused while it cuts the residual tenfold) change the path,
    not the equations or the tests: every step of the path converges to the same data assignment
    and the same fields. Both runs stop at a relative increment of 1e-9 (scaled, of unknowns of
    order one), within about that of the same root (Newton's error after its last step is below
    that step; a chord step's is below 0.1/0.9 of it): 1e-8 relative to the largest value allows
    ten times that. The factorisations Newton makes must be fewer."""
    with monkeypatch.context() as m:
        plain, plain_factors = ddcm_run(m, 10**9)
    live: list[int] = []
    chord, chord_factors = ddcm_run(monkeypatch, 0, live)
    assert all(s.converged for s in plain.steps) and all(s.converged for s in chord.steps)
    for a, b in zip(chord.steps, plain.steps):
        np.testing.assert_array_equal(a.data_index, b.data_index)
        for field in ("u", "p", "stress"):
            x, y = np.asarray(getattr(a, field)), np.asarray(getattr(b, field))
            assert np.max(np.abs(x - y)) <= 1e-8 * max(np.max(np.abs(y)), 1e-300), field
    assert chord_factors < plain_factors
    # Every factor made in the factorising thread went back to it, but for the few the active-set
    # solver caches (LU_CACHE pieces on FACTORS_KEPT references) and Newton's current one: the
    # count may not grow from the 3rd projection to the last.
    assert len(live) >= 10
    assert max(live[2:]) <= 8 and live[-1] <= max(live[:3]) + 2, live


@pytest.mark.parametrize("size", [0, 10**9])
def test_newton_solves_a_nonlinear_system_with_and_without_chord_steps(monkeypatch, size):
    """``r(z) = z + z^3/10 - b`` (Jacobian ``1 + 3 z^2/10``, changing with ``z``): both ways reach
    the root to the residual tolerance 1e-12."""
    import scipy.sparse as sp

    monkeypatch.setattr(newton, "CHORD_MIN_SIZE", size)
    b = np.linspace(-2.0, 2.0, 50)

    def r(z, _):
        return z + z**3 / 10 - b

    def rj(z, _):
        return r(z, None), 1.0 + 0.3 * z**2

    pattern = sp.identity(b.size, format="csc")

    def to_csc(J):
        return sp.csc_matrix((J, pattern.indices, pattern.indptr), shape=pattern.shape)

    res = newton.newton_solve(rj, r, np.zeros(b.size), None, jacobian=to_csc, tol=1e-12, residual_tol=1e-12)
    assert res.converged and np.max(np.abs(r(res.z, None))) <= 1e-12
