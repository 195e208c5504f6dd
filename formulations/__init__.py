"""Contact formulations: named, registered transformations of complementarity pairs.

>>> from ddcm_casadi import formulations
>>> formulations.available()
['penalty', 'augmented_lagrangian', 'fischer_burmeister', 'mpcc']
>>> fb = formulations.get("fischer_burmeister", tol=1e-10)
"""

from .base import BuiltFormulation, Formulation, LocalSolution
from .pairs import NewtonSystem
from .registry import available, enforcing, get, register
from . import penalty, augmented_lagrangian, fischer_burmeister, mpcc  # noqa: F401,E402  (registration)

__all__ = ["BuiltFormulation", "Formulation", "LocalSolution", "NewtonSystem", "available", "enforcing", "get", "register"]
