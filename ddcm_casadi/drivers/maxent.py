r"""Max-ent, the maximum-entropy data-driven scheme with annealing (T. Kirchdoerfer and
M. Ortiz, CMAME 326 (2017) 622-641).

The material state of point ``i`` is the mean of its ``K`` nearest data under the Boltzmann
weights

.. math::  p_{ij} = \frac{\exp(-\tfrac{\beta}{2} d^2(z_i, y_j))}{Z_i} , \qquad
           z^*_i = \sum_j p_{ij} y_j ,

alternated with the ``Z_E`` projection at ``beta_s = beta_0 g^s``, ``beta_0 = 1 / <d^2>`` over
the first projected state's neighbourhoods (the maths, the descent argument and the schedule:
:mod:`ddcm_casadi.drivers.noise_robust`).
"""

from __future__ import annotations

import numpy as np

from ddcm_casadi.drivers.noise_robust import STAGE_TOL, SettlingScheme, boltzmann_weights, neighbourhoods


class MaxEnt(SettlingScheme):
    """Max-ent's material update and its annealing schedule (``maxent_neighbours``,
    ``maxent_steps``, ``maxent_beta_growth``)."""

    name = "maxent"

    def __init__(self, model, options) -> None:
        super().__init__(model, options)
        self.k = options.maxent_neighbours
        self.steps, self.growth = options.maxent_steps, options.maxent_beta_growth
        self.beta = self.beta0 = float("nan")
        self.stage, self.concentrated, self.last = 0, False, False

    def start(self, strain, stress) -> None:
        _, d2 = neighbourhoods(self.model, strain, stress, self.k)
        # all neighbours on the state (duplicated data): any beta gives the same mean
        self.beta0 = self.beta = 1.0 / max(float(np.mean(d2)), np.finfo(float).tiny)
        self.stage, self.concentrated, self.last = 0, False, False

    def material(self, strain, stress) -> tuple[np.ndarray, np.ndarray]:
        data, model = self.model.dataset, self.model
        near, d2 = neighbourhoods(model, strain, stress, self.k)
        w, self.concentrated = boltzmann_weights(d2, self.beta)
        shape = near.shape + (model.strain_components,)
        e = np.einsum("ij,ijk->ik", w, data.strain[near].reshape(shape))
        s = np.einsum("ij,ijk->ik", w, data.stress[near].reshape(shape))
        return e.reshape(np.shape(strain)), s.reshape(np.shape(stress))

    def tolerance(self, tol: float) -> float:
        """An intermediate stage only has to follow the minimiser within a small fraction of the
        kernel's width ``beta^-1/2`` (the next stage moves it anyway); the last one settles to ``tol``."""
        return tol if self.last else max(tol, STAGE_TOL / np.sqrt(self.beta))

    def advance(self) -> bool:
        if self.last or self.concentrated or self.stage + 1 >= self.steps:
            self.last = True
            return False
        self.stage += 1
        self.beta *= self.growth
        return True

    def settled(self) -> str:
        how = "weights concentrated" if self.concentrated else "final temperature"
        return f"fixed point (max-ent, {how} at stage {self.stage + 1}/{self.steps}, beta = {self.beta:.3g}/Pa)"
