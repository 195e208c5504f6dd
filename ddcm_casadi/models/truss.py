"""Pin-jointed trusses in 1-D, 2-D and 3-D with rigid planar obstacles, small or finite kinematics.

A truss is ``nodes`` (nn x d), ``members`` (ne x 2 node indices) with a cross-section and a
material each, ``supports`` (fixed nodal directions), nodal and distributed loads scaled by a load
factor per step, and rigid planes, each acting on chosen nodes with the gap

.. math::  g = n \\cdot (X + u) - d \\;\\ge 0 ,

``n`` the unit normal pointing away from the obstacle and ``d`` its offset (possibly moving, one
value per step). Every member is one material point with strain ``e . (u_j - u_i) / L`` (``e``
the unit vector from node ``i`` to ``j``), or with ``kinematics = "finite"`` the Green-Lagrange
strain ``(l^2 - L^2) / (2 L^2)`` of its current length ``l`` (:meth:`TrussModel.strain`). The result is a plain
:class:`~ddcm_casadi.models.base.ContactModel` (sparse ``B`` and ``G``, built without a loop over
members), so every formulation and both variants apply unchanged.

A contact pair's pressure acts on the mean cross-section of the members at its node, so pressures
are stress-like (well scaled); :meth:`TrussModel.contact_force` gives forces in newtons.
A bar of N elements is a 1-D truss (:func:`bar_chain`); :func:`warren_truss` builds a bridge.
:func:`truss_model` puts together the checked pieces of :mod:`ddcm_casadi.models.truss_assembly`
(geometry, supports, loads, contact pairs, the mechanism check).

The model describes itself to the front ends (:meth:`TrussModel.describe`,
:meth:`TrussModel.extra_fields`, :meth:`TrussModel.figures`); the ``[structure]`` case files are
parsed by :mod:`ddcm_casadi.casefiles.truss`, and the figures drawn by :mod:`ddcm_casadi.outputs.plots`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ddcm_casadi.data.dataset import MaterialDataset, check_positive
from ddcm_casadi.errors import InputError
from ddcm_casadi.linalg import to_casadi
from ddcm_casadi.models.base import ContactModel, FigureSpec, drawn_formulation
from ddcm_casadi.models.prescribed import Prescribed, displacement_path, nonzero_free_components, path_steps
from ddcm_casadi.models.truss_assembly import (AXES, Obstacle, check_not_mechanism, contact_areas,
                                               contact_pairs, fixed_directions, gap_operator, load_path,
                                               member_data, member_geometry, node_coordinates, per_member,
                                               prescribed_supports, reference_loads, strain_operator)

#: The names importers use; the assembly pieces (supports' axis letters, the obstacle record, the
#: mechanism check, the member data) are re-exported from :mod:`ddcm_casadi.models.truss_assembly`.
__all__ = ["AXES", "HardDeviceBarModel", "Obstacle", "StoppedBarModel", "TrussModel", "bar_chain",
           "check_not_mechanism", "member_data", "truss_model", "warren_truss"]


@dataclass(frozen=True, eq=False)
class TrussModel(ContactModel):
    """A :class:`ContactModel` that remembers its truss geometry (for results and plots)."""

    nodes: np.ndarray | None = None
    members: np.ndarray | None = None
    free_dofs: np.ndarray | None = None
    contact_nodes: np.ndarray | None = None
    contact_normals: np.ndarray | None = None
    member_area: np.ndarray | None = None

    @property
    def dimension(self) -> int:
        return self.nodes.shape[1]

    def nodal_displacements(self, u: np.ndarray, step: int | None = None) -> np.ndarray:
        """``(nn, d)`` nodal displacements from the free unknowns ``u`` (fixed ones are 0; with a
        hard device, the prescribed ones those of load step ``step``, which it then needs)."""
        full = np.zeros(self.nodes.size)
        full[self.free_dofs] = u
        if self.prescribed is not None:
            if step is None:
                raise ValueError("the nodal displacements of a truss with prescribed displacements need the step")
            full[self.prescribed.dofs] = self.prescribed.values[step]
        return full.reshape(self.nodes.shape)

    # ------------------------------------------------------------ kinematics
    def _differences(self, prescribed: bool = False) -> list[sp.csr_matrix]:
        """Per axis ``c``, ``D_c`` (ne x n): ``(u_j - u_i)_c / L`` of every member from the free
        displacements (cached); ``prescribed``: from the prescribed ones (ne x nD)."""
        key = "differences_prescribed" if prescribed else "differences"
        D = self._cache.get(key)
        if D is None:
            nn, d = self.nodes.shape
            ne = self.members.shape[0]
            L = self.volumes / self.member_area
            rows = np.repeat(np.arange(ne), 2)
            columns = self.prescribed.dofs if prescribed else self.free_dofs
            D = []
            for c in range(d):
                cols = (self.members * d + c).ravel()
                vals = np.column_stack([-1.0 / L, 1.0 / L]).ravel()
                D.append(sp.csr_matrix((vals, (rows, cols)), shape=(ne, nn * d))[:, columns].tocsr())
            self._cache[key] = D
        return D

    def strain(self, u: np.ndarray, u_prescribed: np.ndarray | None = None) -> np.ndarray:
        """Member strains. Small kinematics: ``e . (u_j - u_i) / L``. Finite: the Green-Lagrange
        strain ``E = (l^2 - L^2) / (2 L^2) = e . du / L + |du|^2 / (2 L^2)``, ``du = u_j - u_i`` and
        ``l`` the current length (exact for any displacement and rotation). With a hard device the
        prescribed displacements ``u_prescribed`` of the step enter ``du``."""
        u = np.asarray(u, float)
        linear = super().strain(u, u_prescribed)
        if self.kinematics == "small":
            return linear
        u_D = None if self.prescribed is None else self._given_prescribed(u_prescribed)
        return linear + 0.5 * sum(d ** 2 for d in self._member_differences(u, u_D, lambda A, v: A @ v))

    def strain_expression(self, u, values=None):
        """:meth:`strain` for a CasADi symbol ``u`` (``values``: the step's parameters, for the
        prescribed displacements of a hard device)."""
        linear = super().strain_expression(u, values)
        if self.kinematics == "small":
            return linear
        u_D = None if self.prescribed is None else values("u_prescribed")
        return linear + 0.5 * sum(d ** 2 for d in self._member_differences(
            u, u_D, lambda A, v: ca.mtimes(to_casadi(A), v)))

    def _member_differences(self, u, u_D, apply) -> list:
        """``du_c = D_c u (+ D_Dc u_D)`` per component ``c`` (``apply(A, v)``: ``A v``, numeric or
        symbolic; ``u_D`` ``None`` without a hard device)."""
        if u_D is None:
            return [apply(D, u) for D in self._differences()]
        return [apply(D, u) + apply(DD, u_D) for D, DD in zip(self._differences(), self._differences(True))]

    def prescribed_strain_jacobian(self, u: np.ndarray, u_prescribed: np.ndarray):
        """``dE / du_D``: ``B_D`` (small), ``B_D + sum_c diag(D_c u + D_Dc u_D) D_Dc`` (finite)."""
        B_D = self.prescribed.strain_operator
        if self.kinematics == "small":
            return B_D
        u, u_D = np.asarray(u, float), np.asarray(u_prescribed, float)
        return (B_D + sum(sp.diags(D @ u + DD @ u_D) @ DD
                          for D, DD in zip(self._differences(), self._differences(True)))).tocsr()

    def contact_force(self, p: np.ndarray) -> np.ndarray:
        """Contact forces (N) from contact pressures: ``area * p``, one per pair."""
        return self.contact_area * np.asarray(p)

    def member_force(self, stress: np.ndarray) -> np.ndarray:
        """Member forces (N) from member stresses: ``member_area * stress`` (stacked steps too)."""
        return self.member_area * np.asarray(stress)

    def contact_pair_labels(self) -> list[str]:
        """One legend label per contact pair: the node it acts on."""
        return [f"node {int(n)}" for n in self.contact_nodes]

    # ------------------------------------------------------------ self-description
    def describe(self) -> dict:
        """The generic model record plus the truss's ``dimension``, ``n_nodes`` and ``n_members``."""
        out = super().describe()
        if self.nodes is not None:
            out.update(dimension=int(self.nodes.shape[1]), n_nodes=int(self.nodes.shape[0]),
                       n_members=int(self.members.shape[0]))
        return out

    def extra_fields(self, u: np.ndarray, stress: np.ndarray) -> dict:
        """``nodal_displacement`` (n_steps, n_nodes, dim) and ``member_force`` (n_steps, n_members)."""
        return dict(nodal_displacement=np.array([self.nodal_displacements(x, k) for k, x in enumerate(u)]),
                    member_force=self.member_force(stress))

    def figures(self, runs) -> dict[str, FigureSpec]:
        """``structure_classical.png`` and ``structure_ddcm.png`` (last step, Fischer-Burmeister
        if it was run, else the first formulation of that variant; a variant that was not run is
        skipped; drawn by :func:`ddcm_casadi.outputs.plots.figure_structure`) and ``contact_history.png``."""
        runs = list(runs)
        specs = {}
        for variant in ("classical", "ddcm"):
            name = drawn_formulation(runs, variant)
            if name is not None:
                specs[f"structure_{variant}.png"] = FigureSpec("structure", {"variant": variant, "formulation": name})
        return {**specs, **super().figures(runs)}


def truss_model(*, nodes, members, area, youngs_modulus=None, supports, loads=None,
                distributed_loads=None, obstacles: Sequence[Obstacle] = (), load_factors=None,
                dataset: MaterialDataset | Sequence[MaterialDataset] | None = None, material=None,
                name: str = "truss", kinematics: str = "small") -> TrussModel:
    """Build a truss contact model.

    Parameters
    ----------
    nodes : (nn, d) array_like
        Node coordinates (m), ``d`` in {1, 2, 3}.
    members : (ne, 2) array_like of int
        Node pairs.
    area, youngs_modulus : float or (ne,)
        Cross-sections (m^2) and moduli (Pa; omit for a data-only model).
    supports : (nn, d) array_like of bool, or sequence of (node, axes) or (node, axes, displacement)
        Fixed directions, e.g. ``[(0, "xy"), (4, "y")]``. A third entry prescribes the
        displacement of those axes (a hard device): one ``d``-vector (m) scaled by the load
        factors, or one ``d``-vector per step, e.g. ``(4, "x", [0.01, 0.0])``; components along
        axes the support leaves free must be 0. The force the device exerts on the body is
        reported per step (:meth:`~ddcm_casadi.models.base.ContactModel.hard_device_forces`).
    loads : (nn, d) array_like, optional
        Reference nodal forces (N), multiplied by the load factor of each step.
    distributed_loads : (ne, d) array_like, optional
        Reference load per unit length on each member (N/m), lumped half to each end node.
    obstacles : sequence of Obstacle
    load_factors : (n_steps,) array_like, optional
        Load factor per step. Default: ones, as many steps as the obstacle offsets or the
        prescribed displacements given per step have (or one).
    dataset : MaterialDataset or sequence of MaterialDataset, optional
        Data for the DDCM variant: one set for all members, or one per material.
    material : (ne,) array_like of int, optional
        Data set of each member when several are given.
    kinematics : {"small", "finite"}
        ``"finite"``: large displacements and rotations, Green-Lagrange member strains
        (:meth:`TrussModel.strain`); data and stresses are then ``(E, S)`` pairs.
    """
    X = node_coordinates(nodes)
    nn, d = X.shape
    M, length, unit = member_geometry(members, X)
    ne = M.shape[0]
    A = per_member("area", area, ne)
    E = None if youngs_modulus is None else per_member("youngs_modulus", youngs_modulus, ne)
    free = np.flatnonzero(~fixed_directions(supports, nn, d).ravel())
    if free.size == 0:
        raise InputError("every degree of freedom is fixed or prescribed: nothing is left to solve for")
    B = strain_operator(M, unit, length, nn, free)
    f_ref = reference_loads(loads, distributed_loads, M, length, nn, d)
    pairs = contact_pairs(obstacles, nn, d)
    devices = prescribed_supports(supports, nn, d)
    lf, n_steps = load_path(load_factors, _path_steps(pairs.n_steps, devices, d, load_factors))
    G, gap0 = gap_operator(pairs, X, free, n_steps)
    contact_area = contact_areas(M, A, nn, pairs)
    prescribed = (_truss_prescribed(devices, M, unit, length, X, pairs, lf if load_factors is not None else None,
                                    n_steps, f_ref) if devices else None)
    check_not_mechanism(B, A * length)
    data = member_data(dataset, material)
    size = float(np.max(np.ptp(X, axis=0))) or float(np.max(length))
    return TrussModel(
        strain_operator=B, volumes=A * length, gap_operator=G, contact_area=contact_area,
        gap_offsets=gap0, loads=lf[:, None] * f_ref.ravel()[free][None, :], load_parameter=np.arange(n_steps, dtype=float)
        if load_factors is None else lf, youngs_modulus=E, dataset=data, length_scale=size, name=name,
        load_parameter_name="load step" if load_factors is None else "load factor",
        nodes=X, members=M.astype(np.intp), free_dofs=free, contact_nodes=pairs.node_indices(),
        contact_normals=np.asarray(pairs.normals).reshape(pairs.count, d), member_area=A, kinematics=kinematics,
        prescribed=prescribed, **pairs.friction_fields(X, free))


def _path_steps(from_obstacles: int | None, devices: list, d: int, load_factors=None) -> int | None:
    """The number of steps the obstacles' offsets and the prescribed displacements given per
    step fix (``None``: none does); they must agree with each other and with the load factors
    (whose agreement with the obstacles :func:`~ddcm_casadi.models.truss_assembly.load_path` checks)."""
    steps, what = from_obstacles, "the obstacle offsets have"
    if load_factors is not None:
        steps, what = int(np.size(load_factors)), "load_factors has"
    for node, _, value in devices:
        n = path_steps(value, d)
        if n is not None and steps is not None and n != steps:
            raise InputError(f"support at node {node}: displacement has {n} steps but {what} {steps}")
        if n is not None and steps is None:
            steps, what = n, f"the displacement at node {node} has"
    return from_obstacles if load_factors is not None or from_obstacles is not None else steps


def _truss_prescribed(devices: list, M: np.ndarray, unit: np.ndarray, length: np.ndarray, X: np.ndarray,
                      pairs, factors: np.ndarray | None, n_steps: int, f_ref: np.ndarray) -> Prescribed:
    """The hard device of a truss: the prescribed dofs of the supports with a displacement, their
    strain and gap operators, values per step and loads (:class:`~ddcm_casadi.models.prescribed.Prescribed`)."""
    nn, d = X.shape
    dofs, values, support, component, names = [], [], [], [], []
    for s, (node, axes, value) in enumerate(devices):
        where = f"support at node {node}:"
        path = displacement_path(value, d, n_steps, factors, where)
        nonzero_free_components(path, axes, where)
        for c in axes:
            dofs.append(node * d + c)
            values.append(path[:, c])
            support.append(s)
            component.append(c)
        names.append(f"node {node}")
    dofs = np.asarray(dofs, dtype=np.intp)
    lf = np.ones(n_steps) if factors is None else np.asarray(factors, float)
    return Prescribed(strain_operator=strain_operator(M, unit, length, nn, dofs),
                      gap_operator=gap_operator(pairs, X, dofs, n_steps)[0],
                      values=np.column_stack(values), loads=lf[:, None] * f_ref.ravel()[dofs][None, :],
                      support=np.asarray(support), component=np.asarray(component), support_names=tuple(names),
                      dimension=d, dofs=dofs)


class StoppedBarModel(TrussModel):
    """A bar fixed at ``x = 0``, pushed at its tip by a moving obstacle, with fixed stops behind
    interior nodes. It has a closed form (see :meth:`closed_form`)."""

    def closed_form(self, step: int):
        """The classical solution by the 1-D obstacle problem's upper concave envelope.

        With no loads and a uniform bar, the displacement minimises the Dirichlet energy with
        ``u(0) = 0``, ``u(L) <= w`` and ``u(x_j) >= -s_j``: for ``w >= 0`` it is 0, otherwise the
        least concave majorant of the points ``(0, 0)``, ``(x_j, -s_j)`` and ``(L, w)`` (linear
        between touching nodes). Pressures are the jumps of the stress ``E u'``.
        """
        if self.youngs_modulus is None:
            return None
        x = self.nodes[:, 0]
        E = float(self.youngs_modulus[0])
        w = self.gap_offsets[step, 0]  # tip pair first: g = w - u_N, so gap0 = w = h - l0
        stops = self.gap_offsets[step, 1:]  # g_j = u_j + s_j
        n_free = x.size - 1
        if w >= 0:
            return np.zeros(n_free), np.zeros(self.n_contacts)
        pts_x = np.concatenate([[x[0]], x[self.contact_nodes[1:]], [x[-1]]])
        pts_y = np.concatenate([[0.0], -stops, [w]])
        order = np.argsort(pts_x, kind="stable")
        hull = _upper_hull(pts_x[order], pts_y[order])
        hx, hy = pts_x[order][hull], pts_y[order][hull]
        u = np.interp(x, hx, hy)
        slope = np.diff(u) / np.diff(x)
        stress = E * slope
        p = np.empty(self.n_contacts)
        p[0] = -stress[-1]
        for i, node in enumerate(self.contact_nodes[1:], start=1):
            p[i] = stress[node - 1] - stress[node]  # jump of the normal force / A
        return u[1:], p


def _upper_hull(x: np.ndarray, y: np.ndarray) -> list[int]:
    """Indices of the upper concave envelope of points sorted by ``x`` (monotone chain)."""
    hull: list[int] = []
    for i in range(x.size):
        while len(hull) >= 2:
            a, b = hull[-2], hull[-1]
            if (x[b] - x[a]) * (y[i] - y[a]) - (y[b] - y[a]) * (x[i] - x[a]) >= 0:
                hull.pop()  # b lies on or below the chord a-i
            else:
                break
        hull.append(i)
    return hull


def bar_chain(*, length: float, elements: int, area: float = 1.0, youngs_modulus: float | None = None,
              tip_positions=None, stops: dict[int, float] | None = None,
              dataset: MaterialDataset | None = None, name: str = "bar with stops",
              tip_displacements=None, stops_ahead: dict[int, float] | None = None) -> StoppedBarModel:
    """An N-element bar fixed at ``x = 0``, pushed by a rigid obstacle at ``x = h`` (as in the
    paper), or with its tip displaced by a hard device, with fixed stops behind (or ahead of)
    interior nodes that close one after another.

    Parameters
    ----------
    length : float
        ``l0`` (m).
    elements : int
        Number of equal elements ``N``.
    tip_positions : array_like
        Obstacle position ``h`` per step (m). Exactly one of ``tip_positions`` and
        ``tip_displacements``.
    stops : {node: clearance}, optional
        A rigid stop at ``x_j - s_j`` behind node ``j`` (``0 < j < N``): ``u_j >= -s_j``.
    tip_displacements : array_like, optional
        The tip's displacement ``u_N`` per step (m): a hard device (prescribed displacement)
        instead of the tip obstacle; the result is a :class:`HardDeviceBarModel`, its load
        parameter the tip displacement.
    stops_ahead : {node: clearance}, optional
        A rigid stop at ``x_j + a_j`` ahead of node ``j``: ``u_j <= a_j`` (a bar pulled onto it).
    """
    L = check_positive("length", length)
    if isinstance(elements, bool) or int(elements) != elements or elements < 1:
        raise InputError(f"elements must be a positive integer, got {elements!r}")
    N = int(elements)
    x = np.linspace(0.0, L, N + 1)
    if (tip_positions is None) == (tip_displacements is None):
        raise InputError("give exactly one of tip_positions (an obstacle at the tip) and tip_displacements "
                         "(a hard device at the tip)")
    tip = tip_positions if tip_displacements is None else tip_displacements
    h = np.asarray(tip, dtype=float).ravel()
    what = "tip positions" if tip_displacements is None else "tip displacements"
    if h.size == 0 or not np.all(np.isfinite(h)):
        raise InputError(f"{what} must be a non-empty list of finite numbers")
    obstacles = [Obstacle(normal=[-1.0], offset=-h, nodes=[N])] if tip_displacements is None else []
    for side, table in (("behind", stops), ("ahead of", stops_ahead)):
        for node, s in (table or {}).items():
            if isinstance(node, bool) or not isinstance(node, (int, np.integer)) or not 0 < node < N:
                raise InputError(f"stop at node {node}: interior nodes are 1..{N - 1}")
            s = float(s)
            if not np.isfinite(s) or s < 0:
                raise InputError(f"stop at node {node}: clearance must be finite and >= 0")
            if side == "behind":
                obstacles.append(Obstacle(normal=[1.0], offset=x[int(node)] - s, nodes=[int(node)]))
            else:
                obstacles.append(Obstacle(normal=[-1.0], offset=-(x[int(node)] + s), nodes=[int(node)]))
    supports = [(0, "x")] if tip_displacements is None else [(0, "x"), (N, "x", h[:, None])]
    base = truss_model(nodes=x[:, None], members=np.column_stack([np.arange(N), np.arange(1, N + 1)]),
                       area=area, youngs_modulus=youngs_modulus, supports=supports, obstacles=obstacles,
                       load_factors=None, dataset=dataset, name=name)
    kw = {f: getattr(base, f) for f in base.__dataclass_fields__ if not f.startswith("_")}
    if tip_displacements is None:
        kw.update(load_parameter=h, load_parameter_name="h", length_scale=L)
        return StoppedBarModel(**kw)
    kw.update(load_parameter=h, load_parameter_name="u_tip", length_scale=L)
    return HardDeviceBarModel(**kw)


class HardDeviceBarModel(TrussModel):
    """A bar fixed at ``x = 0`` whose tip a hard device displaces (a prescribed displacement per
    step), with fixed stops behind or ahead of interior nodes (:func:`bar_chain`). Its classical
    solution is known in closed form (:meth:`closed_form`)."""

    def closed_form(self, step: int):
        """The classical solution: the taut string through ``(0, 0)`` and ``(L, U)``.

        Without stops ``u = U x / L``, the stress ``E U / L``. With stops that the string meets
        on one side only (behind, ``u_j >= -s_j``, a bar pushed, ``U < 0``; or ahead, ``u_j <=
        a_j``, a bar pulled), the least concave majorant (behind) or the greatest convex minorant
        (ahead) of the points ``(0, 0)``, the stops and ``(L, U)``, linear between touching nodes;
        pressures are the jumps of the stress ``E u'``. ``None`` with stops on both sides (the
        general taut string is not implemented) or a bar that is not uniform.
        """
        if self.youngs_modulus is None or np.ptp(self.youngs_modulus) > 0 or np.ptp(self.member_area) > 0:
            return None
        normals = self.contact_normals[:, 0] if self.n_contacts else np.zeros(0)
        if np.any(normals > 0) and np.any(normals < 0):
            return None  # stops on both sides: the general taut string (not implemented)
        x = self.nodes[:, 0]
        E = float(self.youngs_modulus[0])
        U = float(self.prescribed.values[step, 0])
        # a pair's gap is n u_j + gap0: behind (n = +1) u_j >= -gap0; ahead (n = -1) u_j <= gap0
        bound = self.gap_offsets[step] * -normals if self.n_contacts else np.zeros(0)
        u = U * x / x[-1]
        bent = False
        for side in (+1.0, -1.0):  # behind: concave majorant; ahead: convex minorant (negated)
            on = normals == side
            if not np.any(on):
                continue
            pts_x = np.concatenate([[x[0]], x[self.contact_nodes[on]], [x[-1]]])
            pts_y = side * np.concatenate([[0.0], bound[on], [U]])
            order = np.argsort(pts_x, kind="stable")
            hull = _upper_hull(pts_x[order], pts_y[order])
            candidate = side * np.interp(x, pts_x[order][hull], pts_y[order][hull])
            if np.any(side * (candidate - u) > 0):
                if bent:
                    return None  # stops on both sides touch
                u, bent = candidate, True
        gaps = normals * u[self.contact_nodes] + self.gap_offsets[step] if self.n_contacts else np.zeros(0)
        if np.any(gaps < -1e-12 * max(1.0, abs(U))):
            return None
        stress = E * np.diff(u) / np.diff(x)
        p = np.empty(self.n_contacts)
        for i, node in enumerate(self.contact_nodes):
            p[i] = normals[i] * (stress[node - 1] - stress[node])  # jump of the normal force / A
        return u[1:-1], p


def warren_truss(*, panels: int, gap: float, contact_nodes, load_factors, panel_length: float = 1.0,
                 height: float = 0.8, area: float = 1e-3, youngs_modulus: float | None = 200e9,
                 node_load: float = 1e5, dataset=None, name: str | None = None) -> TrussModel:
    """A 2-D Warren truss on a pin and a roller, its top nodes loaded downwards, above a plane.

    Parameters
    ----------
    panels : int
        Number of bottom-chord panels (``4 panels - 1`` members, ``2 panels + 1`` nodes).
    gap : float or sequence of float
        Initial distance (m) between the bottom chord and the plane ``y = -gap`` under each
        contact node (one value, or one per contact node: a stepped ground).
    contact_nodes : sequence of int
        Bottom-chord nodes (``0 .. panels``) that may touch the ground.
    load_factors : sequence of float
        Load path: the top-node loads ``-node_load`` (N, in ``y``) times each factor.
    """
    panels = int(panels)
    if panels < 2:
        raise InputError(f"a Warren truss needs at least 2 panels, got {panels}")
    nb = panels + 1
    X = np.vstack([np.column_stack([np.arange(nb) * panel_length, np.zeros(nb)]),
                   np.column_stack([(np.arange(panels) + 0.5) * panel_length, np.full(panels, height)])])
    i = np.arange(panels)
    members = np.vstack([np.column_stack([i, i + 1]), np.column_stack([nb + i[:-1], nb + i[1:]]),
                         np.column_stack([i, nb + i]), np.column_stack([i + 1, nb + i])])
    loads = np.zeros_like(X)
    loads[nb:, 1] = -node_load
    contact_nodes = np.asarray(contact_nodes, dtype=int).ravel()
    gaps = np.broadcast_to(np.asarray(gap, dtype=float), contact_nodes.shape)
    obstacles = [Obstacle(normal=[0, 1], offset=-float(g), nodes=contact_nodes[gaps == g].tolist())
                 for g in np.unique(gaps)]
    return truss_model(nodes=X, members=members, area=area, youngs_modulus=youngs_modulus,
                       supports=[(0, "xy"), (panels, "y")], loads=loads, obstacles=obstacles,
                       load_factors=list(load_factors), dataset=dataset,
                       name=name or f"Warren truss, {panels} panels")
