r"""The shallow two-bar (von Mises) truss pushed down by a moving rigid plane: finite kinematics.

Two members of reference length ``L0 = sqrt(a^2 + h^2)`` join the supports ``(-a, 0)`` and
``(a, 0)`` to the apex ``(0, h)``. A rigid plane above the apex moves down by ``t`` (the load
parameter). With the apex's descent ``w``, each member has the Green-Lagrange strain

.. math::  E(w) = \frac{l^2 - L_0^2}{2 L_0^2}, \qquad l^2 = a^2 + (h - w)^2 ,

and the second Piola-Kirchhoff stress ``S = E_mod E`` (Saint Venant-Kirchhoff). The virtual work
``2 A L0 S dE`` with ``dE = -(h - w) dw / L0^2`` gives the force the plane must exert,

.. math::  F(w) = -\frac{2 A E_{mod} E(w) (h - w)}{L_0} ,

positive (compressive members) for ``0 < w < h``. The plane can only push: while ``F(t) >= 0`` the
apex follows it (``w = t``, contact). Past ``t = h`` the force would turn negative, the apex snaps
through and leaves the plane: the only equilibrium left below the plane is the inverted one
``w = 2 h`` (``E = 0``, free). Contact resumes when the plane reaches it (``t >= 2 h``, members in
tension). The load path avoids ``t = h`` and ``t = 2 h``, where the plane grazes an equilibrium and
the solution is not unique.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.truss import Obstacle, TrussModel, truss_model


def green_lagrange(w, half_span: float, rise: float):
    """``E(w)`` of both members at the apex descent ``w``."""
    L2 = half_span**2 + rise**2
    return (half_span**2 + (rise - np.asarray(w, float)) ** 2 - L2) / (2.0 * L2)


def plane_force(w, *, half_span: float, rise: float, area: float, youngs_modulus: float):
    """``F(w) = -2 A E_mod E(w) (h - w) / L0``: the downward force that holds the apex at ``w``."""
    L0 = np.hypot(half_span, rise)
    return -2.0 * area * youngs_modulus * green_lagrange(w, half_span, rise) * (rise - np.asarray(w, float)) / L0


def descent(travel, rise: float):
    """The apex descent ``w`` at the plane's travel ``t``: ``t`` in contact (``t < h`` or
    ``t > 2 h``), ``2 h`` after the snap (free)."""
    t = np.asarray(travel, float)
    return np.where((t > rise) & (t < 2.0 * rise), 2.0 * rise, t)


@dataclass(frozen=True, eq=False)
class VonMisesTrussModel(TrussModel):
    """The two-bar truss of this module, with its closed form (:meth:`closed_form`)."""

    half_span: float = 1.0
    rise: float = 0.1

    def closed_form(self, step: int):
        """``(u, p)``: the apex at ``(0, -w)`` and the plane's pressure ``F(w) / A`` (zero when free)."""
        t = float(self.load_parameter[step])
        w = float(descent(t, self.rise))
        in_contact = not (self.rise < t < 2.0 * self.rise)
        A = float(self.contact_area[0])
        F = plane_force(w, half_span=self.half_span, rise=self.rise, area=A,
                        youngs_modulus=float(self.youngs_modulus[0])) if in_contact else 0.0
        return np.array([0.0, -w]), np.array([F / A])


def von_mises_truss(*, half_span: float = 1.0, rise: float = 0.1, area: float = 1e-4,
                    youngs_modulus: float | None = 200e9, travel: float = 2.5, steps: int = 24,
                    dataset: MaterialDataset | None = None, name: str = "von Mises truss") -> VonMisesTrussModel:
    """The von Mises truss with finite kinematics, the plane moving down in ``steps`` equal steps
    to ``travel * rise`` (step 0: the plane touches the apex, no load).

    Parameters
    ----------
    half_span, rise : float
        ``a`` and ``h`` (m).
    area, youngs_modulus : float
        Cross-section (m^2) and modulus (Pa; ``None`` for a data-only model).
    travel : float
        The plane's final travel, in units of ``h``.
    steps : int
        Load steps; no step may land on ``t = h`` or ``t = 2 h`` (non-unique solutions).
    dataset : MaterialDataset, optional
        ``(E, S)`` data for the data-driven variant.
    """
    if not (np.isfinite(half_span) and np.isfinite(rise) and half_span > 0 and rise > 0):
        raise InputError(f"half_span and rise must be finite and positive, got {half_span!r}, {rise!r}")
    if isinstance(steps, bool) or int(steps) != steps or steps < 1:
        raise InputError(f"steps must be a positive integer, got {steps!r}")
    t = travel * rise * np.arange(int(steps) + 1) / int(steps)
    for special in (rise, 2.0 * rise):
        if np.any(np.isclose(t, special, rtol=1e-9, atol=0.0)):
            raise InputError(f"a load step lands on t = {special:g} m, where the plane grazes an equilibrium "
                             "and the solution is not unique; choose another number of steps")
    base = truss_model(nodes=[[-half_span, 0.0], [half_span, 0.0], [0.0, rise]], members=[[0, 2], [1, 2]],
                       area=area, youngs_modulus=youngs_modulus, supports=[(0, "xy"), (1, "xy")],
                       obstacles=[Obstacle(normal=[0.0, -1.0], offset=t - rise, nodes=[2])],
                       dataset=dataset, name=name, kinematics="finite")
    fields = {f: getattr(base, f) for f in base.__dataclass_fields__ if f != "_cache"}
    fields.update(load_parameter=t, load_parameter_name="plane travel t (m)")
    return VonMisesTrussModel(**fields, half_span=float(half_span), rise=float(rise))
