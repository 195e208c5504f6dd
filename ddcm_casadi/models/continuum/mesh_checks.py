"""Checks, summaries and lookups of the continua's simplex meshes.

- :func:`check_mesh` rejects meshes a model cannot use (the model builders and
  :func:`~ddcm_casadi.models.continuum.mesh_files.read_mesh` call it);
- :func:`mesh_size`, :func:`describe` and :func:`select_facets` are small helpers;
  :class:`FacetBox` and :class:`FacetPlane` are facet tests for :func:`select_facets` (boundaries
  chosen by position, for mesh files without named boundaries);
- :func:`match_simplices` finds simplices by their vertex sets (refinement, mesh files);
- :func:`check_count`, :func:`check_point`, :func:`check_mesh_type` and :func:`short_repr` check
  the arguments of the mesh functions with one-line messages.

All are re-exported by :mod:`ddcm_casadi.models.continuum.mesh`, the module users import.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Callable, Union

import numpy as np
from skfem import MeshTet1, MeshTri1

from ddcm_casadi.errors import InputError

Mesh = Union[MeshTri1, MeshTet1]

#: Elements are degenerate when their area (volume) is at most this times ``h^2`` (``h^3``).
DEGENERATE = 1e-12


# --- checks and summaries --------------------------------------------------------------------


def check_mesh(mesh: Mesh) -> None:
    """Raise :class:`InputError` unless ``mesh`` is a usable triangle or tetrahedron mesh.

    Rejected: non-finite coordinates, unused nodes (no element references them), degenerate
    elements (area or volume at most ``1e-12 h^d``, ``h`` the element's mean edge length) and
    folded meshes: an interior facet whose two elements lie on the same side of it, i.e. an
    element inverted against its neighbour. The vertex order is not used: a consistently
    negative (clockwise) orientation is fine, as are the mixed orders that :class:`skfem.MeshTri1`
    makes by sorting its connectivity (scikit-fem integrates with ``|det J|``).
    :func:`~ddcm_casadi.models.continuum.mesh_files.read_mesh` calls this, and so do the model builders.
    """
    check_mesh_type(mesh)
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
    check_mesh_type(mesh)
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
        raise InputError(f"where must be a boundary name or a callable, got {short_repr(where)}")
    facets = mesh.boundary_facets()
    hit = np.asarray(where(mesh.p[:, mesh.facets[:, facets]].mean(axis=1)))
    if hit.dtype != bool or hit.shape != facets.shape:
        raise InputError(f"a facet test must return a bool array of shape {facets.shape}, "
                         f"got {hit.dtype} of shape {hit.shape}")
    return facets[hit].astype(np.int64)


@dataclass(frozen=True)
class FacetBox:
    """A facet test: the boundary facets whose midpoints lie in the box ``lo <= x <= hi``
    (bounds included). Pass it to :func:`select_facets` or as a ``where`` of the model builder.

    Parameters
    ----------
    lo, hi : tuple of float
        The box's corners, one number per axis.
    """

    lo: tuple[float, ...]
    hi: tuple[float, ...]

    def __post_init__(self) -> None:
        lo, hi = check_point("box min", self.lo), check_point("box max", self.hi, len(self.lo))
        if np.any(lo > hi):
            raise InputError(f"box min must not exceed box max, got min {tuple(lo)} and max {tuple(hi)}")
        object.__setattr__(self, "lo", tuple(map(float, lo)))
        object.__setattr__(self, "hi", tuple(map(float, hi)))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        if x.shape[0] != lo.size:
            raise InputError(f"a box of {lo.size} coordinates on a {x.shape[0]}-D mesh")
        return np.all((x >= lo[:, None]) & (x <= hi[:, None]), axis=0)


#: The default tolerance of :class:`FacetPlane`, relative to the extent of the boundary: facets
#: on the plane have their midpoints on it to the roundoff of their coordinates (1e-16 of the
#: size), a facet off it by at least about half an element; 1e-6 lies between for any mesh whose
#: elements are larger than 2e-6 of the body.
PLANE_TOL = 1e-6


@dataclass(frozen=True)
class FacetPlane:
    """A facet test: the boundary facets whose midpoints lie on the plane (a line in 2-D) through
    ``point`` with normal ``normal``, within ``tolerance`` (m; default :data:`PLANE_TOL` times
    the extent of the boundary).

    Parameters
    ----------
    point, normal : tuple of float
        A point of the plane and its normal (any length but zero).
    tolerance : float, optional
        The largest distance of a midpoint from the plane (m).
    """

    point: tuple[float, ...]
    normal: tuple[float, ...]
    tolerance: float | None = None

    def __post_init__(self) -> None:
        point, normal = check_point("plane point", self.point), check_point("plane normal", self.normal, len(self.point))
        norm = float(np.linalg.norm(normal))
        if not norm > 0:
            raise InputError("plane normal must be a non-zero vector")
        if self.tolerance is not None and not (isinstance(self.tolerance, (int, float)) and 0 < self.tolerance < math.inf):
            raise InputError(f"plane tolerance must be a positive finite number (m), got {short_repr(self.tolerance)}")
        object.__setattr__(self, "point", tuple(map(float, point)))
        object.__setattr__(self, "normal", tuple(map(float, normal / norm)))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        p, n = np.asarray(self.point), np.asarray(self.normal)
        if x.shape[0] != p.size:
            raise InputError(f"a plane of {p.size} coordinates on a {x.shape[0]}-D mesh")
        tol = self.tolerance
        if tol is None:
            tol = PLANE_TOL * max(float(np.max(np.ptp(x, axis=1), initial=0.0)), float(np.max(np.abs(x), initial=0.0)))
        return np.abs(n @ (x - p[:, None])) <= tol


def match_simplices(old_s: np.ndarray, new_s: np.ndarray) -> np.ndarray:
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


# --- argument checks -------------------------------------------------------------------------


def short_repr(value: object) -> str:
    """``repr`` on one short line."""
    text = " ".join(repr(value).split())
    return text if len(text) <= 80 else text[:77] + "..."


def check_count(name: str, value: object, minimum: int = 1) -> int:
    """``value`` if it is an integer of at least ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {short_repr(value)}")
    return int(value)


def check_point(name: str, value: object, dim: int | None = None) -> np.ndarray:
    """``value`` as a point: ``dim`` finite numbers (any number of them if ``dim`` is ``None``)."""
    try:
        x = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        x = np.full(0, np.nan)
    if x.ndim != 1 or x.shape[0] != (dim or x.shape[0]) or not x.size or not np.isfinite(x).all():
        need = f"{dim} finite numbers" if dim else "finite numbers"
        raise InputError(f"{name} must be {need}, got {short_repr(value)}")
    return x


def check_mesh_type(mesh: object) -> None:
    """Refuse anything but a :class:`skfem.MeshTri1` or :class:`skfem.MeshTet1`."""
    if not isinstance(mesh, (MeshTri1, MeshTet1)):
        raise InputError(f"expected a skfem MeshTri1 or MeshTet1, got {type(mesh).__name__}")
