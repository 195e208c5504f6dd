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
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Mapping

import casadi as ca
import numpy as np
import scipy.sparse as sp

from .linalg import to_casadi
from .metric import weighted_distance2
from .model import ContactModel


class Parameters:
    """Named CasADi parameters, packed in order into one vector (no hidden layouts).

    >>> P = Parameters(gap0=1, f=2)
    >>> Q = P.extend(mu=1)                 # a formulation's own parameters after the problem's
    >>> Q.pack(P.pack(gap0=[0.1], f=[0, 1]), mu=0.0)
    array([0.1, 0. , 1. , 0. ])

    Parameters
    ----------
    **sizes : int
        Name and length of each parameter, in order.
    """

    def __init__(self, _symbols: Mapping[str, ca.SX] | None = None, **sizes: int) -> None:
        symbols = dict(_symbols or {})
        for name, n in sizes.items():
            if name in symbols:
                raise ValueError(f"parameter {name!r} is defined twice")
            symbols[name] = ca.SX.sym(name, int(n))
        self.symbols = symbols
        self.names = tuple(symbols)
        offsets = np.cumsum([0] + [s.numel() for s in symbols.values()])
        self._slices = {n: slice(int(a), int(b)) for n, a, b in zip(self.names, offsets[:-1], offsets[1:])}
        self.size = int(offsets[-1])
        self.vector = ca.vertcat(*symbols.values()) if symbols else ca.SX(0, 1)

    def __getitem__(self, name: str) -> ca.SX:
        return self.symbols[name]

    def extend(self, **sizes: int) -> "Parameters":
        """These parameters followed by new ones (the same symbols)."""
        return Parameters(self.symbols, **sizes)

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


@dataclass(frozen=True, eq=False)
class ComplementarityProblem:
    """A nondimensional complementarity problem, the contract between models and formulations.

    Attributes
    ----------
    kind : {"mcp", "mpcc"}
    x : casadi.SX
        Smooth unknowns (scaled).
    p : casadi.SX
        One multiplier per pair: the scaled contact pressures.
    parameters : Parameters
        Named parameters (load step; assigned data), in physical units.
    residual : casadi.SX
        ``mcp``: ``F(x, p)``, as many rows as ``x``. ``mpcc``: equality constraints ``h(x, p)``.
    residual_terms : casadi.SX
        Per row of ``residual``, the size of the terms that cancel in it, before they cancel
        (``|K| |u| + |G^T a| |p| + |f|`` and the like): residual tests are relative to it
        (:meth:`relative_residual`).
    objective : casadi.SX or None
        ``mpcc`` only: the scaled squared distance.
    gap : casadi.SX
        Scaled gaps ``g(x)``.
    gap_ref, pressure_ref : float
        Physical size of one unit of scaled gap (m) and of scaled pressure (Pa).
    contact_stiffness : float
        Reference stiffness (Pa/m) in which penalty parameters are given.
    fb_alpha, fb_beta : float
        Default Fischer-Burmeister scalings (1/m and 1/Pa), as in the paper (``beta = 1/c`` for the
        projection, ``1/E`` for the classical problem).
    """

    kind: Literal["mcp", "mpcc"]
    x: ca.SX
    p: ca.SX
    parameters: Parameters
    residual: ca.SX
    residual_terms: ca.SX
    objective: ca.SX | None
    gap: ca.SX
    gap_ref: float
    pressure_ref: float
    contact_stiffness: float
    fb_alpha: float
    fb_beta: float

    @property
    def params(self) -> ca.SX:
        """All parameters as one symbolic vector (in the order of :attr:`parameters`)."""
        return self.parameters.vector

    @property
    def n_x(self) -> int:
        return self.x.numel()

    @property
    def n_pairs(self) -> int:
        return self.p.numel()

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

    def step_params(self, step: int) -> np.ndarray:
        """Parameters of the classical problem at a load step."""
        m = self.model
        return self.classical.parameters.pack(gap0=m.gap_offsets[step], f=m.loads[step])

    def projection_params(self, step: int, strain_star: np.ndarray, stress_star: np.ndarray) -> np.ndarray:
        """Parameters of the ``Z_E`` projection: the load step and the assigned data, per point
        (``(m,)`` or ``(m, k)``, flattened point-major). For one-component points, ``(m, N)``
        arrays give an ``(n_params, N)`` matrix, one column per data assignment."""
        m = self.model
        strain_star, stress_star = np.asarray(strain_star, float), np.asarray(stress_star, float)
        if strain_star.ndim < 2 or self.model.strain_components > 1:
            strain_star, stress_star = strain_star.reshape(-1), stress_star.reshape(-1)
        return self.projection.parameters.pack(gap0=m.gap_offsets[step], f=m.loads[step],
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


def _common(model: ContactModel, G: ca.DM, s: dict, u: ca.SX, gap0: ca.SX, fb_beta: float) -> dict:
    gap = (ca.mtimes(G, u) + gap0) / s["displacement"]
    return dict(gap=gap, gap_ref=s["displacement"], pressure_ref=s["stress"],
                contact_stiffness=model.contact_stiffness, fb_alpha=1.0 / (0.01 * model.length_scale),
                fb_beta=fb_beta)


def build_problems(model: ContactModel) -> ProblemPair:
    """Build the classical MCP and the DDCM projection MPCC of ``model`` (each symbolically, once)."""
    n, m, nc, k = model.n_dofs, model.n_points, model.n_contacts, model.strain_components
    B, G = to_casadi(model.strain_operator), to_casadi(model.gap_operator)
    GtA = model.gap_operator.T @ sp.diags(model.contact_area)  # contact forces G^T (a p)
    Ga, Gabs = to_casadi(GtA), to_casadi(abs(GtA))

    classical = None
    if model.youngs_modulus is not None:
        s = model.scales_for("classical")
        P = Parameters(gap0=nc, f=n)
        u_hat, p_hat = ca.SX.sym("u", n), ca.SX.sym("p", nc)
        u, p = s["displacement"] * u_hat, s["stress"] * p_hat
        K = model.stiffness()
        F = (ca.mtimes(to_casadi(K), u) - ca.mtimes(Ga, p) - P["f"]) / s["force"]
        # |K| |u| + |G^T a| |p| + |f|: the terms before they cancel (roundoff is relative to them).
        size = (ca.mtimes(to_casadi(abs(K)), ca.fabs(u)) + ca.mtimes(Gabs, ca.fabs(p)) + ca.fabs(P["f"])) / s["force"]
        classical = ComplementarityProblem(kind="mcp", x=u_hat, p=p_hat, parameters=P, residual=F,
                                           residual_terms=size, objective=None,
                                           **_common(model, G, s, u, P["gap0"], 1.0 / s["modulus"]))

    projection = None
    if model.dataset is not None:
        s = model.scales_for("ddcm")
        P = Parameters(gap0=nc, f=n, strain_star=m * k, stress_star=m * k)
        u_hat, p_hat, sig_hat = ca.SX.sym("u", n), ca.SX.sym("p", nc), ca.SX.sym("stress", m * k)
        u, p, sig = s["displacement"] * u_hat, s["stress"] * p_hat, s["stress"] * sig_hat
        metrics, material = model.dataset.point_materials(m)
        d2 = weighted_distance2(ca.mtimes(B, u) - P["strain_star"], sig - P["stress_star"], metrics, material,
                                model.volumes)
        objective = 0.5 * d2 / s["energy"]
        BtW = model.strain_operator.T @ sp.diags(np.repeat(model.volumes, k))
        h = (ca.mtimes(to_casadi(BtW), sig) - ca.mtimes(Ga, p) - P["f"]) / s["force"]
        size = (ca.mtimes(to_casadi(abs(BtW)), ca.fabs(sig)) + ca.mtimes(Gabs, ca.fabs(p)) + ca.fabs(P["f"])) / s["force"]
        projection = ComplementarityProblem(
            kind="mpcc", x=ca.vertcat(u_hat, sig_hat), p=p_hat, parameters=P, residual=h,
            residual_terms=size, objective=objective,
            **_common(model, G, s, u, P["gap0"], 1.0 / s["metric"]))
    return ProblemPair(model=model, classical=classical, projection=projection)
