"""The paper's model kind: a 1-D bar of one element pushed by a moving rigid obstacle.

One unknown (the tip displacement ``u``), one material point (strain ``u / l0``) and one contact
pair with the gap ``g = w - u``, ``w = h - l0``. The classical solution, the penalty solution and
the exact projection of a datum onto ``Z_E`` are known in closed form (see the methods).

The model describes itself to the front ends (:meth:`BarModel.describe`,
:meth:`BarModel.penalty_closed_form`, :meth:`BarModel.figures`); the ``[bar]`` case files are parsed
by :mod:`ddcm_casadi.casefiles.bar`, and the figures drawn by :mod:`ddcm_casadi.outputs.plots`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ddcm_casadi.data.dataset import MaterialDataset, check_positive
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.base import ContactModel, FigureSpec


@dataclass(frozen=True, eq=False)
class BarModel(ContactModel):
    """The paper's 1-D bar against a moving rigid obstacle (one unknown: the tip displacement).

    Gap ``g = w - u`` with ``w = h - length``; strain ``u / length``; ``stress = -p``.
    """

    area: float = 1.0
    length: float = 1.0

    def closed_form(self, step: int):
        """``u = min(0, w)``, ``p = -E u / length`` (paper, eq. (1))."""
        if self.youngs_modulus is None:
            return None
        w = self.gap_offsets[step, 0]
        u = min(0.0, w)
        return np.array([u]), np.array([-self.youngs_modulus[0] * u / self.length])

    def penalty_closed_form(self, step: int, gamma: float):
        """Penalty solution: ``u = gamma w / (E/length + gamma)`` for ``w < 0``, else ``u = 0``."""
        w = self.gap_offsets[step, 0]
        k = self.youngs_modulus[0] / self.length
        u = gamma * w / (k + gamma) if w < 0 else 0.0
        return np.array([u]), np.array([gamma * max(0.0, u - w)])

    def projection_closed_form(self, step: int, strain_star: float, stress_star: float):
        """Exact projection of one data point onto ``Z_E``: the nearer of the free and contact branches.

        Returns ``(u, p, d2)`` with ``d2`` the squared DDCM distance per unit volume.
        """
        metric = self.dataset.metric
        w = self.gap_offsets[step, 0]
        L = self.length
        u_free, p_free = min(L * strain_star, w), 0.0
        u_cont, p_cont = w, max(0.0, -stress_star)

        def d2(u, p):  # strain u / L, stress -p
            return float(metric.distance2(u / L - strain_star, -p - stress_star)[0])

        cand = [(d2(u_free, p_free), u_free, p_free), (d2(u_cont, p_cont), u_cont, p_cont)]
        best = min(cand)
        return best[1], best[2], best[0]

    # ------------------------------------------------------------ self-description
    def describe(self) -> dict:
        """The bar's record in ``results.json``: ``length``, ``area``, ``youngs_modulus`` and the
        obstacle ``positions`` (one per step)."""
        return dict(length=self.length, area=self.area,
                    youngs_modulus=None if self.youngs_modulus is None else float(self.youngs_modulus[0]),
                    positions=self.load_parameter.tolist())

    def figures(self, runs) -> dict[str, FigureSpec]:
        """The paper's Fig. 2: tip displacement and contact pressure against the obstacle position
        (drawn by :func:`ddcm_casadi.outputs.plots.figure_displacement` and
        :func:`~ddcm_casadi.outputs.plots.figure_pressure`)."""
        return {"fig2a_tip_displacement.png": FigureSpec("tip_displacement"),
                "fig2b_contact_pressure.png": FigureSpec("contact_pressure")}


def bar_model(*, length: float, area: float = 1.0, youngs_modulus: float | None = None,
              positions, dataset: MaterialDataset | None = None, name: str = "bar") -> BarModel:
    """A 1-D bar of ``length`` fixed at ``x = 0`` and pushed by a rigid obstacle at ``x = h``.

    Parameters
    ----------
    length, area : float
        Undeformed length ``l0`` (m) and cross-section ``A`` (m^2).
    youngs_modulus : float, optional
        ``E`` (Pa) for the classical variant.
    positions : array_like
        Obstacle positions ``h`` (m), one per load step.
    dataset : MaterialDataset, optional
        Material data for the DDCM variant.
    """
    L = check_positive("length", length)
    A = check_positive("area", area)
    E = None if youngs_modulus is None else check_positive("youngs_modulus", youngs_modulus)
    h = np.asarray(positions, dtype=float).ravel()
    if h.size == 0:
        raise InputError("obstacle positions are empty")
    if not np.all(np.isfinite(h)):
        raise InputError("obstacle positions must be finite (no NaN or infinity)")
    return BarModel(
        strain_operator=sp.csr_matrix(np.array([[1.0 / L]])),
        volumes=np.array([A * L]),
        gap_operator=sp.csr_matrix(np.array([[-1.0]])),
        contact_area=np.array([A]),
        gap_offsets=(h - L)[:, None],
        loads=np.zeros((h.size, 1)),
        load_parameter=h,
        youngs_modulus=None if E is None else np.array([E]),
        dataset=dataset,
        length_scale=L,
        name=name,
        load_parameter_name="h",
        area=A,
        length=L,
    )


def paper_bar(*, n_data: int = 500, c: float = 300e9) -> BarModel:
    """The numerical example of the paper (Section 4).

    ``E = 200 GPa``, ``l0 = 1 m``, ``h`` from 1.01 m down to 0.99 m in 21 steps, 500 Hookean data
    points with strain in ``[-0.05, 0.01]`` and ``c = 300 GPa``.
    """
    E = 200e9
    data = MaterialDataset.hookean(E, -0.05, 0.01, n_data, c=c)
    return bar_model(length=1.0, area=1.0, youngs_modulus=E, positions=np.linspace(1.01, 0.99, 21),
                     dataset=data, name="paper bar")
