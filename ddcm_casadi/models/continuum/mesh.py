"""Simplex meshes of the continua: generated shapes, mesh files, checks and grading.

Meshes are plain scikit-fem meshes, :class:`skfem.MeshTri1` (2-D, plane strain) or
:class:`skfem.MeshTet1` (3-D), with named facet sets in ``mesh.boundaries`` (name -> facet
indices) and, where known, named element sets in ``mesh.subdomains`` (name -> element indices).

- generated shapes: :func:`rectangle`, :func:`box`, :func:`disc`, :func:`half_disc`, :func:`ball`;
- :func:`refine_near` grades a mesh towards a (contact) point and keeps the named sets and the
  curved boundaries (:class:`Curved`);
- :func:`read_mesh` reads Gmsh ``.msh`` (2.2 and 4.1), ``.vtu`` and ``.xdmf`` files with meshio;
- :func:`check_mesh` rejects meshes a model cannot use (the model builders call it too);
- :func:`mesh_size`, :func:`describe` and :func:`select_facets` are small helpers.
"""

from __future__ import annotations

import itertools
import logging
import math
import xml.etree.ElementTree as ET
import zlib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence, Union

import meshio
import numpy as np
from scipy.spatial import cKDTree
from skfem import MeshTet1, MeshTri1

from ddcm_casadi.data.dataset import check_positive
from ddcm_casadi.errors import InputError
from ddcm_casadi.inputs import input_file

Mesh = Union[MeshTri1, MeshTet1]

#: File suffix -> (format, meshio reader). The readers are called directly: ``meshio.read``
#: ends the process (``sys.exit(1)``) when a file does not parse.
READERS = {".msh": ("Gmsh", meshio.gmsh.read), ".vtu": ("VTU", meshio.vtu.read),
           ".xdmf": ("XDMF", meshio.xdmf.read)}

#: Elements are degenerate when their area (volume) is at most this times ``h^2`` (``h^3``).
DEGENERATE = 1e-12


@dataclass(frozen=True)
class Curved:
    """A named boundary whose nodes lie on a circle (2-D) or a sphere (3-D).

    :func:`disc`, :func:`half_disc` and :func:`ball` remember theirs in the attribute
    ``mesh.curved`` (a tuple of these), and :func:`refine_near` keeps it up to date. scikit-fem's
    own transformations (``translated``, ``scaled``, ...) return meshes without the attribute:
    pass ``shape=`` to :func:`refine_near` then.

    Parameters
    ----------
    boundary : str
        The name of the boundary in ``mesh.boundaries``.
    center : sequence of float
        The centre of the circle or sphere.
    radius : float
        Its radius (> 0).
    """

    boundary: str
    center: tuple[float, ...]
    radius: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", tuple(float(c) for c in _point("center", self.center)))
        object.__setattr__(self, "radius", check_positive("radius", self.radius))


# --- generated shapes ------------------------------------------------------------------------


def rectangle(width: float, height: float, *, nx: int, ny: int,
              origin: Sequence[float] = (0.0, 0.0)) -> MeshTri1:
    """A ``width x height`` rectangle: ``nx x ny`` cells of two triangles each.

    Returns
    -------
    MeshTri1
        With boundaries ``xmin``, ``xmax``, ``ymin``, ``ymax``.
    """
    size = np.array([check_positive("width", width), check_positive("height", height)])
    counts = [_count("nx", nx), _count("ny", ny)]
    lo = _point("origin", origin, 2)
    mesh = MeshTri1.init_tensor(*(np.linspace(a, a + s, n + 1) for a, s, n in zip(lo, size, counts)))
    return mesh.with_boundaries(_sides(lo, lo + size, 1e-9 * np.min(size / counts)))


def box(lx: float, ly: float, lz: float, *, nx: int, ny: int, nz: int,
        origin: Sequence[float] = (0.0, 0.0, 0.0)) -> MeshTet1:
    """An ``lx x ly x lz`` box: ``nx x ny x nz`` cells of six tetrahedra each.

    Returns
    -------
    MeshTet1
        With boundaries ``xmin``, ``xmax``, ``ymin``, ``ymax``, ``zmin``, ``zmax``.
    """
    size = np.array([check_positive(n, v) for n, v in (("lx", lx), ("ly", ly), ("lz", lz))])
    counts = [_count("nx", nx), _count("ny", ny), _count("nz", nz)]
    lo = _point("origin", origin, 3)
    mesh = MeshTet1.init_tensor(*(np.linspace(a, a + s, n + 1) for a, s, n in zip(lo, size, counts)))
    return mesh.with_boundaries(_sides(lo, lo + size, 1e-9 * np.min(size / counts)))


def disc(radius: float, *, center: Sequence[float] = (0.0, 0.0), refine: int = 3) -> MeshTri1:
    """A disc: four triangles refined ``refine`` times, the boundary nodes projected each time.

    The boundary is a regular polygon of ``4 * 2**refine`` sides inscribed in the circle.

    Returns
    -------
    MeshTri1
        With boundary ``arc`` (the whole circle) and ``mesh.curved`` (:class:`Curved`).
    """
    r, c = check_positive("radius", radius), _point("center", center, 2)
    unit = np.array([[0.0, 1.0, 0.0, -1.0, 0.0], [0.0, 0.0, 1.0, 0.0, -1.0]])
    t = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]]).T
    return _round(MeshTri1(c[:, None] + r * unit, t), {"arc": _everywhere},
                  Curved("arc", c, r), _count("refine", refine, 0))


def half_disc(radius: float, *, center: Sequence[float] = (0.0, 0.0),
              refine: int = 3) -> MeshTri1:
    """The lower half ``y <= center_y`` of a disc, flat side on top (a cylinder's contact zone).

    The arc is a regular polygon of ``2 * 2**refine`` sides inscribed in the circle.

    Returns
    -------
    MeshTri1
        With boundaries ``arc`` and ``flat`` and ``mesh.curved`` (:class:`Curved`).
    """
    r, c = check_positive("radius", radius), _point("center", center, 2)
    unit = np.array([[0.0, 1.0, 0.0, -1.0], [0.0, 0.0, -1.0, 0.0]])
    t = np.array([[0, 1, 2], [0, 2, 3]]).T
    # midpoints of flat facets are exactly at center_y; arc facets are well below it
    tests = {"flat": lambda x: np.abs(x[1] - c[1]) <= 1e-9 * r,
             "arc": lambda x: np.abs(x[1] - c[1]) > 1e-9 * r}
    return _round(MeshTri1(c[:, None] + r * unit, t), tests, Curved("arc", c, r),
                  _count("refine", refine, 0))


def ball(radius: float, *, center: Sequence[float] = (0.0, 0.0, 0.0), refine: int = 2) -> MeshTet1:
    """A ball: an octahedron of eight tetrahedra refined ``refine`` times, projected each time.

    Returns
    -------
    MeshTet1
        With boundary ``surface`` (``8 * 4**refine`` triangles) and ``mesh.curved``.
    """
    r, c = check_positive("radius", radius), _point("center", center, 3)
    unit = np.hstack((np.zeros((3, 1)), np.eye(3), -np.eye(3)))
    t = np.array([[0, 1, 2, 3], [0, 4, 5, 6], [0, 1, 2, 6], [0, 1, 3, 5],
                  [0, 2, 3, 4], [0, 4, 5, 3], [0, 4, 6, 2], [0, 5, 6, 1]]).T
    return _round(MeshTet1(c[:, None] + r * unit, t), {"surface": _everywhere},
                  Curved("surface", c, r), _count("refine", refine, 0))


# --- grading ---------------------------------------------------------------------------------


def refine_near(mesh: Mesh, point: Sequence[float], radius: float, *, levels: int = 1,
                shrink: float = 0.5, buffer: float = 0.0,
                shape: Curved | Sequence[Curved] | None = None) -> Mesh:
    """Grade ``mesh`` towards ``point``: ``levels`` rounds of local refinement.

    Each round refines the elements with a vertex within ``radius`` of ``point`` (and those at
    the node nearest to it, so that the grading goes on once the radius is below the node
    spacing), then multiplies the radius by ``shrink`` (a half by default). With ``shrink = 1``
    and a ``buffer`` of a few elements the whole disc of ``radius`` ends up uniformly fine (a
    contact zone) with a graded transition: a round marks the vertices within ``radius + buffer
    h``, ``h`` the smallest edge at the start of the round. In 2-D a round is one red-green refinement, which halves
    the edges of the marked triangles; in 3-D it is three longest-edge bisections, the number
    that halves a tetrahedron's edges.

    The named sets survive: a facet (element) of the refined mesh belongs to a boundary
    (subdomain) when it lies in a facet (element) of it in the coarse mesh. Nodes of a curved
    boundary are projected radially onto its circle or sphere after every refinement.

    Parameters
    ----------
    mesh : MeshTri1 or MeshTet1
        The mesh to refine.
    point : sequence of float
        The point to grade towards (e.g. the first point of contact).
    radius : float
        The radius of the first round (> 0); at least one node must lie within it.
    levels : int
        The number of rounds (>= 0).
    shrink : float
        The radius factor per round, in (0, 1].
    buffer : float
        Element sizes added to the radius in every round (>= 0).
    shape : Curved, sequence of Curved or None
        The curved boundaries to keep on their circle or sphere; ``None`` takes the mesh's
        ``curved`` attribute (set by :func:`disc`, :func:`half_disc`, :func:`ball`), ``()``
        projects nothing.

    Returns
    -------
    MeshTri1 or MeshTet1
        A new mesh, with ``curved`` set to the curved boundaries.
    """
    _check_type(mesh)
    x0 = _point("point", point, mesh.dim())
    r = check_positive("radius", radius)
    levels = _count("levels", levels, 0)
    if not (isinstance(shrink, (int, float)) and 0 < shrink <= 1):
        raise InputError(f"shrink must be in (0, 1], got {_show(shrink)}")
    if not (isinstance(buffer, (int, float)) and 0 <= buffer < math.inf):
        raise InputError(f"buffer must be a finite number >= 0, got {_show(buffer)}")
    curved = _curved(mesh, shape)
    for level in range(levels):
        reach = r + (buffer * mesh_size(mesh)[0] if buffer else 0.0)
        for _ in range(1 if mesh.dim() == 2 else 3):
            dist = np.linalg.norm(mesh.p - x0[:, None], axis=0)
            near = dist <= reach
            if level == 0 and not near.any():
                raise InputError(f"no mesh node lies within radius={radius!r} of point={_show(point)}")
            near[np.argmin(dist)] = True
            marked = np.nonzero(near[mesh.t].any(axis=0))[0]
            fine = _refined(mesh, marked)
            _inherit(mesh, fine)
            _project(fine, curved)
            mesh = fine
        r *= shrink
    if levels:
        mesh.curved = curved
    return mesh


# --- mesh files ------------------------------------------------------------------------------


def read_mesh(path: str | Path) -> Mesh:
    """Read a triangle or tetrahedron mesh from a Gmsh ``.msh``, ``.vtu`` or ``.xdmf`` file.

    The highest-dimensional simplices are the elements (tetrahedra, else triangles); quadratic
    ones (``triangle6``, ``tetra10``) contribute their corners, and their mid-edge nodes are
    dropped. A 2-D mesh may be stored with ``z = 0``. Named sets come from, in this order of
    preference, meshio's cell sets (Gmsh 4 physical names), Gmsh physical tags (``gmsh:physical``
    with ``$PhysicalNames``, names looked up by tag *and* dimension; an unnamed tag is named by
    its number), and scikit-fem's own ``skfem:b:``/``skfem:s:`` cell data (what
    ``skfem.io.meshio.to_file`` writes). Facet-dimensional groups become ``mesh.boundaries``,
    element groups ``mesh.subdomains``. The mesh is checked with :func:`check_mesh`.

    Raises
    ------
    InputError
        For a missing file, an unknown suffix, a file meshio cannot read, no triangle or tetra
        cells, mixed element kinds, or a mesh :func:`check_mesh` rejects.
    """
    path = Path(path)
    kind, reader = READERS.get(path.suffix.lower(), (None, None))
    if reader is None:
        raise InputError(f"unknown mesh file suffix {path.suffix!r} of {path}; use .msh, .vtu or .xdmf")
    path = input_file(path, "mesh file")
    try:
        raw = reader(str(path))
    except ImportError as err:  # meshio's XDMF reader needs h5py, even for inline XML data
        raise InputError(f"cannot read {path}: meshio needs the Python module {err.name!r} "
                         f"for {path.suffix} files") from None
    except (meshio.ReadError, OSError, ValueError, KeyError, IndexError, TypeError,
            AttributeError, EOFError, ET.ParseError, zlib.error) as err:
        # meshio's readers fail in many ways on a bad file: one line is enough to say which file
        detail = " ".join(str(err).split())[:160]
        raise InputError(f"cannot read {kind} file {path}: {type(err).__name__}"
                         + (f": {detail}" if detail else "")) from None
    mesh = _from_meshio(raw, str(path))
    try:
        check_mesh(mesh)
    except InputError as err:
        raise InputError(f"{path}: {err}") from None
    return mesh


def _from_meshio(raw: meshio.Mesh, source: str) -> Mesh:
    """The linear simplex mesh in ``raw``, with its named groups."""
    kinds = {block.type for block in raw.cells}
    solids = {k for k in kinds if k.startswith(("tetra", "hexahedron", "wedge", "pyramid"))}
    plates = {k for k in kinds if k.startswith(("triangle", "quad", "polygon"))}
    body = solids or plates
    if not body & {"tetra", "tetra10", "triangle", "triangle6"}:
        raise InputError(f"no triangle or tetra cells in {source} (found: {', '.join(sorted(kinds)) or 'none'})")
    if len(body) > 1:
        raise InputError(f"mixed cells in {source}: {', '.join(sorted(body))}; "
                         "only meshes of triangles or of tetrahedra are supported")
    (body,) = body
    dim = 3 if solids else 2
    facet_kinds = ("triangle", "triangle6") if dim == 3 else ("line", "line3")
    elements = [i for i, b in enumerate(raw.cells) if b.type == body]
    facet_blocks = [i for i, b in enumerate(raw.cells) if b.type in facet_kinds]
    cells = [np.asarray(b.data, dtype=np.int64) for b in raw.cells]
    t = np.vstack([cells[i][:, :dim + 1] for i in elements])
    f = np.vstack([cells[i][:, :dim] for i in facet_blocks] or [np.zeros((0, dim), np.int64)])

    x = np.asarray(raw.points, dtype=float)
    if x.shape[1] == 3 and dim == 2:
        if np.any(x[:, 2] != 0.0):
            raise InputError(f"triangles off the plane z = 0 in {source}: surface meshes in 3-D are not supported")
        x = x[:, :2]
    if x.shape[1] != dim:
        raise InputError(f"{body} cells with {x.shape[1]}-D points in {source}")
    if t.size and (t.min() < 0 or t.max() >= len(x)):
        raise InputError(f"{body} cells of {source} refer to node {t.max()} but there are {len(x)} nodes")
    if body in ("triangle6", "tetra10"):
        # mid-edge nodes are not P1 geometry: drop them (and only them: other unused nodes are errors)
        mid = np.setdiff1d(np.vstack([cells[i][:, dim + 1:] for i in elements]), t)
        keep = np.ones(len(x), dtype=bool)
        keep[mid] = False
        renumber = np.cumsum(keep) - 1
        x, t, f = x[keep], renumber[t], renumber[f]

    mesh = (MeshTet1 if dim == 3 else MeshTri1)(np.ascontiguousarray(x.T), np.ascontiguousarray(t.T))
    element_sets, facet_sets = _groups(raw, elements, facet_blocks, dim)
    subdomains = {name: ix for name, ix in element_sets.items() if len(ix)}
    boundaries = {}
    which = _match(mesh.facets, f.T) if len(f) else np.zeros(0, dtype=np.int64)
    for name, ix in facet_sets.items():
        if len(ix) and np.any(which[ix] < 0):
            raise InputError(f"{np.count_nonzero(which[ix] < 0)} cells of group {name!r} in {source} "
                             f"are not element facets (first: cell {ix[which[ix] < 0][0]})")
        if len(ix):
            boundaries[name] = np.unique(which[ix])
    for key, data in raw.cell_data.items():  # scikit-fem's encoding of its named sets
        kind, _, name = key.partition(":")[2].partition(":")
        if key.startswith("skfem:") and kind in ("s", "b") and name:
            code = np.concatenate([np.asarray(data[i]).ravel() for i in elements]).astype(np.int64)
            if kind == "s":
                subdomains[name] = np.nonzero(code)[0]
            else:  # bit k of an element's code: its local facet k is in the boundary
                bits = (code[None, :] >> np.arange(mesh.t2f.shape[0])[:, None]) & 1
                boundaries[name] = np.unique(mesh.t2f[bits.astype(bool)])
    return replace(mesh, _boundaries=boundaries or None, _subdomains=subdomains or None)


def _groups(raw: meshio.Mesh, elements: list[int], facet_blocks: list[int],
            dim: int) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Named groups of element cells and of facet cells (indices into their stacked blocks)."""
    def stacked(blocks: list[int], per_block: Sequence) -> np.ndarray:
        out, start = [np.zeros(0, dtype=np.int64)], 0
        for i in blocks:
            if per_block[i] is not None:
                out.append(start + np.asarray(per_block[i], dtype=np.int64).ravel())
            start += len(raw.cells[i])
        return np.concatenate(out)

    element_sets: dict[str, np.ndarray] = {}
    facet_sets: dict[str, np.ndarray] = {}
    # cell sets of Gmsh 4 files hold the physical names ("gmsh:bounding_entities" is no group)
    sets = {k: v for k, v in raw.cell_sets.items() if not k.startswith("gmsh:")}
    if sets:
        for name, per_block in sets.items():
            element_sets[name] = stacked(elements, per_block)
            facet_sets[name] = stacked(facet_blocks, per_block)
    elif "gmsh:physical" in raw.cell_data:
        # Gmsh numbers physical groups per dimension: a name is found by (tag, dimension)
        names = {(int(v[0]), int(v[1])): k for k, v in raw.field_data.items() if np.size(v) >= 2}
        tags = raw.cell_data["gmsh:physical"]
        for blocks, d, out in ((elements, dim, element_sets), (facet_blocks, dim - 1, facet_sets)):
            all_tags = stacked(blocks, [np.asarray(a).ravel() for a in tags])
            for tag in np.unique(all_tags[all_tags > 0]):
                out[names.get((int(tag), d), str(tag))] = np.nonzero(all_tags == tag)[0]
    return element_sets, facet_sets


# --- checks and summaries --------------------------------------------------------------------


def check_mesh(mesh: Mesh) -> None:
    """Raise :class:`InputError` unless ``mesh`` is a usable triangle or tetrahedron mesh.

    Rejected: non-finite coordinates, unused nodes (no element references them), degenerate
    elements (area or volume at most ``1e-12 h^d``, ``h`` the element's mean edge length) and
    folded meshes: an interior facet whose two elements lie on the same side of it, i.e. an
    element inverted against its neighbour. The vertex order is not used: a consistently
    negative (clockwise) orientation is fine, as are the mixed orders that :class:`skfem.MeshTri1`
    makes by sorting its connectivity (scikit-fem integrates with ``|det J|``).
    :func:`read_mesh` calls this, and so do the model builders.
    """
    _check_type(mesh)
    p, t = mesh.p, mesh.t
    dim, nn = mesh.dim(), p.shape[1]
    if t.shape[1] == 0:
        raise InputError("mesh has no elements")
    if t.min() < 0 or t.max() >= nn:
        raise InputError(f"mesh elements refer to node {t.max()} but the mesh has {nn} nodes")
    bad = np.nonzero(~np.isfinite(p).all(axis=0))[0]
    if len(bad):
        raise InputError(f"mesh has {len(bad)} nodes with non-finite coordinates (first: node {bad[0]})")
    unused = np.setdiff1d(np.arange(nn), t)
    if len(unused):
        raise InputError(f"mesh has {len(unused)} unused nodes that no element references (first: node {unused[0]})")

    x = p[:, t]  # (dim, dim + 1, elements)
    size = np.linalg.det(np.moveaxis(x[:, 1:] - x[:, :1], -1, 0)) / math.factorial(dim)
    h = np.mean([np.linalg.norm(x[:, i] - x[:, j], axis=0)
                 for i, j in itertools.combinations(range(dim + 1), 2)], axis=0)
    flat = np.nonzero(np.abs(size) <= DEGENERATE * h**dim)[0]
    if len(flat):
        what = "area" if dim == 2 else "volume"
        raise InputError(f"mesh has {len(flat)} degenerate elements ({what} <= {DEGENERATE:g} h^{dim}; "
                         f"first: element {flat[0]})")

    # each element's vertex opposite each of its facets must lie on the other side of the facet
    # than the neighbour's: sum the sides per facet, +-2 means both on one side
    f = mesh.facets
    edges = p[:, f[1:]] - p[:, f[:1]]
    normal = (np.array([-edges[1, 0], edges[0, 0]]) if dim == 2
              else np.cross(edges[:, 0], edges[:, 1], axis=0))
    opposite = [(set(range(dim + 1)) - set(local)).pop() for local in mesh.refdom.facets]
    t2f = mesh.t2f
    side = np.sign(np.einsum("dke,dke->ke", normal[:, t2f], p[:, t[opposite]] - p[:, f[0, t2f]]))
    folded = np.nonzero(np.abs(np.bincount(t2f.ravel(), side.ravel(), f.shape[1])) > 1.5)[0]
    if len(folded):
        a, b = mesh.f2t[:, folded[0]]
        raise InputError(f"mesh is folded: {len(folded)} interior facets have both their elements on "
                         f"one side, i.e. inverted elements (first: elements {a} and {b})")


def mesh_size(mesh: Mesh) -> tuple[float, float]:
    """The shortest and the longest edge length of ``mesh``."""
    _check_type(mesh)
    e = mesh.facets if mesh.dim() == 2 else mesh.edges
    length = np.linalg.norm(mesh.p[:, e[0]] - mesh.p[:, e[1]], axis=0)
    return float(length.min()), float(length.max())


def describe(mesh: Mesh) -> dict:
    """A small JSON-friendly summary: sizes, named sets with their counts, edge lengths."""
    h_min, h_max = mesh_size(mesh)
    return {
        "dimension": int(mesh.dim()),
        "nodes": int(mesh.p.shape[1]),
        "elements": int(mesh.t.shape[1]),
        "boundaries": {k: int(len(v)) for k, v in (mesh.boundaries or {}).items()},
        "subdomains": {k: int(len(v)) for k, v in (mesh.subdomains or {}).items()},
        "h_min": h_min,
        "h_max": h_max,
    }


def select_facets(mesh: Mesh, where: str | Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """Facet indices: a named boundary, or the boundary facets whose midpoints pass a test.

    Parameters
    ----------
    mesh : MeshTri1 or MeshTet1
        The mesh.
    where : str or callable
        A name in ``mesh.boundaries``, or ``f(x) -> bool array`` on the midpoints ``x``
        (``(dim, nfacets)``) of the boundary facets.
    """
    if isinstance(where, str):
        known = mesh.boundaries or {}
        if where not in known:
            raise InputError(f"unknown boundary {where!r}; known: {', '.join(sorted(known)) or 'none'}")
        return np.asarray(known[where], dtype=np.int64)
    if not callable(where):
        raise InputError(f"where must be a boundary name or a callable, got {_show(where)}")
    facets = mesh.boundary_facets()
    hit = np.asarray(where(mesh.p[:, mesh.facets[:, facets]].mean(axis=1)))
    if hit.dtype != bool or hit.shape != facets.shape:
        raise InputError(f"a facet test must return a bool array of shape {facets.shape}, "
                         f"got {hit.dtype} of shape {hit.shape}")
    return facets[hit].astype(np.int64)


# --- helpers ---------------------------------------------------------------------------------


def _show(value: object) -> str:
    """``repr`` on one short line."""
    text = " ".join(repr(value).split())
    return text if len(text) <= 80 else text[:77] + "..."


def _count(name: str, value: object, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {_show(value)}")
    return int(value)


def _point(name: str, value: object, dim: int | None = None) -> np.ndarray:
    try:
        x = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        x = np.full(0, np.nan)
    if x.ndim != 1 or x.shape[0] != (dim or x.shape[0]) or not x.size or not np.isfinite(x).all():
        need = f"{dim} finite numbers" if dim else "finite numbers"
        raise InputError(f"{name} must be {need}, got {_show(value)}")
    return x


def _check_type(mesh: object) -> None:
    if not isinstance(mesh, (MeshTri1, MeshTet1)):
        raise InputError(f"expected a skfem MeshTri1 or MeshTet1, got {type(mesh).__name__}")


def _everywhere(x: np.ndarray) -> np.ndarray:
    return np.ones(x.shape[1], dtype=bool)


def _sides(lo: np.ndarray, hi: np.ndarray, tol: float) -> dict[str, Callable]:
    """Facet tests ``xmin``, ``xmax``, ... of an axis-aligned box."""
    tests = {}
    for i, axis in enumerate("xyz"[:len(lo)]):
        tests[f"{axis}min"] = lambda x, i=i: np.abs(x[i] - lo[i]) <= tol
        tests[f"{axis}max"] = lambda x, i=i: np.abs(x[i] - hi[i]) <= tol
    return tests


def _round(coarse: Mesh, tests: dict[str, Callable], curved: Curved, refine: int) -> Mesh:
    """Refine ``coarse`` uniformly, tagging and projecting the curved boundary every time."""
    mesh = coarse.with_boundaries(tests)
    _project(mesh, (curved,))
    for _ in range(refine):
        # scikit-fem keeps named facets on uniform refinement of triangles, not of tetrahedra
        mesh = _bare(mesh).refined().with_boundaries(tests)
        _project(mesh, (curved,))
    mesh.curved = (curved,)
    return mesh


def _curved(mesh: Mesh, shape: Curved | Sequence[Curved] | None) -> tuple[Curved, ...]:
    shapes = getattr(mesh, "curved", ()) if shape is None else shape
    shapes = (shapes,) if isinstance(shapes, Curved) else tuple(shapes)
    for s in shapes:
        if not isinstance(s, Curved):
            raise InputError(f"shape must be a Curved or a sequence of them, got {_show(s)}")
        if s.boundary not in (mesh.boundaries or {}):
            raise InputError(f"curved boundary {s.boundary!r} is not a boundary of the mesh; "
                             f"known: {', '.join(sorted(mesh.boundaries or {})) or 'none'}")
        if len(s.center) != mesh.dim():
            raise InputError(f"curved boundary {s.boundary!r} has a {len(s.center)}-D center in a {mesh.dim()}-D mesh")
    return shapes


def _project(mesh: Mesh, curved: Sequence[Curved]) -> None:
    """Move the nodes of each curved boundary radially onto its circle or sphere.

    In place, and so only on a mesh made here, before any use of it: that keeps the facets
    scikit-fem has built (they do not depend on the coordinates, and are slow to build).
    """
    p = mesh.doflocs
    for c in curved:
        nodes = np.unique(mesh.facets[:, mesh.boundaries[c.boundary]])
        center = np.array(c.center)[:, None]
        d = p[:, nodes] - center
        p[:, nodes] = center + c.radius * d / np.linalg.norm(d, axis=0)


def _bare(mesh: Mesh) -> Mesh:
    return replace(mesh, _boundaries=None, _subdomains=None)


def _refined(mesh: Mesh, marked: np.ndarray) -> Mesh:
    """``mesh.refined(marked)`` without named sets, quietly, leaving NumPy's random state alone.

    scikit-fem 12, refining adaptively, drops the named facets of triangles (it carries their
    subdomains) and keeps both, stale, on tetrahedra: :func:`_inherit` re-derives them. Its
    tetrahedral bisection calls ``np.random.seed(1337)`` and logs a note on memory layout for
    meshes of over 1000 elements.
    """
    state = np.random.get_state()
    log = logging.getLogger("skfem.mesh.mesh")
    log.addFilter(_no_layout_note)
    try:
        fine = _bare(mesh).refined(marked)
        fine.doflocs = fine.doflocs.copy()  # never share coordinates with the caller's mesh
        return fine
    finally:
        log.removeFilter(_no_layout_note)
        np.random.set_state(state)


def _no_layout_note(record: logging.LogRecord) -> bool:
    return "C_CONTIGUOUS" not in record.getMessage()


def _inherit(coarse: Mesh, fine: Mesh) -> None:
    """Give ``fine``, a new refinement of ``coarse``, the named sets of ``coarse`` (in place)."""
    boundaries = subdomains = None
    if coarse.subdomains:
        parent = _parents(coarse.p, coarse.t, fine.p, fine.t)
        subdomains = {k: np.nonzero(np.isin(parent, ix))[0] for k, ix in coarse.subdomains.items()}
    if coarse.boundaries:
        named = np.unique(np.concatenate([np.asarray(ix, dtype=np.int64).ravel()
                                          for ix in coarse.boundaries.values()]))
        parent = _parents(coarse.p, coarse.facets[:, named], fine.p, fine.facets)
        owner = np.where(parent >= 0, named[parent], -1)
        boundaries = {k: np.nonzero(np.isin(owner, ix))[0] for k, ix in coarse.boundaries.items()}
    fine._boundaries, fine._subdomains = boundaries, subdomains


def _parents(old_p: np.ndarray, old_s: np.ndarray, new_p: np.ndarray,
             new_s: np.ndarray) -> np.ndarray:
    """The column of ``old_s`` whose simplex contains each simplex of ``new_s`` (-1: none).

    Refinement keeps the old nodes, first and in order, so a simplex it left alone has the same
    vertex set; only the new ones are located geometrically, among the old ones that vanished.
    """
    parent = _match(old_s, new_s)
    new = np.nonzero(parent < 0)[0]
    gone = np.setdiff1d(np.arange(old_s.shape[1]), parent)
    if len(new) and len(gone):
        found = _locate(new_p[:, new_s[:, new]].mean(axis=1), old_p[:, old_s[:, gone]])
        parent[new] = np.where(found >= 0, gone[found], -1)
    return parent


def _match(old_s: np.ndarray, new_s: np.ndarray) -> np.ndarray:
    """For each column of ``new_s``, the column of ``old_s`` with the same vertex set, or -1."""
    n_old, n_new = old_s.shape[1], new_s.shape[1]
    if not n_old or not n_new:
        return np.full(n_new, -1, dtype=np.int64)
    rows = np.sort(np.hstack((old_s, new_s)).astype(np.int64), axis=0)
    # label equal rows equally, one column at a time (much faster than np.unique(axis=0))
    label, base = np.zeros(rows.shape[1], dtype=np.int64), rows.max() + 1
    for column in rows:
        label = np.unique(label * base + column, return_inverse=True)[1].reshape(-1)
    first = np.full(label.max() + 1, -1, dtype=np.int64)
    first[label[:n_old]] = np.arange(n_old)
    return first[label[n_old:]]


def _locate(x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Index of a simplex ``v[:, :, j]`` (``(dim, k + 1, m)``, ``k <= dim``) holding each point.

    -1 where none does. Candidates are the simplices whose centroid is within the largest
    centroid-vertex distance of the point, which includes every simplex that holds it.
    """
    centroid = v.mean(axis=1)
    reach = np.linalg.norm(v - centroid[:, None], axis=0).max()
    near = cKDTree(centroid.T).query_ball_point(x.T, reach * (1.0 + 1e-9))
    i = np.repeat(np.arange(x.shape[1]), [len(c) for c in near])
    j = np.fromiter(itertools.chain.from_iterable(near), dtype=np.int64, count=len(i))
    found = np.full(x.shape[1], -1, dtype=np.int64)
    if not len(i):
        return found
    a = v[:, 1:, j] - v[:, :1, j]  # (dim, k, pairs)
    b = x[:, i] - v[:, 0, j]
    mu = np.linalg.solve(np.einsum("dkq,dlq->qkl", a, a), np.einsum("dkq,dq->qk", a, b)[..., None])[..., 0]
    lam = np.column_stack((1.0 - mu.sum(axis=1), mu))
    off = np.linalg.norm(b - np.einsum("dkq,qk->dq", a, mu), axis=0)  # distance from a facet's plane
    inside = (lam.min(axis=1) >= -1e-9) & (off <= 1e-9 * np.linalg.norm(a, axis=0).max(axis=0))
    found[i[inside]] = j[inside]
    return found
