"""The nondimensional complementarity problems built from a model: the contract between models
and formulations (:mod:`~ddcm_casadi.problems.contract`), the pieces of complementarity
(:mod:`~ddcm_casadi.problems.complementarity`) and the exact enumeration of an affine problem's
branches (:mod:`~ddcm_casadi.problems.exact`)."""
