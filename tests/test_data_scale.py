"""Large data sets: compact storage without full-size temporaries, the warm search's compact graph,
and memory-mapped ``.npy`` data files (with their one-line errors)."""

import io
import mmap
import tracemalloc

import numpy as np
import pytest

from ddcm_casadi.data.search import CHUNK
import ddcm_casadi.data.limits as limits
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.errors import InputError
from ddcm_casadi.data.metric import Metric, isotropic_elasticity

RNG = np.random.default_rng(11)
D3 = isotropic_elasticity(200e9, 0.3, 3)[0]


def _samples(n, k, noise=0.0):
    """``n`` random points of the isotropic law (one component: E = 200 GPa), stress noise
    relative to the stress scale."""
    if k == 1:
        e = RNG.uniform(-0.01, 0.01, n)
        return e, 200e9 * e + noise * 2e9 * RNG.standard_normal(n)
    e = RNG.uniform(-0.01, 0.01, (n, 6))
    return e, e @ D3.T + noise * 2e9 * RNG.standard_normal((n, 6))


@pytest.mark.parametrize("k", [1, 6])
def test_build_allocates_only_the_coordinates_and_the_tree(k):
    """The search keeps one float64 array of coordinates (16 k bytes per point) and the tree's
    index (8 bytes per point); the checks, the centring and the rotation add nothing of the
    data's size, only one block of rows (the first version held three full copies)."""
    n = 300_000
    strain, stress = _samples(n, k)
    tracemalloc.start()
    try:
        data = MaterialDataset(strain, stress, 200e9 if k == 1 else D3)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    kept = n * (16 * k + 8)
    block = CHUNK * 2 * k * 8
    assert peak <= kept + block + 2**20
    assert data.strain is strain and data.stress is stress  # float64 input is not copied


@pytest.mark.parametrize("k", [1, 6])
def test_compact_graph_radii_never_exceed_the_distances(k):
    """The warm search's radii are float32 rounded down (certifying fewer states, never a wrong
    one) and its answers are the cold search's, on noisy data with duplicates."""
    strain, stress = _samples(3000, k, noise=0.01)
    strain, stress = np.concatenate([strain, strain[:500]]), np.concatenate([stress, stress[:500]])
    data = MaterialDataset(strain, stress, 200e9 if k == 1 else D3)
    graph = data.search("graph")
    nbrs, radius = graph.neighbours, graph.radius
    assert nbrs.dtype == np.int32 and radius.dtype == np.float32
    pts = graph.points
    exact = np.sqrt(np.sum((pts[nbrs[:, -1]] - pts) ** 2, axis=1))
    assert np.all(radius.astype(float) <= exact)
    assert np.all(radius.astype(float) >= exact * (1 - 2.0**-23))
    q_e, q_s = _samples(2000, k, noise=0.003)
    prev = data.nearest(q_e * 1.001, q_s)
    stats = {}
    warm = data.nearest_warm(q_e, q_s, prev, stats=stats)
    cold = data.nearest(q_e, q_s)
    assert np.array_equal(data.distance2(q_e, q_s, warm), data.distance2(q_e, q_s, cold))
    assert stats["queries"] == 2000


@pytest.mark.parametrize("k", [1, 6])
@pytest.mark.parametrize("dtype", ["<f8", ">f8", "<f4", "<i4"])
@pytest.mark.parametrize("order", ["C", "F"])
def test_npy_file_reads_as_the_csv_columns(tmp_path, k, dtype, order):
    strain, stress = _samples(400, k, noise=0.01)
    c = 200e9 if k == 1 else D3
    if dtype == "<i4":  # micro-strain and MPa: the modulus and the metric in MPa
        strain, stress, c = np.round(strain * 1e6), np.round(stress / 1e6), c / 1e12
    table = np.column_stack([strain, stress]).astype(dtype)
    np.save(tmp_path / "d.npy", np.asfortranarray(table) if order == "F" else table)
    data = MaterialDataset.from_file(tmp_path / "d.npy", c=c)
    want = table.astype(float)
    assert np.array_equal(data.strain, want[:, 0] if k == 1 else want[:, :k])
    assert np.array_equal(data.stress, want[:, 1] if k == 1 else want[:, k:])
    if dtype == "<f8":  # memory-mapped, not read into the process
        assert _mapped(data.strain) and _mapped(data.stress)
    csv = tmp_path / "d.csv"
    names = ["strain", "stress"] if k == 1 else [f"strain_{i}" for i in range(1, k + 1)] + \
        [f"stress_{i}" for i in range(1, k + 1)]
    np.savetxt(csv, want, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    ref = MaterialDataset.from_file(csv, c=c)
    q_e, q_s = _samples(500, k, noise=0.02)
    if dtype == "<i4":
        q_e, q_s = q_e * 1e6, q_s / 1e6
    assert np.array_equal(data.nearest(q_e, q_s), ref.nearest(q_e, q_s))


def _mapped(a) -> bool:
    """Whether ``a`` is a view of a memory-mapped file."""
    while a is not None:
        if isinstance(a, (np.memmap, mmap.mmap)):
            return True
        a = getattr(a, "base", None)
    return False


def _npy_bytes(array) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=True)
    return buf.getvalue()


GOOD = _npy_bytes(np.column_stack([np.linspace(0, 1, 10), np.linspace(0, 2e11, 10)]))


@pytest.mark.parametrize("content, match", [
    pytest.param(b"", "empty", id="empty"),
    pytest.param(b"strain,stress\n0,0\n", "not a .npy file", id="csv-named-npy"),
    pytest.param(GOOD[:-8], "damaged or unsupported", id="truncated-data"),
    pytest.param(GOOD[:20], "damaged or unsupported", id="truncated-header"),
    pytest.param(GOOD[:8] + b"\x50\x00{'descr': '<f8', 'fortran_order': False, 'shape': (10, 2) ", "damaged",
                 id="broken-header"),
    pytest.param(_npy_bytes(np.array([[object(), 1.0]], dtype=object)), "damaged or unsupported", id="objects"),
    pytest.param(_npy_bytes(np.ones((4, 2), dtype=complex)), "complex128 values", id="complex"),
    pytest.param(_npy_bytes(np.ones((4, 2), dtype=bool)), "bool values", id="bool"),
    pytest.param(_npy_bytes(np.ones((4, 3))), r"shape \(4, 3\)", id="three-columns"),
    pytest.param(_npy_bytes(np.ones(8)), r"shape \(8,\)", id="one-dimensional"),
    pytest.param(_npy_bytes(np.ones((0, 2))), r"shape \(0, 2\)", id="no-rows"),
    pytest.param(_npy_bytes(np.array([[0.0, np.nan]])), "NaN", id="nan"),
    pytest.param(_npy_bytes(np.array([[0.0, 1e300]])), "out of range", id="huge"),
])
def test_bad_npy_files_are_one_line_input_errors(tmp_path, content, match):
    path = tmp_path / "data.npy"
    path.write_bytes(content)
    with pytest.raises(InputError, match=match) as err:
        MaterialDataset.from_file(path, c=200e9)
    assert "\n" not in str(err.value)


def test_npy_file_limits_and_paths(tmp_path, monkeypatch):
    np.save(tmp_path / "d.npy", np.ones((50, 12)))
    with pytest.raises(InputError, match=r"needs \(N, 2\)"):
        MaterialDataset.from_npy(tmp_path / "d.npy", c=200e9)
    assert len(MaterialDataset.from_npy(tmp_path / "d.npy", c=Metric(D3))) == 50
    monkeypatch.setattr(limits, "MAX_MAPPED_DATA_POINTS", 49)
    with pytest.raises(InputError, match="50 points, more than 49"):
        MaterialDataset.from_npy(tmp_path / "d.npy", c=D3)
    with pytest.raises(InputError, match="directory"):
        MaterialDataset.from_file(tmp_path, c=200e9)
    with pytest.raises(InputError, match="not found"):
        MaterialDataset.from_file(tmp_path / "missing.npy", c=200e9)
