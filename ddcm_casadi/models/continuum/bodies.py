"""Several bodies in one continuum model: their meshes joined into one mesh of disconnected
pieces, each body a named region and each of its boundaries named ``"<body>/<boundary>"``.

The stiffness of the joined mesh is block diagonal (no node is shared); the bodies interact only
through the contact pairs between them (:mod:`ddcm_casadi.models.continuum.mortar`). A mesh file
may instead hold several bodies as regions of one mesh (Gmsh physical groups): that needs no
joining.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from ddcm_casadi.errors import InputError
from ddcm_casadi.models.continuum.mesh_checks import Mesh

#: The separator of a body's name and its own boundary or region names.
SEPARATOR = "/"


def _facet_keys(facets: np.ndarray, n_nodes: int) -> np.ndarray:
    """One integer per facet (its sorted node indices in base ``n_nodes``)."""
    key = np.zeros(facets.shape[1], dtype=np.int64)
    for row in np.sort(facets, axis=0):
        key = key * n_nodes + row
    return key


def join(bodies: Mapping[str, Mesh]) -> Mesh:
    """One mesh of the named ``bodies`` (all triangles or all tetrahedra).

    Returns
    -------
    Mesh
        Subdomains: each body by its name, and its own subdomains as ``"<body>/<name>"``;
        boundaries ``"<body>/<name>"`` for each body's named boundaries, and ``"<body>"`` for its
        whole boundary.
    """
    if len(bodies) < 1:
        raise InputError("join needs at least one body")
    kinds = {type(m) for m in bodies.values()}
    if len(kinds) != 1:
        raise InputError("the bodies' meshes must all be of one kind (triangles in 2-D, tetrahedra in 3-D)")
    for name in bodies:
        if not isinstance(name, str) or not name or SEPARATOR in name:
            raise InputError(f"a body name must be a non-empty string without {SEPARATOR!r}, got {name!r}")
    kind = kinds.pop()
    offsets = np.cumsum([0] + [m.p.shape[1] for m in bodies.values()])
    el_offsets = np.cumsum([0] + [m.t.shape[1] for m in bodies.values()])
    joined = kind(np.hstack([m.p for m in bodies.values()]),
                  np.hstack([m.t + off for m, off in zip(bodies.values(), offsets)]))
    n_nodes = joined.p.shape[1]
    keys = _facet_keys(joined.facets, n_nodes)
    order = np.argsort(keys)
    boundaries, subdomains = {}, {}
    for (name, mesh), off, el_off in zip(bodies.items(), offsets, el_offsets):
        subdomains[name] = np.arange(el_off, el_off + mesh.t.shape[1])
        for sub, elements in (mesh.subdomains or {}).items():
            subdomains[f"{name}{SEPARATOR}{sub}"] = np.asarray(elements) + el_off
        own = dict(mesh.boundaries or {})
        own[""] = mesh.boundary_facets()
        for b, facets in own.items():
            wanted = _facet_keys(mesh.facets[:, np.asarray(facets, dtype=np.int64)] + off, n_nodes)
            found = order[np.searchsorted(keys, wanted, sorter=order)]
            boundaries[f"{name}{SEPARATOR}{b}" if b else name] = found
    return joined.with_boundaries(boundaries).with_subdomains(subdomains)
