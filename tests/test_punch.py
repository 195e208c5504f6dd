"""The flat-punch obstacle (signed distance, normals, case files) and the softening-punch example."""

import numpy as np
import pytest

from ddcm_casadi.models.continuum import FlatPunch
from ddcm_casadi.errors import InputError
from ddcm_casadi.validation.ladder import EXACT_TOL
from ddcm_casadi.data.metric import isotropic_elasticity

from .test_examples import _load

A, R = 5e-3, 1e-3  # half-width, edge radius
DS = 1e-7          # spacing of the sampled outline


def _outline_samples(a: float, r: float, height: float) -> np.ndarray:
    """The punch's boundary in 2-D (face on y = 0, body below), sampled every ``DS``: the face,
    the two quarter-circle edges and the sides."""
    face = np.column_stack([np.arange(-(a - r), a - r, DS), np.zeros(int(np.ceil(2 * (a - r) / DS)))])
    t = np.arange(0.0, 0.5 * np.pi, DS / r)
    edge = np.column_stack([a - r + r * np.sin(t), r - r * np.cos(t)])
    side = np.column_stack([np.full(int(height / DS), a), r + DS * np.arange(int(height / DS))])
    right = np.vstack([edge, side])
    return np.vstack([face, right, right * [-1.0, 1.0]])


def test_signed_distance_matches_the_distance_to_the_outline():
    """Against brute force: the nearest of the sampled outline points is within ``DS / 2`` of the
    true distance (the nearest boundary point lies between two samples)."""
    punch = FlatPunch(center=(0.0, 0.0), normal=(0.0, -1.0), half_width=A, edge_radius=R)
    rng = np.random.default_rng(1)
    x = rng.uniform([-8e-3, -3e-3], [8e-3, 2e-3], size=(200, 2))
    samples = _outline_samples(A, R, 6e-3)
    dist = np.min(np.linalg.norm(x[:, None, :] - samples[None, :, :], axis=2), axis=1)
    # inside the rounded strip, decided without phi: |x| <= a, y >= 0, and not in a corner cut-out
    corner = (np.abs(x[:, 0]) > A - R) & (x[:, 1] < R)
    in_arc = (np.abs(x[:, 0]) - (A - R)) ** 2 + (x[:, 1] - R) ** 2 <= R ** 2
    inside = (np.abs(x[:, 0]) <= A) & (x[:, 1] >= 0) & (~corner | in_arc)
    expected = np.where(inside, -dist, dist)
    assert inside.any() and (~inside).any()
    assert np.max(np.abs(punch.phi(x) - expected)) <= DS / 2 + 1e-15


def test_normals_are_the_gradient_of_the_signed_distance():
    punch = FlatPunch(center=(1e-3, 2e-3), normal=(0.6, -0.8), half_width=A, edge_radius=R)
    rng = np.random.default_rng(2)
    x = punch.center + rng.uniform(-8e-3, 8e-3, size=(100, 2))
    x = x[punch.phi(x) > 1e-5]  # outside, away from the corners of the medial axis
    h = 1e-8
    fd = np.column_stack([(punch.phi(x + h * e) - punch.phi(x - h * e)) / (2 * h) for e in np.eye(2)])
    # phi is C^1 outside with curvature <= 1/dist: the central difference errs by O(h^2 / dist^2)
    assert np.max(np.linalg.norm(punch.grad_phi(x) - fd, axis=1)) <= 1e-6


def test_three_dimensional_punch_is_the_two_dimensional_one_turned_about_its_axis():
    p2 = FlatPunch(center=(0.0, 0.0), normal=(0.0, -1.0), half_width=A, edge_radius=R)
    p3 = FlatPunch(center=(0.0, 0.0, 0.0), normal=(0.0, 0.0, -1.0), half_width=A, edge_radius=R)
    rng = np.random.default_rng(3)
    rho, z, angle = rng.uniform(0, 8e-3, 50), rng.uniform(-3e-3, 2e-3, 50), rng.uniform(0, 2 * np.pi, 50)
    x3 = np.column_stack([rho * np.cos(angle), rho * np.sin(angle), z])
    np.testing.assert_allclose(p3.phi(x3), p2.phi(np.column_stack([rho, z])), rtol=0, atol=1e-15)


@pytest.mark.parametrize("kw, message", [
    (dict(edge_radius=6e-3), "edge_radius must be in"),
    (dict(edge_radius=float("nan")), "edge_radius must be in"),
    (dict(half_width=0.0), "radius must be finite and positive"),
    (dict(normal=(0.0, 0.0)), "non-zero"),
])
def test_bad_punches_are_refused(kw, message):
    args = dict(center=(0.0, 0.0), normal=(0.0, -1.0), half_width=A, edge_radius=R) | kw
    with pytest.raises(InputError, match=message):
        FlatPunch(**args)


_CASE = """
[mesh]
shape = "rectangle"
size = [0.02, 0.01]
divisions = [8, 4]
origin = [0.0, -0.01]
[material]
youngs_modulus = 50e6
poisson_ratio = 0.3
[[supports]]
boundary = "xmin"
fix = "x"
[[supports]]
boundary = "ymin"
fix = "xy"
[[contact]]
boundary = "ymax"
obstacle = "punch"
center = [0.0, 0.0]
normal = [0.0, -1.0]
half_width = 0.005
edge_radius = 0.001
travel = [0.0, 1e-5]
"""


def test_a_punch_from_a_case_file(tmp_path):
    from ddcm_casadi import compare
    from ddcm_casadi.casefiles.config import load_case

    (tmp_path / "punch.toml").write_text(_CASE)
    model = load_case(tmp_path / "punch.toml").model
    assert model.obstacles[0].describe()["half_width"] == 0.005
    r = compare(model, ["fischer_burmeister"], variants=["classical"])["classical", "fischer_burmeister"]
    assert r.converged
    p = r.steps[-1].p
    x = model.contact_points[:, 0]
    # pressed under the face only (free pairs at roundoff: the solver tolerance relative to max p)
    assert np.all(np.abs(p[x > A - R]) <= EXACT_TOL * p.max()) and np.all(p[x < A - R] > 0)
    (tmp_path / "bad.toml").write_text(_CASE.replace("edge_radius = 0.001", "edge_radius = 0.01"))
    with pytest.raises(InputError, match="edge_radius must be in"):
        load_case(tmp_path / "bad.toml")


# ------------------------------------------------------------------------ the softening example
@pytest.fixture(scope="module")
def example():
    return _load("softening_punch")


def test_softening_law_limits(example):
    """Small strain: ``sigma - C eps = -2 mu0 (gamma / gamma0) / (1 + gamma / gamma0) dev``, and
    ``|C eps| >= 2 mu0 gamma`` (the volumetric part is orthogonal to ``dev``), so the relative
    difference is at most ``gamma / gamma0``; pure shear ``gamma``: ``2 mu0 gamma / (1 + gamma / gamma0)``,
    which saturates at ``2 mu0 gamma0``."""
    C = isotropic_elasticity(example.E, example.NU, 2)[0]
    eps = 1e-7 * np.array([[1.0, -0.5, 0.3], [-2.0, 1.0, 1.0]])
    gamma = np.linalg.norm(eps - 0.5 * (eps[:, :1] + eps[:, 1:2]) * [1, 1, 0], axis=1)
    lin = eps @ C.T
    rel = np.linalg.norm(example.softening_stress(eps) - lin, axis=1) / np.linalg.norm(lin, axis=1)
    assert np.all(rel <= gamma / example.GAMMA0)
    shear = np.array([[0.0, 0.0, 1e3 * example.GAMMA0]])  # pure shear, Mandel
    mu0 = 0.5 * C[2, 2]
    tau = example.softening_stress(shear)[0, 2]
    assert tau == pytest.approx(2 * mu0 * example.GAMMA0 / (1 + 1e-3), rel=1e-12)


def test_softening_punch_example_quick(example, tmp_path):
    """Quick mode: every run converges, the exact formulations agree, the softening data carry
    less force than the linear law, and the outputs are written. (MPCC's DDCM runs take most of
    a minute even here; the continuum tests cover it on smaller bodies.)"""
    forms = ["penalty", "augmented_lagrangian", "fischer_burmeister"]
    res = example.main(tmp_path, quick=True, formulations=forms, data_sizes=(9,))
    cmp = res.comparison
    assert all(r.converged for r in cmp.results.values())
    force = {key: example.punch_force(res.model, cmp, *key) for key in cmp.results}
    for variant in ("classical", "ddcm"):
        a, b = force[variant, "augmented_lagrangian"], force[variant, "fischer_burmeister"]
        assert np.max(np.abs(a - b)) <= EXACT_TOL * np.max(np.abs(b))
    linear, soft = force["classical", "fischer_burmeister"], force["ddcm", "fischer_burmeister"]
    assert soft[-1] < linear[-1] and np.all(soft <= linear + EXACT_TOL * linear[-1])
    assert res.data_sizes[9][1]
    for name in ("force_indentation.png", "pressure_profile.png", "deformed_ddcm.png", "vtu/ddcm_fischer_burmeister.pvd"):
        assert (tmp_path / name).stat().st_size > 0
    assert "punch force at the last step" in res.table()
