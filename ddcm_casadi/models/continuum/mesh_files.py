"""Mesh files of the continua: Gmsh ``.msh`` (2.2 and 4.1), ``.vtu`` and ``.xdmf``, read with meshio.

:func:`read_mesh` (re-exported by :mod:`ddcm_casadi.models.continuum.mesh`) reads a triangle or
tetrahedron mesh with its named boundaries and subdomains, and checks it.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
import zlib
from dataclasses import replace
from pathlib import Path
from typing import Sequence

import meshio
import numpy as np
from skfem import MeshTet1, MeshTri1

from ddcm_casadi.errors import InputError
from ddcm_casadi.inputs import input_file
from ddcm_casadi.models.continuum.mesh_checks import Mesh, check_mesh, match_simplices

#: File suffix -> (format, meshio reader). The readers are called directly: ``meshio.read``
#: ends the process (``sys.exit(1)``) when a file does not parse.
READERS = {".msh": ("Gmsh", meshio.gmsh.read), ".vtu": ("VTU", meshio.vtu.read),
           ".xdmf": ("XDMF", meshio.xdmf.read)}


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
        For a missing file, a folder, a missing or unknown suffix, undecodable bytes, a file meshio cannot read, no triangle or tetra
        cells, mixed element kinds, or a mesh :func:`check_mesh` rejects.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"mesh path {path} is a folder, not a mesh file (.msh, .vtu or .xdmf)")
    kind, reader = READERS.get(path.suffix.lower(), (None, None))
    if reader is None:
        if not path.suffix:
            raise InputError(f"mesh file {path} has no suffix; name it .msh, .vtu or .xdmf")
        raise InputError(f"unknown mesh file suffix {path.suffix!r} of {path}; use .msh, .vtu or .xdmf")
    path = input_file(path, "mesh file")
    try:
        raw = reader(str(path))
    except ImportError as err:  # meshio's XDMF reader needs h5py, even for inline XML data
        raise InputError(f"cannot read {path}: meshio needs the Python module {err.name!r} "
                         f"for {path.suffix} files") from None
    except UnicodeDecodeError:  # a binary file that is no mesh (meshio decodes its header as text)
        raise InputError(f"cannot read {kind} file {path}: not a {kind} mesh (undecodable bytes)") from None
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
    which = match_simplices(mesh.facets, f.T) if len(f) else np.zeros(0, dtype=np.int64)
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
