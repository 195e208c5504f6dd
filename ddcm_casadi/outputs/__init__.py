"""Outputs: the registries of drawings and field writers (:mod:`~ddcm_casadi.outputs.drawings`),
the figures (:mod:`~ddcm_casadi.outputs.plots`, :mod:`~ddcm_casadi.outputs.continuum`), the VTU
series (:mod:`~ddcm_casadi.outputs.continuum_results`), and what draws and writes what a model
declares (:mod:`~ddcm_casadi.outputs.save`). matplotlib is imported only when a figure is drawn."""
