"""The material-update schemes of the DDCM driver, by the name that selects them
(:class:`~ddcm_casadi.solvers.ddcm_options.DDCMOptions` ``variant``; the interface:
:class:`~ddcm_casadi.solvers.scheme.MaterialScheme`)."""

from __future__ import annotations

from .lcdd import LCDD
from .maxent import MaxEnt
from .nearest_datum import NearestDatum
from .scheme import MaterialScheme

#: The schemes by name.
SCHEMES: dict[str, type[MaterialScheme]] = {s.name: s for s in (NearestDatum, LCDD, MaxEnt)}
