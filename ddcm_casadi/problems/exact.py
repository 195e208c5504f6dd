"""Exact solutions of linear complementarity problems by enumerating branches (active sets).

For a linear model the classical problem is a linear complementarity problem and the ``Z_E``
projection is a union of convex QPs, one per branch. Every pair is either *free* (``p = 0``),
*in contact* (``g = 0``) or *grazing* (both). For a convex QP, the optimum on a branch solves the
equality-constrained QP of its active constraints, so the global projection is the best
*sign-feasible* solution of these equality-constrained problems over all ``3^nc`` partitions
(``2^nc`` for the classical problem). A projection is solved in the bordered form (see
:class:`ExactEnumerator`): one factorisation with every constraint imposed serves every branch,
each branch then costing a ``2 nc x 2 nc`` block; branch by branch (the classical problem, the
reference, a singular bordered matrix) each partition's KKT matrix is factorised once (sparse LU).
Either is reused for any number of right-hand sides (load steps, data points). The linear parts are
the problem's own sparse maps, and nothing is factorised before the first solve.

This is independent of the formulations (no complementarity function, no IPOPT) and serves as the
reference the tests and the DDCM driver check against. Its cost grows as ``3^nc``: it is meant for
problems with few contact pairs (``max_pairs``).

Many projections at once (the DDCM global optimum). When only a few parameters change between
the projections, ``P = P0 + D c`` with ``D`` (n_params x r) and one ``c`` (r) per projection (the
data assigned to the points), every branch's solution is affine in ``c``, ``z = z0 + Z c``, and its
objective is the quadratic ``a0 + a1 . c + c^T A2 c / 2``: :meth:`ExactEnumerator.affine_family`
solves ``r + 1`` right-hand sides only (once, or per branch), and :meth:`BorderedFamily.best`
(:meth:`AffineFamily.best`) evaluates signs and objectives for millions of ``c`` with one
quadratic and a ``2 nc``-vector per branch (a quadratic per branch): no solve per projection.
:meth:`BorderedFamily.relaxed` is the projection without contact constraints, a lower bound of
every branch (the greedy screen leaves out the moves it shows cannot descend).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from ddcm_casadi.problems.complementarity import (
    BIACTIVE, CONTACT, FREE, b_stationarity, imposes_gap, imposes_pressure,
)
from ddcm_casadi.errors import InputError
from ddcm_casadi.linalg import SingularMatrix, factorize
from ddcm_casadi.problems.contract import ComplementarityProblem

GRAZING = BIACTIVE  # the name this module has used for the biactive piece


@dataclass
class ExactSolution:
    """Exact solution(s): one column per parameter vector."""

    x: np.ndarray          # (n_x, k) scaled
    p: np.ndarray          # (nc, k) scaled
    objective: np.ndarray  # (k,) scaled (0 for the classical problem)
    partition: np.ndarray  # (nc, k) FREE / CONTACT / GRAZING
    found: np.ndarray      # (k,) bool: a sign-feasible branch exists


@dataclass
class Branch:
    """One sign-feasible partition's solution (scaled), with the multipliers of its active pairs."""

    partition: tuple
    z: np.ndarray
    objective: float
    gap_multiplier: np.ndarray  # per pair; 0 where g = 0 is not imposed
    pressure_multiplier: np.ndarray  # per pair; 0 where p = 0 is not imposed


@dataclass
class _AffineBranch:
    """One branch's solution as an affine function of ``c``: gaps, pressures and objective."""

    gap0: np.ndarray    # (nc,)
    gap_c: np.ndarray   # (nc, r)
    p0: np.ndarray      # (nc,)
    p_c: np.ndarray     # (nc, r)
    a0: float
    a1: np.ndarray      # (r,)
    A2: np.ndarray      # (r, r)


def _quadratic(c, a0: float, a1: np.ndarray, A2: np.ndarray) -> np.ndarray:
    """``a0 + a1^T c + c^T A2 c / 2`` per column of ``c`` (dense, or sparse with few nonzeros)."""
    if sp.issparse(c):
        c = sp.csc_matrix(c)
        return a0 + c.T @ a1 + 0.5 * np.asarray(c.multiply((c.T @ A2.T).T).sum(axis=0)).ravel()
    return a0 + a1 @ c + 0.5 * np.einsum("ik,ik->k", c, A2 @ c)


def move_terms(a1: np.ndarray, A2: np.ndarray, rows: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The linear and quadratic terms ``a1^T c`` and ``c^T A2 c / 2`` of the columns ``c`` whose
    only nonzeros are ``d[g, i]`` at the rows ``rows[g]`` (``rows``: ``(G, j)``, one row set per
    group; ``d``: ``(G, N, j)``): two ``(G, N)`` arrays."""
    a1g, A2g = a1[rows], A2[rows[:, :, None], rows[:, None, :]]  # (G, j), (G, j, j)
    j = rows.shape[1]
    if d.shape[1] == 1:  # one move per group (the screen's survivors): two contractions
        d1 = d[:, 0, :]
        return np.einsum("gi,gi->g", d1, a1g)[:, None], 0.5 * np.einsum("gi,gij,gj->g", d1, A2g, d1)[:, None]
    if j > 4:  # many nonzeros per move: batched products
        return np.matmul(d, a1g[:, :, None])[..., 0], 0.5 * np.sum(d * np.matmul(d, A2g), axis=2)
    # Few (one-component points: 2): j^2 vector operations beat batched products of tiny matrices.
    linear = sum(d[..., i] * a1g[:, i, None] for i in range(j))
    quadratic = sum(d[..., i] * sum(d[..., m] * A2g[:, i, m, None] for m in range(j)) for i in range(j))
    return linear, 0.5 * quadratic


def _moves_matrix(rows: np.ndarray, d: np.ndarray, r: int) -> sp.csc_matrix:
    """The columns of :func:`move_terms` as a sparse ``(r, G N)`` matrix (group-major)."""
    G, N, j = d.shape
    return sp.csc_matrix((d.ravel(), (np.repeat(rows, N, axis=0).ravel(), np.repeat(np.arange(G * N), j))),
                         shape=(r, G * N))


@dataclass
class AffineFamily:
    """The exact projections of ``P0 + D c`` for any ``c`` (see :meth:`ExactEnumerator.affine_family`),
    branch by branch (the reference form, used where the bordered form is singular)."""

    branches: list[_AffineBranch]
    sign_tol: float

    def best(self, c, *, chunk: int = 1 << 20) -> np.ndarray:
        """The exact projection's objective (scaled) for every column of ``c`` (r, N; dense or
        sparse): the smallest over the sign-feasible branches, ``inf`` where none is."""
        c = c.tocsc() if sp.issparse(c) else np.asarray(c, float)
        out = np.full(c.shape[1], np.inf)
        for a in range(0, c.shape[1], chunk):
            cc = c[:, a:a + chunk]
            best = out[a:a + chunk]
            for b in self.branches:
                ok = np.ones(cc.shape[1], dtype=bool)
                for g0, gc in ((b.gap0, b.gap_c), (b.p0, b.p_c)):
                    values = g0[:, None] + (cc.T @ gc.T).T if sp.issparse(cc) else g0[:, None] + gc @ cc
                    ok &= np.all(values >= -self.sign_tol, axis=0)
                obj = _quadratic(cc, b.a0, b.a1, b.A2)
                better = ok & (obj < best)
                best[better] = obj[better]
        return out

    def base(self) -> float:
        """:meth:`best` at ``c = 0``: the exact projection's objective of ``P0``."""
        return float(self.best(np.zeros((self.branches[0].a1.size if self.branches else 0, 1)))[0])

    def best_moves(self, rows: np.ndarray, d: np.ndarray) -> np.ndarray:
        """:meth:`best` of the columns with the nonzeros ``d[g, i]`` at ``rows[g]`` (:func:`move_terms`): ``(G, N)``."""
        if not self.branches:
            return np.full(d.shape[:2], np.inf)
        return self.best(_moves_matrix(rows, d, self.branches[0].a1.size)).reshape(d.shape[:2])


@dataclass
class BorderedFamily:
    r"""The exact projections of ``P0 + D c`` in the bordered form (:class:`_Bordered`): the
    projection with every constraint imposed is the quadratic ``a0 + a1^T c + c^T A2 c / 2``, its
    constraint multipliers ``w = w0 + W c``, and branch ``s`` adds ``w^T P_s w / 2`` to the
    objective and frees its dropped constraints to the values ``-P_s w`` (gaps, pressures), which
    must be ``>= 0``. Same answers as :class:`AffineFamily`, with one quadratic per ``c`` instead
    of one per branch."""

    a0: float
    a1: np.ndarray       # (r,)
    A2: np.ndarray       # (r, r)
    w0: np.ndarray       # (2 nc,)
    W: np.ndarray        # (2 nc, r)
    branches: Branches
    sign_tol: float
    relaxed_P: np.ndarray | None = None  # M^-1: every constraint dropped (None: that problem is singular)
    relaxed_A2: np.ndarray | None = None  # the quadratic term of relaxed() where the caller has it

    def relaxed(self) -> tuple[float, np.ndarray, np.ndarray] | None:
        r"""``(a0, a1, A2)`` of the projection without any contact constraint (``R z = r`` only),
        ``a0 + a1^T c + c^T A2 c / 2``, or None where that problem is singular. Every branch adds
        constraints to it, so it is a lower bound of :meth:`best` (a convex QP: ``H`` is positive
        semidefinite and ``K_R`` nonsingular, so its stationary point is its minimum)."""
        if self.relaxed_P is None:
            return None
        Pw0 = self.relaxed_P @ self.w0
        if self.relaxed_A2 is None:
            A2 = self.A2 + self.W.T @ (self.relaxed_P @ self.W)
            A2 = 0.5 * (A2 + A2.T)
        else:  # it does not depend on the family's base (P0): the step's, once
            A2 = self.relaxed_A2
        return self.a0 + 0.5 * float(self.w0 @ Pw0), self.a1 + self.W.T @ Pw0, A2

    def best(self, c, *, chunk: int = 1 << 20) -> np.ndarray:
        """As :meth:`AffineFamily.best`."""
        c = c.tocsc() if sp.issparse(c) else np.asarray(c, float)
        out = np.full(c.shape[1], np.inf)
        for a in range(0, c.shape[1], chunk):
            cc = c[:, a:a + chunk]
            w = self.w0[:, None] + ((cc.T @ self.W.T).T if sp.issparse(cc) else self.W @ cc)
            out[a:a + chunk] = _best_branch(_quadratic(cc, self.a0, self.a1, self.A2), w, self.branches,
                                            self.sign_tol)[0]
        return out

    def base(self) -> float:
        """:meth:`best` at ``c = 0``: the exact projection's objective of ``P0``."""
        return float(_best_branch(np.array([self.a0]), self.w0[:, None], self.branches, self.sign_tol)[0][0])

    def best_moves(self, rows: np.ndarray, d: np.ndarray) -> np.ndarray:
        """:meth:`best` of the columns with the nonzeros ``d[g, i]`` at ``rows[g]`` (:func:`move_terms`),
        without forming them: ``(G, N)``."""
        linear, quadratic = move_terms(self.a1, self.A2, rows, d)
        w = self.w0[:, None, None] + np.einsum("mgj,gij->mgi", self.W[:, rows], d)  # (2 nc, G, N)
        G, N = linear.shape
        return _best_branch((self.a0 + linear + quadratic).ravel(), w.reshape(-1, G * N), self.branches,
                            self.sign_tol)[0].reshape(G, N)


#: Rows x columns up to which :func:`_best_branch` treats every branch at once.
ALL_BRANCHES_AT_ONCE = 1 << 18


@dataclass(frozen=True)
class Branches:
    r"""The branches of the bordered form: ``P`` (``(branches, 2 nc, 2 nc)``, ``M_DD^-1`` embedded
    at each branch's dropped rows ``D``) and which are ``solvable``; for :func:`_best_branch`, the
    rows of ``P_s`` that are not zero (``P_s[D]``) of each solvable branch (``branch``, in order),
    padded with zero rows to the most a branch drops (``rows``: ``(solvable branches, most, 2 nc)``),
    and the constraint each row frees (``freed``; 0 for a padding row, whose product is 0)."""

    P: np.ndarray
    solvable: np.ndarray
    rows: np.ndarray
    freed: np.ndarray
    branch: np.ndarray

    @classmethod
    def of(cls, P: np.ndarray, solvable: np.ndarray) -> "Branches":
        branch = np.flatnonzero(solvable)
        dropped = [np.flatnonzero(np.any(P[s] != 0, axis=1)) for s in branch]
        most = max([1] + [d.size for d in dropped])
        rows = np.zeros((branch.size, most, P.shape[2]))
        freed = np.zeros((branch.size, most), dtype=np.intp)
        for i, (s, d) in enumerate(zip(branch, dropped)):
            rows[i, :d.size] = P[s, d]
            freed[i, :d.size] = d
        return cls(P=P, solvable=solvable, rows=rows, freed=freed, branch=branch)


def _best_branch(base: np.ndarray, w: np.ndarray, branches: Branches, sign_tol: float):
    """``(objective, branch)`` per column of the bordered form: the smallest ``base + w^T P_s w / 2``
    over the solvable branches ``s`` whose freed constraints ``-P_s w`` are ``>= -sign_tol`` (the
    first such branch on ties, as the enumeration in order); ``inf`` and ``-1`` where none is.
    Only the rows of ``P_s`` that are not zero enter (:class:`Branches`: for three pairs 81 of
    the 162 rows)."""
    B, most, n2 = branches.rows.shape
    if not B:
        return np.full(w.shape[1], np.inf), np.full(w.shape[1], -1)
    if B * most * w.shape[1] <= ALL_BRANCHES_AT_ONCE:  # few columns: one product for every branch
        Pw = (branches.rows.reshape(-1, n2) @ w).reshape(B, most, -1)
        feasible = Pw.max(axis=1) <= sign_tol  # padding rows are 0: never above the tolerance
        Pw *= w[branches.freed]
        obj = np.where(feasible, base + 0.5 * Pw.sum(axis=1), np.inf)
        which = obj.argmin(axis=0)  # the first on ties
        best = obj[which, np.arange(w.shape[1])]
        return best, np.where(np.isfinite(best), branches.branch[which], -1)
    best = np.full(w.shape[1], np.inf)
    which = np.full(w.shape[1], -1)
    for s in branches.branch:
        Pw = branches.P[s] @ w
        obj = base + 0.5 * np.einsum("ik,ik->k", w, Pw)
        better = np.all(Pw <= sign_tol, axis=0) & (obj < best)
        best[better], which[better] = obj[better], s
    return best, which


#: Bordered form: a branch whose block ``M_DD`` of the multipliers' inverse has a condition number
#: above this is singular (its own KKT matrix is: ``det M_DD = det K_S / det K``).
SINGULAR_CONDITION = 1e12


@dataclass
class _Bordered:
    r"""The projection with every constraint imposed (``R z = r``, ``g = 0`` and ``p = 0`` at every
    pair), factorised once, and what each branch changes (see :meth:`ExactEnumerator.solve`)."""

    lu: object
    Zc: np.ndarray       # (n_z, 2 nc): z of unit right-hand sides in the constraint rows
    M: np.ndarray        # (2 nc, 2 nc): their multipliers
    branches: Branches   # M_DD^-1 embedded at each branch's dropped rows, and which are solvable
    relaxed_P: np.ndarray | None  # M^-1 (every constraint dropped), None if singular


class ExactEnumerator:
    """Branch enumeration for a linear :class:`ComplementarityProblem` (built once, solves many).

    The problem's sparse maps are its linear parts: ``R = R_z z + R_P P``, ``g = G_z z + g_P P``
    and, for a projection, ``f = |d|_W^2 / 2`` with ``d = D_z z + D_P P``, so ``grad f = H z + H_P P``
    (:attr:`~ddcm_casadi.problems.maps.Distance.hessian`) and ``f(0; P) = P^T D_P^T W D_P P / 2``.
    Nothing is factorised before the first solve.

    Bordered form (projections). With ``K`` the KKT matrix of every constraint imposed and
    ``M = (K^-1)`` restricted to the ``2 nc`` multipliers ``mu`` of ``g = 0`` and ``p = 0``, the
    branch that drops the constraints ``D`` solves ``K y = b + E_D t`` with ``mu_D = 0``:
    ``t = -M_DD^-1 mu_D(y_0)``. Its dropped constraints take the values ``t`` (the others stay 0)
    and its objective is ``f(y_0) + mu_D^T M_DD^-1 mu_D / 2`` (from ``K``'s own equations:
    ``C Z = I``, ``Z^T H Z = -M``). One solve with ``K`` then serves all ``3^nc`` branches. Where
    ``K`` is singular (dependent constraints), each branch is factorised instead.
    """

    def __init__(self, problem: ComplementarityProblem, *, max_pairs: int = 8, sign_tol: float = 1e-10) -> None:
        if problem.n_pairs > max_pairs:
            raise InputError(f"exact enumeration is limited to {max_pairs} contact pairs, got {problem.n_pairs}")
        if not problem.affine:
            raise InputError("exact enumeration needs a linear model")
        self.problem = problem
        self.sign_tol = sign_tol
        self.nx, self.nc = problem.n_x, problem.n_pairs
        self.nz = self.nx + self.nc
        R, g = problem.residual_map, problem.gap_map
        self.Rz, self.Gz = R.z.tocsc(), g.z.tocsc()
        self._R_P, self._g_P = R.params, g.params
        if problem.kind == "mpcc":
            self.H, self._q_P = (m.tocsc() for m in problem.distance.hessian)
            d = problem.distance.d
            self._d, self._weight = d, problem.distance.weight
            self._f_PP = (d.params.T @ self._weight @ d.params).tocsr()
        else:
            self.H = self._d = None
        self._factors: dict[tuple, object] = {}
        self._bordered_form: _Bordered | None | bool = False  # False: not built yet
        self.partitions = list(itertools.product(
            (FREE, CONTACT) if problem.kind == "mcp" else (FREE, CONTACT, GRAZING), repeat=self.nc))

    def _affine_parts(self, params: np.ndarray):
        """``R(0; P)``, ``g(0; P)``, ``grad f(0; P)`` and ``f(0; P)`` per column of ``params``."""
        if self.problem.kind == "mcp":
            return self._R_P @ params, self._g_P @ params, np.zeros((self.nz, params.shape[1])), np.zeros(params.shape[1])
        f0 = 0.5 * np.einsum("ik,ik->k", params, self._f_PP @ params)
        return self._R_P @ params, self._g_P @ params, self._q_P @ params, f0

    @property
    def _bordered(self) -> _Bordered | None:
        """The bordered form of a projection (built on first use), or None (a classical problem,
        or ``K`` singular)."""
        if self._bordered_form is False:
            self._bordered_form = self._build_bordered() if self.problem.kind == "mpcc" else None
        return self._bordered_form

    def _build_bordered(self) -> _Bordered | None:
        nc, nz = self.nc, self.nz
        C = sp.vstack([self.Gz, sp.csr_matrix((np.ones(nc), (np.arange(nc), self.nx + np.arange(nc))),
                                              shape=(nc, nz))]).tocsc()
        K = sp.bmat([[self.H, self.Rz.T, C.T], [self.Rz, None, None], [C, None, None]]).tocsc()
        try:
            lu = factorize(K)
        except SingularMatrix:
            return None
        n1 = nz + self.Rz.shape[0]
        E = np.zeros((K.shape[0], 2 * nc))
        E[n1 + np.arange(2 * nc), np.arange(2 * nc)] = 1.0
        Y = lu.solve(E)
        if not np.all(np.isfinite(Y)):
            return None
        M = 0.5 * (Y[n1:] + Y[n1:].T)
        P = np.zeros((len(self.partitions), 2 * nc, 2 * nc))
        solvable = np.ones(len(self.partitions), dtype=bool)
        for s, part in enumerate(self.partitions):
            part = np.asarray(part)
            dropped = np.flatnonzero(np.concatenate([~imposes_gap(part), ~imposes_pressure(part)]))
            if dropped.size == 0:
                continue
            MDD = M[np.ix_(dropped, dropped)]
            if not np.linalg.cond(MDD) <= SINGULAR_CONDITION:
                solvable[s] = False
                continue
            P[s][np.ix_(dropped, dropped)] = np.linalg.inv(MDD)
        relaxed = np.linalg.inv(M) if nc and np.linalg.cond(M) <= SINGULAR_CONDITION else None
        return _Bordered(lu=lu, Zc=Y[:nz], M=M, branches=Branches.of(P, solvable), relaxed_P=relaxed)

    def _imposed(self, params: np.ndarray, b: _Bordered) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The projection with every constraint imposed, per column of ``params``: ``(z0, d, mu)``,
        ``d`` the distance (its objective is ``d^T W d / 2``: no cancellation of large terms) and
        ``mu`` the multipliers of the ``2 nc`` constraints."""
        R0, g0, q, _ = self._affine_parts(params)
        y = b.lu.solve(np.vstack([-q, -R0, -g0, np.zeros((self.nc, params.shape[1]))]))
        z0 = y[:self.nz]
        return z0, self._d.z @ z0 + self._d.params @ params, y[self.nz + self.Rz.shape[0]:]

    @property
    def bordered(self) -> bool:
        """Whether the projection has the bordered form (``K`` nonsingular; built on first use)."""
        return self._bordered is not None

    def imposed(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The unknowns ``z``, the distance ``d`` and the multipliers ``mu`` of the ``2 nc``
        constraints of the projection with every constraint imposed, per column of ``params``
        (linear in them: the maps have no constant terms). Needs the bordered form (:attr:`bordered`)."""
        return self._imposed(np.asarray(params, float), self._bordered)

    def from_imposed(self, z0: np.ndarray, d: np.ndarray, w: np.ndarray) -> ExactSolution:
        """The exact projections (per column) from their projections with every constraint
        imposed (:meth:`imposed`, or linear combinations of its columns): the best sign-feasible
        branch, ``z = z0 + Z_c t`` with its freed constraints ``t = -P_s mu``."""
        b = self._bordered
        Wd = self._weight_diagonal[:, None] * d if self._weight_diagonal is not None else self._weight @ d
        obj, which = _best_branch(0.5 * np.einsum("ik,ik->k", d, Wd), w, b.branches, self.sign_tol)
        found = which >= 0
        if d.shape[1] == 1:  # one projection (a checked or a search's projection): no gathers
            s = int(which[0])
            z = z0 + b.Zc @ (-(b.branches.P[s] @ w)) if s >= 0 else np.full(z0.shape, np.nan)
            partition = self._partition_array[max(s, 0)][:, None] if s >= 0 else np.zeros((self.nc, 1), dtype=int)
            return ExactSolution(x=z[:self.nx], p=z[self.nx:], objective=obj, partition=partition, found=found)
        cols = np.flatnonzero(found)
        t = np.zeros((2 * self.nc, d.shape[1]))
        t[:, cols] = -np.einsum("kij,jk->ik", b.branches.P[which[cols]], w[:, cols])
        z = np.where(found, z0 + b.Zc @ t, np.nan)
        partition = np.zeros((self.nc, d.shape[1]), dtype=int)
        partition[:, cols] = self._partition_array[which[cols]].T
        return ExactSolution(x=z[:self.nx], p=z[self.nx:], objective=obj, partition=partition, found=found)

    @cached_property
    def _partition_array(self) -> np.ndarray:
        """``(branches, nc)``: the partitions as an array."""
        return np.array(self.partitions, dtype=int).reshape(len(self.partitions), self.nc)

    @cached_property
    def _weight_diagonal(self) -> np.ndarray | None:
        """The distance's weight as a vector where it is diagonal (one-component points), else None."""
        W = sp.csr_matrix(self._weight)
        diag = W.diagonal()
        return diag if W.nnz == np.count_nonzero(diag) else None

    def family(self, d0: np.ndarray, w0: np.ndarray, E: np.ndarray, W: np.ndarray, *,
               A2: np.ndarray | None = None, relaxed_A2: np.ndarray | None = None) -> BorderedFamily:
        """The :class:`BorderedFamily` of the projections of ``P0 + D c`` from :meth:`imposed` of
        ``P0`` (``d0``, ``w0``) and of the columns of ``D`` (``E``, ``W``). ``A2``: ``E^T W E``
        (symmetric) where the caller has it (a family of some of the directions of a larger
        one: its rows and columns), else computed; ``relaxed_A2``: the quadratic term of
        :meth:`BorderedFamily.relaxed` where the caller has it (the same for every ``P0``)."""
        b = self._bordered
        Wd0 = self._weight_diagonal * d0 if self._weight_diagonal is not None else self._weight @ d0
        if A2 is None:
            A2 = E.T @ (self._weight @ E)
            A2 = 0.5 * (A2 + A2.T)
        return BorderedFamily(a0=0.5 * float(d0 @ Wd0), a1=E.T @ Wd0, A2=A2, w0=w0, W=W, branches=b.branches,
                              sign_tol=self.sign_tol, relaxed_P=b.relaxed_P,
                              relaxed_A2=relaxed_A2 if b.relaxed_P is not None else None)

    def _solve_bordered(self, params: np.ndarray, b: _Bordered) -> ExactSolution:
        return self.from_imposed(*self._imposed(params, b))

    def _constraints(self, part) -> sp.csc_matrix:
        part = np.asarray(part)
        on_gap = np.flatnonzero(imposes_gap(part))
        on_p = np.flatnonzero(imposes_pressure(part))
        Ep = sp.csr_matrix((np.ones(on_p.size), (np.arange(on_p.size), self.nx + on_p)), shape=(on_p.size, self.nz))
        return sp.vstack([self.Rz, self.Gz[on_gap], Ep]).tocsc(), on_gap, on_p

    def _factor(self, part):
        if part not in self._factors:
            C, on_gap, on_p = self._constraints(part)
            if self.problem.kind == "mcp":
                M = C
            else:
                M = sp.bmat([[self.H, C.T], [C, None]]).tocsc()
            try:
                lu = factorize(M) if M.shape[0] == M.shape[1] else None
            except SingularMatrix:
                lu = None  # singular: this partition has no unique solution
            self._factors[part] = (lu, on_gap, on_p)
        return self._factors[part]

    def _solve_partition(self, part, affine):
        """Solve one partition for every parameter column: ``(solution, z, ok)`` (``ok``: finite and
        sign-feasible per column), or ``None`` if the partition is singular."""
        R0, g0, q, _ = affine
        lu, on_gap, on_p = self._factor(part)
        if lu is None:
            return None
        d = np.vstack([-R0, -g0[on_gap], np.zeros((on_p.size, R0.shape[1]))])
        sol = lu.solve(d if self.problem.kind == "mcp" else np.vstack([-q, d]))
        z = sol[:self.nz]
        gap = self.Gz @ z + g0
        ok = (np.all(gap >= -self.sign_tol, axis=0) & np.all(z[self.nx:] >= -self.sign_tol, axis=0)
              & np.all(np.isfinite(z), axis=0))
        return sol, z, ok

    def _objective(self, z, affine) -> np.ndarray:
        _, _, q, f0 = affine
        if self.problem.kind == "mcp":
            return np.zeros(z.shape[1])
        return 0.5 * np.einsum("ik,ik->k", z, self.H @ z) + np.einsum("ik,ik->k", q, z) + f0

    def solve(self, params: np.ndarray, *, bordered: bool = True) -> ExactSolution:
        """Exact solution for each column of ``params`` (a vector gives one column); a projection
        by the bordered form unless ``bordered`` is False (then, or where ``K`` is singular, each
        branch's KKT matrix is factorised: the reference)."""
        params = np.asarray(params, float)
        if params.ndim == 1:
            params = params[:, None]
        b = self._bordered if bordered else None
        if b is not None:
            return self._solve_bordered(params, b)
        k = params.shape[1]
        affine = self._affine_parts(params)
        best_obj = np.full(k, np.inf)
        best_z = np.full((self.nz, k), np.nan)
        best_part = np.zeros((self.nc, k), dtype=int)
        for part in self.partitions:
            out = self._solve_partition(part, affine)
            if out is None:
                continue
            _, z, ok = out
            if self.problem.kind == "mcp":  # the first solution found (the LCP's is unique here)
                better = ok & ~np.isfinite(best_obj)
                obj = np.zeros(k)
            else:
                obj = self._objective(z, affine)
                better = ok & (obj < best_obj)
            best_obj[better] = obj[better]
            best_z[:, better] = z[:, better]
            best_part[:, better] = np.asarray(part)[:, None]
        return ExactSolution(x=best_z[:self.nx], p=best_z[self.nx:], objective=best_obj,
                             partition=best_part, found=np.isfinite(best_obj))

    def affine_family(self, base: np.ndarray, directions: np.ndarray, *,
                      bordered: bool = True) -> AffineFamily | BorderedFamily:
        r"""Every branch of the projections of ``P = base + directions @ c``, affine in ``c``.

        The maps have no constant terms, so every solution is linear in the parameters. By the
        bordered form (unless ``bordered`` is False, or ``K`` is singular): one solve with ``K``
        for the ``r + 1`` columns ``[base, directions]`` gives the distance ``d(c) = d_0 + E c``
        of the projection with every constraint imposed, so its objective is
        ``a_0 = d_0^T W d_0 / 2``, ``a_1 = E^T W d_0``, ``A_2 = E^T W E``, and the multipliers
        ``w = w_0 + W c`` (:class:`BorderedFamily`). Branch by branch (:class:`AffineFamily`):
        with ``z0`` a branch's solution for ``base`` and ``Z`` for ``directions``,
        ``z(c) = z0 + Z c``, the gradient's parameter part ``q(c) = q0 + Q c`` and ``f(0; P)``
        quadratic in ``P``, the objective ``f = z^T H z / 2 + q^T z + f(0; P)`` is

        .. math::  a_0 + a_1^T c + \tfrac12 c^T A_2 c,\quad
                   A_2 = Z^T H Z + Z^T Q + Q^T Z + D^T F_{PP} D .

        Only ``r + 1`` right-hand sides are solved (per branch, branch by branch), whatever the
        number of ``c``.
        """
        if self.problem.kind != "mpcc":
            raise InputError("an affine family of projections needs a projection (mpcc) problem")
        base = np.asarray(base, float).reshape(-1, 1)
        D = np.asarray(directions, float)
        if bordered and self.bordered:
            _, d, w = self.imposed(np.hstack([base, D]))
            return self.family(d[:, 0], w[:, 0], d[:, 1:], w[:, 1:])
        R0, g0, q0, f0 = self._affine_parts(base)
        # The linear parts of R, g, grad f in the directions.
        RD, gD, qD = self._R_P @ D, self._g_P @ D, self._q_P @ D
        fD = base[:, 0] @ (self._f_PP @ D)
        FDD = D.T @ (self._f_PP @ D)
        out = []
        for part in self.partitions:
            lu, on_gap, on_p = self._factor(part)
            if lu is None:
                continue
            rhs = np.hstack([np.vstack([-q0, -R0, -g0[on_gap], np.zeros((on_p.size, 1))]),
                             np.vstack([-qD, -RD, -gD[on_gap], np.zeros((on_p.size, D.shape[1]))])])
            sol = lu.solve(rhs)[:self.nz]
            z0, Z = sol[:, 0], sol[:, 1:]
            if not (np.all(np.isfinite(z0)) and np.all(np.isfinite(Z))):
                continue
            Hz0, HZ = self.H @ z0, self.H @ Z
            a0 = 0.5 * z0 @ Hz0 + q0[:, 0] @ z0 + float(f0[0])
            a1 = Z.T @ Hz0 + Z.T @ q0[:, 0] + qD.T @ z0 + fD
            A2 = Z.T @ HZ + Z.T @ qD + qD.T @ Z + FDD
            out.append(_AffineBranch(gap0=self.Gz @ z0 + g0[:, 0], gap_c=self.Gz @ Z + gD,
                                     p0=z0[self.nx:], p_c=Z[self.nx:], a0=float(a0), a1=a1,
                                     A2=0.5 * (A2 + A2.T)))
        return AffineFamily(out, self.sign_tol)

    def branches(self, params: np.ndarray) -> list[Branch]:
        """Every sign-feasible partition's solution for one parameter vector.

        For a projection (``mpcc``) with the multipliers of the imposed ``g = 0`` and ``p = 0``;
        for a classical problem (``mcp``) these are the solutions of the LCP (a solution with a
        biactive pair appears once per partition that admits it: see :meth:`solutions`).
        """
        affine = self._affine_parts(np.asarray(params, float).reshape(-1, 1))
        out = []
        for part in self.partitions:
            solved = self._solve_partition(part, affine)
            if solved is None or not solved[2][0]:
                continue
            sol, z = solved[0][:, 0], solved[1][:, 0]
            mg, mp = np.zeros(self.nc), np.zeros(self.nc)
            if self.problem.kind == "mpcc":
                _, on_gap, on_p = self._factor(part)
                lam = sol[self.nz:]
                ne = self.Rz.shape[0]
                mg[on_gap] = lam[ne:ne + on_gap.size]
                mp[on_p] = lam[ne + on_gap.size:]
            out.append(Branch(tuple(part), z, float(self._objective(z[:, None], affine)[0]), mg, mp))
        return out

    @staticmethod
    def _distinct(branches: list[Branch], tol: float, prefer=None) -> list[Branch]:
        """One branch per distinct solution; among duplicates the first, or the first for which
        ``prefer(branch)`` holds."""
        out: list[Branch] = []
        for b in branches:
            same = [i for i, o in enumerate(out) if np.max(np.abs(b.z - o.z), initial=0.0)
                    <= tol * max(1.0, float(np.max(np.abs(o.z), initial=0.0)))]
            if not same:
                out.append(b)
            elif prefer is not None and prefer(b) and not prefer(out[same[0]]):
                out[same[0]] = b
        return out

    def solutions(self, params: np.ndarray, *, tol: float = 1e-8) -> list[Branch]:
        """The distinct sign-feasible branch solutions (classical: every solution of the LCP)."""
        return self._distinct(self.branches(params), tol)

    def local_minima(self, params: np.ndarray, *, tol: float = 1e-8) -> list[Branch]:
        """The distinct local minima of the projection (B-stationary branch solutions), best first.

        A branch solution is a local minimum of the MPCC when it is optimal on every piece of
        ``Z_E`` that contains it; the pieces differ only at biactive pairs (``g = p = 0``), so it is
        enough that the multipliers of both ``g >= 0`` and ``p >= 0`` there have the sign of an
        active inequality (here ``<= 0``: the Lagrangian is ``f + lambda^T c``). Biactive pairs are
        found by value (``|g|, |p| <= tol``), and a solution is judged on the partition that marks
        all of them grazing (the one that carries both multipliers) whenever that partition solves.
        """
        g0 = self._affine_parts(np.asarray(params, float).reshape(-1, 1))[1][:, 0]

        def biactive(b: Branch) -> np.ndarray:
            gap, p = self.Gz @ b.z + g0, b.z[self.nx:]
            scale = tol * max(1.0, float(np.max(np.abs(b.z), initial=0.0)))
            return (np.abs(gap) <= scale) & (np.abs(p) <= scale)

        def graded(b: Branch) -> bool:  # every biactive pair carries both multipliers
            return bool(np.all(np.asarray(b.partition)[biactive(b)] == GRAZING))

        minima: list[Branch] = []
        for b in self._distinct(self.branches(params), tol, prefer=graded):
            wrong_gap, wrong_p = b_stationarity(b.gap_multiplier, b.pressure_multiplier,
                                                np.array(b.partition) == GRAZING, rel_tol=tol)
            if not (wrong_gap.any() or wrong_p.any()):
                minima.append(b)
        return sorted(minima, key=lambda b: b.objective)
