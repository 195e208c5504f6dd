"""The right-hand sides of a factor with a Schur complement (MUMPS's, :mod:`ddcm_casadi.mumps`;
PARDISO's, :mod:`ddcm_casadi.linalg`): a factor of ``[[A, C^T], [C, 0]]`` whose solves are with
``A`` alone takes right-hand sides of ``n + nc`` rows, the Schur part zero."""

from __future__ import annotations

import numpy as np

from ddcm_casadi.errors import InputError


def schur_columns(rhs: np.ndarray, n: int, nc: int) -> tuple[np.ndarray, np.ndarray]:
    """``rhs`` (a vector or ``n x k`` columns) as floats, and its columns padded with ``nc`` zero
    rows in Fortran order: the right-hand sides of a factor of ``[[A, C^T], [C, 0]]`` whose
    solves are with ``A`` alone (the Schur part zero). Raises :class:`InputError` for a
    right-hand side of another length."""
    b = np.asarray(rhs, dtype=float)
    if b.shape[0] != n:
        raise InputError(f"right-hand side of {b.shape[0]} rows for a matrix of {n}")
    cols = b.reshape(n, -1)
    y = np.zeros((n + nc, cols.shape[1]), order="F")
    y[:n] = cols
    return b, y
