"""Symbolic complementarity problems built from a :class:`~ddcm_casadi.model.ContactModel`.

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

The models are linear (small strains, linearised gaps), so a problem is held as sparse matrices:
the residual and the gaps are affine in the unknowns ``z = [x; p]`` and the parameters ``P``
(:class:`Affine`), the objective is half a weighted squared distance of an affine map
(:class:`Distance`). Formulations build their Newton systems from these matrices
(:mod:`ddcm_casadi.formulations.pairs`): one symbolic expression per matrix nonzero, and its
symbolic derivative, cost about 20 microseconds per nonzero (seconds at 1e5 unknowns) where a
sparse product costs nanoseconds. The CasADi ``SX`` expressions (:attr:`ComplementarityProblem.residual`,
``gap``, ``objective``, ...) are rendered from the same matrices on first use, for the consumers
that differentiate them symbolically (IPOPT, the exact enumeration).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import casadi as ca
import numpy as np
import scipy.sparse as sp

from .linalg import to_casadi
from .metric import block_diagonal, weighted_distance2
from .model import ContactModel
from .solvers.evaluate import NumericFunction


#: Up to this many unknowns :meth:`ComplementarityProblem.stability` is computed (dense).
STABILITY_MAX_UNKNOWNS = 2000


class Parameters:
    """Named CasADi parameters, packed in order into one vector (no hidden layouts).

    >>> P = Parameters(gap0=1, f=2)
    >>> Q = P.extend(mu=1)                 # a formulation's own parameters after the problem's
    >>> Q.pack(P.pack(gap0=[0.1], f=[0, 1]), mu=0.0)
    array([0.1, 0. , 1. , 0. ])

    The ``SX`` symbols (:attr:`symbols`, :attr:`vector`) are created on first use (a million of
    them take about a second, and the sparse builds never need them); an extension shares the
    symbols of the parameters it extends.

    Parameters
    ----------
    **sizes : int
        Name and length of each parameter, in order.
    """

    def __init__(self, _base: "Parameters | None" = None, **sizes: int) -> None:
        inherited = dict(_base.sizes) if _base is not None else {}
        for name in sizes:
            if name in inherited:
                raise ValueError(f"parameter {name!r} is defined twice")
        self._base = _base
        self.sizes: dict[str, int] = {**inherited, **{name: int(n) for name, n in sizes.items()}}
        self.names = tuple(self.sizes)
        offsets = np.cumsum([0] + list(self.sizes.values()))
        self._slices = {n: slice(int(a), int(b)) for n, a, b in zip(self.names, offsets[:-1], offsets[1:])}
        self.size = int(offsets[-1])

    @cached_property
    def symbols(self) -> dict[str, ca.SX]:
        """The ``SX`` symbol of each parameter (those of the extended parameters shared)."""
        symbols = dict(self._base.symbols) if self._base is not None else {}
        for name in self.names:
            if name not in symbols:
                symbols[name] = ca.SX.sym(name, self.sizes[name])
        return symbols

    @cached_property
    def vector(self) -> ca.SX:
        """All symbols as one vector, in order."""
        return ca.vertcat(*self.symbols.values()) if self.names else ca.SX(0, 1)

    def __getitem__(self, name: str) -> ca.SX:
        return self.symbols[name]

    def slice(self, name: str) -> slice:
        """Where ``name`` sits in a packed vector."""
        return self._slices[name]

    def extend(self, **sizes: int) -> "Parameters":
        """These parameters followed by new ones (the same symbols)."""
        return Parameters(self, **sizes)

    def pack(self, _base: np.ndarray | None = None, **values) -> np.ndarray:
        """One vector (or, with 2-D values, one column per case) from values by name.

        ``_base`` is a packed vector of a prefix of these parameters (those of the problem a
        formulation extended); every other name must be given.
        """
        given = 0 if _base is None else np.asarray(_base, float).shape[0]
        names = [n for n in self.names if self._slices[n].start >= given]
        if _base is not None and given not in {self._slices[n].start for n in self.names} | {self.size}:
            raise ValueError(f"a base vector of {given} values does not end on a parameter")
        missing = [n for n in names if n not in values]
        unknown = sorted(set(values) - set(names))
        if missing or unknown:
            raise ValueError(f"parameters: missing {missing}, unknown {unknown}")
        parts = [] if _base is None else [np.asarray(_base, float)]
        cols = max((np.asarray(v).shape[1] for v in values.values() if np.ndim(v) == 2), default=None)
        for n in names:
            v = np.asarray(values[n], dtype=float)
            size = self._slices[n].stop - self._slices[n].start
            if cols is None:
                v = np.broadcast_to(v.ravel() if v.ndim else v, (size,))
            else:
                v = np.broadcast_to(v.reshape(size, -1) if v.ndim == 2 else v.reshape(size, 1), (size, cols))
            parts.append(v)
        if cols is not None and parts and parts[0].ndim == 1:
            parts[0] = np.repeat(parts[0][:, None], cols, axis=1)
        return np.concatenate(parts) if parts else np.zeros(0)

    def get(self, packed: np.ndarray, name: str) -> np.ndarray:
        """The value of ``name`` in a packed vector."""
        return np.asarray(packed)[self._slices[name]]

    def prefix(self, packed: np.ndarray, upto: "Parameters") -> np.ndarray:
        """The part of a packed vector that holds the parameters of ``upto`` (a prefix)."""
        return np.asarray(packed)[:upto.size]


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
        What the pairs mean (:mod:`ddcm_casadi.contact_laws`; ``"signorini"``: one normal pair per
        contact).
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
    def _stacked(self) -> tuple[sp.csr_matrix, sp.csr_matrix, tuple[int, int]]:
        """``[residual; gap; d]`` and ``|residual|`` as matrices of ``[z; P]`` (three sparse products
        per evaluation: scipy's overhead per product, not the arithmetic, is what small problems pay)."""
        maps = [self.residual_map, self.gap_map] + ([self.distance.d] if self.distance is not None else [])
        stacked = sp.vstack([sp.hstack([a.z, a.params]) for a in maps]).tocsr()
        R = self.residual_map
        return stacked, abs(sp.hstack([R.z, R.params]).tocsr()), (R.rows, R.rows + self.gap_map.rows)

    def evaluate(self, x, p, params) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """``(residual, residual_terms, gap, objective)`` at scaled ``(x, p)`` and the parameter
        values (objective 0 for ``mcp``): sparse products with the problem's matrices (those of
        :attr:`residual`, :attr:`residual_terms`, :attr:`gap`, :attr:`objective`), nothing to build."""
        if not self.affine:
            z, P = np.concatenate([np.ravel(x), np.ravel(p)]), np.ravel(params)
            values = self._nonlinear_values(z, P)
            return values[0], values[1], values[2], float(values[3][0]) if self.distance is not None else 0.0
        w = np.concatenate([np.ravel(x), np.ravel(p), np.ravel(params)]).astype(float, copy=False)
        stacked, size, (ne, ng) = self._stacked
        v = stacked @ w
        objective = 0.0 if self.distance is None else 0.5 * float(v[ng:] @ (self.distance.weight @ v[ng:]))
        return v[:ne], size @ np.abs(w), v[ne:ng], objective

    @cached_property
    def _nonlinear_values(self):
        """``(z, P) -> (residual, residual terms, gap, objective)`` in one Function (nonlinear form)."""
        z, P = ca.SX.sym("z", self.n_x + self.n_pairs), ca.SX.sym("P", self.parameters.size)
        objective = ca.SX(1, 1) if self.distance is None else self.distance.render(z, P)
        return NumericFunction(ca.Function("evaluate", [z, P], [
            self.residual_map.render(z, P), self.residual_map.terms(z, P), self.gap_map.render(z, P), objective]))

    @cached_property
    def _tangent(self):
        """``(z, P) -> (dF/dx, gap)``: the tangent stiffness of a classical problem (scaled)."""
        z, P = ca.SX.sym("z", self.n_x + self.n_pairs), ca.SX.sym("P", self.parameters.size)
        F = self.residual_map.render(z, P)
        return NumericFunction(ca.Function("tangent", [z, P], [ca.densify(ca.jacobian(F, z[:self.n_x])),
                                                                  ca.densify(ca.jacobian(self.gap_map.render(z, P), z[:self.n_x]))]))

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
        K, dg = (np.asarray(a, float) for a in self._tangent(z, np.ravel(params)))
        K, dg = K.reshape(self.n_x, self.n_x, order="F"), dg.reshape(self.n_pairs, self.n_x, order="F")
        gap = self.gap_map.value(z, np.ravel(params))
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
        scale = max(float(np.max(np.abs(K))), np.finfo(float).tiny)
        return float(np.linalg.eigvalsh(H)[0]) / scale

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


@dataclass(frozen=True, eq=False)
class ProblemPair:
    """Both problems of one model, with the maps between scaled unknowns and physical fields."""

    model: ContactModel
    classical: ComplementarityProblem | None
    projection: ComplementarityProblem | None

    def _problem(self, kind: str) -> ComplementarityProblem:
        return self.classical if kind == "mcp" else self.projection

    def step_params(self, step: int, previous: dict | None = None) -> np.ndarray:
        """Parameters of the classical problem at a load step (``previous``: the last converged
        step's physical fields, for models whose steps have a history,
        :meth:`~ddcm_casadi.model.ContactModel.step_values`)."""
        return self.classical.parameters.pack(**self.model.step_values(step, previous))

    def projection_params(self, step: int, strain_star: np.ndarray, stress_star: np.ndarray,
                          previous: dict | None = None) -> np.ndarray:
        """Parameters of the ``Z_E`` projection: the load step and the assigned data, per point
        (``(m,)`` or ``(m, k)``, flattened point-major). For one-component points, ``(m, N)``
        arrays give an ``(n_params, N)`` matrix, one column per data assignment."""
        strain_star, stress_star = np.asarray(strain_star, float), np.asarray(stress_star, float)
        if strain_star.ndim < 2 or self.model.strain_components > 1:
            strain_star, stress_star = strain_star.reshape(-1), stress_star.reshape(-1)
        return self.projection.parameters.pack(**self.model.step_values(step, previous),
                                               strain_star=strain_star, stress_star=stress_star)

    def scales(self, kind: str) -> dict:
        """The reference scales of the ``"mcp"`` (classical) or ``"mpcc"`` (projection) problem."""
        return self.model.scales_for("classical" if kind == "mcp" else "ddcm")

    def fields(self, kind: str, x: np.ndarray, p: np.ndarray) -> dict[str, np.ndarray]:
        """Physical displacement, contact pressure, strain and stress from scaled unknowns
        (strain and stress flat and point-major: ``m k`` values)."""
        s = self.scales(kind)
        n = self.model.n_dofs
        u = s["displacement"] * np.asarray(x[:n])
        pressure = s["stress"] * np.asarray(p)
        strain = self.model.strain(u)
        if kind == "mpcc":
            stress = s["stress"] * np.asarray(x[n:])
        else:
            stress = self.model.stress(strain)
        return dict(u=u, p=pressure, strain=strain, stress=stress)

    def scaled_start(self, kind: str, u: np.ndarray, p: np.ndarray, stress: np.ndarray | None = None):
        """Scaled unknowns ``(x, p)`` from physical fields (for warm starts)."""
        s = self.scales(kind)
        x = [np.asarray(u) / s["displacement"]]
        if kind == "mpcc":
            x.append(np.asarray(stress).reshape(-1) / s["stress"])
        return np.concatenate(x), np.asarray(p) / s["stress"]


def _common(model: ContactModel, s: dict, fb_beta: float, n_z: int, P: Parameters) -> dict:
    """The gaps ``(G u + gap0) / s_d`` with ``u = s_d u_hat`` (``gap0`` the first parameter) and the scales."""
    nc = model.n_contacts
    gap = Affine(sp.hstack([model.gap_operator, sp.csr_matrix((nc, n_z - model.n_dofs))]),
                 sp.hstack([sp.identity(nc) / s["displacement"], sp.csr_matrix((nc, P.size - nc))]))
    return dict(parameters=P, gap_map=gap, gap_ref=s["displacement"], pressure_ref=s["stress"],
                contact_stiffness=model.contact_stiffness, fb_alpha=1.0 / (0.01 * model.length_scale),
                fb_beta=fb_beta, contact_law=model.contact_law, kinematics=model.kinematics)


def _selection(rows: int, start: int, columns: int, scale: float = 1.0) -> sp.csr_matrix:
    """``scale`` times the identity placed at column ``start`` of a ``rows x columns`` matrix."""
    return sp.hstack([sp.csr_matrix((rows, start)), scale * sp.identity(rows),
                      sp.csr_matrix((rows, columns - start - rows))]).tocsr()


def distance_weight(model: ContactModel) -> sp.csr_matrix:
    """``W`` with ``sum_i w_i d_i^2 = d^T W d`` for ``d`` point-major ``[e_i - e*_i; s_i - s*_i]``.

    Per point, its volume times half the Hessian of :func:`~ddcm_casadi.metric.weighted_distance2`
    (the one place the metric's formula is written) for one point of unit weight of its material.
    """
    m, k = model.n_points, model.strain_components
    metrics, material = model.dataset.point_materials(m)
    nm, half = len(metrics), len(metrics) * k
    e, s = ca.SX.sym("e", half), ca.SX.sym("s", half)
    d2 = weighted_distance2(e, s, metrics, np.arange(nm), np.ones(nm))
    H = ca.evalf(ca.hessian(d2, ca.vertcat(e, s))[0])
    colind, row = H.sparsity().get_ccs()
    row = np.asarray(row)
    col = np.repeat(np.arange(2 * half), np.diff(colind))
    # (material, position in its [e; s] block) of every Hessian row and column
    (mr, br), (mc, bc) = (((i % half) // k, (i >= half) * k + i % k) for i in (row, col))
    if np.any(mr != mc):
        raise ValueError("the distance couples two material points")
    blocks = np.zeros((nm, 2 * k, 2 * k))
    np.add.at(blocks, (mr, br, bc), 0.5 * np.asarray(H.nonzeros()))
    return block_diagonal(blocks[material] * np.asarray(model.volumes, float)[:, None, None])


def _internal_force(model: ContactModel, s: dict, uh: ca.SX, stress: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """``(E(u), B(u)^T W stress, |B(u)|^T W |stress|)`` with ``u = s_d uh`` and ``B(u) = dE/du``
    by automatic differentiation: the internal forces of a nonlinear strain measure, whose
    virtual work is ``sum_i w_i stress_i . dE_i``."""
    E = model.strain_expression(s["displacement"] * uh)
    B = ca.jacobian(E, uh) / s["displacement"]
    w = ca.DM(np.repeat(np.asarray(model.volumes, float), model.strain_components))
    return E, ca.mtimes(B.T, w * stress), ca.mtimes(ca.fabs(B).T, w * ca.fabs(stress))


def _build_nonlinear(model: ContactModel) -> ProblemPair:
    """Both problems of a model with nonlinear kinematics, as CasADi expressions
    (:class:`NonlinearMap`, :class:`NonlinearObjective`).

    Classical: ``F = (B(u)^T W D E(u) - G^T a p - f) / s_f``. Projection: ``h = (B(u)^T W stress -
    G^T a p - f) / s_f`` and ``f = d^T W d / (2 energy)`` with ``d = [E(u) - E*; stress - S*]`` point
    by point. The gaps stay affine: a plane obstacle's gap ``n . (X + u) - d`` is exact at any
    displacement.
    """
    n, m, nc, k = model.n_dofs, model.n_points, model.n_contacts, model.strain_components
    GtA = to_casadi((model.gap_operator.T @ sp.diags(model.contact_area)).tocsr())
    absGtA = ca.fabs(GtA)
    classical = projection = None
    if model.youngs_modulus is not None:
        s = model.scales_for("classical")
        P = Parameters(gap0=nc, f=n, **model.history_sizes())
        z, Ps = ca.SX.sym("z", n + nc), ca.SX.sym("P", P.size)
        uh, ph, f = z[:n], z[n:], Ps[P.slice("f")]
        E = model.strain_expression(s["displacement"] * uh)
        _, internal, size = _internal_force(model, s, uh, to_casadi(model.material_matrix()) @ E)
        F = (internal - s["stress"] * ca.mtimes(GtA, ph) - f) / s["force"]
        terms = (size + s["stress"] * ca.mtimes(absGtA, ca.fabs(ph)) + ca.fabs(f)) / s["force"]
        classical = ComplementarityProblem(kind="mcp", unknowns=(("u", n),),
                                           residual_map=NonlinearMap.of(F, z, Ps, terms, "residual"), distance=None,
                                           **_common(model, s, 1.0 / s["modulus"], n + nc, P))
    if model.dataset is not None:
        s = model.scales_for("ddcm")
        mk = m * k
        P = Parameters(gap0=nc, f=n, strain_star=mk, stress_star=mk, **model.history_sizes())
        z, Ps = ca.SX.sym("z", n + mk + nc), ca.SX.sym("P", P.size)
        uh, stress, ph, f = z[:n], s["stress"] * z[n:n + mk], z[n + mk:], Ps[P.slice("f")]
        E, internal, size = _internal_force(model, s, uh, stress)
        h = (internal - s["stress"] * ca.mtimes(GtA, ph) - f) / s["force"]
        terms = (size + s["stress"] * ca.mtimes(absGtA, ca.fabs(ph)) + ca.fabs(f)) / s["force"]
        stacked = ca.vertcat(E - Ps[P.slice("strain_star")], stress - Ps[P.slice("stress_star")])
        point, c = np.divmod(np.arange(2 * mk), 2 * k)
        d = stacked[np.where(c < k, point * k + c, mk + point * k + c - k).tolist()]
        W = to_casadi(distance_weight(model) / s["energy"])
        objective = NonlinearObjective(ca.Function("distance", [z, Ps], [0.5 * ca.dot(d, ca.mtimes(W, d))]))
        projection = ComplementarityProblem(
            kind="mpcc", unknowns=(("u", n), ("stress", mk)), residual_map=NonlinearMap.of(h, z, Ps, terms, "h"),
            distance=objective, **_common(model, s, 1.0 / s["metric"], n + mk + nc, P))
    return ProblemPair(model=model, classical=classical, projection=projection)


def build_problems(model: ContactModel) -> ProblemPair:
    """Build the classical MCP and the DDCM projection MPCC of ``model`` once: as sparse matrices
    for small kinematics, as CasADi expressions for finite ones (:func:`_build_nonlinear`)."""
    if model.kinematics != "small":
        return _build_nonlinear(model)
    n, m, nc, k = model.n_dofs, model.n_points, model.n_contacts, model.strain_components
    GtA = (model.gap_operator.T @ sp.diags(model.contact_area)).tocsr()  # contact forces G^T (a p)

    classical = None
    if model.youngs_modulus is not None:
        s = model.scales_for("classical")
        P = Parameters(gap0=nc, f=n, **model.history_sizes())
        # F = (K u - G^T a p - f) / s_f with u = s_d u_hat, p = s_s p_hat
        # (scaled in the order the arithmetic of F does it: each term times its scale, over s_f)
        F = Affine(sp.hstack([model.stiffness() * s["displacement"] / s["force"], GtA * -s["stress"] / s["force"]]),
                   _selection(n, nc, P.size, -1.0 / s["force"]))
        classical = ComplementarityProblem(kind="mcp", unknowns=(("u", n),), residual_map=F, distance=None,
                                           **_common(model, s, 1.0 / s["modulus"], n + nc, P))

    projection = None
    if model.dataset is not None:
        s = model.scales_for("ddcm")
        P = Parameters(gap0=nc, f=n, strain_star=m * k, stress_star=m * k, **model.history_sizes())
        nz, mk = n + m * k + nc, m * k
        BtW = model.strain_operator.T @ sp.diags(np.repeat(model.volumes, k))
        # h = (B^T W stress - G^T a p - f) / s_f with stress = s_s stress_hat
        h = Affine(sp.hstack([sp.csr_matrix((n, n)), BtW * s["stress"] / s["force"], GtA * -s["stress"] / s["force"]]),
                   _selection(n, nc, P.size, -1.0 / s["force"]))
        # d = [B u - strain_star; stress - stress_star] point-major, f = d^T W d / (2 energy)
        stacked = Affine(sp.vstack([sp.hstack([model.strain_operator * s["displacement"], sp.csr_matrix((mk, mk + nc))]),
                                    _selection(mk, n, nz, s["stress"])]),
                         sp.vstack([_selection(mk, nc + n, P.size, -1.0), _selection(mk, nc + n + mk, P.size, -1.0)]))
        point, c = np.divmod(np.arange(2 * mk), 2 * k)
        order = np.where(c < k, point * k + c, mk + point * k + c - k)
        d = Affine(stacked.z[order], stacked.params[order])
        projection = ComplementarityProblem(
            kind="mpcc", unknowns=(("u", n), ("stress", mk)), residual_map=h,
            distance=Distance(d, distance_weight(model) / s["energy"]),
            **_common(model, s, 1.0 / s["metric"], nz, P))
    return ProblemPair(model=model, classical=classical, projection=projection)
