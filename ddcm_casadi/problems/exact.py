"""Exact solutions of linear complementarity problems by enumerating branches (active sets).

For a linear model the classical problem is a linear complementarity problem and the ``Z_E``
projection is a union of convex QPs, one per branch. Every pair is either *free* (``p = 0``),
*in contact* (``g = 0``) or *grazing* (both). For a convex QP, the optimum on a branch solves the
equality-constrained QP of its active constraints, so the global projection is the best
*sign-feasible* solution of these equality-constrained problems over all ``3^nc`` partitions
(``2^nc`` for the classical problem). Each partition's KKT matrix is factorised once (sparse LU)
and reused for any number of right-hand sides (load steps, data points).

This is independent of the formulations (no complementarity function, no IPOPT) and serves as the
reference the tests and the DDCM driver check against. Its cost grows as ``3^nc``: it is meant for
problems with few contact pairs (``max_pairs``).

Many projections at once (the DDCM global optimum). When only a few parameters change between
the projections, ``P = P0 + D c`` with ``D`` (n_params x r) and one ``c`` (r) per projection (the
data assigned to the points), every branch's solution is affine in ``c``, ``z = z0 + Z c``, and its
objective is the quadratic ``a0 + a1 . c + c^T A2 c / 2``: :meth:`ExactEnumerator.affine_family`
solves each branch for ``r + 1`` right-hand sides only, and :meth:`AffineFamily.best` evaluates
signs and objectives for millions of ``c`` with a few vector operations per branch (no solve
per projection).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import casadi as ca
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


def _const(expr, args) -> sp.csc_matrix:
    if ca.depends_on(expr, ca.vertcat(*args)):
        raise InputError("exact enumeration needs a linear model")
    out = ca.Function("c", args, [expr])(*[np.zeros(a.numel()) for a in args])
    colind, row = out.sparsity().get_ccs()
    return sp.csc_matrix((np.asarray(out.nonzeros(), float), row, colind), shape=out.shape)


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


@dataclass
class AffineFamily:
    """The exact projections of ``P0 + D c`` for any ``c`` (see :meth:`ExactEnumerator.affine_family`)."""

    branches: list[_AffineBranch]
    sign_tol: float

    def best(self, c: np.ndarray, *, chunk: int = 1 << 20) -> np.ndarray:
        """The exact projection's objective (scaled) for every column of ``c`` (r, N): the
        smallest over the sign-feasible branches, ``inf`` where none is."""
        c = np.asarray(c, float)
        out = np.full(c.shape[1], np.inf)
        for a in range(0, c.shape[1], chunk):
            cc = c[:, a:a + chunk]
            best = out[a:a + chunk]
            for b in self.branches:
                ok = np.ones(cc.shape[1], dtype=bool)
                for g0, gc in ((b.gap0, b.gap_c), (b.p0, b.p_c)):
                    for i in range(g0.size):
                        ok &= g0[i] + gc[i] @ cc >= -self.sign_tol
                obj = b.a0 + b.a1 @ cc + 0.5 * np.einsum("ik,ik->k", cc, b.A2 @ cc)
                better = ok & (obj < best)
                best[better] = obj[better]
        return out


class ExactEnumerator:
    """Branch enumeration for a linear :class:`ComplementarityProblem` (built once, solves many)."""

    def __init__(self, problem: ComplementarityProblem, *, max_pairs: int = 8, sign_tol: float = 1e-10) -> None:
        if problem.n_pairs > max_pairs:
            raise InputError(f"exact enumeration is limited to {max_pairs} contact pairs, got {problem.n_pairs}")
        self.problem = problem
        self.sign_tol = sign_tol
        z = ca.vertcat(problem.x, problem.p)
        P = problem.params
        self.nx, self.nc, self.nz = problem.n_x, problem.n_pairs, z.numel()
        R, g = problem.residual, problem.gap
        self.Rz = _const(ca.jacobian(R, z), [z, P])
        self.Gz = _const(ca.jacobian(g, z), [z, P])
        zero = ca.DM.zeros(self.nz)
        # Affine parts as functions of the parameters: R(0; P), g(0; P), grad f(0; P), f(0; P).
        obj = problem.objective if problem.objective is not None else ca.SX(0)
        grad = ca.gradient(obj, z)
        self.H = _const(ca.jacobian(grad, z), [z, P]) if problem.kind == "mpcc" else None
        # Affine in the parameters too: R(0; P) = R_P P + R_0, likewise g and grad f; f(0; P) quadratic.
        at0 = lambda e: ca.substitute(e, z, zero)  # noqa: E731
        self._R_P = _const(ca.jacobian(at0(R), P), [z, P])
        self._g_P = _const(ca.jacobian(at0(g), P), [z, P])
        self._q_P = _const(ca.jacobian(at0(grad), P), [z, P])
        f0 = at0(obj)
        self._f_PP = _const(ca.hessian(f0, P)[0], [z, P])
        const = ca.Function("const", [P], [at0(R), at0(g), at0(grad), f0, ca.gradient(f0, P)])
        R0, g0, q0, f00, fP = const(np.zeros(P.numel()))
        self._R_0, self._g_0, self._q_0 = (np.asarray(v, float).reshape(-1, 1) for v in (R0, g0, q0))
        self._f_0, self._f_P = float(f00), np.asarray(fP, float).ravel()
        self._factors: dict[tuple, object] = {}
        self.partitions = list(itertools.product(
            (FREE, CONTACT) if problem.kind == "mcp" else (FREE, CONTACT, GRAZING), repeat=self.nc))

    def _affine_parts(self, params: np.ndarray):
        f0 = self._f_0 + self._f_P @ params + 0.5 * np.einsum("ik,ik->k", params, self._f_PP @ params)
        return (self._R_P @ params + self._R_0, self._g_P @ params + self._g_0,
                self._q_P @ params + self._q_0, f0)

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

    def solve(self, params: np.ndarray) -> ExactSolution:
        """Exact solution for each column of ``params`` (a vector gives one column)."""
        params = np.asarray(params, float)
        if params.ndim == 1:
            params = params[:, None]
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

    def affine_family(self, base: np.ndarray, directions: np.ndarray) -> AffineFamily:
        r"""Every branch of the projections of ``P = base + directions @ c``, affine in ``c``.

        On a branch the KKT system is linear in the parameters: with ``z0`` its solution for
        ``base`` and ``Z`` for the columns of ``directions`` (without the constant parts),
        ``z(c) = z0 + Z c``; the gradient's parameter part is ``q(c) = q0 + Q c`` and
        ``f(0; P)`` is quadratic in ``P``, so the objective
        ``f = z^T H z / 2 + q^T z + f(0; P)`` is

        .. math::  a_0 + a_1^T c + \tfrac12 c^T A_2 c,\quad
                   A_2 = Z^T H Z + Z^T Q + Q^T Z + D^T F_{PP} D .

        Only ``r + 1`` right-hand sides are solved per branch, whatever the number of ``c``.
        """
        if self.problem.kind != "mpcc":
            raise InputError("an affine family of projections needs a projection (mpcc) problem")
        base = np.asarray(base, float).reshape(-1, 1)
        D = np.asarray(directions, float)
        R0, g0, q0, f0 = self._affine_parts(base)
        # The linear parts of R, g, grad f in the directions (no constants).
        RD, gD, qD = self._R_P @ D, self._g_P @ D, self._q_P @ D
        fD = self._f_P @ D + (base[:, 0] @ (self._f_PP @ D))
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
