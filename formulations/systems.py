r"""Newton systems of nonlinear problems, built symbolically, and the choice of builder.

A problem in the affine form (:attr:`~ddcm_casadi.problems.contract.ComplementarityProblem.affine`) is built
from its sparse matrices (:class:`~ddcm_casadi.formulations.pairs.PairSystem`: sparse products,
no symbolic expression per nonzero). A nonlinear problem (finite-strain kinematics: its residual,
gaps or objective are CasADi expressions, :class:`~ddcm_casadi.problems.maps.NonlinearMap`) is built by
:class:`ExpressionPairSystem`, which has the same interface: the formulations write one pair's
expressions (``psi``, ``l``) once and do not know which builder they use. Here the system

.. math::  r(z; P) = A z + A_P P + N(z; P) + \sum_o L_o\, \psi_o(y(z; P))

is one ``SX`` expression (``N`` the problem's own nonlinear residual, in the systems of
:meth:`ExpressionPairSystem.mcp`, :meth:`~ExpressionPairSystem.eliminated` and
:meth:`~ExpressionPairSystem.saddle`) and its Jacobian ``dr/dz`` comes by CasADi's sparse
automatic differentiation. The projection's saddle point is the stationarity of
``f(x) + eta^T h(x, p) + sum_i l(y_i)`` with exact second derivatives of ``f`` and ``h``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ddcm_casadi.linalg import to_casadi
from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.problems.maps import LocalTerms
from ddcm_casadi.problems.parameters import Parameters
from ddcm_casadi.evaluate import NumericFunction
from ddcm_casadi.loops.newton import SparseJacobian

from .pairs import PairSystem, SystemBuilder, SystemFunctions, _columns


def _rows(A, rows: int, offset: int = 0):
    """``A`` placed at row ``offset`` of a matrix with ``rows`` rows."""
    A = sp.csr_matrix(A)
    return sp.vstack([sp.csr_matrix((offset, A.shape[1])), A,
                      sp.csr_matrix((rows - offset - A.shape[0], A.shape[1]))]).tocsr()


def pair_system(problem: ComplementarityProblem, n_unknowns: int, parameters: Parameters):
    """The builder of ``problem``'s systems: :class:`PairSystem` for the affine form (the fast
    path), :class:`ExpressionPairSystem` otherwise. Both have the same interface."""
    cls = PairSystem if problem.affine else ExpressionPairSystem
    return cls(problem, n_unknowns, parameters)


def _product(A, v: ca.SX, columns: int) -> ca.SX:
    """``A v`` for a sparse ``A`` whose columns beyond ``columns`` are zero (or missing)."""
    A = sp.csr_matrix(A)
    if A.shape[1] > columns:
        if A[:, columns:].nnz:
            raise ValueError(f"a map depends on columns beyond the first {columns}")
        A = A[:, :columns]
    return ca.mtimes(to_casadi(A), v[:A.shape[1]])


class ExpressionPairSystem(SystemBuilder):
    """Builder of the Newton systems of a nonlinear problem (the interface of
    :class:`~ddcm_casadi.formulations.pairs.PairSystem`, the parameters of
    :class:`~ddcm_casadi.formulations.pairs.SystemBuilder`), all in one ``SX`` graph."""

    def __init__(self, problem: ComplementarityProblem, n_unknowns: int, parameters: Parameters) -> None:
        super().__init__(problem, n_unknowns, parameters)
        self._z = ca.SX.sym("z", self.nz)
        self._P = ca.SX.sym("P", parameters.size)
        self._slots: list[tuple[ca.SX, ca.SX]] = []  # (one pair's symbol, the values of every pair)

    # ------------------------------------------------------------------ the problem's pieces
    def _xp(self) -> ca.SX:
        """The problem's unknowns ``[x; p]`` within ``z`` (``p`` zero if ``z`` holds only ``x``)."""
        nxp = self.problem.n_x + self.nc
        z = self._z
        return z[:nxp] if self.nz >= nxp else ca.vertcat(z, ca.SX(nxp - self.nz, 1))

    def _problem_params(self) -> ca.SX:
        return self._P[:self.problem.parameters.size]

    def _render(self, value) -> ca.SX:
        """A problem map (:class:`Affine` or nonlinear) at the system's symbols."""
        return value.render(self._xp(), self._problem_params())

    def _split(self, value) -> tuple[ca.SX, tuple[LocalTerms, ...]]:
        """A problem map's expression part at the system's symbols, and its local terms."""
        local = getattr(value, "local", ())
        if not local:
            return self._render(value), ()
        return value.render_expression(self._xp(), self._problem_params()), local

    def _placed(self, terms: LocalTerms, rows: int, offset: int = 0, columns: int | None = None) -> LocalTerms:
        """``terms`` (of the problem's ``[x; p]`` and parameters) in the system's unknowns (its
        first ``columns`` of ``[x; p]``, default all), parameters and rows (at ``offset``)."""
        Y = terms.Y if columns is None else _columns(terms.Y, columns, "local terms")
        return LocalTerms(terms.item, _columns(Y, self.nz, "local terms"),
                          _columns(terms.Y_P, self.parameters.size, "local terms"),
                          _rows(terms.L, rows, offset), terms.constants, terms.terms_item)

    def _lagrangian(self, terms: LocalTerms, eta: int, rows: int) -> LocalTerms:
        """The stationarity rows of ``eta^T L psi(y)`` over ``(x, p, eta)`` as local terms: per
        item ``l(y, zeta) = zeta^T psi(y)`` with ``zeta_i = L_i^T eta``, its gradient
        ``[dpsi/dy^T zeta; psi]`` scattered by the local variables' maps transposed."""
        q, qo, m = terms.q, terms.q_out, terms.count
        y, zeta, c = ca.SX.sym("y", q), ca.SX.sym("zeta", qo), ca.SX.sym("c", terms.item.size1_in(1))
        l = ca.dot(zeta, terms.item(y, c))
        item = ca.Function("lagrangian_item", [ca.vertcat(y, zeta), c], [ca.gradient(l, ca.vertcat(y, zeta))])
        Yz = _columns(terms.Y, self.nz, "local terms")
        Z = sp.hstack([sp.csr_matrix((m * qo, eta)), terms.L.T,
                       sp.csr_matrix((m * qo, self.nz - eta - terms.L.shape[0]))]).tocsr()
        order = np.concatenate([np.arange(m)[:, None] * q + np.arange(q), m * q + np.arange(m)[:, None] * qo
                                + np.arange(qo)], axis=1).ravel()
        Yhat = sp.vstack([Yz, Z]).tocsr()[order]
        YP = sp.vstack([_columns(terms.Y_P, self.parameters.size, "local terms"),
                        sp.csr_matrix((m * qo, self.parameters.size))]).tocsr()[order]
        return LocalTerms(item, Yhat, YP, _rows(Yhat.T, rows), terms.constants)

    def _gradient_rows(self, terms: LocalTerms, rows: int) -> LocalTerms:
        """The rows ``Y^T dl/dy`` of a sum of scalar items ``l`` (an objective's local terms)."""
        y, c = ca.SX.sym("y", terms.q), ca.SX.sym("c", terms.item.size1_in(1))
        item = ca.Function("gradient_item", [y, c], [ca.gradient(terms.item(y, c), y)])
        Yz = _columns(terms.Y, self.nz, "local terms")
        return LocalTerms(item, Yz, _columns(terms.Y_P, self.parameters.size, "local terms"), _rows(Yz.T, rows),
                          terms.constants)

    # ------------------------------------------------------------------ local variables
    def _add(self, name: str, values: ca.SX) -> ca.SX:
        symbol = ca.SX.sym(name)
        self._slots.append((symbol, values))
        return symbol

    def local(self, name: str, z=None, params=None) -> ca.SX:
        """A local variable, per pair row ``k`` of ``Z z + Q P`` (sparse ``Z``, ``Q``)."""
        value = ca.SX(self.nc, 1)
        if z is not None:
            value += _product(z, self._z, self.nz)
        if params is not None:
            value += _product(params, self._P, self.parameters.size)
        return self._add(name, value)

    def affine(self, name: str, value) -> ca.SX:
        """A local variable from a problem's map (:class:`Affine` or nonlinear), one row per pair."""
        return self._add(name, self._render(value))

    def unknowns(self, name: str, start: int) -> ca.SX:
        return self._add(name, self._z[start:start + self.nc])

    def parameter(self, name: str) -> ca.SX:
        where = self.parameters.slice(name)
        size = where.stop - where.start
        if size not in (1, self.nc):
            raise ValueError(f"parameter {name!r} has {size} values for {self.nc} pairs")
        values = self._P[where]
        return self._add(name, ca.repmat(values, self.nc, 1) if size == 1 and self.nc != 1 else values)

    def _per_pair(self, exprs) -> list[ca.SX]:
        """Each expression of one pair's local variables, evaluated for every pair (``nc`` vectors)."""
        exprs = list(exprs)
        if not self.nc:
            return [ca.SX(0, 1) for _ in exprs]
        symbols = ca.vertcat(*[s for s, _ in self._slots])
        values = ca.horzcat(*[v for _, v in self._slots]).T  # (n_slots, nc)
        pair = ca.Function("pair", [symbols], [ca.vertcat(*exprs)])
        out = pair.map(self.nc)(values)
        return [out[i, :].T for i in range(len(exprs))]

    # ------------------------------------------------------------------ functions
    def values(self, name: str, exprs, parameters: Parameters | None = None) -> NumericFunction:
        """``(z, P) -> expr_i`` per pair, ``P`` the values of ``parameters`` (a prefix)."""
        out = self._per_pair(exprs)
        n_params = (parameters or self.parameters).size
        tail = self._P[n_params:]
        if tail.numel() and any(ca.depends_on(o, tail) for o in out):
            raise ValueError(f"{name}: needs parameters beyond the first {n_params}")
        return NumericFunction(ca.Function(name, [self._z, self._P[:n_params]], out))

    def _finish(self, name: str, r: ca.SX, local: tuple[LocalTerms, ...] = ()) -> SystemFunctions:
        """The system ``r + sum of local terms``: the expression's Jacobian by automatic
        differentiation, the local terms' assembled from their items (:meth:`LocalTerms.jacobian_map`)."""
        J = ca.jacobian(r, self._z)
        varying = ca.vertcat(self._z, self._problem_params())
        linear = not ca.depends_on(J, varying) and not local
        if not local:
            rj = NumericFunction(ca.Function(f"{name}_rj", [self._z, self._P], [r, J]))
            return SystemFunctions(rj=rj, r=NumericFunction(ca.Function(f"{name}_r", [self._z, self._P], [r])),
                                   jacobian=SparseJacobian(rj), linear=bool(linear))
        expression = ca.Function(f"{name}_expression", [self._z, self._P], [r, J])
        z, P = ca.MX.sym("z", self.nz), ca.MX.sym("P", self.parameters.size)
        r_all, J_all = expression(z, P)
        for terms in local:
            value, jacobian = terms.assembled(z, P)
            r_all, J_all = r_all + value, J_all + jacobian
        rj = NumericFunction(ca.Function(f"{name}_rj", [z, P], [r_all, J_all]))
        return SystemFunctions(rj=rj, r=NumericFunction(ca.Function(f"{name}_r", [z, P], [r_all])),
                               jacobian=SparseJacobian(rj), linear=False)

    def _scattered(self, outputs) -> ca.SX | int:
        """``sum_o L_o psi_o`` (0 without outputs)."""
        outputs = list(outputs)
        if not outputs or not self.nc:
            return 0
        values = self._per_pair([e for e, _ in outputs])
        return sum(ca.mtimes(to_casadi(sp.csr_matrix(L)), v) for (_, L), v in zip(outputs, values))

    def build(self, name: str, *, linear=None, linear_params=None, rows: int | None = None,
              outputs=()) -> SystemFunctions:
        """The system ``r = A z + A_P P + sum_o L_o psi_o`` (see
        :meth:`PairSystem.build <ddcm_casadi.formulations.pairs.PairSystem.build>`)."""
        r = ca.SX(linear.shape[0] if linear is not None else int(rows), 1)
        if linear is not None:
            r += _product(linear, self._z, self.nz)
        if linear_params is not None:
            r += _product(linear_params, self._P, self.parameters.size)
        return self._finish(name, r + self._scattered(outputs))

    # ------------------------------------------------------------------ the systems of the formulations
    def mcp(self, name: str, pair_equation: ca.SX) -> SystemFunctions:
        """The classical system ``[F(x, p); pair_equation] = 0`` in ``z = [x; p]``."""
        F, local = self._split(self.problem.residual_map)
        values = self._per_pair([pair_equation])[0]
        rows = self.problem.n_residual + self.nc
        return self._finish(name, ca.vertcat(F, values), tuple(self._placed(t, rows) for t in local))

    def eliminated(self, name: str, pressure: ca.SX) -> SystemFunctions:
        """The classical residual ``F(x, p(x))`` in ``z = x``, each pair's pressure an expression
        of its local variables."""
        nx = self.problem.n_x
        p = self._per_pair([pressure])[0]
        R = self.problem.residual_map
        local = getattr(R, "local", ())
        F = (R.render_expression if local else R.render)(ca.vertcat(self._z[:nx], p), self._problem_params())
        # local terms of x alone (the material): the pressures enter through the expression only
        return self._finish(name, F, tuple(self._placed(t, R.rows, columns=nx) for t in local))

    def saddle(self, name: str, lagrangian: ca.SX, rows=()) -> SystemFunctions:
        """The projection's saddle-point system in ``z = [x, p, eta, ...]``: the stationarity of
        ``f + eta^T h + sum_i l(y_i)`` in ``(x, p)``, then ``h``, then one row per pair for each
        expression of ``rows``."""
        problem = self.problem
        nxp, ne = problem.n_x + self.nc, problem.n_residual
        xp, eta = self._z[:nxp], self._z[nxp:nxp + ne]
        h, h_local = self._split(problem.residual_map)
        f, f_local = self._split(problem.distance)
        pairs = self._per_pair([lagrangian, *rows])
        L = f + ca.dot(eta, h) + ca.sum1(pairs[0])
        r = ca.vertcat(ca.gradient(L, xp), h, *pairs[1:])
        total = r.size1()
        local = tuple(self._lagrangian(t, nxp, total) for t in h_local) + tuple(
            self._gradient_rows(t, total) for t in f_local)
        return self._finish(name, r, local)


__all__ = ["ExpressionPairSystem", "pair_system"]
