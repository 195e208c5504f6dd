"""Drivers along a load path: the classical steps (:mod:`~ddcm_casadi.drivers.path`), the DDCM
alternation with its material-update schemes (:mod:`~ddcm_casadi.drivers.ddcm`,
:mod:`~ddcm_casadi.drivers.scheme`), the step records and physical checks, and the comparison of
every formulation on one model (:mod:`~ddcm_casadi.drivers.harness`)."""
