"""Output of continuum results: Mandel helpers, ParaView series, figures, convergence rates."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

from ddcm_casadi.outputs.continuum import (
    figure_convergence,
    figure_deformed_body,
    figure_pressure_profile,
    fit_rate,
    mandel_to_tensor,
    von_mises,
    write_vtu_series,
)
from ddcm_casadi.errors import InputError
from ddcm_casadi.outputs.plots import save_figure

R2 = np.sqrt(2.0)


# --------------------------------------------------------------------------- Mandel
def test_mandel_to_tensor_2d_and_3d():
    t2 = mandel_to_tensor([[1.0, 2.0, R2 * 3.0]], 2)
    assert t2.shape == (1, 3, 3)
    np.testing.assert_allclose(t2[0], [[1, 3, 0], [3, 2, 0], [0, 0, 0]])
    t3 = mandel_to_tensor([[1.0, 2.0, 3.0, R2 * 4.0, R2 * 5.0, R2 * 6.0]], 3)
    np.testing.assert_allclose(t3[0], [[1, 6, 5], [6, 2, 4], [5, 4, 3]])


@pytest.mark.parametrize("dim", [2, 3])
def test_von_mises_textbook_values(dim):
    sigma, tau = 250e6, 80e6
    uniaxial = np.zeros((1, 3 if dim == 2 else 6))
    uniaxial[0, 0] = sigma
    shear = np.zeros_like(uniaxial)
    shear[0, -1] = R2 * tau  # the 12 component, Mandel-scaled
    np.testing.assert_allclose(von_mises(uniaxial, dim), [sigma], rtol=1e-14)
    np.testing.assert_allclose(von_mises(shear, dim), [np.sqrt(3.0) * tau], rtol=1e-14)
    hydro = np.zeros_like(uniaxial)
    hydro[0, :3] = -1e6  # 3-D: pure pressure has no deviator
    if dim == 3:
        np.testing.assert_allclose(von_mises(hydro, 3), [0.0], atol=1e-8)


def test_mandel_bad_input():
    with pytest.raises(InputError, match="shape"):
        mandel_to_tensor(np.zeros((2, 6)), 2)
    with pytest.raises(InputError, match="dim"):
        von_mises(np.zeros((2, 3)), 4)


# --------------------------------------------------------------------------- ParaView series
def _mesh_2d():
    points = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    cells = [("triangle", np.array([[0, 1, 2], [0, 2, 3]]))]
    steps = [{"time": 0.5 * k,
              "point_data": {"u": k * np.arange(8.0).reshape(4, 2), "T": np.full(4, float(k))},
              "cell_data": {"stress": k * np.arange(6.0).reshape(2, 3), "phase": np.array([0, k])}}
             for k in range(3)]
    return points, cells, steps


def _mesh_3d():
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    cells = [("tetra", np.array([[0, 1, 2, 3]]))]
    steps = [{"time": 1.0 + k,
              "point_data": {"u": k * np.arange(12.0).reshape(4, 3)},
              "cell_data": {"stress": k * np.arange(6.0).reshape(1, 6)}}
             for k in range(3)]
    return points, cells, steps


def _pad(a):
    a = np.asarray(a)
    return np.column_stack([a, np.zeros(len(a))]) if a.ndim == 2 and a.shape[1] == 2 else a


@pytest.mark.parametrize("mesh", [_mesh_2d, _mesh_3d])
def test_write_vtu_series_round_trip(tmp_path, mesh):
    points, cells, steps = mesh()
    paths = write_vtu_series(tmp_path / "out", points=points, cells=cells, steps=steps, name="run")
    names = [f"run_{k:04d}.vtu" for k in range(3)] + ["run.pvd"]
    assert [p.name for p in paths] == names
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(names)  # no temporaries
    for k, step in enumerate(steps):
        m = meshio.read(paths[k])
        np.testing.assert_allclose(m.points[:, : points.shape[1]], points)
        np.testing.assert_array_equal(m.points.shape, (4, 3))
        assert m.cells[0].type == cells[0][0]
        np.testing.assert_array_equal(m.cells[0].data, cells[0][1])
        assert set(m.point_data) == set(step["point_data"])
        for key, a in step["point_data"].items():
            np.testing.assert_allclose(m.point_data[key], _pad(a))
        assert set(m.cell_data) == set(step["cell_data"])
        for key, a in step["cell_data"].items():
            np.testing.assert_allclose(m.cell_data[key][0], a)
    root = ET.parse(paths[-1]).getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    ds = root.findall("./Collection/DataSet")
    assert [d.get("file") for d in ds] == names[:3]
    assert [float(d.get("timestep")) for d in ds] == [s["time"] for s in steps]
    assert all(d.get("part") == "0" for d in ds)


def test_write_vtu_series_two_blocks_and_tensors(tmp_path):
    points, _, _ = _mesh_2d()
    cells = [("triangle", np.array([[0, 1, 2]])), ("triangle", np.array([[0, 2, 3]]))]
    tensors = mandel_to_tensor(np.arange(6.0).reshape(2, 3), 2)
    paths = write_vtu_series(tmp_path, points=points, cells=cells,
                             steps=[{"time": 0.0, "cell_data": {"sigma": tensors}}])
    m = meshio.read(paths[0])
    np.testing.assert_allclose(np.vstack(m.cell_data["sigma"]), tensors.reshape(2, 9))


@pytest.mark.parametrize("where, key, bad, message", [
    ("point_data", "u", np.zeros((3, 2)), "step 1 point_data 'u'"),
    ("cell_data", "stress", np.zeros((5, 3)), "step 1 cell_data 'stress'"),
])
def test_write_vtu_series_mismatch_writes_nothing(tmp_path, where, key, bad, message):
    points, cells, steps = _mesh_2d()
    (tmp_path / "keep.txt").write_text("x")
    steps[1][where][key] = bad
    with pytest.raises(InputError, match=message) as err:
        write_vtu_series(tmp_path, points=points, cells=cells, steps=steps)
    assert "\n" not in str(err.value)
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]
    with pytest.raises(InputError):  # the output folder is not even created
        write_vtu_series(tmp_path / "new", points=points, cells=cells, steps=steps)
    assert not (tmp_path / "new").exists()


def test_write_vtu_series_bad_cells(tmp_path):
    points, _, steps = _mesh_2d()
    with pytest.raises(InputError, match="node 7"):
        write_vtu_series(tmp_path, points=points, cells=[("triangle", [[0, 1, 7]])], steps=steps)
    with pytest.raises(InputError, match="cell_type"):
        write_vtu_series(tmp_path, points=points, cells=[("prism", [[0, 1, 2]])], steps=steps)
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- figures
def _saved(fig, path):
    save_figure(fig, path)
    data = path.read_bytes()
    assert data.startswith(b"\x89PNG") and len(data) > 1000


def test_figure_pressure_profile(tmp_path):
    x = np.linspace(-1e-3, 1e-3, 21)
    p = 100e6 * np.sqrt(np.clip(1 - (x / 1e-3) ** 2, 0, None))
    shuffled = np.random.default_rng(0).permutation(x.size)
    runs = [{"label": "classical", "x": x, "pressure": p, "converged": True},
            {"label": "DDCM", "x": x[shuffled], "pressure": 0.9 * p[shuffled], "converged": False,
             "style": {"marker": "s", "ls": "", "mfc": "none"}}]
    fig = figure_pressure_profile(runs, hertz={"x": x, "pressure": p, "label": "Hertz"},
                                  title="profile")
    ax = fig.axes[0]
    labels = ax.get_legend_handles_labels()[1]
    assert "DDCM (NOT CONVERGED)" in labels and "classical" in labels and "Hertz" in labels
    assert ax.get_xlabel() == "x (mm)"
    drawn = next(line for line in ax.get_lines() if line.get_label() == "DDCM (NOT CONVERGED)")
    np.testing.assert_allclose(drawn.get_xdata(), x * 1e3)  # sorted, in mm
    np.testing.assert_allclose(drawn.get_ydata(), 0.9 * p * 1e-6)  # MPa
    _saved(fig, tmp_path / "profile.png")
    with pytest.raises(InputError, match="converged"):
        figure_pressure_profile([{"label": "a", "x": x, "pressure": p}])


def test_figure_deformed_body_2d(tmp_path):
    points, cells, _ = _mesh_2d()
    tri = cells[0][1]
    u = np.array([[0, 0], [1e-4, 0], [1e-4, -2e-4], [0, -2e-4]])
    fig = figure_deformed_body(points, tri, displacement=u, values=np.array([1e8, 2e8]),
                               value_label="von Mises stress", contact_points=np.array([2, 3]),
                               obstacles=[{"kind": "circle", "center": (0.5, 2.0), "radius": 1.0},
                                          {"kind": "plane", "point": (0, -0.1), "normal": (0, 1)}],
                               title="block")
    assert fig._suptitle.get_text() == "block\n(displacements x 220)"  # 0.05 / |u|max = 223.6
    _saved(fig, tmp_path / "body2d.png")
    fig = figure_deformed_body(points, tri, displacement=u, values=np.arange(4) * 1e7,
                               value_label="p", scale=10.0, contact_points=points[2:] + u[2:])
    assert "displacements x 10" in fig._suptitle.get_text()
    _saved(fig, tmp_path / "body2d_nodes.png")
    with pytest.raises(InputError, match="values"):
        figure_deformed_body(points, tri, displacement=u, values=np.zeros(3), value_label="p")


def test_figure_deformed_body_3d(tmp_path):
    # two tetrahedra sharing the face 0-1-2: 5 nodes, 6 boundary triangles
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 1], [0.3, 0.3, -1]])
    faces = np.array([[0, 1, 3], [1, 2, 3], [2, 0, 3], [0, 4, 1], [1, 4, 2], [2, 4, 0]])
    u = 1e-3 * points
    for k, values in enumerate((np.arange(6) * 1e6, np.arange(5) * 1e6)):  # per face, per node
        fig = figure_deformed_body(points, faces, displacement=u, values=values,
                                   value_label="von Mises stress", contact_points=np.array([4]),
                                   obstacles=[{"kind": "circle", "center": (0, 0), "radius": 1}])
        assert fig.axes[0].name == "3d"
        _saved(fig, tmp_path / f"body3d_{k}.png")


def test_figure_convergence_and_fit_rate(tmp_path):
    h = np.array([0.1, 0.05, 0.025, 0.0125])
    e1, e2 = 3 * h ** 1.5, 0.5 * h ** 2
    rates = {"L2": fit_rate(h, e1), "H1": fit_rate(h, e2)}
    assert abs(rates["L2"] - 1.5) < 1e-12 and abs(rates["H1"] - 2.0) < 1e-12
    fig = figure_convergence(h, [e1, e2], labels=["L2", "H1"], rates=rates, title="rates")
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert labels == ["L2 (rate 1.50)", "H1 (rate 2.00)"]
    _saved(fig, tmp_path / "convergence.png")
    # one abscissa per series, of different lengths
    fig = figure_convergence([h, h[:3]], [e1, e2[:3]], labels=["a", "b"], xlabel="N")
    _saved(fig, tmp_path / "convergence2.png")


def test_fit_rate_ignores_non_positive_and_needs_two_points():
    x = np.array([0.0, 1.0, 2.0, 4.0, -1.0])
    y = np.array([5.0, 3.0, 3 * 2 ** 1.5, 3 * 4 ** 1.5, 2.0])
    assert abs(fit_rate(x, y) - 1.5) < 1e-12
    with pytest.raises(InputError, match="2 points"):
        fit_rate([1.0, 2.0], [1.0, 0.0])
    with pytest.raises(InputError, match="2 points"):
        fit_rate([2.0, 2.0], [1.0, 3.0])
