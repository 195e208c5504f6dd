r"""Nearest-neighbour search over material data, behind one small interface.

A search backend answers, for query states ``q_i``, the data ``y_j`` nearest to them. It works in
the metric's scaled coordinates (:meth:`~ddcm_casadi.data.metric.Metric.coordinates`, centred and
rotated by :class:`~ddcm_casadi.data.dataset.MaterialDataset`), where the DDCM distance
``d^2 = de . C de + ds . C^-1 ds`` is the Euclidean one, ``d(q, y) = |q - y|``: a backend never
sees the metric, and any Euclidean search fits.

The interface (:class:`NeighbourSearch`):

- ``build(points, *, base=None)``: the backend over the ``(N, d)`` coordinates (``base``: an
  exact search over the same points that the backend may reuse instead of building its own);
- ``from_rows(rows, exact)``: the backend over a data set's coordinates made on demand
  (:class:`Rows`); by default ``build`` over them in one array, reusing the data set's exact
  search ``exact()``; the strip search is built from blocks of rows instead, so a data set of
  1e9 points needs neither the array (16 GB) nor the KD-tree;
- ``nearest(queries, *, previous=None, stats=None)``: the index of the datum nearest each query,
  optionally warm-started from a previous assignment ``previous``;
- ``k_nearest(queries, k)``: the ``k`` nearest, nearest first;
- ``approximation`` (``exact`` when 0): every returned datum ``j`` satisfies
  ``d(q, j) <= (1 + approximation) min_l d(q, l)``.

Backends are registered by name (:data:`SEARCHES`, :func:`register_search`) and chosen by
``[ddcm] search = "..."`` in a case file (:class:`~ddcm_casadi.drivers.ddcm_options.DDCMOptions`).
The first two are exact:

- ``kdtree`` (:class:`KDTreeSearch`): a cold query of :class:`scipy.spatial.cKDTree`;
- ``graph`` (:class:`GraphSearch`; alias ``warm``): a walk on the data's k-nearest-neighbour
  graph from the previous assignment (Eggersmann et al., 2021), certified by the triangle
  inequality and completed by the KD-tree where the certificate fails.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Callable, ClassVar

import numpy as np
from scipy.spatial import cKDTree

from ddcm_casadi.errors import InputError

#: Rows per block where a pass over the data would otherwise allocate a full-size temporary.
CHUNK = 1 << 16


@dataclass(frozen=True, eq=False)
class Stored:
    r"""Coordinates that are an affine image of the values as stored, column by column scaled:
    ``x = (scale * v - mean) @ axes`` (``v`` a stored row, ``axes`` orthogonal), so that
    ``|x - x'| = |scale * (v - v')|``: a search may keep the stored values as its keys, search
    in the scaled coordinates ``y = scale * v`` and map its queries by ``y = x @ axes^T + mean``.

    Attributes
    ----------
    read : callable
        ``read(a, b)``: the stored rows ``a:b``, ``(m, d)`` of :attr:`dtype`.
    dtype : numpy.dtype
        The stored values' type (float32 values are exact in float64).
    scale, mean : (d,) float64
    axes : (d, d) float64
    extremes : ((d,), (d,)) float64, optional
        The least and largest stored values of each column, where known (a pass over the
        values saved).
    """

    read: Callable[[int, int], np.ndarray]
    dtype: np.dtype
    scale: np.ndarray
    mean: np.ndarray
    axes: np.ndarray
    extremes: tuple[np.ndarray, np.ndarray] | None = None

    def unrotated(self, x: np.ndarray) -> np.ndarray:
        """``x @ axes^T + mean``: coordinates ``x`` back in the scaled stored frame ``y``."""
        out = rotated(x, self.axes.T)
        out += self.mean
        return out


def rotated(X: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``X @ R`` (``R`` small and square) row by row with the same arithmetic whatever the number
    of rows (elementwise, or einsum's own loop: no BLAS kernel chosen by size), so that a row's
    product in a block equals the row's alone; two columns by columns, 5x faster than einsum
    here (2.3 against 11 ns a row)."""
    if X.shape[1] > 2:
        return np.einsum("ij,jk->ik", X, R)
    out = np.empty_like(X)
    for j in range(2):
        np.multiply(X[:, 0], R[0, j], out=out[:, j])
        out[:, j] += X[:, 1] * R[1, j]
    return out


class Rows:
    """The ``(N, d)`` float64 coordinates of a data set, computed on demand from its stored data
    (:class:`~ddcm_casadi.data.dataset.MaterialDataset`): by index (``rows[idx]``, any shape of
    ``idx``; a slice reads a block), never all at once unless :meth:`array` is called.

    Parameters
    ----------
    n, dim : int
        Rows and coordinates.
    rows_of : callable
        ``rows_of(index)``, ``index`` a slice or a 1-D integer array: those rows, ``(m, dim)``
        float64; the same values for a row whichever way it is asked for.
    stored : Stored, optional
        The rows as an affine image of the stored values (:class:`Stored`), where they are one:
        a search may keep those values as its keys instead of rounding the rows.
    """

    dtype = np.dtype(np.float64)

    def __init__(self, n: int, dim: int, rows_of: Callable[[slice | np.ndarray], np.ndarray], *,
                 stored: Stored | None = None) -> None:
        self.shape, self._of, self._array, self.stored = (int(n), int(dim)), rows_of, None, stored

    def read(self, a: int, b: int) -> np.ndarray:
        """The rows ``a:b``."""
        return self._of(slice(a, b))

    def __getitem__(self, index) -> np.ndarray:
        if isinstance(index, slice):
            return self._of(index)
        index = np.asarray(index)
        return self._of(index.ravel()).reshape(index.shape + (self.shape[1],))

    def array(self) -> np.ndarray:
        """All rows in one float64 array (made once, by blocks, and kept)."""
        if self._array is None:
            X = np.empty(self.shape)
            for a in range(0, self.shape[0], CHUNK):
                X[a:a + CHUNK] = self.read(a, a + CHUNK)
            self._array = X
        return self._array


class NeighbourSearch(ABC):
    """A nearest-neighbour search over fixed points in Euclidean coordinates (see the module)."""

    #: The registry name (:data:`SEARCHES`).
    name: ClassVar[str] = ""
    #: ``eps >= 0``: a returned datum is at most ``1 + eps`` times as far as the nearest (0: exact).
    approximation: ClassVar[float] = 0.0

    @classmethod
    def available(cls) -> bool:
        """Whether the libraries the backend needs are installed (an optional extra may be missing)."""
        return True

    @property
    def exact(self) -> bool:
        """Whether :meth:`nearest` returns a nearest datum (ties may go either way)."""
        return self.approximation == 0.0

    @classmethod
    @abstractmethod
    def build(cls, points: np.ndarray, *, base: "NeighbourSearch | None" = None) -> "NeighbourSearch":
        """The search over ``points`` ``(N, d)`` (kept, not copied); ``base``, an exact search over
        the same array, may be reused."""

    @classmethod
    def from_rows(cls, rows: Rows, exact: Callable[[], "NeighbourSearch"]) -> "NeighbourSearch":
        """The search over a data set's coordinates given as :class:`Rows`; ``exact()`` is the data
        set's exact search over ``rows.array()`` (built on its first call, then kept). By default
        :meth:`build` over that array, reusing the exact search; a backend built from blocks of
        rows overrides it and never asks for the array (nor the KD-tree)."""
        base = exact()
        return cls.build(base.points, base=base)

    @property
    @abstractmethod
    def points(self) -> np.ndarray:
        """The ``(N, d)`` coordinates searched."""

    @abstractmethod
    def nearest(self, queries: np.ndarray, *, previous: np.ndarray | None = None,
                stats: dict | None = None) -> np.ndarray:
        """Index of the point nearest each row of ``queries`` ``(n, d)``: ``(n,)`` ``intp``.

        ``previous`` (``(n,)``), a previous answer, may warm-start the search; ``stats``, if
        given, accumulates ``queries`` (and, for a certified search, ``fallbacks``)."""

    @abstractmethod
    def k_nearest(self, queries: np.ndarray, k: int) -> np.ndarray:
        """Indices of the ``k`` points nearest each query, nearest first: ``(n, k)`` (``k``
        capped at the number of points)."""


def _count(stats: dict | None, queries: int, fallbacks: int = 0) -> None:
    if stats is not None:
        stats["queries"] = stats.get("queries", 0) + int(queries)
        stats["fallbacks"] = stats.get("fallbacks", 0) + int(fallbacks)


def kd_tree(X: np.ndarray) -> cKDTree:
    """The KD-tree over the coordinates ``X`` (kept, not copied). Sliding-midpoint splits build
    2-3x faster than scipy's default medians at the same query time (measured at 1e7 points in 2
    coordinates and 1e6 in 12). In 2 coordinates leaves of 32 points halve the nodes' memory
    against the default 16 (27 -> 16 bytes per point beside the coordinates) at the same query
    time; in 12 they cost 15 % more query time, and the nodes are small beside 96 bytes of
    coordinates per point."""
    return cKDTree(X, leafsize=32 if X.shape[1] <= 2 else 16, balanced_tree=False, compact_nodes=False)


class KDTreeSearch(NeighbourSearch):
    """Exact search: a cold, vectorised KD-tree query (``previous`` is not needed)."""

    name = "kdtree"

    def __init__(self, tree: cKDTree) -> None:
        self.tree = tree

    @classmethod
    def build(cls, points: np.ndarray, *, base: NeighbourSearch | None = None) -> "KDTreeSearch":
        if isinstance(base, KDTreeSearch) and base.points is points:
            return base
        return cls(kd_tree(points))

    @property
    def points(self) -> np.ndarray:
        return self.tree.data

    def nearest(self, queries, *, previous=None, stats=None) -> np.ndarray:
        _, idx = self.tree.query(queries)
        idx = np.asarray(idx, dtype=np.intp)
        _count(stats, idx.size)
        return idx

    def k_nearest(self, queries, k: int) -> np.ndarray:
        k = min(int(k), self.tree.n)
        _, idx = self.tree.query(queries, k=k)
        return np.asarray(idx, dtype=np.intp).reshape(-1, k)


class GraphSearch(NeighbourSearch):
    r"""Exact search warm-started from a previous assignment (Eggersmann et al., 2021).

    Each query walks the k-nearest-neighbour graph of the data from its previous datum to the
    nearest datum among a datum and its neighbours. The result ``j`` is certified when
    ``d(q, j) < r_k(j) / 2`` (``r_k`` the distance from ``j`` to its k-th neighbour): any datum
    outside the neighbourhood is then farther from ``q`` than ``j`` (triangle inequality).
    Uncertified queries, and walks that do not settle, fall back to the KD-tree query, so the
    answer is always an exact nearest datum. Without ``previous`` it is the KD-tree query.

    Attributes
    ----------
    neighbours : (N, k) int32 or intp array
        Each point's ``k`` nearest other points.
    radius : (N,) float32 array
        ``r_k``, rounded down to float32 (a smaller radius only certifies fewer queries).
    """

    name = "graph"
    #: Neighbours per datum in the graph.
    NEIGHBOURS = 8
    #: Steps of the walk before a query falls back to the KD-tree.
    MAX_WALK = 8

    def __init__(self, tree: KDTreeSearch, neighbours: np.ndarray, radius: np.ndarray) -> None:
        self.tree, self.neighbours, self.radius = tree, neighbours, radius

    @classmethod
    def build(cls, points: np.ndarray, *, base: NeighbourSearch | None = None) -> "GraphSearch":
        tree = KDTreeSearch.build(points, base=base)
        n = points.shape[0]
        k = min(cls.NEIGHBOURS, n - 1)
        # Compact and built in blocks: int32 indices, radii rounded down to float32, 36 bytes per
        # datum at k = 8; the query of all data at once held 144 more (1e8 points: 14 GB).
        nbrs = np.zeros((n, max(k, 0)), dtype=np.int32 if n < 2**31 else np.intp)
        radius = np.zeros(n, dtype=np.float32)
        for a in range(0, n if k >= 1 else 0, CHUNK):
            dist, idx = tree.tree.query(points[a:a + CHUNK], k=k + 1)
            nbrs[a:a + CHUNK] = idx[:, 1:]
            r = dist[:, -1].astype(np.float32)
            radius[a:a + CHUNK] = np.where(r > dist[:, -1], np.nextafter(r, np.float32(0)), r)
        return cls(tree, nbrs, radius)

    @property
    def points(self) -> np.ndarray:
        return self.tree.points

    def nearest(self, queries, *, previous=None, stats=None) -> np.ndarray:
        if previous is None:
            return self.tree.nearest(queries, stats=stats)
        q = queries
        j = np.array(previous, dtype=np.intp, copy=True)
        if j.shape != (q.shape[0],):
            raise InputError("previous assignment must have one index per state")
        pts, nbrs = self.points, self.neighbours
        rows = np.arange(q.shape[0])
        settled = False
        for _ in range(self.MAX_WALK):
            cand = np.column_stack([j, nbrs[j]])
            d2 = np.sum((pts[cand] - q[:, None, :]) ** 2, axis=2)
            best = cand[rows, np.argmin(d2, axis=1)]
            settled = bool(np.array_equal(best, j))
            j = best
            if settled:
                break
        d = np.sqrt(np.sum((pts[j] - q) ** 2, axis=1))
        uncertain = ~(d < 0.5 * self.radius[j]) if settled else np.ones(j.size, dtype=bool)
        if uncertain.any():
            j[uncertain] = self.tree.nearest(q[uncertain])
        _count(stats, j.size, int(uncertain.sum()))
        return j

    def k_nearest(self, queries, k: int) -> np.ndarray:
        return self.tree.k_nearest(queries, k)


#: The search backends by name.
SEARCHES: dict[str, type[NeighbourSearch]] = {}
#: Other names of registered backends (``warm``: the name of the graph search before the registry).
ALIASES: dict[str, str] = {"warm": "graph"}


def register_search(cls: type[NeighbourSearch]) -> type[NeighbourSearch]:
    """Add a backend to :data:`SEARCHES` under its ``name`` (usable as a class decorator)."""
    if not (isinstance(cls, type) and issubclass(cls, NeighbourSearch)) or not cls.name:
        raise InputError(f"a search backend must be a named NeighbourSearch subclass, got {cls!r:.60}")
    SEARCHES[cls.name] = cls
    return cls


register_search(KDTreeSearch)
register_search(GraphSearch)


def search_name(name: str) -> str:
    """The registered name of the backend ``name`` (an alias resolved), or a one-line
    :class:`InputError` listing the known ones."""
    resolved = ALIASES.get(name, name) if isinstance(name, str) else name
    if not isinstance(resolved, str) or resolved not in SEARCHES:
        aliases = "".join(f", {a} (= {b})" for a, b in ALIASES.items())
        raise InputError(f"unknown data search {name!r:.60}; known: {', '.join(SEARCHES)}{aliases}")
    return resolved


def search_class(name: str) -> type[NeighbourSearch]:
    """The backend registered as ``name`` (see :func:`search_name`)."""
    return SEARCHES[search_name(name)]
