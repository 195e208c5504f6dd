r"""Newton systems whose nonlinearity is local to the contact pairs, built from sparse matrices.

Every system the formulations solve has the form

.. math::  r(z; P) = A z + A_P P + L\, \psi(y), \qquad y = Y z + Y_P P,

with constant sparse ``A``, ``A_P``, ``L``, ``Y``, ``Y_P`` (from the problem's matrices,
:class:`~ddcm_casadi.problems.maps.Affine`) and a function ``psi`` that acts on each pair separately:
``y`` holds, per pair, a few *local variables* (the scaled gap ``a``, the scaled pressure ``b``, the
pair's multipliers, the smoothing ``mu``, ...) and ``psi`` gives, per pair, a few outputs (``Phi``,
``d l / d a``, ...) that ``L`` scatters into the rows. Its Jacobian is

.. math::  J = A + L\, D\, Y_z, \qquad D = \partial \psi / \partial y \ \text{(one small block per pair)},

so the nonzeros of ``J`` are ``J_0 + T d``: ``d`` the nonzeros of the per-pair blocks, ``T`` a
constant sparse matrix computed once (``d_k`` adds the outer product of a column of ``L`` and a row
of ``Y_z``). ``psi`` and ``D`` come from one CasADi ``SX`` function of *one* pair (derived by CasADi,
so a formulation writes only ``psi``), mapped over the pairs; the rest are sparse products in one
``MX`` Function. The build therefore costs sparse matrix products, independent of the number of
pairs in its symbolic part, where one ``SX`` expression per matrix nonzero and its symbolic Jacobian
cost about 20 microseconds per nonzero.

The saddle-point systems of the projections are stationarity conditions of a Lagrangian
``f(x) + eta^T h(x, p) + sum_i l(y_i)`` (:meth:`PairSystem.saddle`): their rows
``grad f + [dh/dz]^T eta + Y_{x,p}^T dl/dy`` are of the same form, with ``dl/dy`` per pair by
CasADi and the Hessian of ``f`` a sparse product.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ddcm_casadi.linalg import to_casadi
from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.problems.maps import Affine, sparse_matrix
from ddcm_casadi.problems.parameters import Parameters
from ddcm_casadi.evaluate import NumericFunction
from ddcm_casadi.loops.newton import SparseJacobian


def _triplets(A, n: int, what: str):
    """``(row, column, value)`` of the nonzeros of ``A`` (``None``: no entries), all in the first
    ``n`` columns."""
    if A is None:
        return None
    A = sp.coo_matrix(A)
    keep = A.data != 0
    if np.any(A.col[keep] >= n):
        raise ValueError(f"{what} depends on columns beyond the first {n}")
    return A.row[keep].astype(np.int64), A.col[keep].astype(np.int64), A.data[keep].astype(float)


def _columns(A, n: int, what: str) -> sp.csr_matrix:
    """``A`` with ``n`` columns: zero columns appended, or trailing columns dropped (they must be
    zero: a block of the unknowns or parameters the system does not have)."""
    A = sparse_matrix(A)
    if A.shape[1] == n:
        return A
    if A.shape[1] < n:
        return sp.hstack([A, sp.csr_matrix((A.shape[0], n - A.shape[1]))]).tocsr()
    if A[:, n:].nnz:
        raise ValueError(f"{what} depends on columns beyond the first {n}")
    return A[:, :n].tocsr()


def scatter(rows: int, start: int, count: int) -> sp.csr_matrix:
    """The ``rows x count`` matrix that puts a vector of ``count`` values at rows ``start...``."""
    return sp.csr_matrix((np.ones(count), (start + np.arange(count), np.arange(count))), shape=(rows, count))


def _narrow(row: np.ndarray, col: np.ndarray, val: np.ndarray, n_rows: int) -> tuple[ca.DM, list[int]]:
    """The entries ``(row, col, val)`` (no duplicates) as a ``DM`` of the columns they use, and
    those columns."""
    used, narrow = np.unique(col, return_inverse=True)
    order = np.lexsort((row, narrow))
    colind = np.concatenate([[0], np.cumsum(np.bincount(narrow, minlength=used.size))])
    sparsity = ca.Sparsity(n_rows, used.size, colind.tolist(), row[order].tolist())
    return ca.DM(sparsity, val[order].tolist()), used.tolist()


def _shared_casadi(problem: ComplementarityProblem, A: sp.spmatrix) -> ca.DM:
    """``to_casadi(A)``, once per problem and matrix content."""
    A = sp.csc_matrix(A)
    A.sort_indices()
    h = hashlib.blake2b(digest_size=16)
    for part in (np.asarray(A.shape, np.int64), A.indptr, A.indices, A.data):
        h.update(np.ascontiguousarray(part).tobytes())
    return problem.shared(("casadi matrix", h.hexdigest()), lambda: to_casadi(A))


def _casadi_pattern(problem: ComplementarityProblem, A: sp.spmatrix, J0: sp.csc_matrix) -> ca.DM:
    """``J0`` (``A``'s values on the pattern of the Jacobian, :meth:`PairSystem._jacobian_map`) as
    a ``DM``: ``A`` without its empty trailing rows and columns converted once per problem
    (:func:`_shared_casadi`), padded, plus ``J0``'s other entries (stored zeros). A formulation's
    system and its branch system share that block (the stiffness or the saddle-point matrix,
    with different rows below and columns beside it), whose conversion is the build's largest:
    2-3 s at 1e6 unknowns."""
    A = sp.csc_matrix(A)
    n_rows, n_cols = A.shape
    used = np.flatnonzero(np.diff(A.indptr))
    r = int(A.indices.max()) + 1 if A.nnz else 0
    c = int(used[-1]) + 1 if used.size else 0
    core = sp.csc_matrix((A.data, A.indices, A.indptr[:c + 1]), shape=(r, c))  # no copy of the arrays
    padded = ca.DM(_shared_casadi(problem, core))  # a copy: resized in place below
    padded.resize(n_rows, n_cols)  # (CasADi's concatenation took 0.8 s at 1e5 unknowns, this 0.03)
    ones = lambda M: sp.csc_matrix((np.ones(M.indices.size), M.indices, M.indptr), shape=M.shape)  # noqa: E731
    extra = (ones(J0) - ones(A)).tocoo()  # 1 where J0 has an entry A has not (A's pattern is within J0's)
    keep = extra.data != 0
    if not keep.any():
        return padded
    E = sp.csc_matrix((np.zeros(int(keep.sum())), (extra.row[keep], extra.col[keep])), shape=A.shape)
    return ca.project(padded, padded.sparsity().unite(to_casadi(E).sparsity()))


def _pair_major(order: int, count: int) -> np.ndarray:
    """Permutation from block-major (``s * count + k``) to pair-major (``k * order + s``) indices."""
    return (np.arange(count)[:, None] + count * np.arange(order)[None, :]).ravel()


def _saddle_matrices(problem: ComplementarityProblem, extra: int) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """``(A, A_P)`` of the saddle-point rows ``[grad f + (dh/dz)^T eta; h]`` and ``extra`` zero rows."""
    nxp = problem.n_x + problem.n_pairs
    H, HP = problem.distance.hessian
    R = problem.residual_map
    A = sp.bmat([[H, R.z.T, sp.csr_matrix((nxp, extra))],
                 [R.z, None, None],
                 [sp.csr_matrix((extra, nxp)), None, None]], format="csr")
    return A, sp.vstack([HP, R.params, sp.csr_matrix((extra, R.params.shape[1]))]).tocsr()


@dataclass(frozen=True)
class SystemFunctions:
    """A built system: ``rj(z, P) -> (r, J nonzeros)``, ``r(z, P) -> r``, the CSC converter of
    ``J`` and whether ``J`` depends on neither the unknowns nor the problem's parameters (then one
    factorisation serves every solve)."""

    rj: NumericFunction
    r: NumericFunction
    jacobian: SparseJacobian
    linear: bool


@dataclass(frozen=True)
class NewtonSystem:
    """The Newton system a built formulation solves, published by name
    (:meth:`~ddcm_casadi.formulations.base.BuiltFormulation.newton_system`): ``r(z; P) = 0`` with
    the sparse Jacobian ``J = dr/dz``. The unknowns ``z`` and the parameters ``P`` are named blocks
    (:class:`~ddcm_casadi.problems.parameters.Parameters`): nothing outside the formulation slices them by
    position.

    Attributes
    ----------
    name : str
    unknowns : Parameters
        The blocks of ``z`` (``x``, ``p``; multipliers ``eta``, ``theta``, ``nu`` for a saddle point).
    parameters : Parameters
        The problem's parameters, then the formulation's (smoothing, multipliers, selectors).
    functions : SystemFunctions
        ``rj``, ``r``, the CSC converter and whether ``J`` is constant.
    """

    name: str
    unknowns: Parameters
    parameters: Parameters
    functions: SystemFunctions

    def residual(self, z: np.ndarray, P: np.ndarray) -> np.ndarray:
        return np.asarray(self.functions.r(z, P), float).ravel()

    def matrix(self, z: np.ndarray, P: np.ndarray) -> sp.csc_matrix:
        """``J(z; P)`` as a scipy CSC matrix."""
        return self.functions.jacobian(self.functions.rj(z, P)[1])

    def pack(self, **blocks) -> np.ndarray:
        """``z`` from its blocks by name."""
        return self.unknowns.pack(**blocks)

    def unpack(self, z: np.ndarray) -> dict[str, np.ndarray]:
        """The blocks of ``z`` by name."""
        return {name: self.unknowns.get(z, name) for name in self.unknowns.names}


class SystemBuilder:
    """What the builders of a problem's Newton systems share (:class:`PairSystem`, and
    :class:`~ddcm_casadi.formulations.systems.ExpressionPairSystem` for nonlinear problems).

    Parameters
    ----------
    problem : ComplementarityProblem
        Its pairs are the pairs of the system; ``z`` starts with the problem's ``[x; p]`` (or
        only ``x``).
    n_unknowns : int
        Size of ``z``.
    parameters : Parameters
        The system's parameters (the problem's first).
    """

    def __init__(self, problem: ComplementarityProblem, n_unknowns: int, parameters: Parameters) -> None:
        self.problem = problem
        self.nc = problem.n_contacts  # one local block per contact (its pair, or its Coulomb block)
        self.nz = int(n_unknowns)
        self.parameters = parameters


class PairSystem(SystemBuilder):
    """Builder of systems ``r(z; P) = A z + A_P P + L psi(y)`` (see the module notes), from the
    problem's sparse matrices (:class:`SystemBuilder` gives the parameters)."""

    def __init__(self, problem: ComplementarityProblem, n_unknowns: int, parameters: Parameters) -> None:
        super().__init__(problem, n_unknowns, parameters)
        # per local variable: its symbol, and (pair, column, value) of its maps of z and of P
        self._slots: list[tuple[ca.SX, tuple, tuple]] = []
        self._maps: dict[tuple, tuple] = {}

    # ------------------------------------------------------------------ local variables
    def local(self, name: str, z=None, params=None) -> ca.SX:
        """A local variable, per pair ``k`` row ``k`` of ``Z z + Q P`` (``Z``: ``nc x nz``, ``Q``:
        ``nc x n_params``, sparse; columns beyond ``nz`` of ``Z`` must be zero). Returns the
        ``SX`` symbol of one pair's value, for writing ``psi``."""
        return self._add(name, _triplets(z, self.nz, f"local {name!r}"),
                         _triplets(params, self.parameters.size, f"local {name!r}"))

    def affine(self, name: str, value: Affine) -> ca.SX:
        """A local variable from a problem's :class:`~ddcm_casadi.problems.maps.Affine` (one row per pair)."""
        return self.local(name, value.z, value.params)

    def unknowns(self, name: str, start: int) -> ca.SX:
        """The block of ``nc`` unknowns starting at ``z[start]`` as a local variable."""
        k = np.arange(self.nc)
        return self._add(name, (k, start + k, np.ones(self.nc)), None)

    def parameter(self, name: str) -> ca.SX:
        """A parameter of one value per pair, or of one value shared by every pair."""
        nc, where = self.nc, self.parameters.slice(name)
        size = where.stop - where.start
        if size not in (1, nc):
            raise ValueError(f"parameter {name!r} has {size} values for {nc} pairs")
        k = np.arange(nc)
        return self._add(name, None, (k, where.start + (0 * k if size == 1 else k), np.ones(nc)))

    def _add(self, name: str, z, params) -> ca.SX:
        symbol = ca.SX.sym(name)
        empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
        self._slots.append((symbol, z or empty, params or empty))
        return symbol

    def _entries(self, which: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(row, column, value)`` of ``Y_z`` (``which`` 1) or ``Y_P`` (2), rows pair-major
        (``k * n_slots + s``)."""
        ns = len(self._slots)
        k, c, v = (np.concatenate(a) for a in zip(*[slot[which] for slot in self._slots]))
        s = np.concatenate([np.full(slot[which][0].size, i) for i, slot in enumerate(self._slots)])
        return k * ns + s, c, v

    def _local_values(self, z: ca.MX, P: ca.MX, n_params: int | None = None) -> ca.MX:
        """The local variables as an ``(n_slots, nc)`` matrix, one column per pair: ``Y_z z + Y_P P``
        with ``Y_P`` cut to ``n_params`` columns, each map applied to the few entries it uses
        (``Y[:, used] v[used]``: of perhaps a million columns; a sparse product costs a step per
        column)."""
        ns = len(self._slots)
        key = ("local", ns, self.parameters.size if n_params is None else n_params)
        if key not in self._maps:  # converted once per system
            maps = []
            for which, columns in ((1, self.nz), (2, key[2])):
                row, col, val = self._entries(which)
                keep = col < columns
                maps.append(_narrow(row[keep], col[keep], val[keep], ns * self.nc))
            self._maps[key] = maps
        y = sum((ca.mtimes(Y, v[used]) for (Y, used), v in zip(self._maps[key], (z, P)) if used),
                ca.MX(ns * self.nc, 1))
        return ca.reshape(y, ns, self.nc)

    # ------------------------------------------------------------------ functions
    def values(self, name: str, exprs, parameters: Parameters | None = None) -> NumericFunction:
        """``(z, P) -> expr_i`` per pair (one ``nc`` vector per expression), with ``P`` the values
        of ``parameters`` (a prefix of the system's; default all)."""
        exprs = list(exprs)
        n_params = (parameters or self.parameters).size
        symbols = [s for s, _, _ in self._slots]
        for s, _, (_, cols, _) in self._slots:
            if np.any(cols >= n_params) and any(ca.depends_on(e, s) for e in exprs):
                raise ValueError(f"{name}: local {s.name()!r} needs parameters beyond the first {n_params}")
        z, P = ca.MX.sym("z", self.nz), ca.MX.sym("P", n_params)
        if not self.nc:  # no pairs
            return NumericFunction(ca.Function(name, [z, P], [ca.MX(0, 1) for _ in exprs]))
        pair = ca.Function(f"{name}_pair", [ca.vertcat(*symbols)], [ca.vertcat(*exprs)])
        out = pair.map(self.nc)(self._local_values(z, P, n_params))
        return NumericFunction(ca.Function(name, [z, P], [out[i, :].T for i in range(len(exprs))]))

    def build(self, name: str, *, linear=None, linear_params=None, rows: int | None = None,
              outputs=()) -> SystemFunctions:
        """The system ``r = A z + A_P P + sum_o L_o psi_o``.

        Parameters
        ----------
        linear, linear_params : sparse
            ``A`` (rows x nz, fewer columns padded) and ``A_P`` (rows x n_params, likewise).
        rows : int
            Number of rows when ``linear`` is not given.
        outputs : sequence of (casadi.SX, sparse)
            ``(psi_o, L_o)``: an expression of one pair's local variables and the ``rows x nc``
            matrix that scatters its value at pair ``k`` (column ``k``) into the rows.
        """
        nz, nc, nP = self.nz, self.nc, self.parameters.size
        rows = linear.shape[0] if linear is not None else int(rows)
        A = _columns(sp.csr_matrix((rows, nz)) if linear is None else linear, nz, name)
        AP = _columns(sp.csr_matrix((rows, nP)) if linear_params is None else linear_params, nP, name)
        outputs = [(e, sparse_matrix(L)) for e, L in outputs] if nc else []
        z, P = ca.MX.sym("z", nz), ca.MX.sym("P", nP)
        J0 = A.tocsc()
        linear_J = True
        if outputs:
            nout = len(outputs)
            symbols = [s for s, _, _ in self._slots]
            y1 = ca.vertcat(*symbols)
            moving = [i for i, (_, Z, _) in enumerate(self._slots) if Z[0].size]  # depend on z
            psi = ca.vertcat(*[e for e, _ in outputs])
            D = ca.jacobian(psi, ca.vertcat(*[symbols[i] for i in moving])) if moving else ca.SX(nout, 0)
            n_problem = self.problem.parameters.size
            varying = [symbols[i] for i, (_, Z, Q) in enumerate(self._slots)
                       if Z[0].size or np.any(Q[1] < n_problem)]
            linear_J = not (D.nnz() and varying and ca.depends_on(D, ca.vertcat(*varying)))
            L = sp.hstack([Lo for _, Lo in outputs]).tocsc()  # column o * nc + k: L_o[:, k]
            J0, T = self._jacobian_map(A, L, D.sparsity(), moving)
        # J0: the pattern of J with the values of A (zeros where only L D Y_z contributes); it
        # serves as A in the residual too, so the largest matrix is converted once.
        J0dm = _casadi_pattern(self.problem, A, J0)
        J = ca.MX(J0dm)  # one constant for the residual's product and the Jacobian
        r = r_only = ca.mtimes(J, z) + ca.mtimes(to_casadi(AP), P)
        if outputs:
            y = self._local_values(z, P)
            L = to_casadi(L[:, _pair_major(nout, nc)])
            # one mapped function for both (the per-pair derivatives cost little next to the products)
            values, derivatives = ca.Function(f"{name}_pair", [y1], [psi, D]).map(nc)(y)
            r = r_only = r + ca.mtimes(L, ca.vec(values))
            if T.nnz:
                J = J + ca.MX(J0dm.sparsity(), ca.mtimes(to_casadi(T), ca.vec(derivatives.nz[:])))
        rj = NumericFunction(ca.Function(f"{name}_rj", [z, P], [r, J]))
        return SystemFunctions(rj=rj, r=NumericFunction(ca.Function(f"{name}_r", [z, P], [r_only])),
                               jacobian=SparseJacobian(rj, pattern=J0), linear=bool(linear_J))

    def _jacobian_map(self, A: sp.csr_matrix, L: sp.csc_matrix, D: ca.Sparsity, moving: list[int]):
        """``(J0, T)``: the pattern of ``J = A + L D Y_z`` with the values of ``A`` (CSC) and ``T``
        with ``nonzeros(J) = J0.data + T d``, ``d`` the nonzeros of the per-pair blocks ``D``,
        pair-major (CasADi's order of a mapped output): entry ``(o, s)`` of pair ``k`` adds
        ``d L_o[:, k] Y_s[k, :]`` (``L``: the ``L_o`` side by side)."""
        nc = self.nc
        colind, out_e = D.get_ccs()
        out_e = np.asarray(out_e, dtype=np.int64)
        slot_e = np.asarray(moving, dtype=np.int64)[np.repeat(np.arange(D.size2()), np.diff(colind))]
        # per entry of d (pair-major): the column of L and the row of Y_z it multiplies
        k = np.repeat(np.arange(nc), out_e.size)
        Lsel = L[:, np.tile(out_e, nc) * nc + k]
        row, col, val = self._entries(1)
        Yz = sp.csr_matrix((val, (row, col)), shape=(len(self._slots) * nc, self.nz))
        Ysel = Yz[k * len(self._slots) + np.tile(slot_e, nc)]
        nl, ny = np.diff(Lsel.indptr), np.diff(Ysel.indptr)
        count = nl * ny
        e = np.repeat(np.arange(count.size), count)
        t = np.arange(e.size) - np.repeat(np.cumsum(count) - count, count)
        il = Lsel.indptr[e] + t // ny[e]
        iy = Ysel.indptr[e] + t % ny[e]
        rows, cols, vals = Lsel.indices[il], Ysel.indices[iy], Lsel.data[il] * Ysel.data[iy]
        # J0: A's values, and stored zeros where only L D Y_z contributes (scipy keeps them)
        Ac = A.tocoo()
        J0 = sp.csc_matrix((np.concatenate([Ac.data, np.zeros(rows.size)]),
                            (np.concatenate([Ac.row, rows]), np.concatenate([Ac.col, cols]))), shape=A.shape)
        J0.sum_duplicates()
        n_rows = A.shape[0]
        keys = np.repeat(np.arange(A.shape[1], dtype=np.int64), np.diff(J0.indptr)) * n_rows + J0.indices
        T = sp.csr_matrix((vals, (np.searchsorted(keys, cols.astype(np.int64) * n_rows + rows), e)),
                          shape=(J0.nnz, count.size))
        T.sum_duplicates()
        return J0, T

    # ------------------------------------------------------------------ classical systems
    def mcp(self, name: str, *pair_equations: ca.SX) -> SystemFunctions:
        """The classical system ``[F(x, p); pair_equations] = 0`` in ``z = [x; p]``: per contact as
        many equations as it has components (one per pair; a Coulomb block's ``b``), each an
        expression of the contact's local variables, component-major like ``p``."""
        problem, nc = self.problem, self.nc
        R = problem.residual_map
        rows = problem.n_residual + problem.n_pairs
        return self.build(name, linear=sp.vstack([R.z, sp.csr_matrix((problem.n_pairs, R.z.shape[1]))]),
                          linear_params=sp.vstack([R.params, sp.csr_matrix((problem.n_pairs, R.params.shape[1]))]),
                          outputs=[(e, scatter(rows, problem.n_residual + j * nc, nc))
                                   for j, e in enumerate(pair_equations)])

    # ------------------------------------------------------------------ classical, pressures eliminated
    def eliminated(self, name: str, *pressures: ca.SX) -> SystemFunctions:
        """The classical residual ``F(x, p(x))`` in ``z = x``, with each contact's pressure (and,
        with friction, its tangential tractions: one expression per component) an expression of
        its local variables (the penalty and augmented Lagrangian laws)."""
        R, nx, nc = self.problem.residual_map, self.problem.n_x, self.nc
        return self.build(name, linear=R.z[:, :nx], linear_params=R.params,
                          outputs=[(e, R.z[:, nx + j * nc:nx + (j + 1) * nc]) for j, e in enumerate(pressures)])

    # ------------------------------------------------------------------ saddle points
    def saddle(self, name: str, lagrangian: ca.SX, rows=()) -> SystemFunctions:
        """The projection's saddle-point system with unknowns ``z = [x, p, eta, ...]``: the
        stationarity of ``L = f(x) + eta^T h(x, p) + sum_i l(y_i)`` in ``(x, p)``, then ``h``,
        then one row per pair for each expression of ``rows`` (in order).

        ``lagrangian`` is ``l``, an expression of one pair's local variables; its derivative in
        each local variable that depends on ``(x, p)`` is scattered by that variable's map
        transposed (``Y_{x,p}^T dl/dy``).
        """
        problem, nc = self.problem, self.nc
        nxp, ne = problem.n_x + problem.n_pairs, problem.n_residual
        extra = len(rows) * nc
        total = nxp + ne + extra
        A, AP = problem.shared(("saddle", extra), lambda: _saddle_matrices(problem, extra))
        outputs = []
        for symbol, (k, col, val), _ in self._slots:
            xp = col < nxp
            if np.any(xp):  # Y_s restricted to (x, p), transposed
                outputs.append((ca.gradient(lagrangian, symbol),
                                sp.csr_matrix((val[xp], (col[xp], k[xp])), shape=(total, nc))))
        outputs += [(expr, scatter(total, nxp + ne + i * nc, nc)) for i, expr in enumerate(rows)]
        return self.build(name, linear=A, linear_params=AP, outputs=outputs)
