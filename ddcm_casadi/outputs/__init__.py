"""Outputs: the registries of drawings and field writers (:mod:`~ddcm_casadi.outputs.drawings`),
the figures (:mod:`~ddcm_casadi.outputs.plots`, which imports the bar's, the truss's and the contact
history's drawing modules and their shared marks; :mod:`~ddcm_casadi.outputs.continuum`, whose
figures are drawn by :mod:`~ddcm_casadi.outputs.continuum_figures`), the VTU series
(:mod:`~ddcm_casadi.outputs.continuum_results`; the material points' in
:mod:`~ddcm_casadi.outputs.point_cloud`), and what draws and writes what a model declares
(:mod:`~ddcm_casadi.outputs.save`). matplotlib is imported only when a figure is drawn."""
