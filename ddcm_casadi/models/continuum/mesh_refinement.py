"""Grading of the continua's meshes towards a point, keeping named sets and curved boundaries.

- :class:`Curved`: a named boundary on a circle or sphere; :func:`refined_shape` refines a
  generated round shape uniformly, projecting its curved boundary every time;
- :func:`refine_near` grades a mesh towards a (contact) point and keeps the named sets and the
  curved boundaries.

Both public names are re-exported by :mod:`ddcm_casadi.models.continuum.mesh`.
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np
from scipy.spatial import cKDTree

from ddcm_casadi.data.dataset import check_positive
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.continuum.mesh_checks import (Mesh, check_count, check_mesh_type, check_point,
                                                      match_simplices, mesh_size, short_repr)


@dataclass(frozen=True)
class Curved:
    """A named boundary whose nodes lie on a circle (2-D) or a sphere (3-D).

    The generated shapes :func:`~ddcm_casadi.models.continuum.mesh.disc`,
    :func:`~ddcm_casadi.models.continuum.mesh.half_disc` and
    :func:`~ddcm_casadi.models.continuum.mesh.ball` remember theirs in the attribute
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
        object.__setattr__(self, "center", tuple(float(c) for c in check_point("center", self.center)))
        object.__setattr__(self, "radius", check_positive("radius", self.radius))


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
        ``curved`` attribute (set by :func:`~ddcm_casadi.models.continuum.mesh.disc`,
        :func:`~ddcm_casadi.models.continuum.mesh.half_disc`, :func:`~ddcm_casadi.models.continuum.mesh.ball`), ``()``
        projects nothing.

    Returns
    -------
    MeshTri1 or MeshTet1
        A new mesh, with ``curved`` set to the curved boundaries.
    """
    check_mesh_type(mesh)
    x0 = check_point("point", point, mesh.dim())
    r = check_positive("radius", radius)
    levels = check_count("levels", levels, 0)
    if not (isinstance(shrink, (int, float)) and 0 < shrink <= 1):
        raise InputError(f"shrink must be in (0, 1], got {short_repr(shrink)}")
    if not (isinstance(buffer, (int, float)) and 0 <= buffer < math.inf):
        raise InputError(f"buffer must be a finite number >= 0, got {short_repr(buffer)}")
    curved = _curved(mesh, shape)
    for level in range(levels):
        reach = r + (buffer * mesh_size(mesh)[0] if buffer else 0.0)
        for _ in range(1 if mesh.dim() == 2 else 3):
            dist = np.linalg.norm(mesh.p - x0[:, None], axis=0)
            near = dist <= reach
            if level == 0 and not near.any():
                raise InputError(f"no mesh node lies within radius {r:g} of point "
                                 f"({', '.join(f'{c:g}' for c in x0)})")
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


def refined_shape(coarse: Mesh, tests: dict[str, Callable], curved: Curved, refine: int) -> Mesh:
    """Refine ``coarse`` uniformly, tagging and projecting the curved boundary every time.

    The generated round shapes of :mod:`ddcm_casadi.models.continuum.mesh` are made so.
    """
    mesh = coarse.with_boundaries(tests)
    _project(mesh, (curved,))
    for _ in range(refine):
        # scikit-fem keeps named facets on uniform refinement of triangles, not of tetrahedra
        mesh = _bare(mesh).refined().with_boundaries(tests)
        _project(mesh, (curved,))
    mesh.curved = (curved,)
    return mesh


def _curved(mesh: Mesh, shape: Curved | Sequence[Curved] | None) -> tuple[Curved, ...]:
    """The curved boundaries to keep: ``shape``, else the mesh's own; each checked against the mesh."""
    shapes = getattr(mesh, "curved", ()) if shape is None else shape
    shapes = (shapes,) if isinstance(shapes, Curved) else tuple(shapes)
    for s in shapes:
        if not isinstance(s, Curved):
            raise InputError(f"shape must be a Curved or a sequence of them, got {short_repr(s)}")
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
    """``mesh`` without its named sets."""
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
    """A logging filter: drop scikit-fem's note on memory layout."""
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
    parent = match_simplices(old_s, new_s)
    new = np.nonzero(parent < 0)[0]
    gone = np.setdiff1d(np.arange(old_s.shape[1]), parent)
    if len(new) and len(gone):
        found = _locate(new_p[:, new_s[:, new]].mean(axis=1), old_p[:, old_s[:, gone]])
        parent[new] = np.where(found >= 0, gone[found], -1)
    return parent


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
