"""Symbolic complementarity problems built from a :class:`~ddcm_casadi.models.base.ContactModel`.

Two kinds arise from one model (``docs/maths.md`` states the maths):

``mcp`` (classical)
    Find ``x, p`` with ``F(x, p) = 0`` and ``g(x) >= 0, p >= 0, g p = 0``.
``mpcc`` (DDCM projection onto ``Z_E``)
    ``min_x f(x)`` subject to ``h(x, p) = 0`` and ``g(x) >= 0, p >= 0, g p = 0``.

Everything is nondimensional: unknowns, residual rows, gaps, pressures and the objective are divided
by reference scales derived from each problem (:meth:`ContactModel.scales_for`: a linear solve
with ``E`` for the classical problem, with the data's modulus for the projection, never with the
metric), so formulations and solvers see O(1) numbers for any units. A formulation only sees a
:class:`ComplementarityProblem`; it never needs the mechanical model. Its parameters are named
(:class:`Parameters`): a formulation extends them with its own (smoothing, multipliers, ...) and
packs values by name, never by position.

Two forms, one contract. Small kinematics (the fast path): the residual and the gaps are affine
in the unknowns ``z = [x; p]`` and the parameters ``P`` (:class:`~ddcm_casadi.problems.maps.Affine`),
the objective is half a weighted squared distance of an affine map
(:class:`~ddcm_casadi.problems.maps.Distance`), all held as sparse matrices. Formulations build
their Newton systems from these matrices (:mod:`ddcm_casadi.formulations.pairs`): one symbolic
expression per matrix nonzero, and its symbolic derivative, cost about 20 microseconds per nonzero
(seconds at 1e5 unknowns) where a sparse product costs nanoseconds. Finite kinematics: the
residual, gaps and objective are CasADi Functions
(:class:`~ddcm_casadi.problems.maps.NonlinearMap`,
:class:`~ddcm_casadi.problems.maps.NonlinearObjective`) whose sparse Jacobians and Hessians come
by automatic differentiation (:mod:`ddcm_casadi.formulations.systems`); :attr:`affine` tells the
two apart. The CasADi ``SX`` expressions (:attr:`ComplementarityProblem.residual`, ``gap``,
``objective``, ...) are rendered from either form on first use, for the consumers that
differentiate them symbolically (IPOPT, the exact enumeration of affine problems). A problem also
records its contact law (:mod:`ddcm_casadi.models.contact_laws`) and kinematics, which the
formulations check before any work.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ddcm_casadi.evaluate import NumericFunction
from ddcm_casadi.models.coulomb import blocks, flat, natural_map
from ddcm_casadi.problems.maps import Affine, Distance
from ddcm_casadi.problems.parameters import Parameters

#: Nonzeros of a problem's maps up to which :meth:`ComplementarityProblem.evaluate` multiplies one
#: stacked copy of them (``_stacked``), above which map by map.
STACKED_MAX_NONZEROS = 1_000_000
#: Up to this many unknowns :meth:`ComplementarityProblem.stability` is computed.
STABILITY_MAX_UNKNOWNS = 2000
#: Up to this many, densely (an eigendecomposition on the touching pairs' null space); above,
#: sparse (shift-invert Lanczos on ``K + rho G^T G``): a dense decomposition of a continuum's
#: stiffness per step would cost more than its solve.
DENSE_STABILITY = 300


def _csc(sparsity: ca.Sparsity, values: np.ndarray) -> sp.csc_matrix:
    colind, row = sparsity.get_ccs()
    return sp.csc_matrix((np.asarray(values, float), row, colind), shape=(sparsity.size1(), sparsity.size2()))


def _sparse_smallest_eigenvalue(K: sp.csc_matrix, touching: sp.spmatrix, scale: float) -> float:
    """The smallest eigenvalue, relative to ``scale``, of ``sym(K)`` on the null space of the
    ``touching`` rows, from ``sym(K) + rho G^T G`` (Finsler: the held directions pushed up by
    ``rho = 1e6 scale / max |G|^2``), its eigenvalues nearest zero by shift-invert Lanczos; ``nan``
    where Lanczos does not converge. An unstable equilibrium is a limit or bifurcation point
    crossed: its negative eigenvalue is the one nearest zero."""
    from scipy.sparse.linalg import ArpackError, ArpackNoConvergence, eigsh

    H = 0.5 * (K + K.T)
    G = sp.csr_matrix(touching)
    if G.nnz:
        H = H + (1e6 * scale / float(abs(G).max()) ** 2) * (G.T @ G)
    try:
        values = eigsh(H.tocsc(), k=min(3, H.shape[0] - 1), sigma=-1e-9 * scale, which="LM",
                       return_eigenvectors=False)
    except (ArpackNoConvergence, ArpackError, RuntimeError):
        return float("nan")
    return float(np.min(values)) / scale

@dataclass(frozen=True, eq=False)
class ComplementarityProblem:
    """A nondimensional complementarity problem, the contract between models and formulations.

    Attributes
    ----------
    kind : {"mcp", "mpcc"}
    parameters : Parameters
        Named parameters (load step; assigned data), in physical units.
    unknowns : tuple of (str, int)
        Names and sizes of the blocks of the smooth unknowns ``x`` (``u``; then ``stress``).
    residual_map : Affine
        ``mcp``: ``F(x, p)``, as many rows as ``x``. ``mpcc``: equality constraints ``h(x, p)``.
    gap_map : Affine
        Scaled gaps ``g(x)``.
    distance : Distance or None
        ``mpcc`` only: the scaled squared distance ``f`` (the objective).
    gap_ref, pressure_ref : float
        Physical size of one unit of scaled gap (m) and of scaled pressure (Pa).
    contact_stiffness : float
        Reference stiffness (Pa/m) in which penalty parameters are given.
    fb_alpha, fb_beta : float
        Default Fischer-Burmeister scalings (1/m and 1/Pa), as in the paper (``beta = 1/c`` for the
        projection, ``1/E`` for the classical problem).
    contact_law : str
        What the pairs mean (:mod:`ddcm_casadi.models.contact_laws`; ``"signorini"``: one normal pair per
        contact).
    block : int
        Components per contact (1 for Signorini; ``1 + (d - 1)`` for Coulomb friction in ``d``
        dimensions). The ``n_pairs = block n_contacts`` "gaps" and "pressures" are component-major:
        entry ``j n_contacts + c`` is component ``j`` of contact ``c``, the normal ones first
        (:mod:`ddcm_casadi.models.coulomb`). A frictional problem has the parameters
        ``friction`` (``mu`` per contact) and ``traction0`` (the last converged step's scaled
        tangential tractions, ``n_pairs - n_contacts``).
    kinematics : {"small", "finite"}
        The model's kinematics (finite: the nonlinear form, :attr:`affine` False).

    The symbolic (``SX``) quantities :attr:`x`, :attr:`p`, :attr:`params`, :attr:`residual`,
    :attr:`residual_terms` (per row of the residual, the size of the terms that cancel in it,
    ``|K| |u| + |G^T a| |p| + |f|`` and the like: residual tests are relative to it,
    :meth:`relative_residual`), :attr:`gap` and :attr:`objective` are rendered from the matrices
    on first use.
    """

    kind: Literal["mcp", "mpcc"]
    parameters: Parameters
    unknowns: tuple
    residual_map: Affine
    gap_map: Affine
    distance: Distance | None
    gap_ref: float
    pressure_ref: float
    contact_stiffness: float
    fb_alpha: float
    fb_beta: float
    contact_law: str = "signorini"
    kinematics: str = "small"
    block: int = 1

    @property
    def affine(self) -> bool:
        """Whether the residual and gaps are affine and the objective quadratic (held as sparse
        matrices). Methods that need it (the exact enumeration, the greedy screen, the elastic
        start) are skipped with a note otherwise."""
        return isinstance(self.residual_map, Affine) and isinstance(self.gap_map, Affine) and (
            self.distance is None or isinstance(self.distance, Distance))

    @property
    def n_x(self) -> int:
        return sum(n for _, n in self.unknowns)

    @property
    def n_pairs(self) -> int:
        return self.gap_map.rows

    @property
    def n_contacts(self) -> int:
        """Contacts: pairs over the components per contact (:attr:`block`)."""
        return self.gap_map.rows // self.block

    @property
    def frictional(self) -> bool:
        """Whether each contact carries tangential components (Coulomb friction)."""
        return self.block > 1

    def normal(self, v: np.ndarray) -> np.ndarray:
        """The normal components of a vector over the pairs (the first :attr:`n_contacts`)."""
        return np.asarray(v, float).reshape(-1)[:self.n_contacts]

    def contact_blocks(self, v: np.ndarray) -> np.ndarray:
        """``(nc, block)``: a vector over the pairs (component-major), one row per contact."""
        return blocks(v, self.block)

    @staticmethod
    def component_major(blocked: np.ndarray) -> np.ndarray:
        """The vector over the pairs of ``(nc, block)`` rows (inverse of :meth:`contact_blocks`)."""
        return flat(blocked)

    def coulomb_residual(self, gap: np.ndarray, p: np.ndarray, params: np.ndarray) -> np.ndarray:
        """``(nc, block)``: the natural-map residual of Coulomb's law per contact
        (:func:`~ddcm_casadi.models.coulomb.natural_map`), in scaled units."""
        mu = self.parameters.get(np.asarray(params, float).reshape(-1), "friction")
        return natural_map(self.contact_blocks(gap), self.contact_blocks(p), mu)

    @property
    def n_residual(self) -> int:
        """Rows of the residual (``F`` or ``h``)."""
        return self.residual_map.rows

    @cached_property
    def pressure_map(self) -> Affine:
        """The scaled pressures ``p`` as an :class:`Affine`."""
        nx, nc = self.n_x, self.n_pairs
        return Affine(sp.hstack([sp.csr_matrix((nc, nx)), sp.identity(nc)]), sp.csr_matrix((nc, self.parameters.size)))

    # ------------------------------------------------------------------ symbolic (SX), on first use
    @cached_property
    def x(self) -> ca.SX:
        """Smooth unknowns (scaled)."""
        return ca.vertcat(*[ca.SX.sym(name, n) for name, n in self.unknowns])

    @cached_property
    def p(self) -> ca.SX:
        """One multiplier per pair: the scaled contact pressures."""
        return ca.SX.sym("p", self.n_pairs)

    @property
    def params(self) -> ca.SX:
        """All parameters as one symbolic vector (in the order of :attr:`parameters`)."""
        return self.parameters.vector

    @cached_property
    def residual(self) -> ca.SX:
        return self.residual_map.render(ca.vertcat(self.x, self.p), self.params)

    @cached_property
    def residual_terms(self) -> ca.SX:
        return self.residual_map.terms(ca.vertcat(self.x, self.p), self.params)

    @cached_property
    def gap(self) -> ca.SX:
        return self.gap_map.render(ca.vertcat(self.x, self.p), self.params)

    @cached_property
    def objective(self) -> ca.SX | None:
        return None if self.distance is None else self.distance.render(ca.vertcat(self.x, self.p), self.params)

    # ------------------------------------------------------------------ numeric, shared by formulations
    @cached_property
    def _shared(self) -> dict:
        return {}

    def shared(self, key, build):
        """``build()``, once per problem and ``key``: what several formulations of one problem
        build alike (a saddle point's matrices) is built once."""
        if key not in self._shared:
            self._shared[key] = build()
        return self._shared[key]

    @cached_property
    def _stacked(self) -> tuple[sp.csr_matrix, sp.csr_matrix, tuple[int, int]] | None:
        """``[residual; gap; d]`` and ``|residual|`` as matrices of ``[z; P]`` (three sparse products
        per evaluation: scipy's overhead per product, not the arithmetic, is what small problems pay),
        or ``None`` above :data:`STACKED_MAX_NONZEROS` (a copy of every map: 42 MB at 1e5 points,
        where the overhead is nothing)."""
        maps = [self.residual_map, self.gap_map] + ([self.distance.d] if self.distance is not None else [])
        if sum(a.z.nnz + a.params.nnz for a in maps) > STACKED_MAX_NONZEROS:
            return None
        stacked = sp.vstack([sp.hstack([a.z, a.params]) for a in maps]).tocsr()
        R = self.residual_map
        return stacked, abs(sp.hstack([R.z, R.params]).tocsr()), (R.rows, R.rows + self.gap_map.rows)

    @cached_property
    def _residual_size(self) -> Affine:
        """``|residual|``: the residual's map with the absolute values of its entries (sharing
        its index arrays), for :meth:`evaluate` without :attr:`_stacked`."""
        R = self.residual_map
        return Affine(*(sp.csr_matrix((np.abs(A.data), A.indices, A.indptr), shape=A.shape) for A in (R.z, R.params)))

    def _objective(self, d: np.ndarray) -> float:
        """``d^T W d / 2`` at the distance's values ``d`` (0 for ``mcp``)."""
        return 0.0 if self.distance is None else 0.5 * float(d @ (self.distance.weight @ d))

    def evaluate(self, x, p, params) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """``(residual, residual_terms, gap, objective)`` at scaled ``(x, p)`` and the parameter
        values (objective 0 for ``mcp``): sparse products with the problem's matrices (those of
        :attr:`residual`, :attr:`residual_terms`, :attr:`gap`, :attr:`objective`), nothing to build."""
        if not self.affine:
            z, P = np.concatenate([np.ravel(x), np.ravel(p)]), np.ravel(params)
            values = self._nonlinear_values(z, P)
            return values[0], values[1], values[2], float(values[3][0]) if self.distance is not None else 0.0
        if self._stacked is None:  # map by map, without a copy of the parameters
            z = np.concatenate([np.ravel(x), np.ravel(p)]).astype(float, copy=False)
            P = np.ravel(params).astype(float, copy=False)
            objective = self._objective(self.distance.d.value(z, P)) if self.distance is not None else 0.0
            return (self.residual_map.value(z, P), self._residual_size.value(np.abs(z), np.abs(P)),
                    self.gap_map.value(z, P), objective)
        w = np.concatenate([np.ravel(x), np.ravel(p), np.ravel(params)]).astype(float, copy=False)
        stacked, size, (ne, ng) = self._stacked
        v = stacked @ w
        return v[:ne], size @ np.abs(w), v[ne:ng], self._objective(v[ng:])

    @cached_property
    def _nonlinear_values(self):
        """``(z, P) -> (residual, residual terms, gap, objective)`` in one Function (nonlinear form)."""
        # MX: local terms stay one mapped call each (SX would inline every element)
        z, P = ca.MX.sym("z", self.n_x + self.n_pairs), ca.MX.sym("P", self.parameters.size)
        objective = ca.MX(1, 1) if self.distance is None else self.distance.render(z, P)
        return NumericFunction(ca.Function("evaluate", [z, P], [
            self.residual_map.render(z, P), self.residual_map.terms(z, P), self.gap_map.render(z, P), objective]))

    @cached_property
    def _tangent(self):
        """``(z, P) -> (dF/dx, gap)``: the tangent stiffness of a classical problem (scaled)."""
        z, P = ca.MX.sym("z", self.n_x + self.n_pairs), ca.MX.sym("P", self.parameters.size)
        K = self.residual_map.jacobian(z, P, self.n_x)
        zs, Ps = ca.SX.sym("z", self.n_x + self.n_pairs), ca.SX.sym("P", self.parameters.size)
        dg = ca.Function("gap_jacobian", [zs, Ps], [ca.jacobian(self.gap_map.render(zs, Ps), zs[:self.n_x])])
        return NumericFunction(ca.Function("tangent", [z, P], [K, dg(z, P)]))

    def stability(self, x, p, params, *, contact_tol: float = 1e-9) -> float:
        """The smallest eigenvalue of the classical tangent stiffness ``dF/dx`` on the directions
        that keep every touching pair closed (``g <= contact_tol``), relative to the largest
        ``|dF/dx|``: negative at an unstable equilibrium (a snap-through truss's horizontal
        members). Dense, for the few unknowns of a nonlinear structure; ``nan`` above
        :data:`STABILITY_MAX_UNKNOWNS` unknowns or for an affine problem (unique, stable solutions
        of a positive definite stiffness)."""
        if self.kind != "mcp" or self.affine or self.n_x > STABILITY_MAX_UNKNOWNS:
            return float("nan")
        z = np.concatenate([np.ravel(x), np.ravel(p)])
        function = self._tangent
        K, dg = (_csc(function.sparsity_out(i), a) for i, a in enumerate(function(z, np.ravel(params))))
        gap = self.gap_map.value(z, np.ravel(params))
        scale = max(float(abs(K).max()) if K.nnz else 0.0, np.finfo(float).tiny)
        if self.n_x > DENSE_STABILITY:
            return _sparse_smallest_eigenvalue(K, dg[np.flatnonzero(gap <= contact_tol)], scale)
        K, dg = K.toarray(), dg.toarray()
        touching = dg[gap <= contact_tol]
        if touching.size:
            _, sv, vt = np.linalg.svd(touching)
            rank = int(np.sum(sv > 1e-12 * max(sv.max(), 1.0)))
            basis = vt[rank:].T
        else:
            basis = np.eye(self.n_x)
        if not basis.size:
            return 1.0  # every direction is held by a contact
        H = basis.T @ (0.5 * (K + K.T)) @ basis
        return float(np.linalg.eigvalsh(H)[0]) / scale

    @cached_property
    def _gap_jacobian(self):
        """``(z, P) -> dg/du`` (sparse, the displacement block ``u`` of ``x``)."""
        z, P = ca.SX.sym("z", self.n_x + self.n_pairs), ca.SX.sym("P", self.parameters.size)
        n_u = self.unknowns[0][1]
        J = ca.jacobian(self.gap_map.render(z, P), z[:n_u])
        colind, row = J.sparsity().get_ccs()
        return NumericFunction(ca.Function("gap_jacobian", [z, P], [J])), (np.asarray(row), np.asarray(colind), J.shape)

    def penetrates(self, x, params, *, tol: float = 1e-9) -> bool:
        """Whether the displacements of ``x`` (scaled) pass an obstacle by more than ``tol``
        (scaled gap units) at the parameters ``params``."""
        z = np.concatenate([np.asarray(x, float), np.zeros(self.n_pairs)])
        return bool(np.any(self.gap_map.value(z, np.asarray(params, float)) < -tol))

    def restoration_start(self, x, params) -> tuple[np.ndarray, np.ndarray]:
        """A start ``(x, p)`` (scaled) for when a warm start fails on a nonlinear problem: the
        displacements moved by the least-norm Gauss-Newton step that closes every violated gap
        (``u - G_v^T (G_v G_v^T)^-1 g_v``, ``G_v`` the rows of ``dg/du`` where ``g < 0``), every
        other block of ``x`` (the stresses of a projection) and the pressures zero: the unloaded
        state resting on the obstacles it had passed. A snap-through makes the previous state a
        poor start: the new solution lies on the other side of an unstable equilibrium."""
        x = np.asarray(x, float)
        n_u = self.unknowns[0][1]
        z = np.concatenate([x, np.zeros(self.n_pairs)])
        P = np.asarray(params, float)
        gap = self.gap_map.value(z, P)
        u = x[:n_u].copy()
        violated = np.flatnonzero(gap < 0)
        if violated.size:
            function, (row, colind, shape) = self._gap_jacobian
            G = sp.csc_matrix((np.asarray(function(z, P), float), row, colind), shape=shape).tocsr()[violated]
            GGt = (G @ G.T).toarray()
            u -= G.T @ np.linalg.lstsq(GGt, gap[violated], rcond=None)[0]
        return np.concatenate([u, np.zeros(x.size - n_u)]), np.zeros(self.n_pairs)

    def scaled_penalty(self, gamma: float) -> float:
        """A physical contact stiffness (Pa/m) in the problem's scaled units."""
        return gamma * self.gap_ref / self.pressure_ref

    def relative_residual(self, residual: np.ndarray, terms: np.ndarray) -> float:
        """``max_i |r_i| / max(1, max_j t_j)``: relative to the terms that cancel when they are
        larger than the scale unit (a stiff, heavily loaded structure), scaled-absolute else."""
        r = np.abs(np.asarray(residual, float))
        if not r.size:
            return 0.0
        return float(np.max(r)) / max(1.0, float(np.max(np.abs(terms), initial=0.0)))
