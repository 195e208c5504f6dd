"""The checks of the arrays the continuum outputs take (coordinates, connectivity, numbers): each
returns the array or raises an :class:`~ddcm_casadi.errors.InputError` whose one line names it.

Shared by the ParaView files (:mod:`ddcm_casadi.outputs.continuum`) and the continuum's figures
(:mod:`ddcm_casadi.outputs.continuum_figures`), which check every input before they write or draw.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ddcm_casadi.errors import InputError


def as_float(name: str, a: Any) -> np.ndarray:
    """``a`` as a float array (any shape), or an error naming ``name``."""
    try:
        return np.asarray(a, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an array of numbers") from None


def coordinates(name: str, a: Any, dims: tuple[int, ...] = (2, 3)) -> np.ndarray:
    """``a`` as finite coordinates ``(n, d)``, ``n >= 1`` and ``d`` one of ``dims``."""
    x = as_float(name, a)
    if x.ndim != 2 or x.shape[1] not in dims or x.shape[0] == 0:
        want = " or ".join(f"(n, {d})" for d in dims)
        raise InputError(f"{name} must have shape {want} with n >= 1, got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise InputError(f"{name} must be finite (no NaN or infinity)")
    return x


def connectivity(name: str, a: Any, nodes_per_cell: int, n_nodes: int) -> np.ndarray:
    """``a`` as integer cells ``(n, nodes_per_cell)`` whose node numbers are in ``0..n_nodes - 1``."""
    c = np.asarray(a)
    if c.dtype.kind not in "iu" or c.ndim != 2 or c.shape[1] != nodes_per_cell:
        raise InputError(f"{name} must be an integer array of shape (n, {nodes_per_cell}), "
                         f"got {c.dtype} {c.shape}")
    if c.size and (c.min() < 0 or c.max() >= n_nodes):
        raise InputError(f"{name} refers to node {int(c.min() if c.min() < 0 else c.max())}, "
                         f"outside 0..{n_nodes - 1}")
    return c
