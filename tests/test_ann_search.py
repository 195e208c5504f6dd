"""The certified searches (:mod:`ddcm_casadi.data.ann`): their certificates against brute force,
their selection and errors, and DDCM fixed points equal to the exact KD-tree's."""

from __future__ import annotations

import builtins
import dataclasses

from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi import formulations
from ddcm_casadi.casefiles.config import load_case
from ddcm_casadi.data.ann import U64, IVFSearch, StripSearch
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.data.search import SEARCHES, KDTreeSearch, Rows, search_class
from ddcm_casadi.drivers.ddcm import DDCMSolver
from ddcm_casadi.drivers.ddcm_options import DDCMOptions
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.truss import bar_chain
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.validation.quality_rungs import noisy_dataset

RNG = np.random.default_rng(28)
CASES = Path(__file__).resolve().parents[1] / "examples" / "cases"


def _brute(X: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Exact nearest distances by direct differences in float64."""
    X = X.astype(np.float64)
    return np.array([np.sqrt(np.min(np.einsum("ij,ij->i", X - q, X - q))) for q in Q])


def _tolerance(d: int) -> float:
    """Relative roundoff of a float64 distance over ``d`` coordinates: ``d`` squares summed, the
    differences and the square root each rounded (``(d + 3) u``), for two distances."""
    return 2.0 * (d + 3) * U64


def _clouds():
    """Data with exact ties (duplicates, a grid with queries at cell centres), a noisy band, a
    line, and float32 data whose rounding the strip keys do not add to."""
    band_e = RNG.uniform(-1.0, 1.0, 3000)
    band = np.column_stack([band_e, 0.02 * RNG.normal(size=3000)])
    line = np.column_stack([np.linspace(-1, 1, 2001), np.zeros(2001)])
    g = np.arange(-10, 11, dtype=float)
    grid = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    dup = np.repeat(RNG.normal(size=(200, 2)), 3, axis=0)
    return {
        "band": (band, np.column_stack([RNG.uniform(-1.5, 1.5, 800), RNG.normal(0, 0.3, 800)])),
        "line": (line, RNG.normal(0, 0.5, (800, 2))),
        "grid ties": (grid, (RNG.integers(-11, 11, (800, 2)) + 0.5)),
        "duplicates": (dup, RNG.normal(size=(800, 2))),
        "float32": (band.astype(np.float32), RNG.normal(0, 0.5, (800, 2))),
        "float64 rounded": (band * (1 + 2.0 ** -30), RNG.normal(0, 0.5, (800, 2))),  # keys differ from coords
        "12 coordinates": (RNG.normal(size=(4000, 12)) * np.linspace(1, 0.01, 12), RNG.normal(size=(300, 12))),
    }


def _searches():
    out = [StripSearch]
    if IVFSearch.available():
        out.append(IVFSearch)
    return out


@pytest.mark.parametrize("cloud", list(_clouds()))
@pytest.mark.parametrize("backend", _searches(), ids=lambda b: b.name)
def test_certificate_is_sound_and_the_search_exact(cloud, backend):
    """At every widening level: a certified answer is at the brute-force distance, and the
    nearest distance is never below ``min(d_j, B)`` (the reported bound); the widest search
    (:meth:`nearest`) is exact."""
    X, Q = _clouds()[cloud]
    search = backend.build(X)
    truth = _brute(X, Q)
    tol = _tolerance(X.shape[1])
    for rounds in (0, 1, None):
        cert = search.certified(Q, rounds=rounds)
        np.testing.assert_allclose(cert.distance[cert.certified], truth[cert.certified], rtol=tol, atol=0)
        assert np.all(truth >= np.minimum(cert.distance, cert.bound) * (1 - tol)), rounds
        assert np.all(cert.gap[cert.certified] == 0)
    exact = search.nearest(Q)
    found = np.sqrt(np.einsum("ij,ij->i", X[exact] - Q, X[exact] - Q))
    np.testing.assert_allclose(found, truth, rtol=tol, atol=0)


@pytest.mark.parametrize("cloud", [c for c in _clouds() if c != "12 coordinates"])
@pytest.mark.parametrize("k", [1, 4, 9])
def test_strips_k_nearest_are_the_kd_tree_s(cloud, k):
    """The strip search's own k nearest (no exact search beside it) are the KD-tree's: the same
    distances, nearest first (ties may differ in index)."""
    X, Q = _clouds()[cloud]
    got = StripSearch.build(X).k_nearest(Q, k)
    want = KDTreeSearch.build(np.asarray(X, dtype=np.float64)).k_nearest(Q, k)
    X = X.astype(np.float64)
    distance = [np.sqrt(np.einsum("ijk,ijk->ij", X[i] - Q[:, None], X[i] - Q[:, None])) for i in (got, want)]
    np.testing.assert_allclose(distance[0], distance[1], rtol=_tolerance(2), atol=0)
    assert np.all(np.diff(distance[0], axis=1) >= 0) and all(len(set(row)) == k for row in got)


def test_strips_first_search_certifies_most_states_near_the_data():
    """Near a band of data the first window certifies most answers (the certificate is not
    vacuous), and all of those at the exact distance."""
    X, _ = _clouds()["band"]
    Q = X[RNG.integers(0, len(X), 2000)] + RNG.normal(0, 0.005, (2000, 2))
    cert = StripSearch.build(X).certified(Q, rounds=0)
    assert cert.certified.mean() > 0.8


def test_backends_are_registered_and_selected_by_name():
    assert search_class("strips") is StripSearch and search_class("ann") is IVFSearch
    data = MaterialDataset(*noisy_pair(500), 200e9)
    e, s = noisy_pair(100)
    reference = data.distance2(e, s, data.nearest(e, s))
    assert np.array_equal(data.distance2(e, s, data.nearest(e, s, search="strips")), reference)
    with pytest.raises(InputError, match="unknown data search 'hnsw'; known: kdtree, graph, strips, ann"):
        DDCMOptions(search="hnsw")


def noisy_pair(n):
    e = RNG.uniform(-0.01, 0.01, n)
    return e, 200e9 * e + RNG.normal(0, 1e7, n)


def test_missing_faiss_is_one_line_naming_the_extra(monkeypatch):
    real = builtins.__import__

    def no_faiss(name, *args, **kwargs):
        if name == "faiss":
            raise ImportError("No module named 'faiss'")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_faiss)
    assert not IVFSearch.available()
    with pytest.raises(InputError) as err:
        IVFSearch.build(np.zeros((10, 2)))
    assert str(err.value) == "data search 'ann' needs faiss: pip install 'ddcm-casadi[ann]' (faiss-cpu)"


def test_bad_input_is_one_line():
    with pytest.raises(InputError, match=r"^the strip search needs \(N, 2\) coordinates"):
        StripSearch.build(np.zeros((5, 1)))
    with pytest.raises(InputError, match=r"^queries must be \(n, 2\) coordinates"):
        StripSearch.build(np.zeros((5, 2))).certified(np.zeros((3, 3)))
    with pytest.raises(InputError, match=r"^queries must be \(n, 2\) coordinates"):
        StripSearch.build(np.zeros((5, 2))).k_nearest(np.zeros((1, 3)), 2)


@pytest.mark.parametrize("search", [b.name for b in _searches()])
def test_ddcm_fixed_points_equal_the_kd_tree_s(search):
    """A noisy bar chain on stops: the whole DDCM path (data assignment, displacements,
    pressures, distances, iterations) is the KD-tree's."""
    model = bar_chain(length=1.0, elements=12, youngs_modulus=200e9, tip_positions=np.linspace(1.002, 0.99, 5),
                      stops={3: 0.002, 8: 0.006}, dataset=noisy_dataset(0.05, 1, n_data=3000), name="noisy chain")
    paths = {}
    for name in ("kdtree", search):
        problems = build_problems(model)
        solver = DDCMSolver(problems, formulations.get("fischer_burmeister").build(problems.projection),
                            options=DDCMOptions(search=name))
        paths[name] = solver.solve()
    for field in ("data_index", "outer_iterations", "u", "p", "distance"):
        np.testing.assert_array_equal(paths[search].array(field), paths["kdtree"].array(field), err_msg=field)
    assert search in model.dataset._searches  # the backend was used


@pytest.mark.parametrize("group", [64, 1 << 16])
def test_strip_build_in_blocks_and_groups_sorts_every_strip(monkeypatch, tmp_path, group):
    """The build's passes over blocks of rows, its deal to groups of strips and each group's
    radix sort (groups of one strip or of many) give strips sorted by key ``b``, each datum in
    the strip of its key ``a``, ``perm`` a permutation with ``keys = X[perm]``; the search over
    a float32 ``.npy`` file read in blocks answers as over the array, exactly."""
    monkeypatch.setattr(StripSearch, "READ", 333)
    monkeypatch.setattr(StripSearch, "GROUP", group)
    X, Q = _clouds()["band"]
    X = X.astype(np.float32)
    X[::7, 1] *= -1.0  # negative keys b and signed zeros (the sort's order-preserving bits)
    X[::11, 1] = 0.0
    X[::13, 1] = -0.0
    path = tmp_path / "band.npy"
    np.save(path, X)
    for search in (StripSearch.build(X), StripSearch.from_npy(path)):
        a, b = search.axes
        assert np.array_equal(np.sort(search.perm), np.arange(len(X)))
        assert np.array_equal(search.keys[0], X[search.perm, a]) and np.array_equal(search.keys[1], X[search.perm, b])
        t = np.floor((search.keys[0].astype(np.float64) - search.low) / search.width)
        strip = np.repeat(np.arange(search.lo_t.size), np.diff(search.offsets))
        assert np.array_equal(np.clip(t, 0, search.lo_t.size - 1), strip)
        assert np.all((np.diff(search.keys[1]) >= 0) | (np.diff(strip) > 0))
        ties = (np.diff(search.keys[1].view(np.int32)) == 0) & (np.diff(strip) == 0)
        assert np.all(np.diff(search.perm)[ties] > 0)  # equal keys in the order of the data
        truth = _brute(X, Q)
        exact = search.nearest(Q)
        np.testing.assert_allclose(np.sqrt(np.einsum("ij,ij->i", X[exact] - Q, X[exact] - Q)), truth,
                                   rtol=_tolerance(2), atol=0)


def test_strips_over_a_float32_file_never_read_the_points_again(tmp_path, monkeypatch):
    """Float32 coordinates are their own keys: the re-ranking and the brute-force pass read the
    keys (in memory), never the memory-mapped file."""
    X = _clouds()["band"][0].astype(np.float32)
    path = tmp_path / "band.npy"
    np.save(path, X)
    search = StripSearch.from_npy(path)
    assert search.exact_keys

    class Unread:
        shape, dtype = X.shape, X.dtype

        def __getitem__(self, _):
            raise AssertionError("the points were read")

    monkeypatch.setattr(search, "_points", Unread())
    Q = RNG.normal(0, 0.5, (200, 2))
    cert = search.certified(Q)
    np.testing.assert_allclose(cert.distance, _brute(X, Q), rtol=_tolerance(2), atol=0)
    assert np.array_equal(search.brute_force(Q).distance, cert.distance)


def test_float32_storage_of_float64_data_costs_at_most_twice_its_rounding():
    """Exact for the data as stored in float32; against the float64 data they were rounded from,
    each datum moved by at most ``2^-24 R``, so the answer is at most ``2^-23 R`` (with the
    distances' float64 roundoff) farther than the nearest."""
    base = _clouds()["band"][0] * 1e3 + 7.0
    X = np.vstack([base, base + RNG.normal(0, 1e-6, base.shape)])  # pairs that float32 (ulp 6e-5) merges
    Q = X[RNG.integers(0, len(X), 500)] + RNG.normal(0, 1e-4, (500, 2))
    found = StripSearch.build(X.astype(np.float32)).nearest(Q)
    R = float(np.max(np.linalg.norm(X, axis=1)))
    d = np.sqrt(np.einsum("ij,ij->i", X[found] - Q, X[found] - Q))
    truth = _brute(X, Q)
    assert np.all(d <= truth * (1 + _tolerance(2)) + 2.0 ** -23 * R)
    assert np.any(d > truth * (1 + _tolerance(2)))  # the rounding does change answers here


def test_strip_build_with_more_groups_than_sixteen_bits(monkeypatch):
    """More than 2^16 groups of strips (their ids int64, the deal's argsort no longer a radix
    sort of uint16): the strips are still sorted and the answers exact."""
    monkeypatch.setattr(StripSearch, "GROUP", 1)
    n = 540_000  # n / 8 strips of a line, one group each
    X = np.column_stack([np.linspace(-1.0, 1.0, n), 1e-9 * RNG.normal(size=n)]).astype(np.float32)  # a line
    search = StripSearch.build(X)
    assert np.count_nonzero(np.diff(search.offsets)) > 2**16
    strip = np.repeat(np.arange(search.lo_t.size), np.diff(search.offsets))
    assert np.all((np.diff(search.keys[1]) >= 0) | (np.diff(strip) > 0))
    assert np.array_equal(np.sort(search.perm), np.arange(n))
    Q = X[RNG.integers(0, n, 300)].astype(np.float64) + RNG.normal(0, 1e-5, (300, 2))
    found = search.nearest(Q)
    d = np.sqrt(np.einsum("ij,ij->i", X[found] - Q, X[found] - Q))
    np.testing.assert_allclose(d, _brute(X, Q), rtol=_tolerance(2), atol=0)


def test_a_float32_data_file_reaches_the_strip_search_through_a_case_file(tmp_path):
    """A float32 ``.npy`` data file chosen in a case file with ``[ddcm] search = "strips"``: the
    data set keeps the file's float32 values (no float64 copy), the strip search is built from
    blocks of its coordinates without the array of them or the KD-tree, and the DDCM path (data
    assignment, displacements, pressures, distances, iterations) is the exact KD-tree's over the
    same file (the strip search's answers are exact: every one certified or widened). The strip
    search's keys are the file's own float32 values (``c = 300e9``: the search is in their
    scaled frame, the data set's centre and rotation applied to the queries only), so its
    re-ranking and certificates never gather the data set's coordinates."""
    noisy = noisy_dataset(0.05, 1, n_data=3000)
    np.save(tmp_path / "noisy.npy", np.column_stack([noisy.strain, noisy.stress]).astype(np.float32))
    case = (CASES / "bar_stops.toml").read_text()
    case = case.replace(case[case.index("hookean = "):case.index("\n", case.index("hookean = "))], 'path = "noisy.npy"')
    paths = {}
    for search in ("kdtree", "strips"):
        (tmp_path / f"{search}.toml").write_text(case.replace("[ddcm]", f'[ddcm]\nsearch = "{search}"', 1))
        loaded = load_case(tmp_path / f"{search}.toml")
        data = loaded.model.dataset
        assert data.strain.dtype == np.float32 and not data.strain.flags.owndata and not data._searches
        if search == "strips":
            def gathered(index):
                raise AssertionError("the strip search gathered the data set's coordinates")
            data._rows._of = gathered
        problems = build_problems(loaded.model)
        solver = DDCMSolver(problems, formulations.get("fischer_burmeister").build(problems.projection),
                            options=loaded.ddcm_options)
        paths[search] = solver.solve()
        assert set(data._searches) == {search} and (search == "kdtree") == (data._rows._array is not None)
        assert search == "kdtree" or data.search(search).exact_keys
    for field in ("data_index", "outer_iterations", "u", "p", "distance"):
        np.testing.assert_array_equal(paths["strips"].array(field), paths["kdtree"].array(field), err_msg=field)


def test_data_set_coordinates_read_in_blocks_equal_those_gathered():
    """The strip search's keys come from blocks of rows and its re-ranking from gathered rows:
    the two must agree bit for bit (its bound counts only the float32 rounding of the keys)."""
    noisy = noisy_dataset(0.05, 2, n_data=5000)
    data = MaterialDataset(noisy.strain.astype(np.float32), noisy.stress.astype(np.float32), noisy.c)
    rows = data._rows
    pick = RNG.integers(0, len(data), (70, 3))
    assert np.array_equal(rows[pick], rows.read(0, len(data))[pick])
    assert np.array_equal(rows.read(17, 4000), rows.array()[17:4000])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_a_data_set_s_strip_keys_are_its_float32_values(dtype):
    """Over a float32 data set the strip search's keys are the stored strain and stress values
    (the coordinates their scaled values, the data set's centre and rotation applied to the
    queries only); over float64 data they are the coordinates rounded to float32 and re-ranked.
    Either way the answers are the KD-tree's nearest distances (ties apart)."""
    noisy = noisy_dataset(0.05, 3, n_data=4000)
    data = MaterialDataset(noisy.strain.astype(dtype), noisy.stress.astype(dtype), noisy.c)
    search = data.search("strips")
    assert search.exact_keys == (dtype == np.float32)
    if dtype == np.float32:
        stored = np.column_stack([data.strain, data.stress])[search.perm]
        a, b = search.axes
        assert np.array_equal(search.keys[0], stored[:, a]) and np.array_equal(search.keys[1], stored[:, b])
        # the data set's pass gave the extremes: the same structure as with the build's own pass
        rows = data._rows
        unknown = Rows(*rows.shape, rows._of, stored=dataclasses.replace(rows.stored, extremes=None))
        again = StripSearch.from_rows(unknown, None)
        assert (again.low, again.width, again.b_range) == (search.low, search.width, search.b_range)
        assert np.array_equal(again.perm, search.perm)
    e = RNG.uniform(-0.06, 0.02, 600)
    s = 200e9 * e + RNG.normal(0, 0.3 * np.std(noisy.stress), 600)
    found, exact = data.nearest(e, s, search="strips"), data.nearest(e, s)
    # the metric distance of two data of the same squared distance: each computed in float64
    # over 2 coordinates (the frames differ, so the roundoff of both, relative to the squares)
    np.testing.assert_allclose(data.distance2(e, s, found), data.distance2(e, s, exact), rtol=4 * _tolerance(2),
                               atol=0)
    Q = data.coordinates(e, s)
    np.testing.assert_array_equal(search.brute_force(Q).distance, search.certified(Q).distance)
