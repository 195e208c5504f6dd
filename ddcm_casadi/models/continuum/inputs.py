"""What a continuum model is built from (:func:`~ddcm_casadi.models.continuum.model.continuum_model`):
the records of its materials, supports, loads and contacts, shared by the builder and its checked
pieces (:mod:`ddcm_casadi.models.continuum.assembly`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ddcm_casadi.models.continuum.obstacles import Obstacle

#: A boundary: its name in ``mesh.boundaries``, or a predicate on facet midpoints ``(d, nf)``.
Where = str | Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Material:
    """The material of one region.

    Parameters
    ----------
    region : str or None
        A subdomain name of the mesh; ``None``: every element no other material claims.
    youngs_modulus, poisson_ratio : float, optional
        The isotropic law (the classical variant needs it in every region).
    data : int, optional
        Index of this region's data set in the ``datasets`` of :func:`continuum_model` (the
        data-driven variant needs one in every region).
    law : str
        The classical law (:data:`~ddcm_casadi.data.hyperelastic.LAWS`): ``"linear"`` (small
        kinematics), ``"saint_venant_kirchhoff"`` or ``"neo_hookean"`` (finite kinematics).
    """

    region: str | None = None
    youngs_modulus: float | None = None
    poisson_ratio: float | None = None
    data: int | None = None
    law: str = "linear"


@dataclass(frozen=True)
class Support:
    """Fix the displacement components ``components`` (e.g. ``"xy"``, ``"z"``) on a boundary: at
    zero, or with ``displacement`` at that value (a hard device,
    :mod:`ddcm_casadi.models.continuum.prescribed`): ``d`` numbers (m) scaled by the load
    factors, or one ``d``-vector per step; zero along the components the support leaves free."""

    where: Where
    components: str
    displacement: object = None


@dataclass(frozen=True)
class Traction:
    """A constant traction (Pa) on a boundary, scaled by the load factor of each step."""

    where: Where
    traction: Sequence[float]


@dataclass(frozen=True)
class BodyForce:
    """A constant body force (N/m^3) on a region (``None``: everywhere), scaled by the load factor."""

    force_density: Sequence[float]
    region: str | None = None


@dataclass(frozen=True)
class Contact:
    """A rigid ``obstacle`` that the dofs of the boundary ``where`` may touch; with ``friction``
    (Coulomb's ``mu >= 0``; ``None``: frictionless, the Signorini law) the contacts carry
    tangential tractions (:mod:`ddcm_casadi.models.coulomb`)."""

    obstacle: Obstacle
    where: Where
    friction: float | None = None

    kind = "obstacle"

    @property
    def name(self) -> str:
        return self.obstacle.name

    @property
    def travel(self):
        """The obstacle's travel (one number, or one per step)."""
        return self.obstacle.travel


@dataclass(frozen=True)
class BodyContact:
    """Contact between two deformable surfaces (:mod:`~ddcm_casadi.models.continuum.mortar`):
    the nodes of the ``slave`` boundary against the facets of the ``master`` boundary.

    Parameters
    ----------
    slave, master : Where
        Boundaries of the mesh (usually of two bodies, :mod:`~ddcm_casadi.models.continuum.bodies`).
        Choose as slave the surface that stays within the other.
    name : str
        A label for tables and figures.
    search_distance : float, optional
        How far (m) from a slave facet, along its normal, master facets are searched. Default:
        :data:`DEFAULT_SEARCH_SHARE` of the body's size.
    """

    slave: Where
    master: Where
    name: str = "contact"
    search_distance: float | None = None

    kind = "bodies"
    travel = 0.0  # the bodies move by their loads and supports


#: The default search distance of a :class:`BodyContact`, as a share of the model's size: pairs
#: are found once, at the reference configuration (small kinematics), so every slave point that
#: may close its gap along the load path must be within reach.
DEFAULT_SEARCH_SHARE = 0.05
