"""The material-update schemes of the DDCM driver, by the name that selects them
(:class:`~ddcm_casadi.drivers.ddcm_options.DDCMOptions` ``variant``; the interface:
:class:`~ddcm_casadi.drivers.scheme.MaterialScheme`)."""

from __future__ import annotations

from ddcm_casadi.drivers.lcdd import LCDD
from ddcm_casadi.drivers.maxent import MaxEnt
from ddcm_casadi.drivers.nearest_datum import NearestDatum
from ddcm_casadi.drivers.scheme import MaterialScheme

#: The schemes by name.
SCHEMES: dict[str, type[MaterialScheme]] = {s.name: s for s in (NearestDatum, LCDD, MaxEnt)}
