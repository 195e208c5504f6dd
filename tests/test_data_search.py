"""The data search backends return the exact nearest datum, whatever their start."""

from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi.casefiles.config import load_case
from ddcm_casadi.data.dataset import MaterialDataset, PointData
from ddcm_casadi.errors import InputError
from ddcm_casadi.data.metric import isotropic_elasticity
from ddcm_casadi.data.search import SEARCHES
from ddcm_casadi.drivers.ddcm_options import DDCMOptions

CASES = Path(__file__).resolve().parent.parent / "examples" / "cases"

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


@pytest.mark.parametrize("k", [1, 3])
@pytest.mark.parametrize("n", [1, 7, 3000])
def test_every_backend_gives_the_same_nearest_data(k, n):
    """The registered backends (``kdtree``, ``graph``) are exact: on random data and random
    states they return data at the same distance, cold and warm-started (the graph from a
    random previous assignment, the worst start)."""
    rng = np.random.default_rng(n + k)
    if k == 1:
        data = MaterialDataset(rng.uniform(-0.01, 0.01, n), rng.normal(0.0, 1e9, n), 200e9)
        q_e, q_s = rng.uniform(-0.012, 0.012, 500), rng.normal(0.0, 1e9, 500)
    else:
        C = isotropic_elasticity(200e9, 0.3, 2)[0]
        data = MaterialDataset(rng.uniform(-0.01, 0.01, (n, 3)), rng.normal(0.0, 1e9, (n, 3)), C)
        q_e, q_s = rng.uniform(-0.012, 0.012, (500, 3)), rng.normal(0.0, 1e9, (500, 3))
    reference = data.distance2(q_e, q_s, data.nearest(q_e, q_s, search="kdtree"))
    previous = rng.integers(0, n, 500)
    for name, backend in SEARCHES.items():
        if not backend.available():  # an optional extra not installed (tests/test_ann_search.py)
            continue
        assert data.search(name).exact and data.search(name).name == name
        for prev in (None, previous):
            found = data.nearest(q_e, q_s, search=name, previous=prev)
            assert np.array_equal(data.distance2(q_e, q_s, found), reference), (name, prev is None)
    five = data.search("graph").k_nearest(data.coordinates(q_e, q_s), 5)
    assert np.array_equal(five, data.k_nearest(q_e, q_s, 5))


def test_unknown_search_is_one_line_listing_the_known():
    data = _noisy(20)
    with pytest.raises(InputError) as err:
        data.nearest([0.0], [0.0], search="annoy")
    message = str(err.value)
    assert "\n" not in message and "'annoy'" in message
    assert all(name in message for name in SEARCHES)
    assert data.search("warm") is data.search("graph")  # the former name of the graph search


def test_search_from_case_file_and_override(tmp_path):
    """``[ddcm] search`` selects the backend (case file, ``--set``, API) and is checked before
    any work."""
    case = CASES / "bar_stops.toml"
    path = tmp_path / "bar.toml"
    path.write_text(case.read_text().replace("[ddcm]", '[ddcm]\nsearch = "graph"', 1))
    assert load_case(path).ddcm_options.search == "graph"
    assert load_case(case).ddcm_options.search == "kdtree"
    assert load_case(case, overrides=[("ddcm.search", "warm")]).ddcm_options.search == "graph"
    with pytest.raises(InputError, match="unknown data search 'annoy'; known: kdtree, graph"):
        load_case(case, overrides=[("ddcm.search", "annoy")])
    assert DDCMOptions(search="graph").describe()["search"] == "graph"
    with pytest.raises(InputError, match="unknown data search"):
        DDCMOptions(search=3)
