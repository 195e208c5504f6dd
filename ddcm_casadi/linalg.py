"""Sparse linear algebra: the scipy -> CasADi conversion and the pluggable sparse linear solver.

Every factorisation in the package (Newton steps, cached active-set systems, exact enumeration,
the reference scales) goes through :func:`factorize`, so the solver is chosen in one place.
The default is scipy's SuperLU (``splu``): measured at 1e4 unknowns it is about 100x faster than
CasADi's ``csparse`` on the same Jacobian. Others can be registered with :func:`register_solver`
(e.g. a CHOLMOD or MUMPS wrapper) and selected with :func:`use_solver`.
"""

from __future__ import annotations

from typing import Callable, Protocol

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import InputError


def to_casadi(A: sp.spmatrix) -> ca.DM:
    """A scipy sparse matrix as a sparse CasADi ``DM`` (same pattern, no densification)."""
    A = sp.csc_matrix(A)
    A.sort_indices()
    sparsity = ca.Sparsity(A.shape[0], A.shape[1], A.indptr.tolist(), A.indices.tolist())
    return ca.DM(sparsity, A.data.tolist())


class Factor(Protocol):
    """A factorised square sparse matrix."""

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``A^{-1} rhs`` for a vector or a matrix of right-hand sides."""


class SingularMatrix(ArithmeticError):
    """The matrix could not be factorised (exactly singular)."""


def _superlu(A: sp.csc_matrix) -> Factor:
    try:
        return spla.splu(A)
    except RuntimeError as exc:  # SuperLU: "Factor is exactly singular"
        raise SingularMatrix(str(exc)) from None


_SOLVERS: dict[str, Callable[[sp.csc_matrix], Factor]] = {"superlu": _superlu}
_ACTIVE = ["superlu"]


def register_solver(name: str, factorize_fn: Callable[[sp.csc_matrix], Factor]) -> None:
    """Register a sparse direct solver: ``factorize_fn(A_csc)`` returns an object with ``solve``
    and raises :class:`SingularMatrix` for a singular matrix."""
    _SOLVERS[name] = factorize_fn


def use_solver(name: str) -> None:
    """Select the sparse solver used by every factorisation from now on."""
    if name not in _SOLVERS:
        raise InputError(f"unknown linear solver {name!r}; known: {', '.join(_SOLVERS)}")
    _ACTIVE[0] = name


def solver_name() -> str:
    return _ACTIVE[0]


def factorize(A: sp.spmatrix) -> Factor:
    """Factorise a square sparse matrix with the selected solver; raises :class:`SingularMatrix`."""
    return _SOLVERS[_ACTIVE[0]](sp.csc_matrix(A))
