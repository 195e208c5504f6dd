"""Output of continuum results: Mandel helpers, ParaView files and figures.

- :func:`mandel_to_tensor`, :func:`von_mises`: material-point strain and stress in Mandel notation
  (2-D plane strain ``[e11, e22, sqrt(2) e12]``; 3-D
  ``[e11, e22, e33, sqrt(2) e23, sqrt(2) e13, sqrt(2) e12]``) as tensors and equivalent stress.
- :func:`write_vtu_series`: one ``.vtu`` file per load step and a ``.pvd`` collection for ParaView.
- :func:`figure_pressure_profile`, :func:`figure_deformed_body`, :func:`figure_convergence`:
  figures (save them with :func:`ddcm_casadi.outputs.plots.save_figure`), and :func:`fit_rate` for the
  slopes of convergence plots.

Every file is written atomically (temporary file in the target folder, then rename), and every
input is checked before the first file is written, so bad input leaves the folder as it was.
Matplotlib is imported only by the functions that draw.
"""

from __future__ import annotations

import os
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ddcm_casadi.errors import InputError
from ddcm_casadi.io import prepare_output_dir, write_bytes_atomic

if TYPE_CHECKING:
    from matplotlib.figure import Figure

# Tensor index of each Mandel component; off-diagonal components carry a factor sqrt(2).
_MANDEL_INDEX = {2: [(0, 0), (1, 1), (0, 1)],
                 3: [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]}
_NODES_PER_CELL = {"line": 2, "triangle": 3, "quad": 4, "tetra": 4, "hexahedron": 8,
                   "triangle6": 6, "tetra10": 10}


# --------------------------------------------------------------------------- input checks
def _as_float(name: str, a: Any) -> np.ndarray:
    try:
        return np.asarray(a, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an array of numbers") from None


def _coordinates(name: str, a: Any, dims: tuple[int, ...] = (2, 3)) -> np.ndarray:
    x = _as_float(name, a)
    if x.ndim != 2 or x.shape[1] not in dims or x.shape[0] == 0:
        want = " or ".join(f"(n, {d})" for d in dims)
        raise InputError(f"{name} must have shape {want} with n >= 1, got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise InputError(f"{name} must be finite (no NaN or infinity)")
    return x


def _connectivity(name: str, a: Any, nodes_per_cell: int, n_nodes: int) -> np.ndarray:
    c = np.asarray(a)
    if c.dtype.kind not in "iu" or c.ndim != 2 or c.shape[1] != nodes_per_cell:
        raise InputError(f"{name} must be an integer array of shape (n, {nodes_per_cell}), "
                         f"got {c.dtype} {c.shape}")
    if c.size and (c.min() < 0 or c.max() >= n_nodes):
        raise InputError(f"{name} refers to node {int(c.min() if c.min() < 0 else c.max())}, "
                         f"outside 0..{n_nodes - 1}")
    return c


def _mandel(values: Any, dim: int) -> np.ndarray:
    if dim not in _MANDEL_INDEX:
        raise InputError(f"dim must be 2 or 3, got {dim!r}")
    v = _as_float("Mandel values", values)
    k = len(_MANDEL_INDEX[dim])
    if v.ndim != 2 or v.shape[1] != k:
        raise InputError(f"Mandel values for dim={dim} must have shape (N, {k}), got {v.shape}")
    return v


# --------------------------------------------------------------------------- Mandel notation
def mandel_to_tensor(values: Any, dim: int) -> np.ndarray:
    """Symmetric 3 x 3 tensors from Mandel vectors.

    Parameters
    ----------
    values : array_like, shape (N, k)
        Mandel vectors, k = 3 for ``dim=2`` (``[a11, a22, sqrt(2) a12]``) and k = 6 for ``dim=3``
        (``[a11, a22, a33, sqrt(2) a23, sqrt(2) a13, sqrt(2) a12]``).
    dim : {2, 3}
        Spatial dimension.

    Returns
    -------
    ndarray, shape (N, 3, 3)
        The tensors. In 2-D the third row and column are zero: the plane-strain stress
        ``sigma_33`` is not part of the Mandel vector, so it is *not* filled in here.
    """
    v = _mandel(values, dim)
    t = np.zeros((v.shape[0], 3, 3))
    for c, (i, j) in enumerate(_MANDEL_INDEX[dim]):
        t[:, i, j] = t[:, j, i] = v[:, c] if i == j else v[:, c] / np.sqrt(2.0)
    return t


def von_mises(stress: Any, dim: int) -> np.ndarray:
    """Von Mises equivalent stress ``sqrt(3/2 s:s)`` (``s`` the deviator) of Mandel stresses.

    Parameters
    ----------
    stress : array_like, shape (N, k)
        Mandel stress vectors (see :func:`mandel_to_tensor`).
    dim : {2, 3}
        Spatial dimension.

    Returns
    -------
    ndarray, shape (N,)
        Equivalent stress. In 2-D only the in-plane components enter (``sigma_33 = 0``):
        ``sqrt(s11^2 - s11 s22 + s22^2 + 3 s12^2)``. For the plane-strain value including
        ``sigma_33``, pass the 3-D Mandel vector with ``dim=3``.
    """
    t = mandel_to_tensor(stress, dim)
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
        ``"tetra"``, ``"triangle6"``, ``"tetra10"`` (also ``"line"``, ``"quad"``,
        ``"hexahedron"``), node order as in meshio / VTK.
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
    x = _coordinates("points", points)
    n_nodes, dim = x.shape
    if isinstance(cells, (str, bytes)) or not isinstance(cells, Sequence) or not cells:
        raise InputError("cells must be a non-empty list of (cell_type, connectivity)")
    blocks = []
    for b, block in enumerate(cells):
        if not (isinstance(block, Sequence) and len(block) == 2 and block[0] in _NODES_PER_CELL):
            raise InputError(f"cells[{b}] must be (cell_type, connectivity) with cell_type one of "
                             f"{sorted(_NODES_PER_CELL)}")
        kind = block[0]
        blocks.append((kind, _connectivity(f"cells[{b}] ({kind})", block[1],
                                           _NODES_PER_CELL[kind], n_nodes)))
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


# --------------------------------------------------------------------------- figures
def _profile(what: str, d: Any, keys: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(d, Mapping) or any(k not in d for k in keys):
        raise InputError(f"{what} must be a dict with keys {list(keys)}")
    x, p = _as_float(f"{what} x", d["x"]), _as_float(f"{what} pressure", d["pressure"])
    if x.ndim != 1 or x.shape != p.shape:
        raise InputError(f"{what} x and pressure must be 1-D of equal length, got {x.shape} and {p.shape}")
    order = np.argsort(x, kind="stable")
    return x[order], p[order]


def _mm_label(label: str) -> str:
    """The axis is drawn in mm: show a trailing metre unit as millimetres."""
    for m, mm in (("(m)", "(mm)"), ("[m]", "[mm]")):
        if label.endswith(m):
            return label[: -len(m)] + mm
    return label


def figure_pressure_profile(runs: Sequence[Mapping[str, Any]], *,
                            hertz: Mapping[str, Any] | None = None, xlabel: str = "x (m)",
                            title: str = "") -> Figure:
    """Contact pressure along the contact surface, several runs and optionally the Hertz solution.

    Parameters
    ----------
    runs : list of dict
        ``{"label": str, "x": (nc,) m, "pressure": (nc,) Pa, "converged": bool,
        "style": dict (optional, matplotlib keyword arguments, e.g. ``{"marker": "o", "ls": ""}``
        for data-driven runs)}``. Drawn as lines by default, sorted by x. A run that did not
        converge is still drawn, circled in red, and labelled "... (NOT CONVERGED)" in red.
    hertz : dict, optional
        ``{"x": array, "pressure": array, "label": str}``: a dashed black line.
    xlabel : str
        Label of the coordinate; the axis is in mm, so a trailing "(m)" is shown as "(mm)".
    title : str
        Axes title.

    Returns
    -------
    Figure
        Pressure in MPa against x in mm.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.6), constrained_layout=True)
    ax = fig.add_subplot()
    if hertz is not None:
        x, p = _profile("hertz", hertz, ("x", "pressure"))
        ax.plot(x * 1e3, p * 1e-6, "k--", lw=1.0, label=str(hertz.get("label", "Hertz")), zorder=1)
    failed = []
    for i, run in enumerate(runs):
        x, p = _profile(f"runs[{i}]", run, ("label", "x", "pressure", "converged"))
        style = {"lw": 1.4} | dict(run.get("style") or {})
        label = str(run["label"])
        if not run["converged"]:
            label += " (NOT CONVERGED)"
            failed.append(label)
        ax.plot(x * 1e3, p * 1e-6, label=label, zorder=2, **style)
        if not run["converged"]:
            ax.plot(x * 1e3, p * 1e-6, "o", ms=9, mfc="none", mec="red", mew=1.5, zorder=3)
    ax.set_xlabel(_mm_label(xlabel))
    ax.set_ylabel("contact pressure (MPa)")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if ax.get_legend_handles_labels()[1]:
        for text in ax.legend(fontsize=8).get_texts():
            if text.get_text() in failed:
                text.set_color("red")
    return fig


def _nice_scale(x: float) -> float:
    """``x`` rounded down to two significant digits (the largest displacement stays <= 5 %)."""
    p = 10.0 ** (np.floor(np.log10(x)) - 1)
    return float(np.floor(x / p * (1 + 1e-12)) * p)


def _boundary_edges(tri: np.ndarray) -> np.ndarray:
    """Edges that belong to one triangle only: the outline of a 2-D mesh."""
    edges = np.sort(tri[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    return unique[count == 1]


def _draw_obstacles(ax, obstacles: Sequence[Mapping[str, Any]], lo: np.ndarray,
                    hi: np.ndarray) -> None:
    from matplotlib.patches import Circle, Polygon

    for i, ob in enumerate(obstacles):
        kind = ob.get("kind") if isinstance(ob, Mapping) else None
        if kind == "circle":
            c, r = _as_float(f"obstacles[{i}] center", ob.get("center")), ob.get("radius")
            if c.shape != (2,) or not isinstance(r, (int, float)) or not r > 0:
                raise InputError(f"obstacles[{i}] circle needs center (x, y) and radius > 0")
            ax.add_patch(Circle(tuple(c), float(r), facecolor="0.85", edgecolor="0.2", lw=1.0,
                                zorder=0))
        elif kind == "plane":
            p, n = (_as_float(f"obstacles[{i}] {k}", ob.get(k)) for k in ("point", "normal"))
            if p.shape != (2,) or n.shape != (2,) or not np.linalg.norm(n) > 0:
                raise InputError(f"obstacles[{i}] plane needs point (x, y) and a non-zero normal")
            t = np.array([-n[1], n[0]]) / np.linalg.norm(n)
            # long enough to cross the whole view from wherever the point lies
            half = 2.0 * (np.linalg.norm(hi - lo) + np.linalg.norm(p - (lo + hi) / 2))
            ax.plot(*np.array([p - half * t, p + half * t]).T, color="0.2", lw=1.5, zorder=0)
        elif kind == "outline":
            pts = _as_float(f"obstacles[{i}] points", ob.get("points"))
            if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 3:
                raise InputError(f"obstacles[{i}] outline needs at least 3 points (x, y)")
            ax.add_patch(Polygon(pts, closed=True, facecolor="0.85", edgecolor="0.2", lw=1.0, zorder=0))
        else:
            raise InputError(f"obstacles[{i}] must be a dict with kind 'circle', 'plane' or 'outline'")


def figure_deformed_body(points: Any, cells: Any, *, displacement: Any, values: Any,
                         value_label: str, scale: float | None = None,
                         contact_points: Any = None,
                         obstacles: Sequence[Mapping[str, Any]] | None = None,
                         title: str = "") -> Figure:
    """The deformed body coloured by a stress-like quantity.

    Parameters
    ----------
    points : array_like, shape (nn, 2) or (nn, 3)
        Reference node coordinates.
    cells : array_like of int, shape (ne, 3)
        2-D: the triangles (corner nodes); 3-D: the boundary triangles of the body's surface.
    displacement : array_like, shape (nn, d)
        Node displacements.
    values : array_like, shape (ne,) or (nn,)
        Per triangle or per node (per triangle if ne == nn), in Pa, e.g. von Mises stress;
        shown in MPa. In 3-D node values are averaged over each surface triangle.
    value_label : str
        Colour bar label (" (MPa)" is appended).
    scale : float, optional
        Displacement magnification. Default: the largest displacement is 5 % of the body's size
        (rounded down to two digits). Given in the title either way.
    contact_points : array_like, optional
        Active contact nodes, drawn as small red dots: either node indices (int, shape (nc,)),
        drawn on the magnified deformed mesh, or coordinates (nc, d) drawn as given (already
        deformed; they match the drawn mesh only if ``scale`` is 1).
    obstacles : list of dict, optional
        2-D rigid obstacles, drawn at their true position (not magnified) and clipped to the
        body's view: ``{"kind": "circle", "center": (x, y), "radius": r}``,
        ``{"kind": "plane", "point": (x, y), "normal": (nx, ny)}`` or
        ``{"kind": "outline", "points": [(x, y), ...]}`` (a closed polygon). Ignored in 3-D.
    title : str
        Title; " (displacements x <scale>)" is added.

    Returns
    -------
    Figure
        2-D: ``tripcolor`` of the deformed mesh with the undeformed outline in thin grey;
        3-D: the deformed surface triangles, equal aspect.
    """
    from matplotlib.cm import ScalarMappable
    from matplotlib.collections import LineCollection
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from matplotlib.tri import Triangulation
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    x = _coordinates("points", points)
    n_nodes, dim = x.shape
    tri = _connectivity("cells", cells, 3, n_nodes)
    u = _as_float("displacement", displacement)
    if u.shape != x.shape or not np.all(np.isfinite(u)):
        raise InputError(f"displacement must be finite with shape {x.shape}, got {u.shape}")
    v = _as_float("values", values) * 1e-6  # Pa -> MPa
    if v.ndim != 1 or len(v) not in (len(tri), n_nodes):
        raise InputError(f"values must have shape ({len(tri)},) per triangle or ({n_nodes},) "
                         f"per node, got {v.shape}")
    per_cell = len(v) == len(tri)
    size = float(np.max(np.ptp(x, axis=0)))
    umax = float(np.max(np.linalg.norm(u, axis=1)))
    if scale is None:
        scale = _nice_scale(0.05 * size / umax) if umax > 0 and size > 0 else 1.0
    elif not (isinstance(scale, (int, float)) and np.isfinite(scale) and scale >= 0):
        raise InputError(f"scale must be a finite number >= 0, got {scale!r}")
    y = x + scale * u

    dots = None
    if contact_points is not None:
        c = np.asarray(contact_points)
        if c.size == 0:
            dots = np.empty((0, dim))
        elif c.ndim == 1 and c.dtype.kind in "iu":
            dots = y[_connectivity("contact_points", c[:, None], 1, n_nodes)[:, 0]]
        else:
            dots = _coordinates("contact_points", c, (dim,))

    fig = Figure(figsize=(7.0, 5.2), constrained_layout=True)
    if dim == 2:
        ax = fig.add_subplot()
        mesh = Triangulation(y[:, 0], y[:, 1], tri)
        mappable = (ax.tripcolor(mesh, facecolors=v, cmap="viridis") if per_cell
                    else ax.tripcolor(mesh, v, shading="gouraud", cmap="viridis"))
        outline = x[_boundary_edges(tri)]
        ax.add_collection(LineCollection(outline, colors="0.4", linewidths=0.8, zorder=3))
        # The view is the body's (reference and deformed); obstacles are clipped to it.
        lo, hi = np.minimum(x.min(0), y.min(0)), np.maximum(x.max(0), y.max(0))
        margin = 0.1 * max(float(np.max(hi - lo)), 1e-300)
        _draw_obstacles(ax, obstacles or [], lo, hi)
        ax.set_xlim(lo[0] - margin, hi[0] + margin)
        ax.set_ylim(lo[1] - margin, hi[1] + margin)
        ax.set_aspect("equal")
        if dots is not None:
            ax.plot(dots[:, 0], dots[:, 1], "o", color="red", ms=3, zorder=4)
    else:
        ax = fig.add_subplot(projection="3d")
        face = v if per_cell else v[tri].mean(axis=1)
        mappable = ScalarMappable(Normalize(face.min(), face.max()), cmap="viridis")
        ax.add_collection3d(Poly3DCollection(y[tri], facecolors=mappable.to_rgba(face),
                                             edgecolors="0.2", linewidths=0.3))
        # Equal aspect: a cube around the deformed body.
        centre, half = (y.min(0) + y.max(0)) / 2, max(float(np.max(np.ptp(y, axis=0))), 1e-300) / 2
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(centre[2] - half, centre[2] + half)
        ax.set_box_aspect((1, 1, 1))
        if dots is not None:
            ax.scatter(*dots.T, color="red", s=6, depthshade=False)
    fig.colorbar(mappable, ax=ax, label=f"{value_label} (MPa)", shrink=0.8)
    note = f"displacements x {scale:g}"
    ax.set_title(f"{title} ({note})" if title else note)
    return fig


def figure_convergence(h: Any, errors: Sequence[Any], *, labels: Sequence[str],
                       rates: Mapping[str, float] | None = None, xlabel: str = "h (m)",
                       ylabel: str = "relative error", title: str = "") -> Figure:
    """Log-log plot of error series against mesh size (or data size).

    Parameters
    ----------
    h : array_like
        Abscissae: one 1-D array shared by all series, or one array per series.
    errors : list of array_like
        The error series. Non-positive values cannot be shown on log axes and are left out.
    labels : list of str
        One legend label per series.
    rates : dict, optional
        label -> fitted slope (e.g. from :func:`fit_rate`), shown in the legend.
    xlabel, ylabel, title : str
        Axis labels and title.

    Returns
    -------
    Figure
    """
    from matplotlib.figure import Figure

    series = [_as_float(f"errors[{i}]", e) for i, e in enumerate(errors)]
    labels = [str(s) for s in labels]
    if len(labels) != len(series):
        raise InputError(f"labels has {len(labels)} entries for {len(series)} error series")
    rates = dict(rates or {})
    unknown = set(rates) - set(labels)
    if unknown:
        raise InputError(f"rates has labels not in labels: {sorted(unknown)}")
    try:
        grid = np.asarray(h, dtype=float)
    except (TypeError, ValueError):  # ragged: one array per series
        grid = None
    if grid is not None and grid.ndim == 1:
        hs = [grid] * len(series)
    elif grid is not None and grid.ndim != 2:
        raise InputError(f"h must be a 1-D array or one array per series, got shape {grid.shape}")
    else:
        hs = [_as_float(f"h[{i}]", a) for i, a in enumerate(h)]
    if len(hs) != len(series):
        raise InputError(f"h has {len(hs)} arrays for {len(series)} error series")

    fig = Figure(figsize=(6.4, 4.6), constrained_layout=True)
    ax = fig.add_subplot()
    for i, (x, e, label) in enumerate(zip(hs, series, labels)):
        if x.ndim != 1 or x.shape != e.shape:
            raise InputError(f"errors[{i}] has shape {e.shape}, h has {x.shape}")
        ok = (x > 0) & (e > 0)
        if label in rates:
            label = f"{label} (rate {rates[label]:.2f})"
        ax.loglog(x[ok], e[ok], "o-", ms=5, label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    if series:
        ax.legend(fontsize=8)
    return fig


def fit_rate(x: Any, y: Any) -> float:
    """Least-squares slope of ``log y`` against ``log x`` (the convergence rate).

    Points where x or y is not positive (or not finite) are ignored.

    Raises
    ------
    InputError
        If x and y differ in shape or fewer than 2 usable points with distinct x remain.
    """
    x, y = _as_float("x", x), _as_float("y", y)
    if x.ndim != 1 or x.shape != y.shape:
        raise InputError(f"x and y must be 1-D of equal length, got {x.shape} and {y.shape}")
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    lx, ly = np.log(x[ok]), np.log(y[ok])
    dx = lx - lx.mean() if lx.size else lx
    if lx.size < 2 or not np.any(dx):
        raise InputError(f"fit_rate needs >= 2 points with distinct x > 0 and y > 0, got {lx.size}")
    return float(dx @ (ly - ly.mean()) / (dx @ dx))
