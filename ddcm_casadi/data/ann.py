r"""Certified partition searches for large data sets: every answer carries a lower bound.

Both backends here split the data into cells, search the cells nearest a query, re-rank the
candidates with exact distances and prove (or fail to prove) that nothing outside is nearer
(the maths: ``docs/maths.md``, "Certified approximate search"). For a query ``q`` with best
candidate ``j`` at the exact distance ``d_j = |q - y_j|`` and a lower bound ``B(q)`` on the
distance of every datum *not examined*,

.. math::  d_j \le B(q) \;\Rightarrow\; d_j = \min_l |q - y_l| ,

and otherwise ``min_l |q - y_l| >= min(d_j, B)``: the returned datum is at most ``d_j - B``
farther than the nearest (:class:`Certificate`). :meth:`CertifiedSearch.nearest` widens the
search of uncertified queries until every one is certified, so it is exact; ``certified(q,
rounds=...)`` stops early and reports the bound.

- ``strips`` (:class:`StripSearch`, numpy only): for one-component data (2 coordinates). The data
  are cut into strips along their longest axis and sorted within a strip along the other; a query
  scans a window of each nearby strip. Stored in float32 (12 bytes a point with the permutation)
  beside the exact coordinates, float32 rounding counted in the bound.
- ``ann`` (:class:`IVFSearch`, the optional ``faiss-cpu``, ``pip install ddcm-casadi[ann]``): an
  inverted file (k-means cells) for any dimension, the bound from the Voronoi cells (faiss's float32
  arithmetic counted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ddcm_casadi.data.search import CHUNK, NeighbourSearch, Stored, _count, register_search
from ddcm_casadi.errors import InputError
from ddcm_casadi.heap import kept_heap

#: Unit roundoff of float32 and float64 (round to nearest).
U32 = 2.0 ** -24
U64 = 2.0 ** -53


@dataclass(frozen=True)
class Certificate:
    """The answer of a certified search, per query.

    Attributes
    ----------
    index : (n,) intp
        The returned datum: the nearest among those examined (exact distances).
    distance : (n,) float64
        Its exact distance ``d_j`` (the metric's, in the search's coordinates).
    bound : (n,) float64
        ``B``: every datum not examined is at least this far (``inf`` when all were examined).
    certified : (n,) bool
        ``d_j <= B`` (with a margin for float64 roundoff): ``index`` is a nearest datum. Where it
        is False, the nearest datum is at least ``min(d_j, B)`` away, so ``index`` is at most
        ``d_j - B`` (:attr:`gap`) farther than the nearest.
    """

    index: np.ndarray
    distance: np.ndarray
    bound: np.ndarray
    certified: np.ndarray

    @property
    def gap(self) -> np.ndarray:
        """``max(d_j - B, 0)``: how much farther than the nearest the returned datum may be."""
        return np.maximum(self.distance - self.bound, 0.0)


def _is_certified(distance: np.ndarray, bound: np.ndarray) -> np.ndarray:
    # exact distances are float64 sums: a relative 8 eps covers their roundoff
    return distance * (1.0 + 8.0 * U64) <= bound


class CertifiedSearch(NeighbourSearch):
    """A search whose answers carry a :class:`Certificate`; :meth:`nearest` is exact (it widens
    the search of uncertified queries until all are certified)."""

    #: Rounds of widening before :meth:`certified` reports the remaining queries uncertified.
    MAX_ROUNDS: ClassVar[int] = 64

    def certified(self, queries: np.ndarray, *, rounds: int | None = None) -> Certificate:
        """The nearest examined datum of each query with its certificate, after at most
        ``rounds`` widenings of the first search (default: until every query is certified)."""
        q = self._queries(queries)
        n = q.shape[0]
        index = np.zeros(n, dtype=np.intp)
        dist = np.full(n, np.inf)
        bound = np.zeros(n)
        todo = np.arange(n)
        last = self.MAX_ROUNDS if rounds is None else int(rounds)
        for level in range(last + 1):
            if todo.size == 0:
                break
            for a in range(0, todo.size, CHUNK):
                rows = todo[a:a + CHUNK]
                found = self._search(q[rows], level, dist[rows])
                better = found[1] < dist[rows]  # a widened search keeps the best seen (ties: the first)
                index[rows[better]], dist[rows[better]] = found[0][better], found[1][better]
                bound[rows] = found[2]
            todo = todo[~_is_certified(dist[todo], bound[todo])]
        return Certificate(index, dist, bound, _is_certified(dist, bound))

    def _queries(self, queries) -> np.ndarray:
        """The queries, coordinates of :attr:`points`, in the search's own coordinates (checked;
        here the same: float64)."""
        q = np.ascontiguousarray(queries, dtype=np.float64)
        if q.ndim != 2 or q.shape[1] != self.points.shape[1]:
            raise InputError(f"queries must be (n, {self.points.shape[1]}) coordinates, got shape {q.shape}")
        return q

    def _search(self, q: np.ndarray, level: int, reach: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Best examined index, its exact distance and the bound on the rest, at widening
        ``level`` (0: the first search; each level examines more), ``reach`` the best distance
        found so far (``inf`` at level 0). Where none is nearer than ``reach`` the index may be
        any: :meth:`certified` keeps the one it has unless a strictly nearer one is returned."""
        raise NotImplementedError

    def nearest(self, queries, *, previous=None, stats=None) -> np.ndarray:
        """Exact: the certified search, then a pass over all data for any query still uncertified
        (``stats``: ``fallbacks`` counts them)."""
        cert = self.certified(queries)
        left = np.flatnonzero(~cert.certified)
        index = cert.index
        if left.size:
            index = index.copy()
            index[left] = self.brute_force(np.asarray(queries, dtype=np.float64)[left]).index
        _count(stats, index.size, left.size)
        return index

    def exact_distance(self, q: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """``|q - y_idx|`` in float64 from the exact coordinates (``idx`` any shape ``(n, ...)``)."""
        return _distances(q, np.asarray(self.points[idx], dtype=np.float64))

    def _rows(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray | None]:
        """The float64 coordinates of the stored rows ``a:b`` and their data indices (``None``:
        ``a + arange``), for :meth:`brute_force`."""
        return np.asarray(self.points[a:b], dtype=np.float64), None

    def brute_force(self, q: np.ndarray) -> Certificate:
        """The exact nearest of each query by a pass over all data in float64 (for the rare
        queries the widest search leaves uncertified: ties within float32 roundoff)."""
        q = self._queries(q)
        n, d = q.shape
        index = np.zeros(n, dtype=np.intp)
        best = np.full(n, np.inf)
        rows = max(1, (1 << 22) // max(1, n * d))
        for a in range(0, self.points.shape[0], rows):
            y, which = self._rows(a, a + rows)
            diff = y[None, :, :] - q[:, None, :]
            d2 = np.einsum("qjd,qjd->qj", diff, diff)
            j = np.argmin(d2, axis=1)
            dist = np.sqrt(d2[np.arange(n), j])
            better = dist < best
            index[better], best[better] = (j[better] + a if which is None else which[j[better]]), dist[better]
        return Certificate(index, best, np.full(n, np.inf), np.ones(n, dtype=bool))

    def k_nearest(self, queries, k: int) -> np.ndarray:
        if self.base is None:
            raise InputError(f"the {self.name} search answers k_nearest through an exact search given at build")
        return self.base.k_nearest(queries, k)


def _distances(q: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``|q_i - y_i...|`` in float64, ``y`` of shape ``(n, ..., d)``."""
    diff = y - q.reshape((q.shape[0],) + (1,) * (y.ndim - 2) + (q.shape[1],))
    return np.sqrt(np.einsum("...i,...i->...", diff, diff))


def _rounding(values_max: float, dtype) -> float:
    """The largest ``|x - fl32(x)|`` of values up to ``values_max`` in magnitude (0 if already float32)."""
    return 0.0 if np.dtype(dtype) == np.float32 else U32 * values_max + 2.0 ** -149  # (+ the subnormal step)


class StripSearch(CertifiedSearch):
    r"""Exact certified search for one-component data (2 coordinates), numpy only.

    The data are cut into strips of width ``w`` along their longest axis ``a`` (strip
    ``t = floor((y_a - min y_a) / w)``) and sorted within a strip along the other axis ``b``; the
    strips' ``a``-extents ``[lo_t, hi_t]`` are kept. The first search of a query ``q`` in strip
    ``s`` takes the ``2 m`` data around ``q_b`` in strips ``s - 1, s, s + 1``. Lower bounds on the
    distance of the data not examined:

    - in an examined strip ``t``, below (above) the window, every datum has
      ``|q_a - y_a| >= g_t = dist(q_a, [lo_t, hi_t])`` and ``|q_b - y_b| >= q_b - y_b^-`` (``y_b^+ - q_b``),
      ``y_b^-`` (``y_b^+``) the datum next to the window: ``B_t = sqrt(g_t^2 + (q_b - y_b^-)^2)``;
    - in the strips beyond ``s + 1`` (before ``s - 1``), ``|q_a - y_a| >= lo_{s+2} - q_a``
      (``q_a - hi_{s-2}``; ``lo``, ``hi`` taken over all strips beyond, as stored) and ``|q_b - y_b|`` is at
      least the distance from ``q_b`` to the data's ``b``-range.

    ``B`` is the least of them. Keys are stored in float32 (``y`` rounded by at most
    ``delta = 2^-24 max|y|``), so every key difference is reduced by ``delta`` of its axis before
    it bounds anything. The window is ranked by key distances (within ``|delta|`` of the exact
    ones), the two nearest re-ranked with exact distances and the third bounds the rest. The
    widening (:meth:`_rings`) examines every datum nearer than the best found, strip by strip
    outwards, and certifies every answer.
    The strip width ``w = max(sqrt(A M / N), L M / N)`` (``L``, ``A``: the data's ``a``-extent and
    bounding area, ``M = 8``) puts about ``M`` data in a ``w x w`` cell of a band of data and
    ``M`` in a strip of data along a line.

    The build (:meth:`_built`) is O(N) passes over blocks of rows (the extremes, the strip counts,
    a deal of the data to groups of consecutive strips: a counting sort) and one radix sort a
    group of at most :attr:`GROUP` data (strip, then the key ``b``'s order-preserving bits:
    three passes of 16-bit digits): O(N) work and bounded temporaries.

    Memory: 12 bytes a datum (two float32 keys and an int32 permutation up to ``2^31`` data)
    beside the coordinates it is given (kept, not copied). Float32 coordinates are their own keys
    (``delta = 0``): the re-ranking reads the keys in float64, exactly, and never the points
    again, so the data may stay in a file (:meth:`from_npy`; 1e9 data: 12 GB in the process).
    Answers are exact for the data as stored: where a float32 file was rounded from float64
    data, each datum moved by at most ``2^-24 |y| <= 2^-24 R`` (``R`` the largest norm), so
    against the float64 data a certified answer is at most ``2^-23 R`` farther than the nearest
    (an uncertified one, ``gap + 2^-23 R``).
    """

    name = "strips"
    #: Data per ``w x w`` cell the strip width aims at.
    PER_CELL = 8
    #: Half-width ``m`` of the first search's window in each strip: 6 answered 1e5 states of 1e8
    #: data, all certified, in 0.36 s CPU (5: 0.37, 8: 0.40, 10: 0.50; the first search certifies
    #: 91 % at 6, 97 % at 8, and the widening is cheap).
    WINDOW = 6

    def __init__(self, points, keys, perm, offsets, axes, width, low, lo_t, hi_t, right_lo, left_hi,
                 b_range, delta, base=None, *, scale=(1.0, 1.0), frame: Stored | None = None) -> None:
        self._points, self.keys, self.perm, self.offsets = points, keys, perm, offsets
        self.axes, self.width, self.low = axes, width, low
        self.lo_t, self.hi_t, self.right_lo, self.left_hi = lo_t, hi_t, right_lo, left_hi
        self.b_range, self.delta, self.base = b_range, delta, base
        #: ``(s_a, s_b)``: a datum's coordinates are ``s * key`` in float64 (1: the keys themselves).
        self.scale = tuple(np.float64(v) for v in scale)
        #: Where the keys are stored values of an affine image (:class:`~ddcm_casadi.data.search.Stored`),
        #: the queries' map to the scaled stored frame; else ``None``.
        self.frame = frame
        self.largest = int(np.max(np.diff(offsets)))
        # each strip's key-b extent (its first and last key): a strip's box bounds all its data
        full = np.diff(offsets) > 0
        self.b_lo_t, self.b_hi_t = np.full(full.size, np.inf), np.full(full.size, -np.inf)
        self.b_lo_t[full] = keys[1][offsets[:-1][full]] * self.scale[1]
        self.b_hi_t[full] = keys[1][offsets[1:][full] - 1] * self.scale[1]
        #: The keys are the coordinates themselves, or their stored values scaled (two float32
        #: columns): key distances are exact.
        self.exact_keys = points.shape[1] == 2 and delta == (0.0, 0.0)

    @classmethod
    def build(cls, points: np.ndarray, *, base: NeighbourSearch | None = None) -> "StripSearch":
        X = points
        if X.ndim != 2 or X.shape[1] < 2 or X.shape[0] < 1:
            raise InputError(f"the strip search needs (N, 2) coordinates (one-component data), got shape {X.shape}")
        return cls._built(X, lambda a, b: X[a:b], base if base is not None and base.points is points else None)

    @classmethod
    def from_rows(cls, rows, exact) -> "StripSearch":
        """Built from blocks of a data set's rows (:meth:`_built`): neither the array of its
        coordinates nor the exact KD-tree is made (``exact`` is not called). Where the rows are
        an affine image of float32 values as stored (:attr:`Rows.stored
        <ddcm_casadi.data.search.Rows>`: a one-component data set's float32 file), the keys are
        those values and the search is in their scaled frame ``y = scale * v``, computed from the
        keys in float64 (monotone in each key, so the keys' order is the coordinates' and every
        bound is exact, ``delta = 0``); only the queries are moved there
        (:meth:`~ddcm_casadi.data.search.Stored.unrotated`), and the rows are never read again.
        Otherwise the keys are the rows rounded to float32 and the candidates are re-ranked
        from rows gathered."""
        stored = rows.stored
        if stored is not None and np.dtype(stored.dtype) == np.float32 and rows.shape[1] == 2:
            return cls._built(rows, stored.read, None, stored)
        return cls._built(rows, rows.read, None)

    @classmethod
    def from_npy(cls, path) -> "StripSearch":
        """The search over the ``(N, 2)`` coordinates of a ``.npy`` file larger than memory: the
        file is read in blocks by plain reads (its pages stay in the operating system's page
        cache, outside the process) and kept memory-mapped as :attr:`points`, which a float32
        file never needs again (its keys are its values)."""
        X = np.load(path, mmap_mode="r")
        if X.ndim != 2 or X.shape[1] < 2 or X.shape[0] < 1 or X.dtype.kind != "f" or not X.flags.c_contiguous:
            raise InputError(f"the strip search needs an (N, 2) float array in C order in {path}, got "
                             f"{X.dtype} {X.shape}")
        row = X.dtype.itemsize * X.shape[1]

        def read(a: int, b: int) -> np.ndarray:
            with open(path, "rb") as fh:
                fh.seek(X.offset + a * row)
                return np.fromfile(fh, dtype=X.dtype, count=(b - a) * X.shape[1]).reshape(b - a, X.shape[1])
        return cls._built(X, read, None)

    #: Rows read per block by the build's passes over the data, and data per group of strips
    #: sorted at once (:meth:`_sort_group`). Temporaries of 2 MB and 0.5 MB stay in
    #: malloc's heap (32 MB ones were mapped and faulted in anew each time): the build of 1e8
    #: data took 10-11 s CPU, against 14-15 s with 2^22 and 2^20.
    READ = 1 << 18
    GROUP = 1 << 16

    @classmethod
    def _built(cls, X, read, base, frame: Stored | None = None) -> "StripSearch":
        """The search over ``X`` (its ``shape`` and ``dtype``) read by blocks ``read(a, b)``
        (:meth:`_passes`), with glibc's heap kept (:func:`~ddcm_casadi.heap.kept_heap`);
        ``frame``: ``read`` gives the stored values of ``X`` (:class:`~ddcm_casadi.data.search.Stored`)."""
        with kept_heap():
            return cls._passes(X, read, base, frame)

    @classmethod
    def _passes(cls, X, read, base, frame) -> "StripSearch":
        """The build: one pass for the extremes (none where the ``frame`` knows them), one for
        the strip counts, one that deals the data to groups of consecutive strips (a counting
        sort, O(N)), and a sort within each group of at most :attr:`GROUP` data (strip, then key
        ``b``). Beside the result (12 bytes a datum) it holds one block of :attr:`READ` rows and
        one group. With a ``frame``, the blocks read are stored values ``v`` and the coordinates
        are ``frame.scale * v``."""
        n, dim = X.shape
        scale = np.ones(dim) if frame is None else np.asarray(frame.scale, dtype=np.float64)
        if frame is not None and frame.extremes is not None:  # known: one pass fewer
            lo, hi = (np.array(v, dtype=np.float64) for v in frame.extremes)
        else:
            lo, hi = np.full(dim, np.inf), np.full(dim, -np.inf)
            for c in range(0, n, cls.READ):
                block = read(c, min(n, c + cls.READ))  # by columns: 30x faster than along axis 0
                lo = np.minimum(lo, [block[:, i].min() for i in range(dim)])
                hi = np.maximum(hi, [block[:, i].max() for i in range(dim)])
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):  # NaN propagates to the extremes
            raise InputError("the strip search's coordinates must be finite")
        lo, hi = lo * scale, hi * scale  # scale > 0 keeps the order: the extremes of the coordinates
        extent = hi - lo
        a, b = (int(i) for i in np.argsort(extent)[::-1][:2])
        L, H = float(extent[a]), float(extent[b])
        width = max(math.sqrt(L * H * cls.PER_CELL / n), L * cls.PER_CELL / n) if L > 0 else 1.0
        strips = min(int(L / width) + 1, n)

        def strip(key_a: np.ndarray) -> np.ndarray:
            # from the float32 key, so that every pass (and the sort) puts a datum in one strip; the
            # bounds use the strips' extents as stored, whatever this rounding
            t = key_a.astype(np.float64)
            t *= scale[a]
            t -= lo[a]
            t *= 1.0 / width
            t = t.astype(np.int64)  # truncation: t >= 0
            return np.minimum(t, strips - 1, out=t)

        counts = np.zeros(strips, dtype=np.int64)
        for c in range(0, n, cls.READ):
            counts += np.bincount(strip(read(c, min(n, c + cls.READ))[:, a].astype(np.float32)), minlength=strips)
        offsets = np.zeros(strips + 1, dtype=np.int64)
        np.cumsum(counts, out=offsets[1:])
        # groups of consecutive strips: GROUP data (and at most one strip more) and at most 2^12
        # strips, so that a group's strip is one 16-bit digit of its radix sort
        span = 1 << 12
        first = np.flatnonzero(np.diff(np.minimum(offsets[:-1] // cls.GROUP, n) * (strips // span + 1)
                                       + np.arange(strips) // span, prepend=-1))
        group = np.zeros(strips, dtype=np.int64)
        group[first[1:]] = 1
        group = np.cumsum(group).astype(np.uint16 if first.size < 2**16 else np.int64)
        starts = np.append(offsets[first], n)
        keys = np.empty((2, n), dtype=np.float32)  # rows a and b, each contiguous (fast gathers)
        perm = np.empty(n, dtype=np.int32 if n < 2**31 else np.int64)
        fill = starts[:-1].copy()
        for c in range(0, n, cls.READ):  # deal the data to their groups
            block = read(c, min(n, c + cls.READ))
            ka, kb = block[:, a].astype(np.float32), block[:, b].astype(np.float32)
            g = group[strip(ka)]
            order = np.argsort(g, kind="stable")  # the block by group (a radix sort up to 2^16 groups)
            g = g[order]
            per = np.bincount(g, minlength=first.size)
            # the sorted block's place in its groups' ranges, written group by group in ascending
            # order (the deal at 1e8: 46-53 against 53-57 ns a datum written in the block's order)
            place = (fill - (np.cumsum(per) - per))[g]
            place += np.arange(g.size)
            keys[0, place], keys[1, place] = ka[order], kb[order]
            order += c
            perm[place] = order
            fill += per
        for s0, s1 in zip(starts[:-1], starts[1:]):  # each group sorted by (strip, key b)
            if s1 - s0 > 1:
                cls._sort_group(keys[:, s0:s1], perm[s0:s1], strip(keys[0, s0:s1]))
        lo_t, hi_t = np.full(strips, np.inf), np.full(strips, -np.inf)
        full = counts > 0
        lo_t[full] = np.minimum.reduceat(keys[0], offsets[:-1][full]) * scale[a]
        hi_t[full] = np.maximum.reduceat(keys[0], offsets[:-1][full]) * scale[a]
        right_lo = np.minimum.accumulate(lo_t[::-1])[::-1]  # least key a of strips >= t
        left_hi = np.maximum.accumulate(hi_t)  # largest key a of strips <= t
        reach = np.maximum(np.abs(lo), np.abs(hi))
        stored = X.dtype if frame is None else frame.dtype
        delta = (_rounding(reach[a], stored), _rounding(reach[b], stored))
        return cls(X, keys, perm, offsets, (a, b), width, lo[a], lo_t, hi_t, right_lo, left_hi,
                   (lo[b], hi[b]), delta, base, scale=(scale[a], scale[b]), frame=frame)

    @staticmethod
    def _sort_group(keys: np.ndarray, perm: np.ndarray, t: np.ndarray) -> None:
        """Sort one group's ``keys`` (2, m) and ``perm`` in place by strip ``t``, then key ``b``
        (ties in the order given): a least-significant-digit radix sort, three stable passes of
        16-bit digits (numpy's stable argsort of ``uint16`` is a counting sort): the low and the
        high half of the key's order-preserving bits, then the strip (a group spans at most 2^12
        strips). 30 against 50 ns a datum for one sort of packed ``uint64`` keys (2^16 data)."""
        code = keys[1].view(np.int32) >> 31  # order-preserving bits of a float: every bit flipped
        code = code.view(np.uint32)  # on negatives, the sign bit set on positives
        code |= np.uint32(1 << 31)
        code ^= keys[1].view(np.uint32)
        order = np.argsort(code.astype(np.uint16), kind="stable")  # the low 16 bits
        code >>= np.uint32(16)
        order = order[np.argsort(code.astype(np.uint16)[order], kind="stable")]
        t -= t.min()  # the group's strips are consecutive
        if t.max() > 0:
            order = order[np.argsort(t.astype(np.uint16)[order], kind="stable")]
        keys[0], keys[1], perm[:] = keys[0][order], keys[1][order], perm[order]

    @property
    def points(self) -> np.ndarray:
        return self._points

    def _coordinates(self, pos: np.ndarray) -> np.ndarray:
        """The float64 coordinates of the data at sorted positions ``pos`` (any shape): the keys,
        scaled, where they are the coordinates (float32 data; the points are then never read),
        else the exact points."""
        if not self.exact_keys:
            return np.asarray(self.points[self.perm[pos]], dtype=np.float64)
        y = np.empty(pos.shape + (2,))
        for i in range(2):
            np.multiply(self.keys[i][pos], self.scale[i], out=y[..., self.axes[i]])
        return y

    def _queries(self, queries) -> np.ndarray:
        """Queries in the search's coordinates: those of :attr:`points`, or with a :attr:`frame`
        moved back to the scaled stored frame (a rotation and a shift: distances unchanged)."""
        q = super()._queries(queries)
        return q if self.frame is None else self.frame.unrotated(q)

    def _rows(self, a, b):
        if not self.exact_keys:
            return super()._rows(a, b)
        return self._coordinates(np.arange(a, min(b, self.perm.size))), self.perm[a:b]

    #: The widening's passes take ``k / RING_STEP`` more rings at ring ``k`` (8: 25 % less CPU than
    #: one ring a pass and 4x less than doubling, which examines more data before the radius
    #: shrinks; 2 600 uncertified states of 3e7 data).
    RING_STEP = 8

    #: Queries per block of the first search: its temporaries (48 candidates a query) stay in cache
    #: (blocks of 65 536 queries took 2-3x longer, measured at 1e6 data on a loaded machine).
    BLOCK = 4096

    def _search(self, q, level, reach):
        if level == 0:
            parts = [self._window(q[c:c + self.BLOCK]) for c in range(0, q.shape[0], self.BLOCK)]
            return tuple(np.concatenate(p) for p in zip(*parts))
        # from the first search's best (kept by certified() unless a nearer one is found)
        index, radius = np.zeros(q.shape[0], dtype=np.intp), np.array(reach, dtype=np.float64)
        far = ~np.isfinite(radius)
        if far.any():  # nothing in the first window: start from a datum of the nearest filled strip
            index[far], radius[far] = self._some_datum(q[far])
        return self._rings(q, index, radius)

    def _some_datum(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A datum of the filled strip nearest each query's and its distance (an upper bound on
        the nearest distance where the first window found nothing)."""
        filled = np.flatnonzero(np.diff(self.offsets))
        s = np.clip(np.floor((q[:, self.axes[0]] - self.low) / self.width), 0, self.lo_t.size - 1)
        k = np.clip(np.searchsorted(filled, s), 0, filled.size - 1)
        p = self.offsets[filled[k]]
        return self.perm[p].astype(np.intp), _distances(q, self._coordinates(p))

    def _position(self, t: np.ndarray, value: np.ndarray, right: bool) -> np.ndarray:
        """The insertion point of ``value`` among the sorted keys ``b`` of strip ``t`` (bisection,
        vectorised and branch-free: the answer stays in ``[base, base + length]``, each level
        halves ``length``; ``right``: after equal keys)."""
        base = self.offsets[t].copy()
        length = self.offsets[t + 1] - base
        keys, last, sb = self.keys[1], self.keys[1].size - 1, self.scale[1]
        below = np.less_equal if right else np.less
        for _ in range(int(length.max(initial=0)).bit_length()):
            half = length >> 1
            mid = base + half
            base = np.where(below(keys[np.minimum(mid, last)] * sb, value), mid, base)
            length -= half
        return base + ((length > 0) & below(keys[np.minimum(base, last)] * sb, value))

    def _strip_gap(self, t: np.ndarray, qa: np.ndarray) -> np.ndarray:
        """``dist(q_a, [lo_t, hi_t])`` less the keys' rounding (``inf`` for an empty strip)."""
        with np.errstate(invalid="ignore"):  # inf - inf of empty strips
            g = np.maximum(self.lo_t[t] - qa, qa - self.hi_t[t]) - self.delta[0]
        return np.where(np.isnan(g), np.inf, np.maximum(g, 0.0))

    def _rings(self, q: np.ndarray, index: np.ndarray, radius: np.ndarray):
        """Examine every datum nearer than the best so far, strips outwards from the query's
        (ring ``k``: strips ``s - k`` and ``s + k``; several rings a pass, :attr:`RING_STEP`):
        in strip ``t``, unless its box ``[lo_t, hi_t] x [b_lo_t, b_hi_t]`` is farther than the
        radius, the keys ``b`` within ``sqrt(radius^2 - g_t^2)`` of ``q_b``; the radius shrinks
        to the best distance found. Each pass first probes, in each strip whose box is within
        the radius, the two data around ``q_b`` (one bisection), and shrinks the radius to the
        best of them before it scans: a query far from the data (in the sparse tails) starts
        from a radius many strips wide, and the scans of those strips would examine every datum
        within it. A query stops when the strips beyond its ring are farther than its radius,
        so what is left is farther than the answer: certified, ``B = radius`` (enlarged by a
        relative ``1e-9`` so that the float64 distances of the examined data stay below it)."""
        a, b = self.axes
        strips = self.lo_t.size
        grow = 1.0 + 1e-9
        index, best = index.copy(), radius.copy()
        radius = radius * grow
        qa, qb = q[:, a], q[:, b]
        s = np.clip(np.floor((qa - self.low) / self.width), 0, strips - 1).astype(np.int64)
        todo = np.arange(q.shape[0])
        k0, k1 = 0, 1

        def improve(owner: np.ndarray, flat: np.ndarray) -> None:
            # the nearest of each query's run of examined data, where nearer than its best
            diff = self._coordinates(flat) - q[owner]
            dist = np.sqrt(np.einsum("ij,ij->i", diff, diff))
            starts = np.flatnonzero(np.diff(owner, prepend=-1))
            low = np.repeat(np.minimum.reduceat(dist, starts), np.diff(starts, append=dist.size))
            win = np.flatnonzero(dist == low)  # each run's nearest (ties: the first of the run)
            win = win[np.diff(owner[win], prepend=-1) != 0]
            win = win[dist[win] < best[owner[win]]]
            index[owner[win]], best[owner[win]] = self.perm[flat[win]], dist[win]
            radius[owner[win]] = dist[win] * grow

        def within(rows: np.ndarray, t: np.ndarray):
            # the strips whose box is within the radius, and their gaps along a
            g = self._strip_gap(t, qa[rows])
            with np.errstate(invalid="ignore"):  # empty strips: inf - inf, and g = inf
                gb = np.maximum(self.b_lo_t[t] - qb[rows], qb[rows] - self.b_hi_t[t]) - self.delta[1]
            near = np.hypot(g, np.maximum(gb, 0.0)) <= radius[rows]
            return rows[near], t[near], g[near]

        while todo.size:
            # rings k0 .. k1 - 1 in one pass, k1 growing by k1 / RING_STEP: fewer passes for a
            # query many strips from its nearest, while the radius still shrinks between them
            ks = np.arange(k0, k1)
            ks = ks if k0 == 0 else np.concatenate([-ks, ks])
            t = (s[todo][:, None] + ks).ravel()
            keep = (t >= 0) & (t < strips)
            rows, t, g = within(np.repeat(todo, ks.size)[keep], t[keep])
            if rows.size and k0 > 0:  # the probe (ring 0 is the first search's own strip)
                p = self._position(t, qb[rows], right=False)
                pair = np.clip(p[:, None] + np.array([-1, 0]), self.offsets[t][:, None],
                               self.offsets[t + 1][:, None] - 1)
                improve(np.repeat(rows, 2), pair.ravel())
                rows, t, g = within(rows, t)
            h = np.sqrt(radius[rows] ** 2 - g ** 2) + self.delta[1]
            p0 = self._position(t, qb[rows] - h, right=False)
            counts = self._position(t, qb[rows] + h, right=True) - p0
            flat = np.repeat(p0 - (np.cumsum(counts) - counts), counts) + np.arange(int(counts.sum()))
            if flat.size:
                improve(np.repeat(rows, counts), flat)  # in runs, one a query (rows are by query)
            # strips beyond ring k1 - 1: at least this far along a
            right_t, left_t = s[todo] + k1, s[todo] - k1
            ga = np.minimum(
                np.where(right_t < strips, self.right_lo[np.minimum(right_t, strips - 1)] - qa[todo], np.inf),
                np.where(left_t >= 0, qa[todo] - self.left_hi[np.maximum(left_t, 0)], np.inf)) - self.delta[0]
            todo = todo[ga <= radius[todo]]
            k0, k1 = k1, k1 + max(1, k1 // self.RING_STEP)
        return index, best, radius

    def k_nearest(self, queries, k: int) -> np.ndarray:
        """The ``k`` nearest data of each query, nearest first (ties by data index), exactly and
        without an exact search beside it: the ``k``-th nearest of ``2k`` data around the query's
        key ``b`` in its strip (clipped to the data) is an upper bound ``r`` on the ``k``-th nearest
        distance, and every datum within ``r`` is examined (:meth:`_within`) and ranked by exact
        distances."""
        q = self._queries(queries)
        n, size = q.shape[0], self.keys.shape[1]
        k = min(int(k), size)
        if k < 1:
            return np.zeros((n, 0), dtype=np.intp)
        a, b = self.axes
        s = np.clip(np.floor((q[:, a] - self.low) / self.width), 0, self.lo_t.size - 1).astype(np.int64)
        start = np.clip(self._position(s, q[:, b], right=False) - k, 0, max(size - 2 * k, 0))
        pos = np.minimum(start[:, None] + np.arange(min(2 * k, size)), size - 1)
        some = _distances(q, self._coordinates(pos))
        radius = np.partition(some, k - 1, axis=1)[:, k - 1] * (1.0 + 1e-9)  # >= the k-th nearest distance
        owner, flat = self._within(q, radius)
        dist = _distances(q[owner], self._coordinates(flat)[:, None, :])[:, 0]
        index = self.perm[flat].astype(np.intp)
        order = np.lexsort((index, dist, owner))
        owner, index = owner[order], index[order]
        first = np.searchsorted(owner, np.arange(n))  # each query has at least k data within r
        return index[first[:, None] + np.arange(k)]

    def _within(self, q: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every datum whose keys are within ``radius`` of each query's (so every datum within
        ``radius`` of it, the keys' rounding counted): the query and the datum's sorted
        position, by query. In each strip ``t`` whose gap ``g_t`` along ``a`` is within the
        radius, the keys ``b`` within ``sqrt(radius^2 - g_t^2)`` of ``q_b``."""
        a, b = self.axes
        strips = self.lo_t.size
        reach = radius + self.delta[0] + self.width  # a datum's strip is its key's
        s0 = np.clip(np.floor((q[:, a] - reach - self.low) / self.width), 0, strips - 1).astype(np.int64)
        s1 = np.clip(np.floor((q[:, a] + reach - self.low) / self.width), 0, strips - 1).astype(np.int64)
        span = s1 - s0 + 1
        rows = np.repeat(np.arange(q.shape[0]), span)
        t = np.repeat(s0 - (np.cumsum(span) - span), span) + np.arange(int(span.sum()))
        g = self._strip_gap(t, q[rows, a])
        near = g <= radius[rows]
        rows, t, g = rows[near], t[near], g[near]
        h = np.sqrt(radius[rows] ** 2 - g ** 2) + self.delta[1]
        p0 = self._position(t, q[rows, b] - h, right=False)
        counts = self._position(t, q[rows, b] + h, right=True) - p0
        flat = np.repeat(p0 - (np.cumsum(counts) - counts), counts) + np.arange(int(counts.sum()))
        return np.repeat(rows, counts), flat

    def _window(self, q):
        """The first search: ``2 m`` data around ``q_b`` in the query's strip and its two neighbours."""
        r, m = 1, min(self.WINDOW, self.largest)
        a, b = self.axes
        da, db = self.delta
        (ka, kb), off = self.keys, self.offsets
        sa, sb = self.scale
        strips = self.lo_t.size
        qa, qb = q[:, a], q[:, b]
        s = np.clip(np.floor((qa - self.low) / self.width), 0, strips - 1).astype(np.int64)
        T = s[:, None] + np.arange(-r, r + 1)
        inside = (T >= 0) & (T < strips)
        Tc = np.clip(T, 0, strips - 1)
        seg_lo = off[Tc]
        seg_hi = np.where(inside, off[Tc + 1], seg_lo)
        lo = np.where(inside, self._position(Tc, np.broadcast_to(qb[:, None], Tc.shape), right=False), seg_lo)
        w_lo, w_hi = np.maximum(seg_lo, lo - m), np.minimum(seg_hi, lo + m)
        # an empty or short window repeats a datum (clipped into range): a datum examined twice, or
        # one more examined, changes no minimum and no bound
        small = ka.size < 2**31
        pos = np.minimum(w_lo[..., None] + np.arange(2 * m), np.maximum(w_hi - 1, w_lo)[..., None])
        pos = np.minimum(pos, ka.size - 1).astype(np.int32 if small else np.intp)
        n = q.shape[0]
        rows = np.arange(n)
        # squared distances of the keys (the coordinates a, b rounded to float32): their roots are at
        # most |delta| from the exact distances (and below them in more than 2 coordinates); the
        # two nearest are re-ranked exactly
        da_ = ka[pos] * sa - qa[:, None, None]
        kd2 = da_ * da_
        da_ = kb[pos] * sb - qb[:, None, None]
        kd2 += da_ * da_
        kd2, pos = kd2.reshape(n, -1), pos.reshape(n, -1)
        if self.exact_keys:
            j = np.argmin(kd2, axis=1)
            best_pos, best, rest = pos[rows, j], np.sqrt(kd2[rows, j]), np.full(n, np.inf)
        else:
            two = np.argpartition(kd2, 1, axis=1)[:, :2] if kd2.shape[1] > 2 else np.argsort(kd2, axis=1)[:, :2]
            rest = (np.sqrt(np.partition(kd2, 2, axis=1)[:, 2]) - math.hypot(da, db) if kd2.shape[1] > 2
                    else np.full(n, np.inf))
            cand = pos[rows[:, None], two]
            exact = _distances(q, self._coordinates(cand))
            j = np.argmin(exact, axis=1)
            best_pos, best = cand[rows, j], exact[rows, j]
        # bounds of the data left in the examined strips ...
        gap = self._strip_gap(Tc, qa[:, None])
        under = np.where(w_lo > seg_lo, np.maximum(qb[:, None] - kb[np.maximum(w_lo - 1, 0)] * sb - db, 0.0), np.inf)
        over = np.where(w_hi < seg_hi, np.maximum(kb[np.minimum(w_hi, kb.size - 1)] * sb - qb[:, None] - db, 0.0),
                        np.inf)
        left = np.where(inside, np.hypot(gap, np.minimum(under, over)), np.inf)
        bound = np.minimum(left.min(axis=1), rest)
        # ... and of the strips not examined
        right_t, left_t = s + r + 1, s - r - 1
        ga = np.minimum(np.where(right_t < strips, self.right_lo[np.minimum(right_t, strips - 1)] - qa - da, np.inf),
                        np.where(left_t >= 0, qa - self.left_hi[np.maximum(left_t, 0)] - da, np.inf))
        gb = np.maximum(np.maximum(self.b_range[0] - qb, qb - self.b_range[1]), 0.0)
        bound = np.minimum(bound, np.hypot(np.maximum(ga, 0.0), gb))
        return self.perm[best_pos].astype(np.intp), best, bound


register_search(StripSearch)


def _faiss():
    """The faiss module, or a one-line InputError naming the extra that installs it."""
    try:
        import faiss
    except ImportError:
        raise InputError("data search 'ann' needs faiss: pip install 'ddcm-casadi[ann]' (faiss-cpu)") from None
    return faiss


class IVFSearch(CertifiedSearch):
    r"""Certified inverted-file search (faiss ``IndexIVFFlat``, the optional extra ``ann``) for
    any number of coordinates.

    The data, stored in float32, are split into the Voronoi cells of ``n_c`` k-means centroids
    ``c_i`` (faiss's exact float32 assignment); a query ``q`` scans the ``p`` cells of its
    nearest centroids for its ``k`` nearest stored points, which are re-ranked with exact
    distances. Lower bounds (``D_i = |q - c_i|``, ``c_a`` the nearest centroid scanned,
    ``D_u`` the nearest not scanned):

    - a datum ``y`` of a cell ``i`` not scanned is nearer ``c_i`` than ``c_a`` (up to the
      assignment's roundoff ``E``: ``|y - c_i|^2 <= |y - c_a|^2 + 2E``), so it lies in a half-space
      whose distance from ``q`` is ``(D_i^2 - D_a^2 - 2E) / (2 |c_i - c_a|)``; with
      ``|c_i - c_a| <= D_i + D_a`` and that increasing in ``D_i``,
      ``|q - y| >= (D_u - D_a) / 2 - E / (D_u + D_a)``;
    - a datum of a scanned cell not among the ``k`` returned is at least as far (in float32) as
      the ``k``-th: ``|q - y| >= sqrt(d_k^2 - E)``.

    ``E = 2 (d + 3) u (|x| + |y|)^2`` bounds the float32 roundoff of a squared distance between
    ``x`` and ``y`` (``u = 2^-24``; faiss may expand ``|x|^2 + |y|^2 - 2 x.y``), taken with the
    largest norm ``R`` of the data and centroids (``|q| + R`` from a query, ``2R`` for the
    assignment), and the float32 rounding of ``q`` and ``y``
    (``u |q|``, ``u R``) is taken off every bound. A widening multiplies ``p`` by 4 and doubles
    ``k``; once every cell is scanned only the second bound is left.
    """

    name = "ann"
    #: Cells scanned and candidates returned by the first search.
    PROBES, CANDIDATES = 8, 8

    def __init__(self, points, index, centroids, radius, base=None) -> None:
        self._points, self.index, self.centroids, self.radius, self.base = points, index, centroids, radius, base

    @classmethod
    def available(cls) -> bool:
        try:
            import faiss  # noqa: F401
        except ImportError:
            return False
        return True

    @classmethod
    def build(cls, points: np.ndarray, *, base: NeighbourSearch | None = None) -> "IVFSearch":
        faiss = _faiss()
        X = points
        if X.ndim != 2 or X.shape[0] < 1:
            raise InputError(f"the ann search needs (N, d) coordinates, got shape {X.shape}")
        n, d = X.shape
        # 2 sqrt(N) cells: 20 % less CPU than sqrt(N) or 4 sqrt(N) for exact answers (1e6 data, 12
        # coordinates); at most 16 384, as the assignment costs N x cells distances
        cells = int(max(1, min(2.0 * math.sqrt(n), n // 40, 16384)))
        rng = np.random.default_rng(0)
        sample = np.ascontiguousarray(X[np.sort(rng.choice(n, min(n, 40 * cells), replace=False))], dtype=np.float32)
        index = faiss.IndexIVFFlat(faiss.IndexFlatL2(d), d, cells)
        index.cp.niter = 10
        index.cp.min_points_per_centroid = 1
        index.train(sample)
        radius = 0.0
        for c in range(0, n, 1 << 20):
            block = np.ascontiguousarray(X[c:c + (1 << 20)], dtype=np.float32)
            index.add(block)
            radius = max(radius, float(np.sqrt(np.max(np.einsum("ij,ij->i", block, block, dtype=np.float64)))))
        centroids = index.quantizer.reconstruct_n(0, cells).astype(np.float64)
        radius = max(radius, float(np.sqrt(np.max(np.einsum("ij,ij->i", centroids, centroids)))))
        return cls(X, index, centroids, radius, base if base is not None and base.points is points else None)

    @property
    def points(self) -> np.ndarray:
        return self._points

    def _search(self, q, level, reach):
        d = q.shape[1]
        cells = self.centroids.shape[0]
        probes = min(cells, self.PROBES * 4 ** level)
        k = int(min(self.points.shape[0], self.CANDIDATES * 2 ** level, 2048))
        q32 = q.astype(np.float32)
        qn = np.sqrt(np.einsum("ij,ij->i", q, q))
        shift = U32 * qn + U32 * self.radius  # |q - q32| + |y - y32|
        E = 2.0 * (d + 3) * U32 * (qn + self.radius) ** 2  # a squared distance from q
        E_assign = 2.0 * (d + 3) * U32 * (2.0 * self.radius) ** 2  # one between a datum and a centroid
        Dc, Ic = self.index.quantizer.search(q32, min(cells, probes + 1))
        self.index.nprobe = probes
        D, Idx = self.index.search_preassigned(q32, k, Ic[:, :probes], Dc[:, :probes])
        valid = Idx >= 0
        exact = np.where(valid, self.exact_distance(q, np.where(valid, Idx, 0)), np.inf)
        j = np.argmin(exact, axis=1)
        rows = np.arange(q.shape[0])
        best, index = exact[rows, j], Idx[rows, j].astype(np.intp)
        # data of the scanned cells beyond the k returned
        kth = np.where(valid[:, -1], np.sqrt(np.maximum(D[:, -1].astype(np.float64) - E, 0.0)) - shift, np.inf)
        if probes >= cells:
            return index, best, kth
        # data of the cells not scanned (Voronoi half-spaces)
        diff = self.centroids[Ic[:, :probes]] - q32.astype(np.float64)[:, None, :]
        Da = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff)).min(axis=1)
        Du = np.sqrt(np.maximum(Dc[:, probes].astype(np.float64) - E, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            vor = np.where(Du > Da, 0.5 * (Du - Da) - E_assign / (Du + Da), 0.0) - shift
        return index, best, np.minimum(kth, np.maximum(vor, 0.0))


register_search(IVFSearch)
