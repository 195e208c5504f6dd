r"""LCDD, the locally convex data-driven scheme (Q. He and J.-S. Chen, CMAME 363 (2020) 112791).

The material update is the projection onto the convex hull of the ``k`` data nearest to the
state,

.. math::  z^*_i = \arg\min_{y \in \operatorname{conv} N_k(z_i)} d(z_i, y)^2 ,

``N_k(z_i)`` the ``k`` nearest data of point ``i`` under the metric, computed exactly in the
metric's scaled coordinates (:func:`~ddcm_casadi.drivers.noise_robust.hull_projection`).
One-component points only (bars, trusses). See :mod:`ddcm_casadi.drivers.noise_robust`.
"""

from __future__ import annotations

import numpy as np

from ddcm_casadi.drivers.noise_robust import SettlingScheme, hull_projection


def lcdd_states(model, strain, stress, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The LCDD material states of every point: the projection onto the hull of its k nearest data."""
    data = model.dataset
    rc = np.sqrt(model.metric)  # per point: coordinates (sqrt(c) e, s / sqrt(c))
    near = data.k_nearest(strain, stress, k)
    q = np.column_stack([rc * strain, stress / rc])
    Y = np.stack([rc[:, None] * data.strain[near], data.stress[near] / rc[:, None]], axis=-1)
    y = hull_projection(q, Y)
    return y[:, 0] / rc, y[:, 1] * rc


class LCDD(SettlingScheme):
    """LCDD's material update (one stage), over ``lcdd_neighbours`` data."""

    name = "lcdd"

    def material(self, strain, stress) -> tuple[np.ndarray, np.ndarray]:
        return lcdd_states(self.model, strain, stress, self.options.lcdd_neighbours)

    def settled(self) -> str:
        return "fixed point (LCDD)"
