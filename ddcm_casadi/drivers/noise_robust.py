r"""Noise-robust data-driven schemes: local convexity (LCDD) and maximum entropy (max-ent).

Both keep the projection onto ``Z_E`` of the DDCM driver (:meth:`DDCMSolver.project_data`, the
same CasADi problem with the material states passed as parameters) and replace the projection
onto the data, "the nearest datum", by another *material update* ``z* = M(z)``
(:class:`~ddcm_casadi.drivers.scheme.MaterialScheme`; :class:`~ddcm_casadi.drivers.lcdd.LCDD`,
:class:`~ddcm_casadi.drivers.maxent.MaxEnt`; this module holds what they share,
:class:`SettlingScheme`):

.. math::  z \leftarrow P_{Z_E}(z^*) , \qquad z^* \leftarrow M(z) ,

alternated until ``z*`` moves less than :data:`TOL` of the data's spread (in the metric; such
alternations converge only in the limit, so a load step that does not settle within
``max_outer`` projections is reported as not converged). The reported ``distance`` is
``1/2 sum_i w_i d^2(z_i, z*_i)``, ``data_index`` the datum nearest ``z*``.

**LCDD** (Q. He and J.-S. Chen, "A physics-constrained data-driven approach based on locally
convex reconstruction for noisy database", CMAME 363 (2020) 112791): the projection onto the
convex hull of the ``k`` data nearest to the state,

.. math::  z^*_i = \arg\min_{y \in \operatorname{conv} N_k(z_i)} d(z_i, y)^2 ,

``N_k(z_i)`` the ``k`` nearest data of point ``i`` under the metric. The reconstructed state
averages the noise of its neighbours instead of jumping between noisy data (He & Chen report
about an order of magnitude on noisy data). In the metric's scaled coordinates
(:meth:`~ddcm_casadi.data.metric.Metric.coordinates`, where the metric distance is Euclidean) the
projection onto the hull of ``k`` points in the ``(strain, stress)`` plane is exact and
vectorised over points: the state itself if it lies in one of the triangles of three neighbours,
else the nearest point of the segments between two neighbours (every edge of the hull is one of
them). One-component points only (bars, trusses).

**Max-ent** (T. Kirchdoerfer and M. Ortiz, "Data-driven computing with noisy material data
sets", CMAME 326 (2017) 622-641): point ``i`` is not assigned one datum but the distribution of
maximum entropy over its data ``y_j`` at a given mean squared distance, the Boltzmann weights

.. math::  p_{ij} = \frac{\exp(-\tfrac{\beta}{2} d^2(z_i, y_j))}{Z_i} , \qquad
           Z_i = \sum_j \exp(-\tfrac{\beta}{2} d^2(z_i, y_j)) ,

``beta`` the inverse temperature (1/Pa: ``d^2 = de C de + ds C^-1 ds`` is an energy density),
and the material state is their mean ``z*_i = sum_j p_ij y_j``. The scheme minimises the free
energy ``sum_i w_i F_i(z_i)`` over ``Z_E``,

.. math::  F_i(z_i) = -\frac{1}{\beta} \log Z_i
           = \min_{p \ge 0,\ \sum p = 1} \sum_j p_j \tfrac12 d^2(z_i, y_j)
             + \frac{1}{\beta} \sum_j p_j \log p_j ,

by alternating minimisation: the minimising ``p`` is the Boltzmann distribution (Gibbs), and
since ``d^2`` is a quadratic form, ``sum_j p_j d^2(z, y_j) = d^2(z, z*) + sum_j p_j d^2(z*, y_j)``,
so the minimising ``z`` is ``P_{Z_E}(z*)``. With ``G(z, p)`` the bracket above summed with the
weights ``w_i``, ``F(z') <= G(z', p) <= G(z, p) = F(z)``: at fixed ``beta`` the free energy never
increases (as far as the ``Z_E`` projection is a global minimum). As ``beta -> infinity``,
``F_i`` tends to ``min_j d^2 / 2`` and ``z*`` to the nearest datum: plain distance-minimising DDCM.

*Neighbourhoods.* The sums run over the ``K = maxent_neighbours`` data nearest the state (the
KD-tree, each point in its own data set), not over all data: the neighbourhood of ``z_i``. The
``K`` nearest give the largest ``Z_i`` over all sets of ``K`` data, so the truncated ``F_i`` is
also a minimum over ``(set, p)`` and the descent argument holds for it; beyond ``d_K`` the
weights are below ``exp(-beta (d_K^2 - d_1^2) / 2)`` relative to the nearest datum, under
``1e-16`` once ``beta`` has grown (then the truncation is exact to roundoff).

*Annealing.* Per load step, from the first projected state: ``beta_0 = 1 / <d^2>``, the mean of
``d^2`` over all points and their ``K`` nearest data (the neighbourhood's spread: at ``beta_0``
the weights cover the neighbourhood), then ``beta_s = beta_0 g^s``, ``s = 0 .. S - 1``
(``g = maxent_beta_growth``, ``S = maxent_steps``). At each stage the scheme alternates until
``z*`` settles (an intermediate stage to :data:`STAGE_TOL` of the kernel's width, the last to
:data:`TOL`), then ``beta`` grows, from the same state. It stops after stage ``S - 1``, or as soon
as the weights have *concentrated* (every point's second-nearest datum weighs less than
:data:`CONCENTRATED` relative to its nearest: ``z*`` is then the nearest datum to roundoff and the
settled state is a fixed point of plain DDCM). A finite final ``beta`` keeps a weighted mean of
the neighbourhood (the noise of many data averaged: the measured best on noisy data, at one
stage); many stages anneal to plain DDCM, starting from the smooth high-temperature problem
(deterministic annealing: a search for a better plain fixed point, whose error is still that of
single noisy data).
"""

from __future__ import annotations

import itertools
from abc import abstractmethod

import numpy as np

from ddcm_casadi.drivers.records import MaterialStates
from ddcm_casadi.drivers.scheme import MaterialScheme, Update


#: Change of the material states (metric distance over the data's spread) below which an
#: alternation has settled.
TOL = 1e-7
#: Max-ent: an intermediate annealing stage has settled when the material states move less than
#: this fraction of the kernel's width ``beta^-1/2``.
STAGE_TOL = 1e-3
#: Relative weight of a point's second-nearest datum below which max-ent's weights have
#: concentrated on the nearest one (the mean is then that datum to roundoff).
CONCENTRATED = 1e-16


def hull_projection(q: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """The nearest point to each ``q[i]`` (2,) in the convex hull of ``Y[i]`` (K, 2), Euclidean;
    ``q``: (m, 2), ``Y``: (m, K, 2)."""
    m, K, _ = Y.shape
    best = Y[:, 0].copy()
    best_d = np.sum((best - q) ** 2, axis=1)
    for a, b in itertools.combinations(range(K), 2):
        ab = Y[:, b] - Y[:, a]
        L = np.sum(ab * ab, axis=1)
        t = np.where(L > 0, np.sum((q - Y[:, a]) * ab, axis=1) / np.where(L > 0, L, 1.0), 0.0).clip(0.0, 1.0)
        y = Y[:, a] + t[:, None] * ab
        d = np.sum((y - q) ** 2, axis=1)
        better = d < best_d
        best[better], best_d[better] = y[better], d[better]
    inside = np.zeros(m, dtype=bool)
    for a, b, c in itertools.combinations(range(K), 3):
        v0, v1, v2 = Y[:, b] - Y[:, a], Y[:, c] - Y[:, a], q - Y[:, a]
        det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
        ok = np.abs(det) > 0
        safe = np.where(ok, det, 1.0)
        s = (v2[:, 0] * v1[:, 1] - v2[:, 1] * v1[:, 0]) / safe
        t = (v0[:, 0] * v2[:, 1] - v0[:, 1] * v2[:, 0]) / safe
        inside |= ok & (s >= 0) & (t >= 0) & (s + t <= 1)
    best[inside] = q[inside]
    return best


def point_distance2(model, d_strain: np.ndarray, d_stress: np.ndarray) -> np.ndarray:
    """Squared metric distances of strain and stress differences ``(m, K, k)``, each point under
    its own material's metric: ``(m, K)``."""
    metrics, material = model.dataset.point_materials(model.n_points)
    m, K, kc = d_strain.shape
    out = np.empty((m, K))
    for j, mt in enumerate(metrics):
        pts = material == j
        out[pts] = mt.distance2(d_strain[pts].reshape(-1, kc), d_stress[pts].reshape(-1, kc)).reshape(-1, K)
    return out


def per_point(model, a) -> np.ndarray:
    """A flat point-major field as ``(m, 1, k)``."""
    return np.reshape(np.asarray(a, dtype=float), (model.n_points, 1, model.strain_components))


def largest_distance(model, d_strain, d_stress) -> float:
    """The largest metric length of per-point strain and stress differences (flat, point-major)."""
    return float(np.sqrt(np.max(point_distance2(model, per_point(model, d_strain), per_point(model, d_stress)))))


def data_spread(model) -> float:
    """The largest extent of the data along one scaled coordinate (metric units, sqrt(Pa))."""
    return max(float(np.max(np.ptp(d.metric.coordinates(d.strain, d.stress), axis=0)))
               for d in model.dataset.datasets)


def neighbourhoods(model, strain, stress, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` data nearest each point's state (global indices, nearest first, ``(m, k)``) and
    their squared metric distances ``d^2`` (``(m, k)``); ``strain``, ``stress`` flat, point-major."""
    data = model.dataset
    near = data.k_nearest(strain, stress, k)
    m, K = near.shape
    shape = (m, K, model.strain_components)
    de = per_point(model, strain) - data.strain[near].reshape(shape)
    ds = per_point(model, stress) - data.stress[near].reshape(shape)
    return near, point_distance2(model, de, ds)


def boltzmann_weights(d2: np.ndarray, beta: float) -> tuple[np.ndarray, bool]:
    """Max-ent weights ``p_ij ~ exp(-beta d_ij^2 / 2)`` over each row of ``d2`` (``(m, K)``),
    normalised per row, and whether they have concentrated: in every row, each datum farther
    than the nearest weighs less than :data:`CONCENTRATED` times the nearest (data exactly as near,
    such as duplicates, share its weight). Shifted by the row minimum, so no overflow; a ``beta``
    grown to infinity leaves the nearest data only."""
    shifted = d2 - d2.min(axis=1, keepdims=True)
    farther = shifted > 0
    with np.errstate(over="ignore", invalid="ignore"):  # inf x 0 where not farther: not used
        w = np.exp(-0.5 * np.where(farther, beta * shifted, 0.0))
    w /= w.sum(axis=1, keepdims=True)
    far = np.where(farther, w, 0.0).max(axis=1)
    return w, bool(np.all(far < CONCENTRATED * w.max(axis=1)))


class SettlingScheme(MaterialScheme):
    """A material update that settles only in the limit (LCDD, max-ent), in stages.

    A run is done when the material states move less than :data:`TOL` of the data's spread
    (:func:`data_spread`) at the last stage; an intermediate stage settles to its own
    :meth:`tolerance`, then :meth:`advance` starts the next one from the same state (without a
    projection). The states are reported with their nearest datum as ``data_index``.
    Subclasses give :meth:`material` (the update proper) and may give :meth:`start` (called with
    the first projected state of a run), :meth:`tolerance`, :meth:`advance` and :meth:`settled`.
    """

    def __init__(self, model, options) -> None:
        super().__init__(model, options)
        self.tol = TOL * data_spread(model)
        self._star: MaterialStates | None = None
        self._started = False

    def states(self, index: np.ndarray) -> MaterialStates:
        data = self.model.dataset
        return MaterialStates(data.strain[index].ravel(), data.stress[index].ravel())

    def begin(self, start: MaterialStates) -> None:
        self._star, self._started = start, False

    def update(self, strain, stress) -> Update:
        if not self._started:
            self.start(strain, stress)
            self._started = True
        star, converged = self._star, False
        while True:
            # the change is measured from the material states this state was projected from
            new_e, new_s = self.material(strain, stress)
            change = largest_distance(self.model, new_e - star.strain, new_s - star.stress)
            if change > self.tolerance(self.tol):
                break  # not settled at this stage: project again
            if self.advance():
                continue  # settled: the next stage starts from the same state, without a projection
            converged = change <= self.tol  # the last stage, settled to the final tolerance
            break
        self._star = MaterialStates(new_e, new_s)
        return Update(self._star, done=converged, converged=converged, message=self.settled() if converged else "")

    def distance2(self, strain, stress, star: MaterialStates) -> np.ndarray:
        model = self.model
        return point_distance2(model, per_point(model, strain - star.strain), per_point(model, stress - star.stress))[:, 0]

    def finish(self, star: MaterialStates) -> MaterialStates:
        return MaterialStates(star.strain, star.stress, self.model.dataset.nearest(star.strain, star.stress))

    @abstractmethod
    def material(self, strain: np.ndarray, stress: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The material states ``M(z)`` of the projected state (flat, point-major)."""

    def start(self, strain: np.ndarray, stress: np.ndarray) -> None:
        """Set up a run from its first projected state (nothing by default)."""

    def tolerance(self, tol: float) -> float:
        """The change below which the current stage has settled (``tol`` at the last)."""
        return tol

    def advance(self) -> bool:
        """Go to the next stage (True), or say that this is the last one (False)."""
        return False

    def settled(self) -> str:
        """The message of a settled run."""
        return f"fixed point ({self.name})"
