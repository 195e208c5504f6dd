"""Meshes of the continua: generated shapes, grading, mesh files, checks and helpers."""

import json
import math
from pathlib import Path

import meshio
import numpy as np
import pytest
import skfem
from skfem.io.meshio import to_meshio

from ddcm_casadi.models.continuum import mesh as M
from ddcm_casadi.errors import InputError


def measures(mesh):
    """Area (2-D) or volume (3-D) of every element."""
    x = mesh.p[:, mesh.t]
    d = mesh.dim()
    return np.abs(np.linalg.det(np.moveaxis(x[:, 1:] - x[:, :1], -1, 0))) / math.factorial(d)


def facet_measure(mesh, facets):
    """Total length (2-D) or area (3-D) of the facets."""
    x = mesh.p[:, mesh.facets[:, facets]]
    e = x[:, 1:] - x[:, :1]
    if mesh.dim() == 2:
        return float(np.linalg.norm(e[:, 0], axis=0).sum())
    return float(np.linalg.norm(np.cross(e[:, 0], e[:, 1], axis=0), axis=0).sum() / 2)


def radial_error(mesh, curved):
    """Largest | |x - c| - r | / r over the nodes of the curved boundary."""
    nodes = np.unique(mesh.facets[:, mesh.boundaries[curved.boundary]])
    r = np.linalg.norm(mesh.p[:, nodes] - np.array(curved.center)[:, None], axis=0)
    return float(np.max(np.abs(r - curved.radius)) / curved.radius)


def one_line(excinfo):
    message = str(excinfo.value)
    assert message and "\n" not in message, message
    return message


def same_columns(a, b):
    """Element/facet arrays equal up to the order of the vertices in each column."""
    return np.array_equal(np.sort(a, axis=0), np.sort(b, axis=0))


# --- generated shapes ------------------------------------------------------------------------


def test_rectangle():
    m = M.rectangle(2.0, 0.5, nx=4, ny=3, origin=(1.0, -1.0))
    assert isinstance(m, skfem.MeshTri1) and m.dim() == 2
    assert m.nvertices == 5 * 4 and m.nelements == 2 * 4 * 3
    assert measures(m).sum() == pytest.approx(1.0, rel=1e-12)
    lengths = dict(xmin=0.5, xmax=0.5, ymin=2.0, ymax=2.0)
    for name, length in lengths.items():
        assert len(m.boundaries[name]) > 0
        assert facet_measure(m, m.boundaries[name]) == pytest.approx(length, rel=1e-12)
    x = m.p[:, m.facets[:, m.boundaries["xmax"]]]
    assert np.allclose(x[0], 3.0, rtol=0, atol=1e-15)
    M.check_mesh(m)


def test_box():
    m = M.box(1.0, 2.0, 0.5, nx=2, ny=3, nz=1, origin=(0.0, 0.0, -0.5))
    assert isinstance(m, skfem.MeshTet1) and m.dim() == 3
    assert m.nvertices == 3 * 4 * 2 and m.nelements == 6 * 2 * 3 * 1
    assert measures(m).sum() == pytest.approx(1.0, rel=1e-12)
    areas = dict(xmin=1.0, xmax=1.0, ymin=0.5, ymax=0.5, zmin=2.0, zmax=2.0)
    for name, area in areas.items():
        assert len(m.boundaries[name]) > 0
        assert facet_measure(m, m.boundaries[name]) == pytest.approx(area, rel=1e-12)
    M.check_mesh(m)


@pytest.mark.parametrize("refine", [0, 1, 2, 4])
def test_disc_is_the_inscribed_regular_polygon(refine):
    """The boundary is a regular n-gon inscribed in the circle, n = 4 * 2**refine.

    Its area is (n/2) r^2 sin(2 pi/n); relative to pi r^2 the error is 1 - sin(x)/x with
    x = 2 pi/n, an alternating series x^2/6 - x^4/120 + ... with decreasing terms, so
    0 < error < x^2/6 = (2 pi^2/3)/n^2.
    """
    r, c = 0.7, (1.5, -2.0)
    m = M.disc(r, center=c, refine=refine)
    n = 4 * 2**refine
    assert m.dim() == 2 and len(m.boundaries["arc"]) == n
    assert np.array_equal(np.sort(m.boundaries["arc"]), np.sort(m.boundary_facets()))
    area = measures(m).sum()
    assert area == pytest.approx(n / 2 * r**2 * math.sin(2 * math.pi / n), rel=1e-12)
    error = 1 - area / (math.pi * r**2)
    assert 0 < error < 2 * math.pi**2 / 3 / n**2
    (curved,) = m.curved
    assert curved == M.Curved("arc", c, r)
    assert radial_error(m, curved) < 1e-12
    M.check_mesh(m)


@pytest.mark.parametrize("refine", [1, 3])
def test_half_disc(refine):
    """The arc is a regular polygon of n = 2 * 2**refine sides over the angle pi.

    Area (n/2) r^2 sin(pi/n) against pi r^2/2: relative error 1 - sin(x)/x < x^2/6, x = pi/n.
    """
    r, c = 2.0, (0.0, 1.0)
    m = M.half_disc(r, center=c, refine=refine)
    n = 2 * 2**refine
    assert len(m.boundaries["arc"]) == n and len(m.boundaries["flat"]) > 0
    assert np.all(m.p[1] <= c[1])
    flat = m.p[:, m.facets[:, m.boundaries["flat"]]]
    assert np.all(flat[1] == c[1])
    assert facet_measure(m, m.boundaries["flat"]) == pytest.approx(2 * r, rel=1e-12)
    area = measures(m).sum()
    assert area == pytest.approx(n / 2 * r**2 * math.sin(math.pi / n), rel=1e-12)
    assert 0 < 1 - area / (math.pi * r**2 / 2) < (math.pi / n) ** 2 / 6
    assert radial_error(m, m.curved[0]) < 1e-12
    M.check_mesh(m)


def ball_volume_bound(m, radius):
    """A rigorous bound of the relative volume error of a polyhedron inscribed in a sphere.

    A surface triangle with its vertices on the sphere lies in a plane at distance
    d = sqrt(R^2 - rho^2) from the centre, rho its circumradius. The ball outside the polyhedron,
    within the cone from the centre over that triangle (solid angle W), lies between the radii
    d and R: its volume is at most W (R^3 - d^3)/3 <= W R^2 (R - d). The cones tile the sphere
    (sum W = 4 pi), so the error is at most 4 pi R^2 max(R - d), i.e. 3 max(R - d)/R relative.
    """
    x = m.p[:, m.facets[:, m.boundaries["surface"]]]
    a, b, c = (np.linalg.norm(x[:, i] - x[:, j], axis=0) for i, j in ((0, 1), (1, 2), (0, 2)))
    area = np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], axis=0), axis=0) / 2
    rho = a * b * c / (4 * area)
    return 3 * np.max(1 - np.sqrt(1 - (rho / radius) ** 2))


def test_ball_converges_to_the_sphere():
    r, c = 1.5, (0.0, 1.0, -1.0)
    errors = []
    for refine in (1, 2):
        m = M.ball(r, center=c, refine=refine)
        assert isinstance(m, skfem.MeshTet1)
        assert len(m.boundaries["surface"]) == 8 * 4**refine
        assert np.array_equal(np.sort(m.boundaries["surface"]), np.sort(m.boundary_facets()))
        assert radial_error(m, m.curved[0]) < 1e-12
        error = 1 - measures(m).sum() / (4 / 3 * math.pi * r**3)
        assert 0 < error <= ball_volume_bound(m, r)
        errors.append(error)
        M.check_mesh(m)
    assert 3 < errors[0] / errors[1] < 5  # second order in h


@pytest.mark.parametrize("call", [
    lambda: M.rectangle(-1.0, 1.0, nx=2, ny=2),
    lambda: M.rectangle(1.0, float("nan"), nx=2, ny=2),
    lambda: M.rectangle(1.0, 1.0, nx=0, ny=2),
    lambda: M.rectangle(1.0, 1.0, nx=2.5, ny=2),
    lambda: M.rectangle(1.0, 1.0, nx=True, ny=2),
    lambda: M.rectangle(1.0, 1.0, nx=2, ny=2, origin=(0.0, 0.0, 0.0)),
    lambda: M.box(1.0, 1.0, 0.0, nx=1, ny=1, nz=1),
    lambda: M.box(1.0, 1.0, 1.0, nx=1, ny=1, nz=-1),
    lambda: M.disc(0.0),
    lambda: M.disc(1.0, refine=-1),
    lambda: M.half_disc(1.0, center=(0.0, float("inf"))),
    lambda: M.ball(1.0, center=(0.0, 0.0)),
    lambda: M.ball("big"),
])
def test_shape_arguments_are_validated(call):
    with pytest.raises(InputError) as excinfo:
        call()
    one_line(excinfo)


# --- grading ---------------------------------------------------------------------------------


GRADED = {
    "rectangle": (lambda: M.rectangle(2.0, 1.0, nx=8, ny=4), (1.0, 0.0)),
    "half_disc": (lambda: M.half_disc(1.0, refine=3), (0.0, -1.0)),
    "disc": (lambda: M.disc(1.0, center=(0.5, 0.5), refine=2), (0.5, -0.5)),
    "box": (lambda: M.box(1.0, 1.0, 1.0, nx=2, ny=2, nz=2), (0.5, 0.5, 1.0)),
    "ball": (lambda: M.ball(1.0, refine=1), (0.0, 0.0, -1.0)),
}


@pytest.mark.parametrize("name", GRADED)
def test_refine_near_grades_towards_the_point(name):
    build, point = GRADED[name]
    coarse = build()
    p0 = coarse.p.copy()
    curved = {c.boundary for c in getattr(coarse, "curved", ())}
    meshes = [coarse]
    for level in range(2):
        meshes.append(M.refine_near(meshes[-1], point, 0.3 / 2**level))
    assert np.array_equal(coarse.p, p0)  # the input is left alone
    graded = M.refine_near(coarse, point, 0.3, levels=2)
    assert np.array_equal(graded.p, meshes[-1].p) and np.array_equal(graded.t, meshes[-1].t)

    h = [M.mesh_size(m)[0] for m in meshes]
    for coarser, finer in zip(h, h[1:]):
        if curved and coarse.dim() == 3:  # bisection of a projected sphere mesh: roughly 2
            assert 1.5 < coarser / finer < 3.5
        else:
            assert coarser / finer == pytest.approx(2.0, rel=1e-9)
    far = np.argmax(np.linalg.norm(coarse.p - np.array(point)[:, None], axis=0))
    untouched = {tuple(c) for c in np.sort(graded.t, axis=0).T}
    assert all(tuple(c) in untouched for c in np.sort(coarse.t[:, np.any(coarse.t == far, axis=0)], axis=0).T)

    M.check_mesh(graded)
    assert graded.curved == getattr(coarse, "curved", ())
    assert set(graded.boundaries) == set(coarse.boundaries)
    named = np.unique(np.concatenate(list(graded.boundaries.values())))
    assert np.array_equal(named, np.sort(graded.boundary_facets()))
    for b in graded.boundaries:
        assert len(graded.boundaries[b]) >= len(coarse.boundaries[b])
        if b in curved:
            assert radial_error(graded, graded.curved[0]) < 1e-12
        else:
            assert facet_measure(graded, graded.boundaries[b]) == pytest.approx(
                facet_measure(coarse, coarse.boundaries[b]), rel=1e-12)
    if curved:  # the new arc nodes moved out onto the circle: closer to the exact measure
        assert measures(graded).sum() > measures(coarse).sum()
    else:
        assert measures(graded).sum() == pytest.approx(measures(coarse).sum(), rel=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_refine_near_keeps_subdomains_and_interfaces(dim):
    if dim == 2:
        m, point = M.rectangle(2.0, 1.0, nx=4, ny=2), (1.0, 0.5)
    else:
        m, point = M.box(2.0, 1.0, 1.0, nx=2, ny=1, nz=1), (1.0, 0.5, 0.5)
    m = m.with_subdomains({"left": lambda x: x[0] < 1.0, "right": lambda x: x[0] > 1.0})
    m = m.with_boundaries({"interface": lambda x: np.abs(x[0] - 1.0) < 1e-12}, boundaries_only=False)
    fine = M.refine_near(m, point, 0.75, levels=2)
    assert fine.nelements > 4 * m.nelements
    v = measures(fine)
    assert v[fine.subdomains["left"]].sum() == pytest.approx(1.0, rel=1e-12)
    assert v[fine.subdomains["right"]].sum() == pytest.approx(1.0, rel=1e-12)
    assert np.array_equal(np.sort(np.concatenate(list(fine.subdomains.values()))), np.arange(fine.nelements))
    centroids = fine.p[:, fine.t].mean(axis=1)
    assert np.all(centroids[0, fine.subdomains["left"]] < 1.0)
    interface = fine.boundaries["interface"]
    assert facet_measure(fine, interface) == pytest.approx(1.0, rel=1e-12)
    assert np.allclose(fine.p[0, fine.facets[:, interface]], 1.0, rtol=0, atol=1e-12)
    M.check_mesh(fine)


def test_refine_near_shape_argument():
    moved = M.disc(1.0, refine=2).translated((2.0, 0.0))  # skfem's copy forgets `curved`
    assert not hasattr(moved, "curved")
    kept = M.refine_near(moved, (2.0, -1.0), 0.3, shape=M.Curved("arc", (2.0, 0.0), 1.0))
    assert radial_error(kept, kept.curved[0]) < 1e-12
    chords = M.refine_near(moved, (2.0, -1.0), 0.3)  # nothing to project: new nodes on chords
    assert chords.curved == ()
    assert radial_error(chords, M.Curved("arc", (2.0, 0.0), 1.0)) > 1e-4
    assert M.refine_near(moved, (2.0, -1.0), 0.3, levels=0) is moved

    m = M.disc(1.0, refine=2)
    for bad in (dict(shape=M.Curved("rim", (0.0, 0.0), 1.0)), dict(shape=["arc"]),
                dict(shape=M.Curved("arc", (0.0, 0.0, 0.0), 1.0)), dict(levels=-1)):
        with pytest.raises(InputError) as excinfo:
            M.refine_near(m, (0.0, -1.0), 0.3, **bad)
        one_line(excinfo)
    for point, radius in (((5.0, 5.0), 0.1), ((0.0,), 0.1), ((0.0, -1.0), 0.0)):
        with pytest.raises(InputError) as excinfo:
            M.refine_near(m, point, radius)
        one_line(excinfo)
    with pytest.raises(InputError, match="center"):
        M.Curved("rim", (0.0, float("nan")), 1.0)


# --- mesh files ------------------------------------------------------------------------------


def xyz(p):
    """Points as meshio wants them, (n, 3)."""
    return np.column_stack((p.T, np.zeros(p.shape[1]))) if p.shape[0] == 2 else p.T


def assert_same_mesh(read, mesh, *, groups=True):
    assert type(read) is type(mesh)
    assert np.array_equal(read.p, mesh.p)
    assert same_columns(read.t, mesh.t)
    if groups:
        for name, facets in (mesh.boundaries or {}).items():
            assert same_columns(read.facets[:, read.boundaries[name]], mesh.facets[:, facets]), name
        for name, elements in (mesh.subdomains or {}).items():
            assert np.array_equal(np.sort(read.subdomains[name]), np.sort(elements)), name


def with_left(mesh):
    return mesh.with_subdomains({"left": lambda x: x[0] < 0.5})


@pytest.mark.parametrize("mesh", [with_left(M.rectangle(1.0, 1.0, nx=3, ny=2)),
                                  with_left(M.box(1.0, 1.0, 1.0, nx=2, ny=1, nz=1))],
                         ids=["2d", "3d"])
def test_vtu_round_trip(tmp_path, mesh):
    """scikit-fem's cell-data encoding of the named sets survives a VTU file."""
    path = tmp_path / "m.vtu"
    meshio.write(path, to_meshio(mesh))
    assert_same_mesh(M.read_mesh(path), mesh)


def gmsh_mesh(mesh):
    """A meshio mesh with Gmsh physical groups: the body tag 1 collides with a boundary's tag."""
    cells, physical = [], []
    for tag, name in enumerate(("ymin", "ymax"), start=1):
        cells.append(("line", mesh.facets[:, mesh.boundaries[name]].T))
        physical.append(np.full(len(mesh.boundaries[name]), tag))
    cells.append(("line", mesh.facets[:, mesh.boundaries["xmin"]].T))  # an unnamed group
    physical.append(np.full(len(mesh.boundaries["xmin"]), 7))
    cells.append(("triangle", mesh.t.T))
    physical.append(np.ones(mesh.nelements, dtype=int))
    return meshio.Mesh(xyz(mesh.p), cells,
                       cell_data={"gmsh:physical": physical, "gmsh:geometrical": physical},
                       field_data={"ymin": np.array([1, 1]), "ymax": np.array([2, 1]),
                                   "body": np.array([1, 2])})


@pytest.mark.parametrize("binary", [False, True])
def test_gmsh22_round_trip_with_physical_groups(tmp_path, binary):
    mesh = M.rectangle(2.0, 1.0, nx=4, ny=2)
    path = tmp_path / "m.msh"
    meshio.write(path, gmsh_mesh(mesh), file_format="gmsh22", binary=binary)
    read = M.read_mesh(path)
    assert_same_mesh(read, mesh, groups=False)
    assert set(read.boundaries) == {"ymin", "ymax", "7"}
    for name, ours in (("ymin", "ymin"), ("ymax", "ymax"), ("7", "xmin")):
        assert same_columns(read.facets[:, read.boundaries[name]], mesh.facets[:, mesh.boundaries[ours]])
    assert set(read.subdomains) == {"body"}
    assert np.array_equal(np.sort(read.subdomains["body"]), np.arange(mesh.nelements))


#: A unit square written by Gmsh 4.15 (ASCII MSH 4.1): physical curves "bottom" (tag 1) and
#: "top" (tag 2), physical surface "body" (tag 1, the same number as "bottom").
GMSH41 = """$MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
3
1 1 "bottom"
1 2 "top"
2 1 "body"
$EndPhysicalNames
$Entities
4 4 1 0
1 0 0 0 0
2 1 0 0 0
3 1 1 0 0
4 0 1 0 0
1 0 0 0 1 0 0 1 1 2 1 -2
2 1 0 0 1 1 0 0 2 2 -3
3 0 1 0 1 1 0 1 2 2 3 -4
4 0 0 0 0 1 0 0 2 4 -1
1 0 0 0 1 1 0 1 1 4 1 2 3 4
$EndEntities
$Nodes
9 12 1 12
0 1 0 1
1
0 0 0
0 2 0 1
2
1 0 0
0 3 0 1
3
1 1 0
0 4 0 1
4
0 1 0
1 1 0 1
5
0.4999999999986919 0 0
1 2 0 1
6
1 0.4999999999986919 0
1 3 0 1
7
0.5000000000020616 1 0
1 4 0 1
8
0 0.5000000000020616 0
2 1 0 4
9
10
11
12
0.2937500000004593 0.7062500000004168 0
0.3749999999995788 0.3750000000004212 0
0.6479166666669075 0.64374999999984 0
0.7187499999993453 0.2812499999995102 0
$EndNodes
$Elements
3 18 1 18
1 1 1 2
1 1 5
2 5 2
1 3 1 2
3 3 7
4 7 4
2 1 2 14
5 6 3 11
6 8 1 10
7 1 5 10
8 3 7 11
9 5 2 12
10 2 6 12
11 7 4 9
12 4 8 9
13 6 11 12
14 9 8 10
15 9 10 11
16 10 5 12
17 11 10 12
18 7 9 11
$EndElements
"""


def test_gmsh41_physical_names(tmp_path):
    path = tmp_path / "square.msh"
    path.write_text(GMSH41)
    m = M.read_mesh(path)
    assert isinstance(m, skfem.MeshTri1) and m.nvertices == 12 and m.nelements == 14
    assert set(m.boundaries) == {"bottom", "top"}
    for name, y in (("bottom", 0.0), ("top", 1.0)):
        assert len(m.boundaries[name]) == 2
        assert np.all(m.p[1, m.facets[:, m.boundaries[name]]] == y)
    assert set(m.subdomains) == {"body"} and len(m.subdomains["body"]) == 14
    assert measures(m).sum() == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_quadratic_cells_give_their_corners(tmp_path, dim):
    linear = M.rectangle(1.0, 1.0, nx=2, ny=2) if dim == 2 else M.box(1.0, 1.0, 1.0, nx=1, ny=1, nz=1)
    quadratic = (skfem.MeshTri2 if dim == 2 else skfem.MeshTet2).from_mesh(linear)
    assert quadratic.doflocs.shape[1] > linear.nvertices
    path = tmp_path / "q.vtu"
    meshio.write(path, to_meshio(quadratic))
    assert_same_mesh(M.read_mesh(path), linear, groups=False)


def write_xdmf(path, mesh, cell_data=None):
    """An XDMF 3 file with inline XML data, written by hand (meshio's writer needs h5py)."""
    def item(a, kind):
        text = " ".join(map(repr, np.ravel(a).tolist()))  # Python floats: repr is exact
        dims = " ".join(map(str, np.shape(a)))
        return f'<DataItem Dimensions="{dims}" NumberType="{kind}" Precision="8" Format="XML">{text}</DataItem>'

    topology = "Triangle" if mesh.dim() == 2 else "Tetrahedron"
    attributes = "".join(f'<Attribute Name="{k}" Center="Cell">{item(np.asarray(v, float), "Float")}'
                         "</Attribute>" for k, v in (cell_data or {}).items())
    path.write_text(
        '<?xml version="1.0"?><Xdmf Version="3.0"><Domain><Grid Name="m">'
        f'<Topology TopologyType="{topology}" NumberOfElements="{mesh.nelements}">'
        f'{item(mesh.t.T.astype(np.int64), "Int")}</Topology>'
        f'<Geometry GeometryType="{"XY" if mesh.dim() == 2 else "XYZ"}">{item(mesh.p.T, "Float")}</Geometry>'
        f"{attributes}</Grid></Domain></Xdmf>")


def test_xdmf(tmp_path):
    """Read with h5py; without it (meshio's XDMF reader imports it always) a one-line error."""
    mesh = with_left(M.rectangle(1.0, 1.0, nx=3, ny=2))
    path = tmp_path / "m.xdmf"
    write_xdmf(path, mesh, {k: v[0] for k, v in to_meshio(mesh).cell_data.items()})
    try:
        import h5py  # noqa: F401
    except ImportError:
        with pytest.raises(InputError, match="h5py") as excinfo:
            M.read_mesh(path)
        one_line(excinfo)
    else:
        assert_same_mesh(M.read_mesh(path), mesh)


def test_xdmf_written_by_meshio(tmp_path):
    pytest.importorskip("h5py")
    mesh = with_left(M.box(1.0, 1.0, 1.0, nx=2, ny=1, nz=1))
    for data_format in ("XML", "HDF"):
        path = tmp_path / f"m_{data_format}.xdmf"
        meshio.write(path, to_meshio(mesh), data_format=data_format)
        assert_same_mesh(M.read_mesh(path), mesh)


def square_with_a_flipped_triangle():
    """A 2 x 2 square grid whose corner node, in one triangle only, crosses the opposite edge."""
    m = M.rectangle(1.0, 1.0, nx=2, ny=2)
    p, t = m.p.copy(), m.t.copy()
    corner = np.nonzero(np.bincount(t.ravel()) == 1)[0][0]
    element = np.nonzero(np.any(t == corner, axis=0))[0][0]
    a, b = [v for v in t[:, element] if v != corner]
    mid = (p[:, a] + p[:, b]) / 2
    edge = (p[:, b] - p[:, a]) / np.linalg.norm(p[:, b] - p[:, a])
    offset = p[:, corner] - mid
    mirrored = offset - 2 * (offset - edge * (offset @ edge))
    p[:, corner] = mid + 0.5 * mirrored
    return p, t


BAD_MESHES = {
    "unused node": (np.array([[0, 0], [1, 0], [0, 1], [5, 5]], float).T, np.array([[0, 1, 2]]).T,
                    "1 unused nodes.*first: node 3"),
    "collinear triangle": (np.array([[0, 0], [1, 0], [2, 0], [1, 1]], float).T,
                           np.array([[0, 1, 3], [1, 2, 3], [0, 1, 2]]).T,
                           "1 degenerate elements.*first: element 2"),
    "flipped triangle": (*square_with_a_flipped_triangle(), "folded"),
    "non-finite": (np.array([[0, 0], [1, 0], [0, np.nan]]).T, np.array([[0, 1, 2]]).T, "non-finite"),
}


@pytest.mark.parametrize("name", BAD_MESHES)
def test_check_mesh_rejects(name):
    p, t, message = BAD_MESHES[name]
    with pytest.raises(InputError, match=message) as excinfo:
        M.check_mesh(skfem.MeshTri1(p, t))
    one_line(excinfo)


def test_check_mesh_accepts_any_consistent_orientation():
    box = M.box(1.0, 1.0, 1.0, nx=2, ny=2, nz=2)
    M.check_mesh(box)
    M.check_mesh(skfem.MeshTet1(box.p, box.t[[1, 0, 2, 3]]))  # every tetrahedron negative
    M.check_mesh(M.disc(1.0))  # MeshTri1 sorts its connectivity: mixed orders
    with pytest.raises(InputError):
        M.check_mesh("not a mesh")


def bad_file(tmp_path, name):
    """Write the named kind of bad mesh file and return its path."""
    cells = {
        "lines only": ("vtu", [("line", np.array([[0, 1], [1, 2]]))]),
        "quads only": ("vtu", [("quad", np.array([[0, 1, 2, 3]]))]),
        "triangles and quads": ("vtu", [("triangle", np.array([[0, 1, 2]])), ("quad", np.array([[0, 1, 2, 3]]))]),
    }
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    if name in cells:
        suffix, c = cells[name]
        path = tmp_path / f"m.{suffix}"
        meshio.write(path, meshio.Mesh(p, c))
    elif name in BAD_MESHES or name == "off the plane":
        q, t, _ = BAD_MESHES.get(name, BAD_MESHES["unused node"])
        points = xyz(q)
        if name == "off the plane":
            points[:, 2] = [0.0, 0.0, 1.0, 0.0]
        path = tmp_path / "m.vtu"
        meshio.write(path, meshio.Mesh(points, [("triangle", t.T)]))
    elif name == "missing":
        path = tmp_path / "nothing.msh"
    elif name == "unknown suffix":
        path = tmp_path / "m.stl"
        path.write_text("solid x\nendsolid x\n")
    else:  # garbage .msh, .vtu, .xdmf
        path = tmp_path / f"garbage{name.split()[-1]}"
        path.write_bytes(b"\x89 not a mesh \x00\xff" * 10)
    return path


@pytest.mark.parametrize("name, message", [
    ("missing", "not found"),
    ("unknown suffix", "unknown mesh file suffix '.stl'"),
    ("garbage .msh", "cannot read Gmsh file"),
    ("garbage .vtu", "cannot read VTU file"),
    ("garbage .xdmf", "cannot read XDMF file"),
    ("lines only", "no triangle or tetra cells.*line"),
    ("quads only", "no triangle or tetra cells.*quad"),
    ("triangles and quads", "mixed cells"),
    ("unused node", "unused node"),
    ("collinear triangle", "degenerate"),
    ("flipped triangle", "folded"),
    ("non-finite", "non-finite"),
    ("off the plane", "z = 0"),
])
def test_read_mesh_rejects(tmp_path, name, message):
    path = bad_file(tmp_path, name)
    with pytest.raises(InputError, match=message) as excinfo:
        M.read_mesh(path)
    one_line(excinfo)


# --- helpers ---------------------------------------------------------------------------------


def test_mesh_size_and_describe():
    m = M.rectangle(2.0, 1.0, nx=4, ny=2).with_subdomains({"left": lambda x: x[0] < 1.0})
    assert M.mesh_size(m) == pytest.approx((0.5, math.sqrt(0.5)))
    d = M.describe(m)
    assert json.loads(json.dumps(d)) == d
    assert d == {"dimension": 2, "nodes": 15, "elements": 16,
                 "boundaries": {"xmin": 2, "xmax": 2, "ymin": 4, "ymax": 4},
                 "subdomains": {"left": 8}, "h_min": 0.5, "h_max": pytest.approx(math.sqrt(0.5))}
    assert M.describe(M.ball(1.0, refine=1))["boundaries"] == {"surface": 32}


def test_select_facets():
    m = M.rectangle(2.0, 1.0, nx=4, ny=2)
    assert np.array_equal(M.select_facets(m, "ymin"), m.boundaries["ymin"])
    low = M.select_facets(m, lambda x: x[1] < 0.25)
    assert set(low) == set(m.boundaries["ymin"])  # interior facets are never selected
    assert set(M.select_facets(m, lambda x: x[0] < 0.5)) == set(m.boundaries["xmin"]) | {
        f for f in m.boundaries["ymin"] if m.p[0, m.facets[:, f]].mean() < 0.5} | {
        f for f in m.boundaries["ymax"] if m.p[0, m.facets[:, f]].mean() < 0.5}
    with pytest.raises(InputError, match="known: xmax, xmin, ymax, ymin") as excinfo:
        M.select_facets(m, "top")
    one_line(excinfo)
    for bad in (lambda x: x[0], lambda x: np.ones(3, bool), 3):
        with pytest.raises(InputError) as excinfo:
            M.select_facets(m, bad)
        one_line(excinfo)


def test_module_has_no_plotting_or_asserts():
    source = Path(M.__file__).read_text()
    assert "matplotlib" not in source
    assert not any(line.strip().startswith("assert ") for line in source.splitlines())
