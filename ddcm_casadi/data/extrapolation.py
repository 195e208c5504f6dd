r"""Material states the data cannot support: a per-step flag for DDCM results.

Where the states of a load step leave the range of the data, DDCM still finds a fixed point: the
assigned data stop at the last datum and the fixed point is a fixed point, but its stresses are
those of the data's edge, not of the material. This module counts such states, so that a step can
be flagged (it is a flag, not a convergence failure).

Everything is measured in the metric's scaled coordinates
``X = [L^T e, L^{-1} s]`` (:meth:`~ddcm_casadi.data.metric.Metric.coordinates`, ``C = L L^T``), where the
DDCM distance is Euclidean. A material point with state ``X`` and nearest datum ``X*_j`` is
*beyond the data* when either holds:

1. **Past the data's range.** The data's range is their bounding box in scaled coordinates
   (``lo_c <= X_c <= hi_c`` for each of the ``2k`` coordinates; for one component: the smallest
   and largest ``sqrt(c) strain`` and ``stress / sqrt(c)``, the data with the smallest or largest
   strain or stress). The state is flagged when it is past a face of the box by more than half
   the local spacing at its nearest datum, ``X_c - hi_c > h_j / 2`` or ``lo_c - X_c > h_j / 2``:
   a strain or a stress that no datum reaches. Its nearest datum then usually lies on that face
   (the data's extreme in the direction the state went), but not always: in a truss whose
   members saturate at the data's edge, equilibrium pushes other members to stresses beyond the
   data's range at strains inside it, and their nearest datum is an interior one. Half a spacing
   is the margin because a state inside the range is also within about ``h / 2`` of a datum along
   the data: closer than that, the edge costs no more than the data's resolution. The box, not
   the convex hull: for one component it is exactly the range of strains and stresses; for the
   grids of Mandel strains the case files generate, with a matrix metric, it is the bounding box
   of the grid's image under ``L^T`` (a state past the grid escapes it only near the grid's
   corners, where the second test still sees it); and it costs ``2k`` comparisons per state.
2. **Far along the data.** The state's offset from its datum *along the data*, ``t`` (its
   component in the data's local tangent space, :func:`neighbourhood`), exceeds
   :data:`FAR_SPACINGS` local spacings ``h_j``: a state in a hole of the data, or beyond the
   range of data whose box the first test does not see (a curved law).

Along, not across: at a fixed point every state's datum is its nearest one, so along data that
sample a law at spacing ``h`` an interior state is within about ``h / 2`` of its datum, whatever
the problem; across the law its distance is the mismatch between ``Z_E`` and the data, the DDCM
error, which says nothing about the data's range. For one element in contact the full distance is
at most ``h / 2`` (the admissible set is a line crossing the data), but on continua the mismatch
converges more slowly than the spacing: on the Hertz example (grids of 11, 21, 31 points per axis)
the full distance reaches 3.1, 5.0, 6.3 spacings, of which about 1.0 along the data. Measured
along the data (``data_spacings`` of a step), interior states stay below 1.1 spacings on the
examples (bars, trusses, Hertz, and the softening punch until its strains pass the edge of its
data grid; local minima included) and below 2.4 on
random, noisy samples of a Hookean line (LCDD and max-ent included). :data:`FAR_SPACINGS` = 10
is above all of these with a margin of two, and an order of magnitude beyond the data's own
resolution: there the data no longer describe the state, whatever the fixed point says.
"""

from __future__ import annotations

import numpy as np

#: Offset from the nearest datum along the data, in local data spacings, beyond which a state is
#: not described by the data (see the module docstring for the derivation).
FAR_SPACINGS = 10.0
#: Coarse data (:meth:`DataCoverage.coarseness`, :func:`coarse_data`). A state within half a
#: spacing of a datum is rounded to it, so where the states of many points vary by less than a
#: spacing they all sit on one datum (on a continuum, the zero-stress datum of the unloaded
#: region) and the body carries that datum's stress there. On the Hertz example (plane strain,
#: 1308 points, uniform grids of 21, 41, 61, 81, 101 strains per axis) the share of the points on
#: the most used datum at the last step is 0.67, 0.48, 0.36, 0.28, 0.24 and the DDCM contact force
#: 48, 70, 80, 85, 88 % of the classical one: the force error is about 0.5 to 0.8 times the share,
#: and a share above a quarter (an error of about 15 % and more) is flagged. Graded grids (points
#: denser towards zero strain) put at most 4 % of the points on one datum and carry 85 to 95 %.
COARSE_SHARE = 0.25
#: ... unless the states on that datum are alike: all within a tenth of a spacing of their mean
#: (a bar or a block under a uniform strain puts every point on one datum, rightly). On Hertz's
#: zero-stress datum the states spread 1.1 to 1.4 spacings from their mean.
UNIFORM_SPREAD = 0.1
#: The states' size, reported with the share (not a test of its own): the largest, over the points,
#: of a state's distance from the zero state (in the metric's scaled coordinates) in local data
#: spacings at its datum. A state within half a spacing of its datum has its stress resolved to
#: about ``1 / (2 r)`` at ``r`` spacings; but a bar before contact or a truss member at rest sits at
#: zero, so a small size alone says nothing (measured: 1e-32 to 0.6 on the paper's bar before
#: contact, where DDCM is exact), while the grid of 3 strains per axis on the Hertz example gives
#: 0.86 with every point on one datum, which the share catches.
#: Extra neighbours searched for a datum's spacing, for the datum itself and its duplicates.
_DUPLICATES = 8
#: The neighbourhoods of few data (at most this many points checked at once) are remembered, at
#: most :data:`_REMEMBERED` sets of them: a small model's steps (and the DDCM runs of every
#: formulation) come back to the same data.
_FEW = 64
#: Material points checked at a time (:meth:`DataCoverage.check`, :meth:`DataCoverage.coarseness`):
#: the checks are point by point, and their working arrays (coordinates, tangent spaces: 30 MB
#: at 1e5 two-dimensional points) are then bounded, not proportional to the body.
CHUNK = 16384
_REMEMBERED = 4096
#: Data of a set whose neighbourhoods :meth:`DataCoverage._neighbourhood` keeps, datum by datum
#: (a spacing and a ``k x 2k`` tangent space each: 150 bytes in 2-D, 15 MB at this bound).
_REMEMBERED_DATA = 100_000


class DataCoverage:
    """The range of a model's material data, built once, and the check of states against it.

    Parameters
    ----------
    dataset : MaterialDataset or PointData
        The model's data (one set shared by every point, or one set per material).
    n_points : int
        Material points of the model.
    search : str
        The data search backend of its nearest data (:meth:`MaterialDataset.search
        <ddcm_casadi.data.dataset.MaterialDataset.search>`): the run's, so that a set searched
        without the KD-tree (``strips``) is checked without it too.
    """

    def __init__(self, dataset, n_points: int, search: str = "kdtree") -> None:
        self.dataset = dataset
        self.n_points = int(n_points)
        _, self.material = dataset.point_materials(self.n_points)
        self.k = dataset.datasets[0].k
        self.search = search
        self._boxes = [d.box for d in dataset.datasets]  # in scaled coordinates
        self._neighbourhoods: dict[tuple[int, bytes], tuple[np.ndarray, np.ndarray]] = {}
        self._data_neighbourhoods: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def _per_point(self, a) -> np.ndarray:
        return np.asarray(a, dtype=float).reshape((-1,) if self.k == 1 else (-1, self.k))

    def check(self, strain, stress, nearest=None) -> tuple[np.ndarray, np.ndarray]:
        """Which material points are beyond the data, and how far each is from it.

        Parameters
        ----------
        strain, stress : array_like
            The states of every material point (flat and point-major, ``m k`` values, as
            :meth:`~ddcm_casadi.problems.build.ProblemPair.fields` gives them).
        nearest : (m,) int, optional
            The datum nearest each state (global indices), where the caller has searched them
            already; else they are searched here.

        Returns
        -------
        beyond : (m,) bool
            Past the data's range or farther than :data:`FAR_SPACINGS` spacings (module docstring).
        spacings : (m,) float
            Offset from the nearest datum along the data, in local data spacings (0 where the
            set has too few data for a spacing, ``nan`` for non-finite states).
        """
        strain, stress = self._per_point(strain), self._per_point(stress)
        beyond = np.zeros(self.n_points, dtype=bool)
        spacings = np.full(self.n_points, np.nan)
        offsets = np.asarray(self.dataset.offsets, dtype=np.intp)
        nearest = None if nearest is None else np.asarray(nearest, dtype=np.intp)
        for s, d in enumerate(self.dataset.datasets):
            for pts in self._finite_points(s, strain, stress):
                j = None if nearest is None else nearest[pts] - offsets[s]
                beyond[pts], spacings[pts] = self._check_set(s, d, strain[pts], stress[pts], j)
        return beyond, spacings

    def _finite_points(self, s: int, strain: np.ndarray, stress: np.ndarray):
        """The points of set ``s`` whose states are finite, :data:`CHUNK` at a time."""
        for start in range(0, self.n_points, CHUNK):
            pts = start + np.flatnonzero(self.material[start:start + CHUNK] == s)
            pts = pts[np.all(np.isfinite(strain[pts]).reshape(pts.size, -1), axis=1)
                      & np.all(np.isfinite(stress[pts]).reshape(pts.size, -1), axis=1)]
            if pts.size:
                yield pts

    def _check_set(self, s: int, d, strain: np.ndarray, stress: np.ndarray,
                   j: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self._boxes[s]
        if j is None:
            j = d.nearest(strain, stress, search=self.search)
        X = d.metric.coordinates(strain, stress)
        h, tangent = self._neighbourhood(s, d, j)
        along = np.linalg.norm(np.einsum("mij,mj->mi", tangent, X - d.metric.coordinates(d.strain[j], d.stress[j])),
                               axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(along > 0, along / h, 0.0)
        half = 0.5 * np.where(np.isfinite(h), h, 0.0)[:, None]
        past = ((X - hi > half) | (lo - X > half)).any(axis=1)
        return past | (ratio > FAR_SPACINGS), ratio

    def coarseness(self, strain, stress, index) -> tuple[float, float, float]:
        """How coarse the data are for the states of one step (:func:`coarse_data` judges it).

        Parameters
        ----------
        strain, stress : array_like
            The states of every material point (flat and point-major, as in :meth:`check`).
        index : (m,) int
            The datum of each point (global indices of the model's data).

        Returns
        -------
        share : float
            The share of the material points on the most used datum.
        spread : float
            How far the states on that datum are from their mean, at most, in local data
            spacings at the datum (0 when they are alike, or where the set has too few data for
            a spacing).
        spacings : float
            The largest, over the points, of a state's distance from the zero state (scaled
            coordinates) in local data spacings at its datum; ``nan`` where no point has a finite
            state and a spacing.
        """
        strain, stress = self._per_point(strain), self._per_point(stress)
        index = np.asarray(index, dtype=np.intp).reshape(-1)
        if index.size != self.n_points or not self.n_points:
            return float("nan"), float("nan"), float("nan")
        offsets = np.asarray(self.dataset.offsets, dtype=np.intp)
        values, counts = np.unique(index, return_counts=True)
        top = int(values[np.argmax(counts)])
        share = float(counts.max()) / self.n_points
        spread, spacings = 0.0, float("nan")
        for s, d in enumerate(self.dataset.datasets):
            on = []  # the finite points on the most used datum
            for pts in self._finite_points(s, strain, stress):
                h, _ = self._neighbourhood(s, d, index[pts] - offsets[s])
                ok = np.isfinite(h) & (h > 0)
                if np.any(ok):
                    X = d.metric.coordinates(strain[pts[ok]], stress[pts[ok]])
                    size = float(np.max(np.linalg.norm(X, axis=1) / h[ok]))
                    spacings = size if not np.isfinite(spacings) else max(spacings, size)
                on.append(pts[index[pts] == top])
            on = np.concatenate(on) if on else np.zeros(0, np.intp)
            if on.size:  # one datum: one spacing
                h_top = self._neighbourhood(s, d, np.array([top - offsets[s]]))[0][0]
                if np.isfinite(h_top) and h_top > 0:
                    X = d.metric.coordinates(strain[on], stress[on])
                    spread = float(np.max(np.linalg.norm(X - X.mean(axis=0), axis=1)) / h_top)
        return share, spread, spacings

    def _neighbourhood(self, s: int, d, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:func:`neighbourhood` of the data ``index`` of set ``s``, remembered: for few data by
        the set of them, for many datum by datum (up to :data:`_REMEMBERED_DATA` data)."""
        if index.size > _FEW:
            # many points share their nearest datum (on a continuum, most do): each datum once,
            # and once a run (a step's check and its coarseness ask for the same data, the next
            # step for most of them again: 0.13 s of a 1e5-point path's 0.29 s of checks)
            unique, inverse = np.unique(index, return_inverse=True)
            h, tangent = self._remembered(s, d, unique)
            return h[inverse], tangent[inverse]
        key = (s, index.tobytes())
        hit = self._neighbourhoods.get(key)
        if hit is None:
            hit = neighbourhood(d, index, self.search)
            if len(self._neighbourhoods) < _REMEMBERED:
                self._neighbourhoods[key] = hit
        return hit

    def _remembered(self, s: int, d, unique: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:func:`neighbourhood` of the sorted distinct data ``unique`` of set ``s``: those met
        before from memory, the others computed and added to it (all of ``unique`` afresh where
        the memory would pass :data:`_REMEMBERED_DATA` data)."""
        remembered = self._data_neighbourhoods.get(s)
        if remembered is not None:
            known, h, tangent = remembered
            at = np.minimum(np.searchsorted(known, unique), known.size - 1)
            new = unique[known[at] != unique]
            if not new.size:
                return h[at], tangent[at]
            if known.size + new.size > _REMEMBERED_DATA:
                remembered, new = None, unique
        else:
            new = unique
        h_new, t_new = neighbourhood(d, new, self.search)
        if remembered is None:
            known, h, tangent = new, h_new, t_new
        else:
            known, h, tangent = remembered
            order = np.argsort(np.concatenate([known, new]), kind="stable")
            known = np.concatenate([known, new])[order]
            h, tangent = np.concatenate([h, h_new])[order], np.concatenate([tangent, t_new])[order]
        self._data_neighbourhoods[s] = (known, h, tangent)
        at = np.searchsorted(known, unique)
        return h[at], tangent[at]


def neighbourhood(d, index: np.ndarray, search: str = "kdtree") -> tuple[np.ndarray, np.ndarray]:
    """The local spacing and the tangent space of the data set ``d`` at each datum ``index``
    (its nearest data by the backend ``search``).

    From the ``K = 4k`` nearest distinct data of the datum (``k`` strain components; the datum
    itself and its duplicates are left out), in scaled coordinates:

    - the spacing ``h``: half the distance to the ``K``-th of them. For data equally spaced at
      ``h`` along a curve (``k = 1``) that is ``h`` exactly (two neighbours on each side, the
      farther at ``2h``); for a grid of ``k`` Mandel strains it is within a factor ``sqrt 2`` of
      the grid spacing. Not the nearest neighbour alone: random samples have pairs of data much
      closer than their spacing (the nearest-neighbour distance is exponentially distributed),
      and a distance in units of it is meaningless (states up to 200 nearest-neighbour distances
      from their datum on random samples of a Hookean line are within 2.4 of these spacings
      along the data);
    - the tangent space: the ``k`` leading principal directions of the ``K`` offsets (a material
      law is a ``k``-dimensional manifold of the ``2k``-dimensional state space).

    Returns
    -------
    h : (n,) float
        ``inf`` where fewer than ``K`` distinct data are found (a set of a few points).
    tangent : (n, k, 2k) float
        Orthonormal rows spanning the tangent space.
    """
    index = np.asarray(index, dtype=np.intp)
    k = d.k
    K = 4 * k
    n = index.size
    if len(d) <= K:
        return np.full(n, np.inf), np.zeros((n, k, 2 * k))
    near = d.k_nearest(d.strain[index], d.stress[index], K + _DUPLICATES, search=search)
    X = d.metric.coordinates(d.strain[near.ravel()], d.stress[near.ravel()]).reshape(n, near.shape[1], 2 * k)
    Y = X - d.metric.coordinates(d.strain[index], d.stress[index])[:, None, :]
    dist = np.linalg.norm(Y, axis=2)
    dist[dist <= 0] = np.inf  # the datum itself and its duplicates
    order = np.argsort(dist, axis=1, kind="stable")[:, :K]
    rows = np.arange(n)[:, None]
    h = 0.5 * dist[rows[:, 0], order[:, -1]]
    _, _, Vt = np.linalg.svd(np.where(np.isfinite(dist[rows, order])[:, :, None], Y[rows, order], 0.0))
    return h, Vt[:, :k, :]


def coarse_data(share: float, spread: float, spacings: float, n_points: int) -> str:
    """Why the data are too coarse for a step's states (:meth:`DataCoverage.coarseness`), or ``""``.

    Too coarse: more than :data:`COARSE_SHARE` of the (several) points on one datum while their
    states differ by more than :data:`UNIFORM_SPREAD` spacings. The reason gives the share and the
    states' size in data spacings.
    """
    if n_points > 1 and share > COARSE_SHARE and spread > UNIFORM_SPREAD:
        size = f", the states up to {spacings:.2g} data spacings from zero" if np.isfinite(spacings) else ""
        return f"{100 * share:.0f} % of the {n_points} points on one datum{size}"
    return ""
