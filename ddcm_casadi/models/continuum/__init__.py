"""Finite-element continua (2-D plane strain, 3-D) with rigid obstacles.

>>> from ddcm_casadi.models.continuum import mesh, continuum_model, Material, Support, Contact, Circle
>>> body = mesh.rectangle(0.02, 0.01, nx=8, ny=4, origin=(0.0, -0.01))
>>> model = continuum_model(body, materials=[Material(youngs_modulus=200e9, poisson_ratio=0.3)],
...                         supports=[Support("ymin", "xy")],
...                         contacts=[Contact(Circle((0.01, 0.05), 0.05, travel=[0, 1e-5]), "ymax")])
>>> model.n_contacts
9

Modules: :mod:`.mesh` (shapes; it re-exports the checks of :mod:`.mesh_checks`, the grading of
:mod:`.mesh_refinement` and the file reader of :mod:`.mesh_files`), :mod:`.fem` (operators from
scikit-fem), :mod:`.obstacles`, :mod:`.model` (:func:`continuum_model`, put together from the
pieces of :mod:`.assembly`), :mod:`.hertz` (the reference),
:mod:`.output` and :mod:`.results` (VTU series, figures), :mod:`.case` (``[mesh]`` case files).
The names below are imported on first use, so that importing the package (as the case-file
registry does) costs nothing until a continuum is built.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "continuum_model": "model", "ContinuumModel": "model", "Material": "inputs", "Support": "inputs",
    "Traction": "inputs", "BodyForce": "inputs", "Contact": "inputs",
    "Plane": "obstacles", "Ball": "obstacles", "Circle": "obstacles", "Sphere": "obstacles",
    "Cylinder": "obstacles", "FlatPunch": "obstacles", "SignedDistance": "obstacles",
    "HertzReference": "hertz",
}

__all__ = sorted(_EXPORTS) + ["mesh"]


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    if name == "mesh":
        return importlib.import_module(".mesh", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
