"""The classical problem and the DDCM projection of one model, built once
(:func:`build_problems`): as sparse matrices for small kinematics, as CasADi expressions for
finite ones. :class:`ProblemPair` maps scaled unknowns to physical fields and packs each step's
parameters (the load step, the assigned data, the previous step's history)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, partial
from typing import Callable

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ddcm_casadi.data.metric import block_diagonal, weighted_distance2
from ddcm_casadi.linalg import to_casadi
from ddcm_casadi.models.base import ContactModel
from ddcm_casadi.models.prescribed import PARAMETER as PRESCRIBED
from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.problems.maps import Affine, Distance, LocalTerms, NonlinearMap, NonlinearObjective
from ddcm_casadi.problems.parameters import Parameters


@dataclass(frozen=True, eq=False)
class ProblemPair:
    """Both problems of one model, with the maps between scaled unknowns and physical fields.

    Each problem is built on first use (:attr:`classical`, :attr:`projection`), once: a DDCM run
    never builds the classical problem, a classical run never the projection (at 1e5 points the
    classical problem's sparse maps alone are 25 MB). :meth:`has` tells whether the model has a
    problem without building it."""

    model: ContactModel
    #: ``{"classical": build, "projection": build}``: the builders of the problems the model has
    #: (a Young's modulus: the classical one; a data set: the projection).
    builders: dict[str, Callable[[], ComplementarityProblem]]

    def has(self, variant: str) -> bool:
        """Whether the model has the ``"classical"`` problem or the ``"projection"`` (without
        building it)."""
        return variant in self.builders

    @cached_property
    def classical(self) -> ComplementarityProblem | None:
        """The classical MCP (``None`` without a Young's modulus), built on first use."""
        return self._built("classical")

    @cached_property
    def projection(self) -> ComplementarityProblem | None:
        """The DDCM projection MPCC (``None`` without a data set), built on first use."""
        return self._built("projection")

    def _built(self, variant: str) -> ComplementarityProblem | None:
        build = self.builders.get(variant)
        return None if build is None else build()

    def _problem(self, kind: str) -> ComplementarityProblem:
        return self.classical if kind == "mcp" else self.projection

    def step_params(self, step: int, previous: dict | None = None) -> np.ndarray:
        """Parameters of the classical problem at a load step (``previous``: the last converged
        step's physical fields, for models whose steps have a history,
        :meth:`~ddcm_casadi.models.base.ContactModel.step_values`)."""
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

    def fields(self, kind: str, x: np.ndarray, p: np.ndarray, params: np.ndarray | None = None
               ) -> dict[str, np.ndarray]:
        """Physical displacement, contact pressure, strain and stress from scaled unknowns
        (strain and stress flat and point-major: ``m k`` values). ``params``: the parameters the
        unknowns solved (the problem's of ``kind``); a model with prescribed displacements needs
        them (its strains are ``B u + B_D u_D``). With friction also ``traction``: the tangential
        tractions (Pa, component-major), ``p`` the normal pressures only, and (given ``params``)
        ``slip``: the step's slips (m)."""
        s = self.scales(kind)
        n, nc = self.model.n_dofs, self.model.n_contacts
        u = s["displacement"] * np.asarray(x[:n])
        pressure = s["stress"] * np.asarray(p)
        extra = {}
        if self.model.frictional:
            pressure, extra["traction"] = pressure[:nc], pressure[nc:]
            if params is not None:  # the step's slips T u + slip_offset + slip0
                z = np.concatenate([np.asarray(x, float), np.asarray(p, float)])
                extra["slip"] = s["displacement"] * self._problem(kind).gap_map.value(z, params)[nc:]
        u_D = None
        if self.model.prescribed is not None:
            if params is None:
                raise ValueError("the fields of a model with prescribed displacements need the step's parameters")
            u_D = self._problem(kind).parameters.get(params, PRESCRIBED)
        strain = self.model.strain(u, u_D)
        if kind == "mpcc":
            stress = s["stress"] * np.asarray(x[n:])
        else:
            stress = self.model.stress(strain)
        return dict(u=u, p=pressure, strain=strain, stress=stress, **extra)

    def scaled_start(self, kind: str, u: np.ndarray, p: np.ndarray, stress: np.ndarray | None = None,
                     traction: np.ndarray | None = None):
        """Scaled unknowns ``(x, p)`` from physical fields (for warm starts; with friction the
        tangential ``traction`` follows the pressures, zero if not given)."""
        s = self.scales(kind)
        x = [np.asarray(u) / s["displacement"]]
        if kind == "mpcc":
            x.append(np.asarray(stress).reshape(-1) / s["stress"])
        p = np.asarray(p, float).reshape(-1)
        if self.model.frictional:
            nt = self.model.tangent_operator.shape[0]
            p = np.concatenate([p, np.zeros(nt) if traction is None else np.asarray(traction, float).reshape(-1)])
        return np.concatenate(x), p / s["stress"]


def _common(model: ContactModel, s: dict, fb_beta: float, n_z: int, P: Parameters) -> dict:
    """The gaps ``(G u + gap0) / s_d`` with ``u = s_d u_hat`` (``gap0`` the first parameter) and the
    scales; with friction the slips ``(T u + slip_offset + slip0) / s_d`` below them
    (component-major, :mod:`ddcm_casadi.models.coulomb`)."""
    nc = model.n_contacts
    C = model.contact_operator
    Q = sp.hstack([sp.identity(nc) / s["displacement"], sp.csr_matrix((nc, P.size - nc))]).tocsr()
    if model.frictional:
        nt = model.tangent_operator.shape[0]
        Q = sp.vstack([Q, (_placed(sp.identity(nt), P, "slip_offset") + _placed(sp.identity(nt), P, "slip0"))
                       / s["displacement"]]).tocsr()
    gap = Affine(sp.hstack([C, sp.csr_matrix((C.shape[0], n_z - model.n_dofs))]), Q)
    if model.prescribed is not None and nc:  # + G_D u_D / s_d
        gap = gap + Affine(sp.csr_matrix((C.shape[0], n_z)), sp.vstack([
            _placed(model.prescribed.gap_operator / s["displacement"], P, PRESCRIBED),
            sp.csr_matrix((C.shape[0] - nc, P.size))]))
    return dict(parameters=P, gap_map=gap, gap_ref=s["displacement"], pressure_ref=s["stress"],
                contact_stiffness=model.contact_stiffness, fb_alpha=1.0 / (0.01 * model.length_scale),
                fb_beta=fb_beta, contact_law=model.contact_law, kinematics=model.kinematics,
                block=model.contact_block)


def _placed(A: sp.spmatrix, P: Parameters, name: str) -> sp.csr_matrix:
    """``A`` placed at the columns of the parameter ``name`` of ``P`` (zero elsewhere)."""
    sl = P.slice(name)
    A = sp.csr_matrix(A)
    return sp.hstack([sp.csr_matrix((A.shape[0], sl.start)), A,
                      sp.csr_matrix((A.shape[0], P.size - sl.stop))]).tocsr()


def _selection(rows: int, start: int, columns: int, scale: float = 1.0) -> sp.csr_matrix:
    """``scale`` times the identity placed at column ``start`` of a ``rows x columns`` matrix."""
    return sp.hstack([sp.csr_matrix((rows, start)), scale * sp.identity(rows),
                      sp.csr_matrix((rows, columns - start - rows))]).tocsr()


def distance_weight(model: ContactModel) -> sp.csr_matrix:
    """``W`` with ``sum_i w_i d_i^2 = d^T W d`` for ``d`` point-major ``[e_i - e*_i; s_i - s*_i]``:
    the block diagonal of :func:`distance_blocks`, without its zeros (a constant metric
    separates strains from stresses, and an isotropic one shears from normal components: 10 of a
    2-D point's 36 entries, 2.6M zeros of 3.6M entries at 1e5 points)."""
    W = block_diagonal(distance_blocks(model))
    W.eliminate_zeros()
    return W


def distance_blocks(model: ContactModel) -> np.ndarray:
    """``(m, 2k, 2k)``: per point, its volume times half the Hessian of
    :func:`~ddcm_casadi.data.metric.weighted_distance2` (the one place the metric's formula is
    written) for one point of unit weight of its material."""
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
    return blocks[material] * np.asarray(model.volumes, float)[:, None, None]


def _point_major(mk: int, k: int) -> np.ndarray:
    """The rows of ``[strains; stresses]`` (each ``m k`` long) in point-major order
    ``[e_1; s_1; e_2; s_2; ...]``, ``k`` components each: the order of :func:`distance_weight`."""
    point, c = np.divmod(np.arange(2 * mk), 2 * k)
    return np.where(c < k, point * k + c, mk + point * k + c - k)


def _equilibrium(model: ContactModel, s: dict, uh: ca.SX, ph: ca.SX, P: Parameters, Ps: ca.SX,
                 stress_of: Callable[[ca.SX], ca.SX]) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    """``(E, r, t, g)``: the strains ``E(u)`` (``u = s_d uh``), the scaled equilibrium residual
    ``r = (B(u)^T W stress - N(u)^T a p - f) / s_f`` with ``stress = stress_of(E)``, ``p = s_s ph``
    and ``B(u) = dE/du`` by automatic differentiation (the virtual work ``sum_i w_i stress_i .
    dE_i`` of a nonlinear strain measure; the contact forces and loads by
    :func:`_contact_expression`), ``t`` the size of its terms (for relative residuals) and ``g``
    the scaled gaps."""
    values = lambda name: Ps[P.slice(name)]  # noqa: E731 - the step's parameters by name
    E = model.strain_expression(s["displacement"] * uh, values)
    stress = stress_of(E)
    B = ca.jacobian(E, uh) / s["displacement"]
    w = ca.DM(np.repeat(np.asarray(model.volumes, float), model.strain_components))
    r, t, gap = _contact_expression(model, s, uh, ph, P, Ps)
    return (E, ca.mtimes(B.T, w * stress) / s["force"] + r,
            ca.mtimes(ca.fabs(B).T, w * ca.fabs(stress)) / s["force"] + t, gap)


def _with_gap_map(z: ca.SX, Ps: ca.SX, gap: ca.SX, common: dict) -> dict:
    """``common`` (:func:`_common`) with the gaps as a :class:`NonlinearMap` where they are not
    affine (a curved obstacle at the current configuration)."""
    if gap.numel() and ca.depends_on(ca.jacobian(gap, z), z):
        common["gap_map"] = NonlinearMap.of(gap, z, Ps, name="gap")
    return common


def _build_nonlinear(model: ContactModel, variant: str) -> ComplementarityProblem:
    """The ``variant`` (``"classical"`` or ``"projection"``) of a model with nonlinear kinematics,
    as CasADi expressions (:class:`NonlinearMap`, :class:`NonlinearObjective`).

    Classical: ``F = (B(u)^T W S(E(u)) - N(u)^T a p - f) / s_f`` with the model's law ``S``
    (:meth:`~ddcm_casadi.models.base.ContactModel.stress_expression`). Projection: ``h = (B(u)^T W
    stress - N(u)^T a p - f) / s_f`` and ``f = d^T W d / (2 energy)`` with ``d = [E(u) - E*; stress -
    S*]`` point by point. The gaps ``g(u)`` are the model's
    (:meth:`~ddcm_casadi.models.base.ContactModel.gap_expression`): kept affine where they are (a
    plane obstacle's gap ``n . (X + u) - d`` is exact at any displacement), nonlinear otherwise
    (a curved obstacle at the current configuration).
    """
    n, m, nc, k = model.n_dofs, model.n_points, model.n_contacts, model.strain_components
    if variant == "classical":
        s = model.scales_for("classical")
        P = Parameters(**model.step_sizes())
        z, Ps = ca.SX.sym("z", n + nc), ca.SX.sym("P", P.size)
        _, F, terms, gap = _equilibrium(model, s, z[:n], z[n:], P, Ps, model.stress_expression)
        return ComplementarityProblem(kind="mcp", unknowns=(("u", n),),
                                      residual_map=NonlinearMap.of(F, z, Ps, terms, "residual"), distance=None,
                                      **_with_gap_map(z, Ps, gap, _common(model, s, 1.0 / s["modulus"], n + nc, P)))
    # the projection
    s = model.scales_for("ddcm")
    mk = m * k
    P = Parameters(**model.step_sizes(), strain_star=mk, stress_star=mk)
    z, Ps = ca.SX.sym("z", n + mk + nc), ca.SX.sym("P", P.size)
    stress = s["stress"] * z[n:n + mk]
    E, h, terms, gap = _equilibrium(model, s, z[:n], z[n + mk:], P, Ps, lambda E: stress)
    stacked = ca.vertcat(E - Ps[P.slice("strain_star")], stress - Ps[P.slice("stress_star")])
    d = stacked[_point_major(mk, k).tolist()]
    W = to_casadi(distance_weight(model) / s["energy"])
    objective = NonlinearObjective(ca.Function("distance", [z, Ps], [0.5 * ca.dot(d, ca.mtimes(W, d))]))
    return ComplementarityProblem(
        kind="mpcc", unknowns=(("u", n), ("stress", mk)), residual_map=NonlinearMap.of(h, z, Ps, terms, "h"),
        distance=objective, **_with_gap_map(z, Ps, gap, _common(model, s, 1.0 / s["metric"], n + mk + nc, P)))


def _gather(dofs: np.ndarray, columns: int, start: int = 0) -> sp.csr_matrix:
    """Rows item-major: row ``i q + j`` picks column ``start + dofs[i, j]`` (none where ``-1``)."""
    flat = np.asarray(dofs, np.int64).ravel()
    keep = flat >= 0
    return sp.csr_matrix((np.ones(int(keep.sum())), (np.flatnonzero(keep), start + flat[keep])),
                         shape=(flat.size, columns))


def _contact_expression(model: ContactModel, s: dict, uh: ca.SX, ph: ca.SX, P: Parameters, Ps: ca.SX
                        ) -> tuple[ca.SX, ca.SX, ca.SX]:
    """``(r, t, g)`` of the contact forces and loads: ``r = (-s_s N(u)^T a p - f) / s_f``, its terms,
    and the scaled gaps (``N = dg/du`` by automatic differentiation; a few rows per pair)."""
    values = lambda name: Ps[P.slice(name)]  # noqa: E731 - the step's parameters by name
    gap = model.gap_expression(s["displacement"] * uh, values)
    N = ca.jacobian(gap, uh) / s["displacement"]
    ph = ca.reshape(ph, model.n_contacts, 1)  # an empty slice of a symbol is 1 x 0: make it nc x 1
    ap = ca.DM(np.asarray(model.contact_area, float).reshape(-1, 1)) * ph
    f = values("f")
    r = (-s["stress"] * ca.mtimes(N.T, ap) - f) / s["force"]
    t = (s["stress"] * ca.mtimes(ca.fabs(N).T, ca.fabs(ap)) + ca.fabs(f)) / s["force"]
    return r, t, gap / s["displacement"]


def _build_local(model: ContactModel, lk, variant: str) -> ComplementarityProblem:
    r"""The ``variant`` (``"classical"`` or ``"projection"``) of a model with
    :class:`~ddcm_casadi.models.base.LocalKinematics`, the bulk
    as :class:`LocalTerms` (one small function per element, assembled), the contact forces, loads and
    gaps as expressions (a few rows per pair).

    Classical, per element ``e`` of a law group: ``psi_e = dW_e/du_e / s_f`` with ``W_e`` its stored
    energy (``dW_e/du_e = B_e(u)^T w S``). Projection: ``psi_e = B_e(u)^T (w stress_e) / s_f`` and the
    objective's items ``1/2 sum_q d_q^T W_q d_q / energy``, ``d_q = [E_q(u) - E*_q; stress_q - S*_q]``.
    The same problems as :func:`_build_nonlinear` builds, item by item.
    """
    n, m, nc, k = model.n_dofs, model.n_points, model.n_contacts, model.strain_components
    ne, q = lk.dofs.shape
    nq = lk.points_per_item
    qg = lk.geometry.shape[1]

    def guarded(value, u_e, geometry):
        """NaN where an item's point is inverted (``J <= 0``): Newton's line search backs off."""
        if lk.volume_ratio is None:
            return value
        return ca.if_else(ca.mmin(lk.volume_ratio(u_e, geometry)) > 0, 1.0, np.nan) * value

    if variant == "classical":
        s = model.scales_for("classical")
        P = Parameters(**model.step_sizes())
        nz = n + nc
        z, Ps = ca.SX.sym("z", nz), ca.SX.sym("P", P.size)
        local = []
        for items, constants, energy in lk.laws:
            y, c = ca.SX.sym("u_e", q), ca.SX.sym("c", qg + constants.shape[1])
            E = lk.strain(s["displacement"] * y, c[:qg])
            Es, cl = ca.SX.sym("E", E.numel()), ca.SX.sym("cl", constants.shape[1])
            wS = ca.Function("wS", [Es, cl], [ca.gradient(energy(Es, cl), Es)])(E, c[qg:])
            scale = 1.0 / (s["displacement"] * s["force"])
            dE = ca.jacobian(E, y)
            item = ca.Function("element_force", [y, c],
                               [guarded(scale * ca.mtimes(dE.T, wS), s["displacement"] * y, c[:qg])])
            terms = ca.Function("element_terms", [y, c], [scale * ca.mtimes(ca.fabs(dE).T, ca.fabs(wS))])
            Y = _gather(lk.dofs[items], nz)
            local.append(LocalTerms(item, Y, sp.csr_matrix((Y.shape[0], P.size)), Y[:, :n].T,
                                    np.concatenate([lk.geometry[items], constants], axis=1), terms))
        r, t, gap = _contact_expression(model, s, z[:n], z[n:], P, Ps)
        return ComplementarityProblem(
            kind="mcp", unknowns=(("u", n),), residual_map=NonlinearMap.of(r, z, Ps, t, "residual", tuple(local)),
            distance=None, **_with_gap_map(z, Ps, gap, _common(model, s, 1.0 / s["modulus"], nz, P)))
    # the projection
    s = model.scales_for("ddcm")
    mk = m * k
    P = Parameters(**model.step_sizes(), strain_star=mk, stress_star=mk)
    nz = n + mk + nc
    z, Ps = ca.SX.sym("z", nz), ca.SX.sym("P", P.size)
    nk = nq * k
    points = np.arange(ne)[:, None] * nk + np.arange(nk)  # (ne, nq k): the element's stress entries
    Y = sp.vstack([_gather(lk.dofs, nz), _gather(points, nz, n)]).tocsr()
    order = np.concatenate([np.arange(ne)[:, None] * q + np.arange(q), ne * q + points], axis=1).ravel()
    Y = Y[order]
    u_e, S_e, c = ca.SX.sym("u_e", q), ca.SX.sym("S_e", nk), ca.SX.sym("c", qg + nq)
    E = lk.strain(s["displacement"] * u_e, c[:qg])
    stress = s["stress"] * S_e
    w = ca.repmat(c[qg:].T, k, 1)  # (k, nq): each point's weight on its components
    dE = ca.jacobian(E, u_e)
    scale = 1.0 / (s["displacement"] * s["force"])
    item = ca.Function("element_force", [ca.vertcat(u_e, S_e), c],
                       [guarded(scale * ca.mtimes(dE.T, ca.vec(w) * stress), s["displacement"] * u_e, c[:qg])])
    terms = ca.Function("element_terms", [ca.vertcat(u_e, S_e), c],
                        [scale * ca.mtimes(ca.fabs(dE).T, ca.vec(w) * ca.fabs(stress))])
    weights = np.asarray(model.volumes, float).reshape(ne, nq)
    residual_local = LocalTerms(item, Y, sp.csr_matrix((Y.shape[0], P.size)), _gather(lk.dofs, n).T,
                                np.concatenate([lk.geometry, weights], axis=1), terms)
    # the objective: per element [u_e; S_e; E*_e; S*_e] and its points' weight blocks
    stars = sp.vstack([_gather(points, P.size, P.slice("strain_star").start),
                       _gather(points, P.size, P.slice("stress_star").start)]).tocsr()
    star_order = np.concatenate([np.arange(ne)[:, None] * nk + np.arange(nk),
                                 ne * nk + np.arange(ne)[:, None] * nk + np.arange(nk)], axis=1)
    Yo = sp.vstack([Y, sp.csr_matrix((2 * ne * nk, nz))]).tocsr()
    YPo = sp.vstack([sp.csr_matrix((Y.shape[0], P.size)), stars[star_order.ravel()]]).tocsr()
    # item-major: [u_e; S_e] rows of element e, then its [E*_e; S*_e]
    qy = q + nk
    obj_order = np.concatenate([np.arange(ne)[:, None] * qy + np.arange(qy),
                                ne * qy + np.arange(ne)[:, None] * 2 * nk + np.arange(2 * nk)], axis=1).ravel()
    Yo, YPo = Yo[obj_order], YPo[obj_order]
    blocks = distance_blocks(model) / s["energy"]  # (m, 2k, 2k), point-major [e; s]
    Es, Ss, cb = ca.SX.sym("E_star", nk), ca.SX.sym("S_star", nk), ca.SX.sym("c", qg + nq * 4 * k * k)
    Eo = lk.strain(s["displacement"] * u_e, cb[:qg])
    f = 0
    for p_ in range(nq):
        dq = ca.vertcat(Eo[p_ * k:(p_ + 1) * k] - Es[p_ * k:(p_ + 1) * k],
                        s["stress"] * S_e[p_ * k:(p_ + 1) * k] - Ss[p_ * k:(p_ + 1) * k])
        Wq = ca.reshape(cb[qg + p_ * 4 * k * k:qg + (p_ + 1) * 4 * k * k], 2 * k, 2 * k)
        f += 0.5 * ca.dot(dq, ca.mtimes(Wq, dq))
    objective_item = ca.Function("element_distance", [ca.vertcat(u_e, S_e, Es, Ss), cb], [f])
    objective_local = LocalTerms(objective_item, Yo, YPo, sp.csr_matrix(np.ones((1, ne))),
                                 np.concatenate([lk.geometry, blocks.reshape(ne, -1)], axis=1))
    r, t, gap = _contact_expression(model, s, z[:n], z[n + mk:], P, Ps)
    return ComplementarityProblem(
        kind="mpcc", unknowns=(("u", n), ("stress", mk)),
        residual_map=NonlinearMap.of(r, z, Ps, t, "h", (residual_local,)),
        distance=NonlinearObjective(ca.Function("distance", [z, Ps], [ca.SX(1, 1)]), (objective_local,)),
        **_with_gap_map(z, Ps, gap, _common(model, s, 1.0 / s["metric"], nz, P)))


def build_problems(model: ContactModel) -> ProblemPair:
    """The classical MCP and the DDCM projection MPCC of ``model``, each built once on first use
    (:class:`ProblemPair`): as sparse matrices for small kinematics (:func:`_build_small`), as
    CasADi expressions for finite ones (:func:`_build_nonlinear`, :func:`_build_local`)."""
    if model.kinematics != "small":
        lk = model.local_kinematics()
        build = partial(_build_nonlinear, model) if lk is None else partial(_build_local, model, lk)
    else:
        build = partial(_build_small, model)
    has = {"classical": model.youngs_modulus is not None, "projection": model.dataset is not None}
    # The reference scales now, in this order, whichever problem is built first: the projection's
    # share the classical factor where their laws are proportional (``reference_scales``), which is
    # freed once both are known, before any problem's matrices take memory; where the classical
    # condensation may apply, the classical factor is the condensation's, kept by the model
    # (``ContactModel.stiffness_factor``).
    for variant, kind in (("classical", "classical"), ("projection", "ddcm")):
        if has[variant]:
            model.scales_for(kind)
    return ProblemPair(model=model, builders={variant: partial(build, variant) for variant, on in has.items() if on})


def _build_small(model: ContactModel, variant: str) -> ComplementarityProblem:
    """The ``variant`` (``"classical"`` or ``"projection"``) of a model with small kinematics,
    as sparse matrices (:class:`Affine`, :class:`Distance`)."""
    n, m, k = model.n_dofs, model.n_points, model.strain_components
    nc = model.n_contacts * model.contact_block  # the pairs: with friction, a block per contact
    # contact forces G^T (a p) (with friction [G; T]^T (a [p; r_T]))
    GtA = (model.contact_operator.T @ sp.diags(np.tile(model.contact_area, model.contact_block))).tocsr()

    if variant == "classical":
        s = model.scales_for("classical")
        P = Parameters(**model.step_sizes())
        # F = (K u - G^T a p - f) / s_f with u = s_d u_hat, p = s_s p_hat
        # (scaled in the order the arithmetic of F does it: each term times its scale, over s_f)
        F = Affine(sp.hstack([model.stiffness() * s["displacement"] / s["force"], GtA * -s["stress"] / s["force"]]),
                   _selection(n, P.slice("f").start, P.size, -1.0 / s["force"]))
        if model.prescribed is not None:  # + B^T W D B_D u_D / s_f: the hard device's strain offset
            W = sp.diags(np.repeat(model.volumes, k))
            KD = model.strain_operator.T @ (W @ model.material_matrix()) @ model.prescribed.strain_operator
            F = F + Affine(sp.csr_matrix((n, n + nc)), _placed(KD / s["force"], P, PRESCRIBED))
        return ComplementarityProblem(kind="mcp", unknowns=(("u", n),), residual_map=F, distance=None,
                                      **_common(model, s, 1.0 / s["modulus"], n + nc, P))

    # the projection
    s = model.scales_for("ddcm")
    P = Parameters(**model.step_sizes(), strain_star=m * k, stress_star=m * k)
    nz, mk = n + m * k + nc, m * k
    BtW = model.strain_operator.T @ sp.diags(np.repeat(model.volumes, k))
    # h = (B^T W stress - G^T a p - f) / s_f with stress = s_s stress_hat
    h = Affine(sp.hstack([sp.csr_matrix((n, n)), BtW * s["stress"] / s["force"], GtA * -s["stress"] / s["force"]]),
               _selection(n, P.slice("f").start, P.size, -1.0 / s["force"]))
    # d = [B u - strain_star; stress - stress_star] point-major, f = d^T W d / (2 energy)
    stacked = Affine(sp.vstack([sp.hstack([model.strain_operator * s["displacement"], sp.csr_matrix((mk, mk + nc))]),
                                _selection(mk, n, nz, s["stress"])]),
                     sp.vstack([_selection(mk, P.slice("strain_star").start, P.size, -1.0),
                                _selection(mk, P.slice("stress_star").start, P.size, -1.0)]))
    if model.prescribed is not None:  # the strains B u + B_D u_D
        stacked = stacked + Affine(sp.csr_matrix((2 * mk, nz)), sp.vstack([
            _placed(model.prescribed.strain_operator, P, PRESCRIBED), sp.csr_matrix((mk, P.size))]))
    order = _point_major(mk, k)
    d = Affine(stacked.z[order], stacked.params[order])
    return ComplementarityProblem(
        kind="mpcc", unknowns=(("u", n), ("stress", mk)), residual_map=h,
        distance=Distance(d, distance_weight(model) / s["energy"]),
        **_common(model, s, 1.0 / s["metric"], nz, P))
