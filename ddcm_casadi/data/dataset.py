"""Material data sets and the projection onto them (nearest neighbour under the DDCM metric).

The data files are read by :mod:`ddcm_casadi.data.files`; what a data set may hold (its size, the
range of its search coordinates, the balance of its metric) is :mod:`ddcm_casadi.data.limits`.
"""

from __future__ import annotations

import math
import mmap
import os
from dataclasses import dataclass, field

import numpy as np

from ddcm_casadi.errors import InputError
from ddcm_casadi.inputs import positive
from ddcm_casadi.data.files import is_npy, read_csv, read_npy
from ddcm_casadi.data import limits
from ddcm_casadi.data.limits import check_balance, searchable_coordinates
from ddcm_casadi.data.metric import Metric
from ddcm_casadi.data.search import (KDTreeSearch, NeighbourSearch, Rows, Stored, kd_tree, rotated,
                                     search_class, search_name)
from ddcm_casadi.data import ann  # noqa: F401  (registers the certified searches)


#: The metric ``c`` that is fitted to the data (:meth:`Metric.estimated`) rather than given.
ESTIMATED = "estimated"


def _reading_metric(c, components: int | None):
    """The metric whose number of components says which columns of a data file to read: ``c``
    itself, or for ``c = "estimated"`` (fitted after reading) the identity of ``components``."""
    if isinstance(c, str) and c == ESTIMATED:
        if components is None:
            raise InputError("a data file read with c = \"estimated\" needs its number of strain components")
        return 1.0 if components == 1 else np.eye(int(components))
    return c


def check_positive(name: str, value: float) -> float:
    """Return ``value`` as a float, or raise :class:`InputError` unless it is a finite number > 0
    (:func:`ddcm_casadi.inputs.positive`; ``name`` says where it came from)."""
    return positive(value, name)


def _mapping(values: np.ndarray) -> mmap.mmap | None:
    """The memory map under an array (a view of a memory-mapped ``.npy`` file), else ``None``."""
    while isinstance(values, np.ndarray):
        values = values.base
    return values if isinstance(values, mmap.mmap) else None


def _release(*arrays: np.ndarray, least: int = 0) -> None:
    """Leave the pages of memory-mapped arrays (mappings of at least ``least`` bytes) to the page
    cache (``MADV_DONTNEED`` on their mapping: the pages stay cached, shared and clean, but leave
    this process's resident set), so passes over a 1e9-point file do not add the file's 8 GB to
    the process's memory."""
    for mapping in {id(m): m for m in map(_mapping, arrays) if m is not None and len(m) >= least}.values():
        mapping.madvise(mmap.MADV_DONTNEED)


def _stored(values) -> np.ndarray:
    """Data values as stored: float64 and float32 arrays as given (no copy), others as float64."""
    a = np.asarray(values)
    return a if a.dtype in (np.float64, np.float32) else a.astype(np.float64)


#: Data gathered from a memory-mapped file between two releases of its pages: each fault maps
#: the 64 KB around it too (the kernel's fault-around), so at most 1 GB in the process (the
#: gathers of 1e5 states' searches from an 8 GB file mapped 11 GB without the releases).
RELEASE_ROWS = 1 << 14
#: Files from this size on are not kept mapped by a search's gathers (at 1e8 points, 0.8 GB, the
#: releases made 1e5 states 5x slower: every gather faulted again).
RELEASE_BYTES = 1 << 32
#: Rows per block of the data set's pass that fixes its frame (a block of 2^18 rows of 12
#: coordinates is 25 MB of temporaries).
FRAME_BLOCK = 1 << 18


def _principal_frame(metric: Metric, strain: np.ndarray, stress: np.ndarray) -> tuple[np.ndarray, ...]:
    r"""The centre ``m`` and principal axes ``V`` of the data's scaled coordinates ``x_j``
    (:func:`~ddcm_casadi.data.limits.searchable_coordinates`, checked block by block), their
    least and largest values ``lo``, ``hi`` (the data's box) and those of the stored values
    ``[strain, stress]``, column by column (:class:`Stored`), from one pass over blocks of rows:
    with a shift ``x_0`` (the first block's mean, against cancellation), ``S = sum (x_j - x_0)``,
    ``G = sum (x_j - x_0)(x_j - x_0)^T``, ``m = x_0 + S / N`` and ``V`` the eigenvectors of
    ``G - S S^T / N = sum (x_j - m)(x_j - m)^T`` (the largest last).

    Raises
    ------
    InputError
        NaN or infinite values, coordinates out of range, or a metric out of balance with the data.
    """
    n = strain.shape[0]
    d = 2 * metric.k
    lo, hi = np.full(d, np.inf), np.full(d, -np.inf)
    v_lo, v_hi = lo.copy(), hi.copy()
    shift, total, gram = None, np.zeros(d), np.zeros((d, d))
    for a in range(0, n, FRAME_BLOCK):
        e, s = strain[a:a + FRAME_BLOCK], stress[a:a + FRAME_BLOCK]
        X, low, high = searchable_coordinates(metric, e, s, first=a)
        columns = [c for v in (e, s) for c in v.reshape(v.shape[0], -1).T]  # while the pages are in
        v_lo = np.minimum(v_lo, [c.min() for c in columns])
        v_hi = np.maximum(v_hi, [c.max() for c in columns])
        _release(strain, stress)
        lo, hi = np.minimum(lo, low), np.maximum(hi, high)
        if shift is None:
            shift = np.array([X[:, i].mean() for i in range(d)])  # by columns: faster than along axis 0
        X -= shift
        total += [X[:, i].sum() for i in range(d)]
        gram += X.T @ X
    check_balance(metric, lo, hi)
    _, axes = np.linalg.eigh(gram - np.outer(total, total) / n)
    return shift + total / n, axes, lo, hi, (v_lo, v_hi)


@dataclass(frozen=True, eq=False)
class MaterialDataset:
    """A material data set ``Z_D = {(strain*_j, stress*_j)}`` with its metric.

    The DDCM distance is ``d^2 = de . C de + ds . C^-1 ds`` (:class:`~ddcm_casadi.data.metric.Metric`;
    for one component ``c (e - e*)^2 + (s - s*)^2 / c``).

    Parameters
    ----------
    strain, stress : array_like
        The data points: ``(N,)`` for one component per point (bars, trusses), ``(N, k)`` for
        ``k`` Mandel components. Duplicates and any ordering are accepted.
    c : float, (k, k) array_like, Metric or "estimated"
        The metric (Pa): a number for one component, an SPD matrix for ``k``; ``"estimated"``
        fits it to the data (:meth:`~ddcm_casadi.data.metric.Metric.estimated`), so that it is on
        the data's own scale before the data are checked against it.

    Notes
    -----
    Storage per point: the data as given (float64 and float32 arrays are not copied; a
    memory-mapped ``.npy`` file, :meth:`from_npy`, stays in the page cache), and what the searches
    used hold, each built on first use (:meth:`search`): the KD-tree (``kdtree``, and the exact
    search of the others but ``strips``) one float64 array of the search's coordinates (``16 k``
    bytes) and the tree (about 15 bytes); the warm search's graph 36 bytes more. The strip search
    (``strips``, one component) is built from blocks of the stored values (12 bytes a point, neither
    the array nor the tree; over float32 values its keys are those values, so it never reads the
    data again): a float32 file of 1e9 points is searched in 12 GB. The KD-tree's
    coordinates stay float64:
    near the ends of a principal axis a float32 step is ``2^-24`` of the data's extent along it,
    as wide as the spacing of ``2^24 = 1.7e7`` points equally spaced along it (at 1e8 points some
    6 data share each step, so a float32 search would return ties to be re-ranked in float64),
    and scipy's tree is float64 only.
    """

    strain: np.ndarray
    stress: np.ndarray
    c: float | np.ndarray | Metric
    metric: Metric = field(init=False, repr=False)
    _searches: dict = field(init=False, repr=False, default_factory=dict)
    _frame: tuple = field(init=False, repr=False, default=())
    #: The least and largest scaled coordinates of the data (:meth:`Metric.coordinates
    #: <ddcm_casadi.data.metric.Metric.coordinates>`, before centring and rotation), ``(2k,)`` each.
    box: tuple = field(init=False, repr=False, default=())
    _rows: Rows | None = field(init=False, repr=False, default=None)

    def __post_init__(self) -> None:
        if isinstance(self.c, str):
            if self.c != ESTIMATED:
                raise InputError(f"metric c must be a number, a matrix or {ESTIMATED!r}, got {self.c!r}")
            metric = Metric.estimated(self.strain, self.stress)  # fitted to the data (refused if not SPD)
        elif isinstance(self.c, Metric):
            metric = self.c
        elif np.ndim(self.c) == 0:
            metric = Metric(check_positive("metric c", self.c))
        else:
            metric = Metric(self.c)
        k = metric.k
        # No copies: float64 and float32 arrays (memory-mapped files included) are kept as given.
        strain, stress = _stored(self.strain), _stored(self.stress)
        if k == 1:  # a view where ravel() would copy a strided column
            strain, stress = (a if a.ndim == 1 else a.reshape(-1) for a in (strain, stress))
        if strain.size == 0:
            raise InputError("material data set is empty")
        if strain.shape != stress.shape:
            raise InputError("material data set: strain and stress have different lengths")
        if k > 1 and (strain.ndim != 2 or strain.shape[1] != k):
            raise InputError(f"material data set: a {k} x {k} metric needs {k} strain and {k} stress "
                             f"components per point, got shape {strain.shape}")
        object.__setattr__(self, "metric", metric)
        object.__setattr__(self, "c", metric.c if k == 1 else metric.matrix)
        object.__setattr__(self, "strain", strain)
        object.__setattr__(self, "stress", stress)
        # The search works in the principal axes of the scaled data (a rotation: distances are
        # unchanged). Data along a line (a Hookean set) then fill thin slabs instead of fat
        # diagonal boxes, and a state far from the data no longer visits every box its search
        # ball crosses: measured at 1e6 points, 1.9 s -> 6 ms for 9 000 states 1e4 spacings away.
        # The frame comes from one pass over blocks (checked, summed); the coordinates are then
        # made on demand (Rows): in one array only for a backend that needs it (the KD-tree),
        # never for one built from blocks (the strip search over a 1e9-point float32 file).
        mean, axes, lo, hi, extremes = _principal_frame(metric, strain, stress)
        object.__setattr__(self, "_frame", (mean, axes))
        object.__setattr__(self, "box", (lo, hi))
        # With a diagonal metric the coordinates are the stored values scaled, shifted and
        # rotated (Stored): a search may keep the stored values as its keys (the strip search
        # over a float32 file: exact keys, no gathers from the file)
        scales = metric.scales
        stored = None if scales is None else Stored(self._stored_rows, np.result_type(strain.dtype, stress.dtype),
                                                    scales, mean, axes, extremes)
        object.__setattr__(self, "_rows", Rows(strain.shape[0], 2 * k, self._rows_of, stored=stored))

    def _rows_of(self, index) -> np.ndarray:
        """The search coordinates of the data ``index`` (a slice or an index array, :class:`Rows`).
        From a memory-mapped file, the pages read are left to the page cache (:func:`_release`)
        after a block of a build's pass, and, from a file of :data:`RELEASE_BYTES` or more, after
        every :data:`RELEASE_ROWS` data a search gathers."""
        if isinstance(index, slice) or index.size <= RELEASE_ROWS:
            X = self.coordinates(self.strain[index], self.stress[index])
            _release(self.strain, self.stress, least=0 if isinstance(index, slice) else RELEASE_BYTES)
            return X
        return np.concatenate([self._rows_of(index[a:a + RELEASE_ROWS]) for a in range(0, index.size, RELEASE_ROWS)])

    def _stored_rows(self, a: int, b: int) -> np.ndarray:
        """The values ``[strain, stress]`` of the data ``a:b`` as stored (:class:`Stored`), the
        pages read left to the page cache."""
        v = np.column_stack([self.strain[a:b], self.stress[a:b]])
        _release(self.strain, self.stress)
        return v

    @property
    def k(self) -> int:
        """Strain (and stress) components per material point."""
        return self.metric.k

    def __len__(self) -> int:
        return self.strain.shape[0]

    def coordinates(self, strain, stress) -> np.ndarray:
        """The search's coordinates of states ``(strain, stress)``: scaled (Euclidean distance is
        the metric's), centred and rotated to the data's principal axes (:mod:`ddcm_casadi.data.search`).
        Row by row the same arithmetic whatever the number of rows (elementwise, or einsum's own
        loop: no BLAS kernel chosen by size), so a datum's coordinates read in a block equal those
        gathered."""
        mean, axes = self._frame
        X = self.metric.coordinates(strain, stress)
        X -= mean
        return rotated(X, axes)

    def distance2(self, strain, stress, index) -> np.ndarray:
        """Squared DDCM distance ``d^2`` between states and the data points ``index``."""
        shape = (-1,) if self.k == 1 else (-1, self.k)
        de = np.asarray(strain, dtype=float).reshape(shape) - self.strain[index]
        ds = np.asarray(stress, dtype=float).reshape(shape) - self.stress[index]
        return self.metric.distance2(de, ds)

    def search(self, name: str = "kdtree") -> NeighbourSearch:
        """The search backend ``name`` over this data set (:data:`ddcm_casadi.data.search.SEARCHES`),
        built on first use and kept (the KD-tree is built with the data set)."""
        name = search_name(name)
        backend = self._searches.get(name)
        if backend is None:
            backend = self._searches[name] = search_class(name).from_rows(self._rows, self._exact)
        return backend

    def _exact(self) -> KDTreeSearch:
        """The exact KD-tree over the coordinates in one float64 array (``16 k`` bytes a point and
        the tree's 16), built on first use (:meth:`search`, :meth:`k_nearest`) and kept."""
        tree = self._searches.get("kdtree")
        if tree is None:
            tree = self._searches["kdtree"] = KDTreeSearch(kd_tree(self._rows.array()))
        return tree

    def nearest(self, strain, stress, *, search: str = "kdtree", previous=None, stats: dict | None = None) -> np.ndarray:
        """Indices of the data points nearest to each state ``(strain, stress)`` (vectorised), by
        the backend ``search``, warm-started from the assignment ``previous`` if given; ``stats``
        accumulates ``queries`` and ``fallbacks`` (:meth:`NeighbourSearch.nearest`)."""
        return self.search(search).nearest(self.coordinates(strain, stress), previous=previous, stats=stats)

    def k_nearest(self, strain, stress, k: int, *, search: str = "kdtree") -> np.ndarray:
        """Indices of the ``k`` data points nearest to each state, nearest first: ``(n, k)``
        (``k`` is capped at the data set's size), by the backend ``search``."""
        return self.search(search).k_nearest(self.coordinates(strain, stress), k)

    def describe(self) -> dict:
        """Size, metric and strain range, for results files."""
        return dict(points=len(self), c=self.metric.describe(), components=self.k,
                    strain_min=float(self.strain.min()), strain_max=float(self.strain.max()))

    def nearest_warm(self, strain, stress, previous, *, stats: dict | None = None) -> np.ndarray:
        """:meth:`nearest` by the warm-started graph search from the assignment ``previous``
        (exact; :class:`~ddcm_casadi.data.search.GraphSearch`)."""
        return self.nearest(strain, stress, search="graph", previous=previous, stats=stats)

    @property
    def datasets(self) -> tuple["MaterialDataset"]:
        """The data sets of the materials: this one (as :attr:`PointData.datasets`)."""
        return (self,)

    @property
    def offsets(self) -> np.ndarray:
        """Where each material's data start in the global data index (as :attr:`PointData.offsets`)."""
        return np.zeros(1, dtype=np.intp)

    @property
    def secant_modulus(self) -> float:
        """``std(stress) / std(strain)`` (exactly ``E`` for Hookean data): the stiffness the data
        follow, whatever the metric; the metric's own modulus for a set with no spread."""
        se, ss = float(np.std(self.strain)), float(np.std(self.stress))
        return ss / se if se > 0 and ss > 0 else self.metric.modulus

    def point_materials(self, n_points: int) -> tuple[list[Metric], np.ndarray]:
        """The metrics of the materials and the material of each of ``n_points`` points (one here)."""
        return [self.metric], np.zeros(n_points, dtype=np.intp)

    def point_metric(self, n_points: int) -> np.ndarray:
        """Scalar metric ``c`` of each of ``n_points`` one-component material points."""
        return np.full(n_points, self.metric.c)

    @classmethod
    def hookean(cls, youngs_modulus: float, strain_min: float, strain_max: float,
                n_points: int, *, c: float) -> "MaterialDataset":
        """Equally spaced points on ``stress = E strain``, as in the paper."""
        e = check_positive("youngs_modulus", youngs_modulus)
        n = int(n_points)
        if n < 1 or n > limits.MAX_DATA_POINTS:
            raise InputError(f"number of data points must be between 1 and {limits.MAX_DATA_POINTS}, got {n_points!r}")
        if not (math.isfinite(strain_min) and math.isfinite(strain_max)) or strain_min > strain_max:
            raise InputError(f"strain range must be finite with min <= max, got [{strain_min}, {strain_max}]")
        strain = np.linspace(strain_min, strain_max, n)
        return cls(strain, e * strain, c)

    @classmethod
    def hookean_grid(cls, stiffness, strain_min: float, strain_max: float, points_per_axis: int, *,
                     c, grading: float = 1.0) -> "MaterialDataset":
        """A linear law ``stress = D strain`` sampled on a grid of ``points_per_axis^k`` strain
        states in ``[strain_min, strain_max]^k`` (Mandel components; ``D`` a ``k x k`` matrix, e.g.
        :func:`~ddcm_casadi.data.metric.isotropic_elasticity`). With ``grading = 1`` the grid is
        regular, its spacing ``(strain_max - strain_min) / (points_per_axis - 1)`` in every
        component; a larger ``grading`` makes it denser towards zero strain (:func:`graded_axis`)."""
        D = np.atleast_2d(np.asarray(stiffness, dtype=float))
        k = D.shape[0]
        if D.shape != (k, k) or not np.all(np.isfinite(D)):
            raise InputError(f"a Hookean data set needs a finite square stiffness, got shape {D.shape}")
        return cls.from_law(lambda strain: strain @ D.T, k, strain_min, strain_max, points_per_axis, c=c,
                            grading=grading)

    @classmethod
    def from_law(cls, law, components: int, strain_min: float, strain_max: float, points_per_axis: int, *,
                 c, grading: float = 1.0, samples: int | None = None, seed: int = 0,
                 keep=None) -> "MaterialDataset":
        """Any law ``stress = law(strain)`` (``(n, k) -> (n, k)``, Mandel components) sampled on a
        grid of ``points_per_axis^k`` strain states in ``[strain_min, strain_max]^k``, regular or
        graded towards zero strain (``grading``, :func:`graded_axis`), or at ``samples`` states:
        the zero strain and ``samples - 1`` drawn uniformly from that box (``seed``). ``keep(strain) -> bool mask`` (optional) selects
        the states to keep (e.g. principal strains within the range,
        :func:`~ddcm_casadi.data.hyperelastic.principal_strains_within`). States where the law is
        undefined (non-finite stress: a finite-strain law beyond ``det C > 0``) are left out too:
        no material reaches them."""
        k, n = int(components), int(points_per_axis)
        if n < 1 or float(n) ** k > limits.MAX_DATA_POINTS:
            raise InputError(f"points per axis must be between 1 and {int(limits.MAX_DATA_POINTS ** (1 / k))} "
                             f"for {k} components (at most {limits.MAX_DATA_POINTS} points), got {points_per_axis!r}")
        if not (math.isfinite(strain_min) and math.isfinite(strain_max)) or strain_min > strain_max:
            raise InputError(f"strain range must be finite with min <= max, got [{strain_min}, {strain_max}]")
        if samples is not None:
            count = int(samples)
            if count < 1 or count > limits.MAX_DATA_POINTS:
                raise InputError(f"samples must be between 1 and {limits.MAX_DATA_POINTS}, got {samples!r}")
            # the reference state first: a material at rest is a datum, whatever the draw
            strain = np.vstack([np.zeros((1, k)), np.random.default_rng(seed).uniform(strain_min, strain_max,
                                                                                    (count - 1, k))])
        else:
            axis = graded_axis(strain_min, strain_max, n, grading)
            strain = np.stack(np.meshgrid(*([axis] * k), indexing="ij"), axis=-1).reshape(-1, k)
        if keep is not None:
            strain = strain[np.asarray(keep(strain), bool)]
        stress = np.asarray(law(strain), float)
        defined = np.all(np.isfinite(stress), axis=tuple(range(1, stress.ndim)))
        if not np.any(defined):
            raise InputError("the law is undefined at every sampled strain state; narrow the strain range")
        return cls(strain[defined], stress[defined], c)

    @classmethod
    def from_csv(cls, path: str | os.PathLike, *, c, components: int | None = None) -> "MaterialDataset":
        """Read a CSV file with the header ``strain,stress`` (one component per point) or
        ``strain_1,...,strain_k,stress_1,...,stress_k`` (``k`` Mandel components; ``c`` then a
        ``k x k`` SPD matrix). Other columns are ignored.

        A UTF-8 byte-order mark (as written by spreadsheets) is accepted. Read by
        :func:`ddcm_casadi.data.files.read_csv`.

        Raises
        ------
        InputError
            Missing, unreadable, empty, huge, non-UTF-8, one-column or non-numeric file.
        """
        strain, stress = read_csv(path, c=_reading_metric(c, components))
        return cls(strain, stress, c)

    @classmethod
    def from_npy(cls, path: str | os.PathLike, *, c, components: int | None = None) -> "MaterialDataset":
        """Read a numpy ``.npy`` file holding one ``(N, 2k)`` array, the columns of
        :meth:`from_csv` in order: ``strain, stress`` (``k = 1``) or ``strain_1..k, stress_1..k``
        (as ``numpy.save(path, numpy.column_stack([strain, stress]))`` writes it).

        A float64 file is memory-mapped read-only, not read: its data stay in the operating
        system's page cache (shared between processes, dropped and re-read under memory pressure
        instead of swapped) and are never copied; the process itself holds only the search's
        coordinates and tree (``16 k + 16`` bytes per point). Other real and integer types are
        converted (a copy). The file must not change while the data set is in use. Read by
        :func:`ddcm_casadi.data.files.read_npy`.

        Raises
        ------
        InputError
            Missing, unreadable, empty, not ``.npy``, truncated, not real-valued, of another
            shape, or with more than :data:`~ddcm_casadi.data.limits.MAX_MAPPED_DATA_POINTS` points.
        """
        strain, stress = read_npy(path, c=_reading_metric(c, components))
        return cls(strain, stress, c)

    @classmethod
    def from_file(cls, path: str | os.PathLike, *, c, components: int | None = None) -> "MaterialDataset":
        """Read a data file by its suffix: ``.npy`` with :meth:`from_npy`, any other as CSV
        (:meth:`from_csv`). With ``c = "estimated"`` the metric is fitted to the data read, and
        ``components`` (the case's strain components) says which columns to read."""
        reader = cls.from_npy if is_npy(path) else cls.from_csv
        return reader(path, c=c, components=components)


#: The largest grading of a generated grid (:func:`graded_axis`): at 4 the spacing next to zero of
#: 101 points over [-0.01, 0.01] is already 3e-9 of the range's, far below any measured strain.
MAX_GRADING = 4.0


def graded_axis(strain_min: float, strain_max: float, points: int, grading: float = 1.0) -> np.ndarray:
    """``points`` strains from ``strain_min`` to ``strain_max``, denser towards zero.

    Equally spaced in ``t = sign(e) |e|^(1 / grading)``, then ``e = sign(t) |t|^grading``: the ends
    are kept, ``grading = 1`` is :func:`numpy.linspace`, and with ``grading = 2`` the spacing next
    to zero strain is about ``2 / (points - 1)`` of the spacing at the ends (on a range symmetric
    about zero). A continuum's strains decay away from the load, so the many small strains of the
    body need a finer spacing than the few large ones (:mod:`ddcm_casadi.data.extrapolation`,
    coarse data).

    Raises
    ------
    InputError
        ``grading`` not a number in ``[1, MAX_GRADING]``.
    """
    if isinstance(grading, bool) or not isinstance(grading, (int, float, np.integer, np.floating)) \
            or not 1.0 <= float(grading) <= MAX_GRADING:
        raise InputError(f"grading must be a number from 1 (a regular grid) to {MAX_GRADING:g}, got {grading!r}")
    p = float(grading)
    if p == 1.0:
        return np.linspace(strain_min, strain_max, points)
    t = np.linspace(*(math.copysign(abs(e) ** (1.0 / p), e) for e in (strain_min, strain_max)), points)
    return np.sign(t) * np.abs(t) ** p


class PointData:
    """Per-point material data: each material point draws from one of several data sets.

    The data sets are concatenated, so a data assignment is one global index per point, exactly
    as with a single :class:`MaterialDataset`; the search is one vectorised KD-tree query per
    data set (never a loop over points).

    Parameters
    ----------
    datasets : sequence of MaterialDataset
        One data set per material, each with its own metric ``c``.
    material : array_like of int, shape (m,)
        The data set of each material point.
    """

    def __init__(self, datasets, material) -> None:
        self.datasets = tuple(datasets)
        if not self.datasets or not all(isinstance(d, MaterialDataset) for d in self.datasets):
            raise InputError("per-point data needs at least one MaterialDataset")
        material = np.asarray(material)
        if material.ndim != 1 or material.size == 0 or not np.issubdtype(material.dtype, np.integer):
            raise InputError("material must be a non-empty list of integer data-set indices, one per point")
        if material.min() < 0 or material.max() >= len(self.datasets):
            raise InputError(f"material index out of range: data sets are numbered 0..{len(self.datasets) - 1}")
        self.material = material.astype(np.intp)
        sizes = np.array([len(d) for d in self.datasets])
        self.offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.intp)
        if len({d.k for d in self.datasets}) != 1:
            raise InputError("the data sets of one model must have the same number of strain components")
        self.k = self.datasets[0].k
        self.strain = np.concatenate([d.strain for d in self.datasets])
        self.stress = np.concatenate([d.stress for d in self.datasets])
        self._groups = [np.flatnonzero(self.material == k) for k in range(len(self.datasets))]

    def __len__(self) -> int:
        return self.strain.shape[0]

    def point_materials(self, n_points: int) -> tuple[list[Metric], np.ndarray]:
        """The metrics of the materials and the material of each point."""
        if n_points != self.material.size:
            raise InputError(f"material list has {self.material.size} entries, the model has {n_points} points")
        return [d.metric for d in self.datasets], self.material

    def point_metric(self, n_points: int) -> np.ndarray:
        """Scalar metric ``c`` of each one-component material point."""
        metrics, material = self.point_materials(n_points)
        return np.array([m.c for m in metrics])[material]


    def describe(self) -> dict:
        """Sizes, metrics and strain ranges of the sets, and the material of each point."""
        return dict(points=len(self), sets=[d.describe() for d in self.datasets], material=self.material.tolist())

    def _per_point(self, a) -> np.ndarray:
        return np.asarray(a, dtype=float).reshape((-1,) if self.k == 1 else (-1, self.k))

    def nearest(self, strain, stress, *, search: str = "kdtree", previous=None, stats: dict | None = None) -> np.ndarray:
        """The nearest datum of each point in its own set (global indices), by the backend
        ``search`` (:meth:`MaterialDataset.nearest`), warm-started from ``previous`` if given."""
        strain, stress = self._per_point(strain), self._per_point(stress)
        prev = None if previous is None else np.asarray(previous, dtype=np.intp)
        out = np.empty(strain.shape[0], dtype=np.intp)
        for k, pts in enumerate(self._groups):
            if pts.size:
                local = None if prev is None else prev[pts] - self.offsets[k]
                out[pts] = self.datasets[k].nearest(strain[pts], stress[pts], search=search, previous=local,
                                                    stats=stats) + self.offsets[k]
        return out

    def k_nearest(self, strain, stress, k: int, *, search: str = "kdtree") -> np.ndarray:
        """The ``k`` nearest data of each point in its own set (global indices, nearest first;
        ``k`` capped at the smallest set's size), by the backend ``search``."""
        strain, stress = self._per_point(strain), self._per_point(stress)
        k = min(int(k), min(len(d) for d in self.datasets))
        out = np.empty((strain.shape[0], k), dtype=np.intp)
        for j, pts in enumerate(self._groups):
            if pts.size:
                out[pts] = self.datasets[j].k_nearest(strain[pts], stress[pts], k, search=search) + self.offsets[j]
        return out

    def nearest_warm(self, strain, stress, previous, *, stats: dict | None = None) -> np.ndarray:
        """:meth:`nearest` by the warm-started graph search from ``previous``."""
        return self.nearest(strain, stress, search="graph", previous=previous, stats=stats)

    def distance2(self, strain, stress, index) -> np.ndarray:
        """Squared DDCM distance of each point's state to its datum ``index``, under its metric."""
        de = self._per_point(strain) - self.strain[index]
        ds = self._per_point(stress) - self.stress[index]
        out = np.empty(de.shape[0])
        for k, pts in enumerate(self._groups):
            if pts.size:
                out[pts] = self.datasets[k].metric.distance2(de[pts], ds[pts])
        return out
