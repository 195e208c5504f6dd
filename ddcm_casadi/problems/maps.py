"""The maps a problem is made of: affine maps and quadratic distances held as sparse matrices
(the fast path of small kinematics), and their nonlinear counterparts given as CasADi Functions
(finite kinematics). Both render symbolically (``SX``/``MX``) and evaluate numerically."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ddcm_casadi.linalg import to_casadi
from ddcm_casadi.evaluate import NumericFunction


def sparse_matrix(A) -> sp.csr_matrix:
    """``A`` as CSR without stored zeros (a stored zero would become a structural nonzero of
    every Jacobian built from it)."""
    A = sp.csr_matrix(A, dtype=float)
    A.eliminate_zeros()
    return A


@dataclass(frozen=True, eq=False)
class Affine:
    """A vector affine in the scaled unknowns ``z = [x; p]`` and the parameters ``P``:
    ``v = Z z + Q P`` with sparse ``Z`` (rows x (n_x + n_pairs)) and ``Q`` (rows x n_params)."""

    z: sp.csr_matrix
    params: sp.csr_matrix

    def __post_init__(self) -> None:
        object.__setattr__(self, "z", sparse_matrix(self.z))
        object.__setattr__(self, "params", sparse_matrix(self.params))

    @property
    def rows(self) -> int:
        return self.z.shape[0]

    def __add__(self, other):
        if not isinstance(other, Affine):
            return NotImplemented  # a nonlinear map adds itself (NonlinearMap.__radd__)
        return Affine(self.z + other.z, self.params + other.params)

    def __mul__(self, c: float) -> "Affine":
        return Affine(float(c) * self.z, float(c) * self.params)

    __rmul__ = __mul__

    def __truediv__(self, c: float) -> "Affine":
        return self * (1.0 / float(c))

    def value(self, z: np.ndarray, P: np.ndarray) -> np.ndarray:
        """``Z z + Q P`` for numbers."""
        return self.z @ np.asarray(z, float) + self.params @ np.asarray(P, float)

    def render(self, z, P):
        """``Z z + Q P`` for symbols ``z``, ``P`` (``SX`` or ``MX``)."""
        return ca.mtimes(to_casadi(self.z), z) + ca.mtimes(to_casadi(self.params), P)

    def terms(self, z, P):
        """``|Z| |z| + |Q| |P|``: the size of the terms that cancel in each row."""
        return ca.mtimes(to_casadi(abs(self.z)), ca.fabs(z)) + ca.mtimes(to_casadi(abs(self.params)), ca.fabs(P))


@dataclass(frozen=True, eq=False)
class Distance:
    """The objective ``f = d^T W d / 2`` of the projection, ``d`` an :class:`Affine` (the strain
    and stress differences to the assigned data, point by point) and ``W`` sparse symmetric
    positive semidefinite (the metric times the volumes, over the energy unit)."""

    d: Affine
    weight: sp.csr_matrix

    @cached_property
    def hessian(self) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """``(H, H_P)`` with ``grad_z f = H z + H_P P``: ``H = Z^T W Z``, ``H_P = Z^T W Q`` (once)."""
        ZtW = (self.d.z.T @ self.weight).tocsr()
        return sparse_matrix(ZtW @ self.d.z), sparse_matrix(ZtW @ self.d.params)

    def render(self, z, P):
        """``f`` for symbols ``z``, ``P``."""
        d = self.d.render(z, P)
        return 0.5 * ca.dot(d, ca.mtimes(to_casadi(self.weight), d))


class NonlinearMap:
    """A vector function ``v(z, P)`` of the scaled unknowns ``z = [x; p]`` and the parameters
    ``P``, given as a CasADi ``Function`` (the nonlinear counterpart of :class:`Affine`).

    Jacobians come by automatic differentiation, sparse. ``terms`` (optional) gives, per row, the
    size of the terms that cancel in it (for relative residuals, as :meth:`Affine.terms`); without
    it the values' own size is used.

    Parameters
    ----------
    function : casadi.Function
        ``(z, P) -> v``, both inputs dense column vectors.
    terms : casadi.Function, optional
        ``(z, P) -> t`` of the same size as ``v``.
    """

    def __init__(self, function: ca.Function, terms: ca.Function | None = None) -> None:
        self.function = function
        self.terms_function = terms
        self.n_z, self.n_params = function.size1_in(0), function.size1_in(1)

    @classmethod
    def of(cls, expr: ca.SX, z: ca.SX, P: ca.SX, terms: ca.SX | None = None, name: str = "v") -> "NonlinearMap":
        """The map of an ``SX`` expression in the symbols ``z`` and ``P``."""
        return cls(ca.Function(name, [z, P], [expr]),
                   None if terms is None else ca.Function(f"{name}_terms", [z, P], [terms]))

    @property
    def rows(self) -> int:
        return self.function.size1_out(0)

    def render(self, z, P):
        """``v`` for symbols ``z``, ``P`` (``SX`` inlines the expression)."""
        return self.function(z, P)

    def terms(self, z, P):
        return ca.fabs(self.function(z, P)) if self.terms_function is None else self.terms_function(z, P)

    @cached_property
    def _numeric(self):
        return NumericFunction(self.function)

    def value(self, z: np.ndarray, P: np.ndarray) -> np.ndarray:
        """``v`` for numbers."""
        return np.asarray(self._numeric(np.asarray(z, float), np.asarray(P, float)), float).ravel()

    def _combine(self, other, op, name: str) -> "NonlinearMap":
        z, P = ca.SX.sym("z", self.n_z), ca.SX.sym("P", self.n_params)
        expr = op(self.render(z, P), other.render(z, P))
        terms = self.terms(z, P) + other.terms(z, P)
        return NonlinearMap.of(expr, z, P, terms, name)

    def __add__(self, other) -> "NonlinearMap":
        if not isinstance(other, (Affine, NonlinearMap)):
            return NotImplemented
        return self._combine(other, lambda a, b: a + b, "sum")

    __radd__ = __add__

    def __mul__(self, c: float) -> "NonlinearMap":
        c = float(c)
        z, P = ca.SX.sym("z", self.n_z), ca.SX.sym("P", self.n_params)
        return NonlinearMap.of(c * self.render(z, P), z, P, abs(c) * self.terms(z, P), "scaled")

    __rmul__ = __mul__

    def __truediv__(self, c: float) -> "NonlinearMap":
        return self * (1.0 / float(c))


class NonlinearObjective:
    """A scalar objective ``f(z, P)`` given as a CasADi ``Function`` (the nonlinear counterpart
    of :class:`Distance`): its gradient and Hessian come by automatic differentiation."""

    def __init__(self, function: ca.Function) -> None:
        self.function = function

    def render(self, z, P):
        return self.function(z, P)

    @cached_property
    def _numeric(self):
        return NumericFunction(self.function)

    def value(self, z: np.ndarray, P: np.ndarray) -> float:
        return float(np.asarray(self._numeric(np.asarray(z, float), np.asarray(P, float))).ravel()[0])
