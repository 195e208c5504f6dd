r"""The material update of the DDCM alternation, as a pluggable scheme.

Every data-driven scheme of the driver (:class:`~ddcm_casadi.drivers.ddcm.DDCMSolver`) is the
same alternation between the projection onto the equilibrium set ``Z_E`` and a *material
update* ``M``:

.. math::  z \leftarrow P_{Z_E}(z^*) , \qquad z^* \leftarrow M(z) ,

until ``M`` says the material states ``z*`` have settled. A scheme is ``M``:

- ``states(index)``: the material states of a data assignment (the starts);
- ``begin(start)``: a new run from the material states ``start``;
- ``update(strain, stress)``: the next material states from the projected state, and whether
  the run is done (settled, or stopped without settling);
- ``distance2(strain, stress, star)``: per point ``d^2(z_i, z*_i)``; the objective reported is
  ``1/2 sum_i w_i d^2``;
- ``finish(star)``: the material states to report, with the datum nearest each (``data_index``).

The schemes (:data:`ddcm_casadi.drivers.schemes.SCHEMES`): the nearest datum (plain DDCM,
:mod:`~ddcm_casadi.drivers.nearest_datum`), LCDD (:mod:`~ddcm_casadi.drivers.lcdd`) and max-ent
(:mod:`~ddcm_casadi.drivers.maxent`). The driver runs the projections, the restarts and greedy
improvement (for schemes that assign data), the physical checks and the records for all of them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ddcm_casadi.drivers.records import MaterialStates


@dataclass
class Update:
    """What a material update gives: the new material states ``star``; ``done``: the run stops
    here (``converged`` says whether it settled; ``message`` why it stopped)."""

    star: MaterialStates
    done: bool = False
    converged: bool = False
    message: str = ""


class MaterialScheme(ABC):
    """The material update ``z* = M(z)`` of one data-driven scheme (see the module).

    Parameters
    ----------
    model : ContactModel
        The model (its data set, metric, points and volumes).
    options : DDCMOptions
        The driver's options (the scheme reads its own).
    """

    #: The :class:`~ddcm_casadi.drivers.ddcm_options.DDCMOptions` ``variant`` that selects it.
    name: ClassVar[str] = ""
    #: Whether the material states are one datum per point: then restarts, greedy improvement
    #: and the global-optimum certificate apply.
    assigns_data: ClassVar[bool] = False

    def __init__(self, model, options) -> None:
        self.model, self.options = model, options

    def states(self, index: np.ndarray) -> MaterialStates:
        """The material states of the data assignment ``index`` (one global index per point)."""
        data = self.model.dataset
        return MaterialStates(data.strain[index], data.stress[index], index)

    @abstractmethod
    def begin(self, start: MaterialStates) -> None:
        """Start a run from the material states ``start``."""

    @abstractmethod
    def update(self, strain: np.ndarray, stress: np.ndarray) -> Update:
        """The material states after the projected state ``(strain, stress)`` (flat, point-major)."""

    @abstractmethod
    def distance2(self, strain: np.ndarray, stress: np.ndarray, star: MaterialStates) -> np.ndarray:
        """``d^2(z_i, z*_i)`` per point, each under its material's metric."""

    def finish(self, star: MaterialStates) -> MaterialStates:
        """The material states to report, with ``index`` the datum nearest each."""
        return star

    def nearest_index(self, strain: np.ndarray, stress: np.ndarray) -> np.ndarray | None:
        """The datum nearest each of exactly these states (global indices) where the scheme's
        last search found them, else ``None``: the step's checks then search again."""
        return None
