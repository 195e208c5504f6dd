"""The warm-started data search returns the exact nearest datum, whatever its start."""

import numpy as np
import pytest

from ddcm_casadi.data import MaterialDataset, PointData

RNG = np.random.default_rng(7)


def _noisy(n, noise=1e7):
    e = RNG.uniform(-0.01, 0.01, n)
    return MaterialDataset(e, 200e9 * e + RNG.normal(0, noise, n), 200e9)


@pytest.mark.parametrize("n", [1, 2, 9, 500, 20_000])
@pytest.mark.parametrize("start", ["previous", "random"])
def test_warm_search_is_exact(n, start):
    data = _noisy(n)
    m = 2000
    e = RNG.uniform(-0.012, 0.012, m)
    s = 200e9 * e * (1 + 0.05 * RNG.standard_normal(m))
    cold = data.nearest(e, s)
    prev = data.nearest(e * 1.001, s * 0.999) if start == "previous" else RNG.integers(0, n, m)
    warm = data.nearest_warm(e, s, prev)
    # Same distance (an equidistant datum may be returned instead of the KD-tree's).
    assert np.array_equal(data.distance2(e, s, warm), data.distance2(e, s, cold))


def test_warm_search_with_duplicates_and_per_point_data():
    e = np.repeat(np.linspace(-0.01, 0.01, 50), 3)
    steel = MaterialDataset(e, 200e9 * e, 200e9)
    alu = _noisy(300)
    data = PointData([steel, alu], [0, 1, 1, 0, 1])
    q_e = RNG.uniform(-0.01, 0.01, 5)
    q_s = 150e9 * q_e
    cold = data.nearest(q_e, q_s)
    warm = data.nearest_warm(q_e, q_s, data.offsets[data.material])
    assert np.array_equal(data.distance2(q_e, q_s, warm), data.distance2(q_e, q_s, cold))


@pytest.mark.parametrize("noise", [0.0, 1e6, 1e9])
@pytest.mark.parametrize("offset", [0.0, 1e-6, 1e-2])
def test_search_is_exact_near_and_far_from_the_data(noise, offset):
    """The tree works in the data's principal axes; that is a rotation, so the nearest datum is
    the brute-force one, for states on the data and far from it (offset in strain, with the
    stress of the Hookean line). Ties within roundoff (1e-12 relative) may go either way."""
    data = _noisy(5000, noise) if noise else MaterialDataset.hookean(200e9, -0.01, 0.01, 5000, c=300e9)
    e = RNG.uniform(-0.012, 0.012, 300)
    s = 200e9 * e
    e = e + offset
    found = data.nearest(e, s)
    d2 = data.c * (e[:, None] - data.strain) ** 2 + (s[:, None] - data.stress) ** 2 / data.c
    assert np.all(d2[np.arange(e.size), found] <= d2.min(axis=1) * (1 + 1e-12))
