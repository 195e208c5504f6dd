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
        v, w = self.z @ np.asarray(z, float), self.params @ np.asarray(P, float)
        if v.shape != w.shape:  # one column per case of 2-D parameters
            return v + w
        v += w  # in place: one vector of the map's rows fewer (4.8 MB for a projection's d at 1e5 points)
        return v

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


class LocalTerms:
    r"""A sum of small nonlinear terms, one per *item* (a finite element, a material point):

    .. math::  v(z, P) = L\, \mathrm{vec}(\psi(y_1, c_1), \dots, \psi(y_m, c_m)),\qquad
               y_i = (Y z + Y_P P)_{[i q, (i + 1) q)} ,

    ``psi`` one CasADi ``SX`` Function of one item's ``q`` local variables and its constants
    ``c_i`` (geometry, moduli, weights), ``Y``, ``Y_P`` and ``L`` constant sparse matrices (item-major
    rows of ``Y``, item-major columns of ``L``). Its Jacobian ``L blockdiag(dpsi/dy) Y`` is assembled
    from the items' small Jacobians (:meth:`jacobian_map`), never by differentiating one expression
    of every item: finite-element assembly, written once for every nonlinear model.

    Parameters
    ----------
    item : casadi.Function
        ``(y, c) -> psi`` (``c`` may have zero rows).
    Y, Y_P : sparse
        ``(m q, n_z)`` and ``(m q, n_params)``.
    L : sparse
        ``(rows, m q_out)``.
    constants : (m, q_c) array
        One row per item.
    terms : casadi.Function, optional
        ``(y, c) -> t`` of the size of ``psi``: the size of the terms that cancel in each output
        (for relative residuals); default ``|psi|``.
    """

    def __init__(self, item: ca.Function, Y, Y_P, L, constants: np.ndarray, terms: ca.Function | None = None) -> None:
        self.item, self.terms_item = item, terms
        self.q, self.q_out = item.size1_in(0), item.size1_out(0)
        self.Y, self.Y_P, self.L = sparse_matrix(Y), sparse_matrix(Y_P), sparse_matrix(L)
        self.count = self.Y.shape[0] // self.q if self.q else 0
        self.constants = np.asarray(constants, float).reshape(self.count, -1)
        if self.Y.shape[0] != self.count * self.q or self.L.shape[1] != self.count * self.q_out:
            raise ValueError("LocalTerms: Y and L do not match the item's sizes")

    @property
    def rows(self) -> int:
        return self.L.shape[0]

    @property
    def n_z(self) -> int:
        return self.Y.shape[1]

    def with_L(self, L) -> "LocalTerms":
        """The same items scattered by another ``L``."""
        return LocalTerms(self.item, self.Y, self.Y_P, L, self.constants, self.terms_item)

    def local_values(self, z, P):
        """``(q, m)``: the items' local variables, one column per item (symbols)."""
        y = ca.mtimes(to_casadi(self.Y), z) + ca.mtimes(to_casadi(self.Y_P), P)
        return ca.reshape(y, self.q, self.count)

    def _mapped(self, function: ca.Function, z, P):
        return function.map(self.count)(self.local_values(z, P), ca.DM(self.constants.T))

    def render(self, z, P):
        """``v`` for symbols (``MX`` keeps one mapped call; ``SX`` inlines every item)."""
        if not self.count:
            return ca.DM(self.rows, 1) if isinstance(z, ca.DM) else type(z)(self.rows, 1)
        return ca.mtimes(to_casadi(self.L), ca.vec(self._mapped(self.item, z, P)))

    def terms(self, z, P):
        if not self.count:
            return type(z)(self.rows, 1)
        if self.terms_item is None:
            return ca.mtimes(to_casadi(abs(self.L)), ca.vec(ca.fabs(self._mapped(self.item, z, P))))
        return ca.mtimes(to_casadi(abs(self.L)), ca.vec(self._mapped(self.terms_item, z, P)))

    def scaled(self, c: float) -> "LocalTerms":
        return self.with_L(float(c) * self.L)

    def assembled(self, z: ca.MX, P: ca.MX) -> tuple[ca.MX, ca.MX]:
        """``(v, dv/dz)`` for ``MX`` symbols (``z`` of :attr:`n_z` entries): the value by one mapped
        call, the Jacobian assembled from the items' Jacobians (:meth:`jacobian_map`)."""
        J0, T, D = self.jacobian_map(self.n_z)
        if not self.count:
            return ca.MX(self.rows, 1), ca.MX(self.rows, self.n_z)
        y, C = self.local_values(z, P), ca.DM(self.constants.T)
        values, derivatives = self.item.map(self.count)(y, C), D.map(self.count)(y, C)
        sparsity = ca.Sparsity(J0.shape[0], J0.shape[1], J0.indptr.tolist(), J0.indices.tolist())
        J = ca.MX(sparsity, ca.mtimes(to_casadi(T), ca.vec(derivatives.nz[:]))) if T.nnz else ca.MX(*J0.shape)
        return ca.mtimes(to_casadi(self.L), ca.vec(values)), J

    def jacobian_map(self, n_z: int) -> tuple[sp.csc_matrix, sp.csr_matrix, ca.Function]:
        """``(J0, T, D)``: the pattern of ``dv/dz`` (the first ``n_z`` columns; CSC, zero values),
        ``T`` with ``nonzeros(dv/dz) = T d``, and ``D: (y, c) -> dpsi/dy`` of one item, whose
        mapped nonzeros (item-major, CasADi's order) are ``d``."""
        y, c = ca.SX.sym("y", self.q), ca.SX.sym("c", self.item.size1_in(1))
        Dexpr = ca.jacobian(self.item(y, c), y)
        D = ca.Function("item_jacobian", [y, c], [Dexpr])
        colind, out_e = Dexpr.sparsity().get_ccs()
        out_e = np.asarray(out_e, dtype=np.int64)
        slot_e = np.repeat(np.arange(self.q), np.diff(colind))
        J0, T = scatter_products(self.L.tocsc(), self.Y.tocsr()[:, :n_z], out_e, slot_e, self.count,
                                 self.q_out, self.q)
        return J0, T, D


def scatter_products(L: sp.csc_matrix, Y: sp.csr_matrix, out_e: np.ndarray, slot_e: np.ndarray, count: int,
                     q_out: int, q: int) -> tuple[sp.csc_matrix, sp.csr_matrix]:
    """``(J0, T)`` for ``J = L blockdiag(D_1..D_m) Y``, every ``D_i`` with the nonzeros
    ``(out_e, slot_e)`` (column-major): ``J0`` its pattern (CSC, zeros) and ``nonzeros(J) = T d``
    with ``d`` the items' nonzeros item-major. Entry ``e`` of item ``i`` adds ``d L[:, i q_out +
    out_e] Y[i q + slot_e, :]``."""
    ne = out_e.size
    item = np.repeat(np.arange(count, dtype=np.int64), ne)
    Lsel = L[:, np.tile(out_e, count) + item * q_out].tocsc()
    Ysel = Y[np.tile(slot_e, count) + item * q].tocsr()
    nl, ny = np.diff(Lsel.indptr), np.diff(Ysel.indptr)
    n = nl * ny
    e = np.repeat(np.arange(n.size), n)
    t = np.arange(e.size) - np.repeat(np.cumsum(n) - n, n)
    il = Lsel.indptr[e] + t // np.maximum(ny[e], 1)
    iy = Ysel.indptr[e] + t % np.maximum(ny[e], 1)
    rows, cols, vals = Lsel.indices[il], Ysel.indices[iy], Lsel.data[il] * Ysel.data[iy]
    shape = (L.shape[0], Y.shape[1])
    J0 = sp.csc_matrix((np.zeros(rows.size), (rows, cols)), shape=shape)
    J0.sum_duplicates()
    keys = np.repeat(np.arange(shape[1], dtype=np.int64), np.diff(J0.indptr)) * shape[0] + J0.indices
    T = sp.csr_matrix((vals, (np.searchsorted(keys, cols.astype(np.int64) * shape[0] + rows), e)),
                      shape=(J0.nnz, n.size))
    T.sum_duplicates()
    return J0, T


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

    def __init__(self, function: ca.Function, terms: ca.Function | None = None,
                 local: tuple[LocalTerms, ...] = ()) -> None:
        self.function = function
        self.terms_function = terms
        self.local = tuple(local)
        self.n_z, self.n_params = function.size1_in(0), function.size1_in(1)

    @classmethod
    def of(cls, expr: ca.SX, z: ca.SX, P: ca.SX, terms: ca.SX | None = None, name: str = "v",
           local: tuple[LocalTerms, ...] = ()) -> "NonlinearMap":
        """The map of an ``SX`` expression in the symbols ``z`` and ``P`` (plus ``local`` terms,
        :class:`LocalTerms`, kept apart: they are assembled, not differentiated as one expression)."""
        return cls(ca.Function(name, [z, P], [expr]),
                   None if terms is None else ca.Function(f"{name}_terms", [z, P], [terms]), local)

    @property
    def rows(self) -> int:
        return self.function.size1_out(0)

    def render_expression(self, z, P):
        """The part of ``v`` held as one expression (without the :attr:`local` terms)."""
        return self.function(z, P)

    def render(self, z, P):
        """``v`` for symbols ``z``, ``P`` (``SX`` inlines the expression)."""
        return self.function(z, P) + sum((t.render(z, P) for t in self.local), 0)

    def terms(self, z, P):
        own = ca.fabs(self.function(z, P)) if self.terms_function is None else self.terms_function(z, P)
        return own + sum((t.terms(z, P) for t in self.local), 0)

    @cached_property
    def _numeric(self):
        if not self.local:
            return NumericFunction(self.function)
        z, P = ca.MX.sym("z", self.n_z), ca.MX.sym("P", self.n_params)
        return NumericFunction(ca.Function("value", [z, P], [self.render(z, P)]))

    def value(self, z: np.ndarray, P: np.ndarray) -> np.ndarray:
        """``v`` for numbers."""
        return np.asarray(self._numeric(np.asarray(z, float), np.asarray(P, float)), float).ravel()

    def jacobian(self, z: ca.MX, P: ca.MX, columns: int) -> ca.MX:
        """``dv/dz[:columns]`` for ``MX`` symbols: the expression's by automatic differentiation,
        the local terms' assembled (:meth:`LocalTerms.assembled`)."""
        zs, Ps = ca.SX.sym("z", self.n_z), ca.SX.sym("P", self.n_params)
        own = ca.Function("jacobian", [zs, Ps], [ca.jacobian(self.function(zs, Ps), zs[:columns])])(z, P)
        for t in self.local:
            own = own + t.assembled(z, P)[1][:, :columns]
        return own

    def _own_terms(self, z, P):
        return ca.fabs(self.function(z, P)) if self.terms_function is None else self.terms_function(z, P)

    def __add__(self, other) -> "NonlinearMap":
        if not isinstance(other, (Affine, NonlinearMap)):
            return NotImplemented
        z, P = ca.SX.sym("z", self.n_z), ca.SX.sym("P", self.n_params)
        if isinstance(other, Affine):
            expr, terms, local = other.render(z, P), other.terms(z, P), ()
        else:
            expr, terms, local = other.render_expression(z, P), other._own_terms(z, P), other.local
        return NonlinearMap.of(self.render_expression(z, P) + expr, z, P, self._own_terms(z, P) + terms, "sum",
                               self.local + local)

    __radd__ = __add__

    def __mul__(self, c: float) -> "NonlinearMap":
        c = float(c)
        z, P = ca.SX.sym("z", self.n_z), ca.SX.sym("P", self.n_params)
        return NonlinearMap.of(c * self.render_expression(z, P), z, P, abs(c) * self._own_terms(z, P), "scaled",
                               tuple(t.scaled(c) for t in self.local))

    __rmul__ = __mul__

    def __truediv__(self, c: float) -> "NonlinearMap":
        return self * (1.0 / float(c))


class NonlinearObjective:
    """A scalar objective ``f(z, P)`` given as a CasADi ``Function`` (the nonlinear counterpart
    of :class:`Distance`): its gradient and Hessian come by automatic differentiation."""

    def __init__(self, function: ca.Function, local: tuple[LocalTerms, ...] = ()) -> None:
        self.function = function
        self.local = tuple(local)  # scalar items (q_out = 1), summed (L a row of ones)

    def render_expression(self, z, P):
        """The part of ``f`` held as one expression (without the :attr:`local` terms)."""
        return self.function(z, P)

    def render(self, z, P):
        return self.function(z, P) + sum((t.render(z, P) for t in self.local), 0)

    @cached_property
    def _numeric(self):
        if not self.local:
            return NumericFunction(self.function)
        z, P = ca.MX.sym("z", self.function.size1_in(0)), ca.MX.sym("P", self.function.size1_in(1))
        return NumericFunction(ca.Function("value", [z, P], [self.render(z, P)]))

    def value(self, z: np.ndarray, P: np.ndarray) -> float:
        return float(np.asarray(self._numeric(np.asarray(z, float), np.asarray(P, float))).ravel()[0])
