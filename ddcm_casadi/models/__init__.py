"""Model descriptions: what a problem is, independent of how contact is enforced.

- :mod:`~ddcm_casadi.models.base`: :class:`~ddcm_casadi.models.base.ContactModel`, the contract
  every model kind fills (kinematics, equilibrium, contact pairs, load path, material law or data);
- :mod:`~ddcm_casadi.models.scales`: the reference scales of a model's problems and the checks of
  its load path;
- :mod:`~ddcm_casadi.models.contact_laws`: contact laws as kinds (Signorini);
- model kinds: :mod:`~ddcm_casadi.models.bar`, :mod:`~ddcm_casadi.models.truss` (small and finite
  kinematics; assembled by :mod:`~ddcm_casadi.models.truss_assembly`),
  :mod:`~ddcm_casadi.models.von_mises`, :mod:`~ddcm_casadi.models.continuum`.

Models import nothing from the case files, the drivers, the outputs or the commands.
"""
