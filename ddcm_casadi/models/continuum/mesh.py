"""Simplex meshes of the continua: generated shapes, mesh files, checks and grading.

Meshes are plain scikit-fem meshes, :class:`skfem.MeshTri1` (2-D, plane strain) or
:class:`skfem.MeshTet1` (3-D), with named facet sets in ``mesh.boundaries`` (name -> facet
indices) and, where known, named element sets in ``mesh.subdomains`` (name -> element indices).

This module is the one to import; it holds the generated shapes and re-exports the rest:

- generated shapes: :func:`rectangle`, :func:`box`, :func:`disc`, :func:`half_disc`,
  :func:`quarter_disc`, :func:`ball`, :func:`ball_octant`;
- :func:`refine_near` grades a mesh towards a (contact) point and keeps the named sets and the
  curved boundaries (:class:`Curved`) (:mod:`~ddcm_casadi.models.continuum.mesh_refinement`);
- :func:`read_mesh` reads Gmsh ``.msh`` (2.2 and 4.1), ``.vtu`` and ``.xdmf`` files with meshio
  (:mod:`~ddcm_casadi.models.continuum.mesh_files`);
- :func:`check_mesh` rejects meshes a model cannot use (the model builders call it too);
- :func:`mesh_size`, :func:`describe` and :func:`select_facets` are small helpers, and
  :class:`FacetBox`, :class:`FacetPlane` facet tests that choose boundaries by position
  (:mod:`~ddcm_casadi.models.continuum.mesh_checks`).
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np
from skfem import MeshTet1, MeshTri1

from ddcm_casadi.data.dataset import check_positive
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.continuum.mesh_checks import (DEGENERATE, FacetBox, FacetPlane, Mesh, check_count,
                                                      check_mesh, check_point, describe, mesh_size, select_facets)
from ddcm_casadi.models.continuum.mesh_files import READERS, read_mesh
from ddcm_casadi.models.continuum.mesh_refinement import Curved, refine_near, refined_shape

__all__ = ["DEGENERATE", "READERS", "Curved", "FacetBox", "FacetPlane", "Mesh", "ball", "ball_octant", "box", "check_mesh", "describe", "disc",
           "half_disc", "mesh_size", "quarter_disc", "read_mesh", "rectangle", "refine_near", "select_facets"]


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
    counts = [check_count("nx", nx), check_count("ny", ny)]
    lo = check_point("origin", origin, 2)
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
    counts = [check_count("nx", nx), check_count("ny", ny), check_count("nz", nz)]
    lo = check_point("origin", origin, 3)
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
    r, c = check_positive("radius", radius), check_point("center", center, 2)
    unit = np.array([[0.0, 1.0, 0.0, -1.0, 0.0], [0.0, 0.0, 1.0, 0.0, -1.0]])
    t = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]]).T
    return refined_shape(MeshTri1(c[:, None] + r * unit, t), {"arc": _everywhere},
                  Curved("arc", c, r), check_count("refine", refine, 0))


def half_disc(radius: float, *, center: Sequence[float] = (0.0, 0.0),
              refine: int = 3) -> MeshTri1:
    """The lower half ``y <= center_y`` of a disc, flat side on top (a cylinder's contact zone).

    The arc is a regular polygon of ``2 * 2**refine`` sides inscribed in the circle.

    Returns
    -------
    MeshTri1
        With boundaries ``arc`` and ``flat`` and ``mesh.curved`` (:class:`Curved`).
    """
    r, c = check_positive("radius", radius), check_point("center", center, 2)
    unit = np.array([[0.0, 1.0, 0.0, -1.0], [0.0, 0.0, -1.0, 0.0]])
    t = np.array([[0, 1, 2], [0, 2, 3]]).T
    # midpoints of flat facets are exactly at center_y; arc facets are well below it
    tests = {"flat": lambda x: np.abs(x[1] - c[1]) <= 1e-9 * r,
             "arc": lambda x: np.abs(x[1] - c[1]) > 1e-9 * r}
    return refined_shape(MeshTri1(c[:, None] + r * unit, t), tests, Curved("arc", c, r),
                  check_count("refine", refine, 0))


def quarter_disc(radius: float, *, center: Sequence[float] = (0.0, 0.0), refine: int = 3) -> MeshTri1:
    """The quarter ``x >= center_x``, ``y <= center_y`` of a disc: a half model (symmetry plane
    ``x = center_x``) of a cylinder's contact zone, flat side on top.

    Returns
    -------
    MeshTri1
        With boundaries ``arc``, ``flat`` (``y = center_y``) and ``axis`` (``x = center_x``) and
        ``mesh.curved`` (:class:`Curved`).
    """
    r, c = check_positive("radius", radius), check_point("center", center, 2)
    corners = c[:, None] + r * np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])
    tol = 1e-9 * r
    tests = {"flat": lambda x: np.abs(x[1] - c[1]) <= tol, "axis": lambda x: np.abs(x[0] - c[0]) <= tol,
             "arc": lambda x: (np.abs(x[1] - c[1]) > tol) & (np.abs(x[0] - c[0]) > tol)}
    return refined_shape(MeshTri1(corners, np.array([[0], [1], [2]])), tests, Curved("arc", c, r),
                         check_count("refine", refine, 0))


def ball(radius: float, *, center: Sequence[float] = (0.0, 0.0, 0.0), refine: int = 2) -> MeshTet1:
    """A ball: an octahedron of eight tetrahedra refined ``refine`` times, projected each time.

    Returns
    -------
    MeshTet1
        With boundary ``surface`` (``8 * 4**refine`` triangles) and ``mesh.curved``.
    """
    r, c = check_positive("radius", radius), check_point("center", center, 3)
    unit = np.hstack((np.zeros((3, 1)), np.eye(3), -np.eye(3)))
    t = np.array([[0, 1, 2, 3], [0, 4, 5, 6], [0, 1, 2, 6], [0, 1, 3, 5],
                  [0, 2, 3, 4], [0, 4, 5, 3], [0, 4, 6, 2], [0, 5, 6, 1]]).T
    return refined_shape(MeshTet1(c[:, None] + r * unit, t), {"surface": _everywhere},
                  Curved("surface", c, r), check_count("refine", refine, 0))


def ball_octant(radius: float, *, center: Sequence[float] = (0.0, 0.0, 0.0),
                signs: Sequence[int] = (1, 1, -1), refine: int = 2) -> MeshTet1:
    """One eighth of a ball, the octant ``signs`` (e.g. ``(1, 1, -1)``: ``x, y >= c`` and
    ``z <= c``): a quarter model of a sphere's contact zone with symmetry planes ``x = c_x`` and
    ``y = c_y``. One tetrahedron refined ``refine`` times, its curved face projected each time.

    Returns
    -------
    MeshTet1
        With boundaries ``surface`` (the curved face), ``x0``, ``y0``, ``z0`` (the flat faces
        through the centre) and ``mesh.curved``.
    """
    r, c = check_positive("radius", radius), check_point("center", center, 3)
    sg = np.asarray(signs, dtype=float).ravel()
    if sg.size != 3 or not np.all(np.abs(sg) == 1):
        raise InputError(f"signs must be three numbers +1 or -1, got {signs!r}")
    corners = np.hstack((np.zeros((3, 1)), np.diag(sg))) * r + c[:, None]
    tol = 1e-9 * r
    tests = {f"{a}0": (lambda x, i=i: np.abs(x[i] - c[i]) <= tol) for i, a in enumerate("xyz")}
    tests["surface"] = lambda x: np.all(np.abs(x - c[:, None]) > tol, axis=0)
    return refined_shape(MeshTet1(corners, np.array([[0], [1], [2], [3]])), tests, Curved("surface", c, r),
                         check_count("refine", refine, 0))


# --- helpers ---------------------------------------------------------------------------------


def _everywhere(x: np.ndarray) -> np.ndarray:
    """A facet test every facet passes."""
    return np.ones(x.shape[1], dtype=bool)


def _sides(lo: np.ndarray, hi: np.ndarray, tol: float) -> dict[str, Callable]:
    """Facet tests ``xmin``, ``xmax``, ... of an axis-aligned box."""
    tests = {}
    for i, axis in enumerate("xyz"[:len(lo)]):
        tests[f"{axis}min"] = lambda x, i=i: np.abs(x[i] - lo[i]) <= tol
        tests[f"{axis}max"] = lambda x, i=i: np.abs(x[i] - hi[i]) <= tol
    return tests
