"""Output of continuum results: Mandel helpers and ParaView files; the figures are re-exported.

- :func:`mandel_to_tensor`, :func:`von_mises`, :func:`plane_strain_sigma_zz`: material-point strain and
  stress in Mandel notation
  (2-D plane strain ``[e11, e22, sqrt(2) e12]``; 3-D
  ``[e11, e22, e33, sqrt(2) e23, sqrt(2) e13, sqrt(2) e12]``) as tensors and equivalent stress.
- :func:`write_vtu_series`: one ``.vtu`` file per load step and a ``.pvd`` collection for ParaView.
- :func:`figure_pressure_profile`, :func:`figure_deformed_body`, :func:`figure_convergence`:
  figures (save them with :func:`ddcm_casadi.outputs.plots.save_figure`), and :func:`fit_rate` for the
  slopes of convergence plots, drawn by :mod:`ddcm_casadi.outputs.continuum_figures` and importable
  from here.

Every file is written atomically (temporary file in the target folder, then rename), and every
input is checked before the first file is written (:mod:`ddcm_casadi.outputs.array_checks`), so bad
input leaves the folder as it was. Matplotlib is imported only by the functions that draw.
"""

from __future__ import annotations

import os
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ddcm_casadi.errors import InputError
from ddcm_casadi.io import prepare_output_dir, write_bytes_atomic
from ddcm_casadi.data.metric import MANDEL_INDEX, mandel_to_tensor  # noqa: F401 - re-exported
from ddcm_casadi.outputs.array_checks import as_float, connectivity, coordinates
from ddcm_casadi.outputs.continuum_figures import (
    figure_convergence, figure_deformed_body, figure_pressure_profile, fit_rate,
)

__all__ = ["figure_convergence", "figure_deformed_body", "figure_pressure_profile", "fit_rate", "mandel_to_tensor",
           "plane_strain_sigma_zz", "von_mises", "write_vtu_series"]

# Tensor index of each Mandel component; off-diagonal components carry a factor sqrt(2).
_NODES_PER_CELL = {"vertex": 1, "line": 2, "triangle": 3, "quad": 4, "tetra": 4, "hexahedron": 8,
                   "triangle6": 6, "tetra10": 10}


def _mandel(values: Any, dim: int) -> np.ndarray:
    """Mandel vectors ``(N, k)``, checked (:func:`~ddcm_casadi.data.metric.mandel_to_tensor`'s checks)."""
    mandel_to_tensor(values, dim)
    return as_float("Mandel values", values)


# --------------------------------------------------------------------------- Mandel notation
def plane_strain_sigma_zz(stress: Any, poisson_ratio: Any) -> np.ndarray:
    """The out-of-plane stress of plane strain for an isotropic law: ``nu (sigma_11 + sigma_22)``.

    ``e33 = 0`` gives ``sigma_33 = lambda (e11 + e22) = nu (sigma_11 + sigma_22)``.

    Parameters
    ----------
    stress : array_like, shape (N, 3)
        2-D Mandel stresses.
    poisson_ratio : array_like, shape (N,) or scalar
        Poisson's ratio of each point.
    """
    v = _mandel(stress, 2)
    return np.asarray(poisson_ratio, dtype=float) * (v[:, 0] + v[:, 1])


def von_mises(stress: Any, dim: int, out_of_plane: Any = None) -> np.ndarray:
    """Von Mises equivalent stress ``sqrt(3/2 s:s)`` (``s`` the deviator) of Mandel stresses.

    Parameters
    ----------
    stress : array_like, shape (N, k)
        Mandel stress vectors (see :func:`mandel_to_tensor`).
    dim : {2, 3}
        Spatial dimension.
    out_of_plane : array_like, shape (N,) or scalar, optional
        2-D only: ``sigma_33`` (plane strain: :func:`plane_strain_sigma_zz`; NaN if unknown, which
        makes the result NaN). Default 0: only the in-plane components enter,
        ``sqrt(s11^2 - s11 s22 + s22^2 + 3 s12^2)`` (plane *stress*).

    Returns
    -------
    ndarray, shape (N,)
        Equivalent stress.
    """
    t = mandel_to_tensor(stress, dim, out_of_plane)
    dev = t - np.trace(t, axis1=1, axis2=2)[:, None, None] / 3.0 * np.eye(3)
    return np.sqrt(1.5 * np.einsum("nij,nij->n", dev, dev))


# --------------------------------------------------------------------------- ParaView files
def _data_array(where: str, key: Any, a: Any, n: int, dim: int) -> np.ndarray:
    if not isinstance(key, str) or not key:
        raise InputError(f"{where}: array names must be non-empty strings, got {key!r}")
    what = f"{where} {key!r}"
    arr = np.asarray(a)
    if arr.dtype == bool:
        arr = arr.astype(np.uint8)  # VTK has no boolean type
    if arr.dtype.kind not in "iuf":
        raise InputError(f"{what} must be numeric, got dtype {arr.dtype}")
    if arr.ndim not in (1, 2, 3) or arr.shape[0] != n:
        raise InputError(f"{what} has shape {arr.shape}, expected {n} rows")
    if arr.ndim == 3:
        arr = arr.reshape(n, -1)  # e.g. (n, 3, 3) tensors -> 9 components, as ParaView reads them
    if dim == 2 and arr.ndim == 2 and arr.shape[1] == 2:
        arr = np.column_stack([arr, np.zeros(n, dtype=arr.dtype)])  # ParaView draws 3-vectors
    return arr


def _step(k: int, step: Any, n_nodes: int, n_cells: int, dim: int):
    if not isinstance(step, Mapping):
        raise InputError(f"step {k} must be a dict with keys 'time', 'point_data', 'cell_data'")
    unknown = set(step) - {"time", "point_data", "cell_data"}
    if unknown:
        raise InputError(f"step {k} has unknown keys {sorted(map(str, unknown))}")
    try:
        time = float(step["time"])
    except (KeyError, TypeError, ValueError):
        raise InputError(f"step {k} needs a numeric 'time'") from None
    if not np.isfinite(time):
        raise InputError(f"step {k} time must be finite, got {time}")
    data = []
    for where, n in (("point_data", n_nodes), ("cell_data", n_cells)):
        arrays = step.get(where)
        arrays = {} if arrays is None else arrays
        if not isinstance(arrays, Mapping):
            raise InputError(f"step {k} {where} must be a dict name -> array")
        data.append({key: _data_array(f"step {k} {where}", key, a, n, dim)
                     for key, a in arrays.items()})
    return time, data[0], data[1]


def _cell_blocks(cells: Any, n_nodes: int) -> list[tuple[str, np.ndarray]]:
    """The checked cell blocks ``[(cell_type, connectivity), ...]`` of :func:`write_vtu_series`."""
    if isinstance(cells, (str, bytes)) or not isinstance(cells, Sequence) or not cells:
        raise InputError("cells must be a non-empty list of (cell_type, connectivity)")
    blocks = []
    for b, block in enumerate(cells):
        if not (isinstance(block, Sequence) and len(block) == 2 and block[0] in _NODES_PER_CELL):
            raise InputError(f"cells[{b}] must be (cell_type, connectivity) with cell_type one of "
                             f"{sorted(_NODES_PER_CELL)}")
        kind = block[0]
        blocks.append((kind, connectivity(f"cells[{b}] ({kind})", block[1],
                                          _NODES_PER_CELL[kind], n_nodes)))
    return blocks


def write_vtu_series(out_dir: str | os.PathLike, *, points: Any, cells: Sequence[tuple[str, Any]],
                     steps: Sequence[Mapping[str, Any]], name: str = "solution") -> list[Path]:
    """Write a load-step series for ParaView: one ``.vtu`` file per step and a ``.pvd`` collection.

    Parameters
    ----------
    out_dir : path
        Output folder (created if needed).
    points : array_like, shape (nn, d)
        Reference node coordinates, d = 2 or 3 (2-D points are written with z = 0).
    cells : list of (str, array_like)
        Cell blocks as meshio takes them, e.g. ``[("triangle", conn)]``; types ``"triangle"``,
        ``"tetra"``, ``"triangle6"``, ``"tetra10"`` (also ``"vertex"`` for point clouds,
        ``"line"``, ``"quad"``, ``"hexahedron"``), node order as in meshio / VTK.
    steps : list of dict
        One per load step: ``{"time": float, "point_data": {name: array}, "cell_data":
        {name: array}}``. Point arrays have nn rows, cell arrays one row per cell of all blocks in
        order: shape (n,) or (n, c); (n, 3, 3) tensors are written with 9 components. In 2-D,
        2-component arrays are padded to 3-vectors. Mandel arrays are written as given (convert
        them with :func:`mandel_to_tensor` if wanted).
    name : str
        File stem.

    Returns
    -------
    list of Path
        ``{name}_0000.vtu``, ``{name}_0001.vtu``, ... and last ``{name}.pvd``.

    Raises
    ------
    InputError
        On bad input (e.g. an array with the wrong number of rows, naming the array and the step),
        raised before anything is written.
    """
    import meshio

    if not isinstance(name, str) or not name or Path(name).name != name:
        raise InputError(f"name must be a plain file stem, got {name!r}")
    x = coordinates("points", points)
    n_nodes, dim = x.shape
    blocks = _cell_blocks(cells, n_nodes)
    n_cells = sum(len(c) for _, c in blocks)
    if isinstance(steps, Mapping) or not isinstance(steps, Sequence) or not steps:
        raise InputError("steps must be a non-empty list of dicts, one per load step")
    series = [_step(k, s, n_nodes, n_cells, dim) for k, s in enumerate(steps)]

    # Everything is checked: only now touch the disk.
    out = prepare_output_dir(out_dir)
    xyz = np.column_stack([x, np.zeros(n_nodes)]) if dim == 2 else x
    splits = np.cumsum([len(c) for _, c in blocks])[:-1]  # meshio wants cell data per block
    paths = []
    # meshio writes only to a named file: write into a hidden temporary folder beside the target
    # (same file system), then rename, so a target file is never seen half-written.
    with tempfile.TemporaryDirectory(dir=out, prefix=f".{name}-") as tmp:
        for k, (_, point_data, cell_data) in enumerate(series):
            mesh = meshio.Mesh(xyz, blocks, point_data=point_data,
                               cell_data={key: np.split(a, splits) for key, a in cell_data.items()})
            path = out / f"{name}_{k:04d}.vtu"
            meshio.write(Path(tmp) / path.name, mesh, file_format="vtu")
            os.replace(Path(tmp) / path.name, path)
            paths.append(path)

    root = ET.Element("VTKFile", type="Collection", version="0.1")
    collection = ET.SubElement(root, "Collection")
    for (time, _, _), path in zip(series, paths):
        ET.SubElement(collection, "DataSet", timestep=repr(time), part="0", file=path.name)
    ET.indent(root)
    pvd = ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"
    paths.append(write_bytes_atomic(out / f"{name}.pvd", pvd))
    return paths
