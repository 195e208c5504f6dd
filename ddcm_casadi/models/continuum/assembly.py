"""Assembling a continuum: the checked pieces :func:`~ddcm_casadi.models.continuum.model.continuum_model`
is built from.

- materials: :func:`element_materials` (regions), :func:`isotropic_law` (``E``, ``nu`` per point),
  :func:`point_data` (the data sets of the points);
- supports and loads: :func:`free_dofs`, :func:`reference_loads` (tractions, body forces);
- load path and contact: :func:`step_count`, :func:`contact_pairs` (one pair per boundary dof of
  each contact surface, with its gap operator row, tributary area and reference gaps).

Each checks its own input with a one-line :class:`~ddcm_casadi.errors.InputError`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.sparse as sp
import skfem

from ddcm_casadi.data.dataset import MaterialDataset, PointData
from ddcm_casadi.data.metric import isotropic_elasticity
from ddcm_casadi.errors import InputError
from ddcm_casadi.models import coulomb
from ddcm_casadi.models.continuum import fem, mortar
from ddcm_casadi.models.continuum.mesh import select_facets
from ddcm_casadi.models.continuum.inputs import (DEFAULT_SEARCH_SHARE, BodyContact, BodyForce, Contact, Material,
                                                 Support, Traction)
from ddcm_casadi.models.continuum.obstacles import Obstacle

#: Axis letters of support components.
AXES = "xyz"


# --- small checks
def _components(spec: str, d: int) -> list[int]:
    """The axes (0, 1, 2) of a support's components such as ``"xy"``."""
    if not isinstance(spec, str) or not spec or any(c not in AXES[:d] for c in spec.lower()):
        raise InputError(f"support components must be letters from {AXES[:d]!r}, got {spec!r}")
    return sorted({AXES.index(c) for c in spec.lower()})


def elements_of(mesh: skfem.Mesh, region: str) -> np.ndarray:
    """The elements of the named subdomain ``region``."""
    subs = getattr(mesh, "subdomains", None) or {}
    if region not in subs:
        known = ", ".join(sorted(subs)) or "none"
        raise InputError(f"unknown region {region!r}; the mesh's regions: {known}")
    return np.asarray(subs[region], dtype=np.int64)


def _vector(name: str, value, d: int) -> np.ndarray:
    """``d`` finite numbers."""
    v = np.asarray(value, dtype=float).ravel()
    if v.size != d or not np.all(np.isfinite(v)):
        raise InputError(f"{name} must be {d} finite numbers, got {value!r}")
    return v


# --- materials
def element_materials(mesh: skfem.Mesh, materials: Sequence[Material]) -> np.ndarray:
    """The index in ``materials`` of every element: its region's, else the unnamed material's."""
    if not materials:
        raise InputError("a continuum needs at least one material")
    element_material = np.full(mesh.t.shape[1], -1, dtype=np.int64)
    rest = [i for i, mat in enumerate(materials) if mat.region is None]
    if len(rest) > 1:
        raise InputError("only one material may leave its region unnamed (the rest of the mesh)")
    for i, mat in enumerate(materials):
        if mat.region is not None:
            els = elements_of(mesh, mat.region)
            if np.any(element_material[els] >= 0):
                raise InputError(f"region {mat.region!r} overlaps another material's region")
            element_material[els] = i
    if rest:
        element_material[element_material < 0] = rest[0]
    if np.any(element_material < 0):
        raise InputError(f"{int(np.sum(element_material < 0))} elements have no material; "
                         "add a material without a region for the rest of the mesh")
    return element_material


def isotropic_law(materials: Sequence[Material], point_region: np.ndarray,
                   d: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``E`` and ``nu`` per material point if every material has a law, ``(None, None)`` if none has."""
    has_law = [m.youngs_modulus is not None for m in materials]
    if all(has_law):
        for mat in materials:  # checks each law, with the values the user gave
            isotropic_elasticity(mat.youngs_modulus, mat.poisson_ratio, d)
        E = np.array([m.youngs_modulus for m in materials], dtype=float)[point_region]
        nu = np.array([m.poisson_ratio for m in materials], dtype=float)[point_region]
        return E, nu
    if any(has_law):
        raise InputError("give youngs_modulus and poisson_ratio for every material, or for none (DDCM only)")
    return None, None


def point_data(materials: Sequence[Material], datasets: Sequence[MaterialDataset], point_region: np.ndarray,
                d: int, k: int) -> MaterialDataset | PointData | None:
    """The data of the material points: one shared set, one set per material (:class:`PointData`),
    or ``None`` if no material names a data set."""
    has_data = [m.data is not None for m in materials]
    if not any(has_data):
        return None
    if not all(has_data):
        raise InputError("give a data set for every material, or for none (classical only)")
    sets = list(datasets)
    for mat in materials:
        if not 0 <= int(mat.data) < len(sets):
            raise InputError(f"material data index {mat.data!r} out of range: {len(sets)} data sets")
    for s in sets:
        if s.k != k:
            raise InputError(f"a data set has {s.k} strain components per point; a {d}-D continuum "
                             f"needs {k} (Mandel: {'e11,e22,sqrt2 e12' if d == 2 else 'e11,e22,e33,sqrt2 e23,sqrt2 e13,sqrt2 e12'})")
    per_point = np.array([materials[i].data for i in range(len(materials))])[point_region]
    if len(sets) == 1:
        return sets[0]
    return PointData(sets, per_point)


# --- supports and loads
def free_dofs(disc: fem.Discretisation, supports: Sequence[Support]) -> np.ndarray:
    """The dofs no support fixes (the unknowns), in order."""
    vdofs = disc.vector_dofs()
    fixed = np.zeros(disc.n_dofs, dtype=bool)
    for s in supports:
        comps = _components(s.components, disc.dimension)
        dofs = fem.boundary_dofs(disc, select_facets(disc.mesh, s.where))
        for c in comps:
            fixed[vdofs[c, dofs]] = True
    free = np.flatnonzero(~fixed)
    if free.size == 0:
        raise InputError("the supports fix every degree of freedom")
    return free


def reference_loads(disc: fem.Discretisation, tractions: Sequence[Traction],
                     body_forces: Sequence[BodyForce]) -> np.ndarray:
    """The load vector over all dofs at load factor 1: surface tractions plus body forces."""
    mesh, d = disc.mesh, disc.dimension
    f_ref = np.zeros(disc.n_dofs)
    for t in tractions:
        f_ref += fem.surface_load(disc, select_facets(mesh, t.where), _vector("traction", t.traction, d))
    for b in body_forces:
        els = None if b.region is None else elements_of(mesh, b.region)
        f_ref += fem.body_load(disc, _vector("body force", b.force_density, d), els)
    return f_ref


# --- load path and contact pairs
def step_count(load_factors: Sequence[float] | None, contacts: Sequence[Contact]) -> int:
    """Steps: one per load factor, else one per value of the first travel given per step, else one."""
    n_steps = None
    if load_factors is not None:
        n_steps = len(load_factors)
    for c in contacts:
        trav = np.asarray(c.travel)
        if trav.ndim == 1 and n_steps is None:
            n_steps = trav.size
    return n_steps or 1


def _check_not_through(ob: Obstacle, gaps: np.ndarray, nodes: np.ndarray, n_steps: int) -> None:
    """Refuse an obstacle whose travel takes it through the body.

    The body's extent along the direction of travel ``d`` is ``ptp(X . d)`` over its nodes. The
    obstacle's advance past its first position of contact is ``s_t - s_0 - max(min g_0, 0)``
    (``g_0`` the gaps at the first step: the way it has to go before it touches); an advance
    beyond the extent, or one step forward in which a pair goes from inside the obstacle to a
    gap larger than the extent, can only mean it went through the body and out the other side
    (its gaps are then positive again and it carries no force, silently). The threshold is the extent itself: no less than
    the whole body, so an indentation of any depth a small-strain model can mean passes.
    """
    direction = ob.offset(1.0)
    extent = float(np.ptp(nodes @ direction))
    s = ob.travels(n_steps)
    approach = max(float(np.min(gaps[0])), 0.0) if gaps.size else 0.0  # the way to go before it touches
    advance = s - s[0] - approach
    worst = int(np.argmax(advance))
    if advance[worst] > extent:
        raise InputError(f"obstacle {ob.name!r} passes through the body: its travel {s[worst]:.3g} m takes it "
                         f"{advance[worst]:.3g} m past first contact, beyond the body's extent {extent:.3g} m "
                         f"along its direction; reduce the travel")
    # out the other side: a pair inside the obstacle at one step and outside at the next while the
    # obstacle advances (an approach from afar, + to -, and a release while it retreats are fine)
    through = (gaps[:-1] <= 0) & (gaps[1:] > 0) & (np.diff(s) > 0)[:, None]
    jump = np.diff(gaps, axis=0) * through
    if jump.size and float(np.max(jump)) > extent:
        step = int(np.argmax(np.max(jump, axis=1)))
        raise InputError(f"obstacle {ob.name!r} passes through the body between steps {step} and {step + 1}: "
                         f"a gap opens from inside it to {float(np.max(jump)):.3g} m, more than the body's extent "
                         f"{extent:.3g} m along its direction; use smaller steps of travel")


#: A reference gap below ``-PENETRATION_TOL`` times the body's size is a penetration (the
#: tolerance of :func:`~ddcm_casadi.models.scales.load_path_warnings`: 1e-12 of the size is
#: roundoff of coordinates, far below any indentation).
PENETRATION_TOL = 1e-12


def _check_movable(movable: np.ndarray, gap0: np.ndarray, points: np.ndarray, owner: np.ndarray,
                   obstacles: list, size: float) -> None:
    """Refuse an obstacle that presses on pairs whose every displacement component is fixed
    (``movable`` false): the gap there cannot open, so no pressure satisfies contact (the solvers end not converged)."""
    stuck = ~movable & np.any(gap0 < -PENETRATION_TOL * size, axis=0)
    if np.any(stuck):
        first = int(np.flatnonzero(stuck)[0])
        step = int(np.argmin(gap0[:, first]))
        raise InputError(f"obstacle {obstacles[owner[first]].name!r} presses on {int(stuck.sum())} contact node(s) "
                         f"the supports fix in every direction (first at "
                         f"({', '.join(f'{c:.3g}' for c in points[first])}), penetration "
                         f"{-float(gap0[step, first]):.3g} m at step {step}): they cannot move out of its way; "
                         f"free them or keep the obstacle off them")


@dataclass(frozen=True)
class PairSet:
    """The pairs of one contact record, before the supports drop their fixed columns.

    Attributes
    ----------
    dofs : (nc,) int
        The scalar dof (node) of each pair.
    points, normals : (nc, d)
        Its reference coordinates and the normal its gap is measured along.
    area : (nc,)
        The area its pressure acts on.
    gap0 : (n_steps, nc)
        Gaps of the reference configuration per step.
    rows : sparse (nc, n_dofs)
        ``dg/du`` over every vector dof of the mesh.
    facets : (nf,) int
        The boundary facets the pairs stand on.
    counterpart
        What the pairs touch: the rigid :class:`~.obstacles.Obstacle`, or the master surface
        (:class:`~.mortar.MasterSurface`).
    """

    dofs: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    area: np.ndarray
    gap0: np.ndarray
    rows: sp.csr_matrix
    facets: np.ndarray
    counterpart: object


def _normal_rows(disc: fem.Discretisation, dofs: np.ndarray, normals: np.ndarray) -> sp.csr_matrix:
    """``(nc, n_dofs)``: each pair's normal on the vector dofs of its own node."""
    nc, d = normals.shape
    cols = disc.vector_dofs()[:, dofs].T  # (nc, d)
    return sp.csr_matrix((normals.ravel(), (np.repeat(np.arange(nc), d), cols.ravel())), shape=(nc, disc.n_dofs))


def friction_fields(disc: fem.Discretisation, contacts: Sequence, contact: dict, counterparts: list,
                    free: np.ndarray, n_steps: int) -> dict:
    """The :class:`~ddcm_casadi.models.base.ContactModel` fields of Coulomb friction
    (``tangent_operator``, ``friction``, ``slip_offsets``) if any contact record has a
    ``friction``, else none: per pair its tangents (:func:`tangent_basis`) on the vector dofs of
    its node, component-major, and minus its obstacle's displacement along them per step."""
    if not any(getattr(c, "friction", None) is not None for c in contacts):
        return {}
    for i, c in enumerate(contacts):
        if c.kind != "obstacle" and getattr(c, "friction", None) is not None:
            raise InputError(f"contact {i} ({c.name!r}): friction between two bodies is not supported yet "
                             "(rigid obstacles only)")
    owner, normals = contact["contact_obstacle"], contact["contact_normals"]
    if not owner.size:
        return {}
    mu = np.array([contacts[o].friction or 0.0 for o in owner], float)
    for c in contacts:
        if c.friction is not None and not (np.isfinite(c.friction) and c.friction >= 0):
            raise InputError(f"contact {c.name!r}: friction must be a number >= 0, got {c.friction!r}")
    tangents = coulomb.tangent_basis(normals)  # (nc, d - 1, d)
    rows = sp.vstack([_normal_rows(disc, contact["contact_dofs"], tangents[:, j]) for j in range(tangents.shape[1])])
    motion = np.stack([np.asarray(counterparts[o].displacements(n_steps)) for o in owner], axis=1)  # (steps, nc, d)
    offsets = -np.einsum("snd,njd->sjn", motion, tangents).reshape(n_steps, -1)
    return dict(tangent_operator=rows[:, free].tocsr(), friction=mu, slip_offsets=offsets)


def _obstacle_pairs(disc: fem.Discretisation, c: Contact, index: int, n_steps: int, size: float) -> PairSet:
    """One pair per boundary dof of the contact surface against its rigid obstacle."""
    d, ob = disc.dimension, c.obstacle
    if ob.dimension != d:
        raise InputError(f"obstacle {ob.name!r} is {ob.dimension}-D, the mesh {d}-D")
    facets = _facets_of(disc, c.where, f"contact {index} (obstacle {ob.name!r})")
    dofs, area = fem.tributary_areas(disc, facets)
    X = disc.dof_locations()[dofs]
    gaps = ob.gap_offsets(X, n_steps)
    if float(np.min(gaps)) > size:
        raise InputError(f"obstacle {ob.name!r} cannot touch the body: it comes no closer than "
                         f"{float(np.min(gaps)):.3g} m along the path, more than the body's size {size:.3g} m")
    if ob.motion is None:  # a path of any shape is the user's to mean
        _check_not_through(ob, gaps, disc.mesh.p.T, n_steps)
    N = ob.normals(X, n_steps)
    return PairSet(dofs, X, N, area, gaps, _normal_rows(disc, dofs, N), facets, ob)


def _body_pairs(disc: fem.Discretisation, c: BodyContact, index: int, n_steps: int, size: float) -> PairSet:
    """The mortar pairs of a slave boundary against a master surface
    (:func:`~.mortar.mortar_coupling`, at the reference configuration)."""
    mortar.check_linear(disc.degree, c.name)
    mesh, d = disc.mesh, disc.dimension
    slave = _facets_of(disc, c.slave, f"contact {index} ({c.name!r}) slave")
    master = _facets_of(disc, c.master, f"contact {index} ({c.name!r}) master")
    if np.intersect1d(mesh.facets[:, slave], mesh.facets[:, master]).size:
        raise InputError(f"contact {index} ({c.name!r}): the slave and master boundaries share nodes; "
                         "contact is between two separate surfaces")
    reach = DEFAULT_SEARCH_SHARE * size if c.search_distance is None else float(c.search_distance)
    if not (np.isfinite(reach) and reach > 0):
        raise InputError(f"contact {index} ({c.name!r}): search_distance must be a positive length, got {reach!r}")
    X = mesh.p.T
    coupling = mortar.mortar_coupling(X, mortar.Surface.of(mesh, slave), mortar.Surface.of(mesh, master), reach)
    if not coupling.nodes.size:
        raise InputError(f"contact {index} ({c.name!r}): no slave node faces the master surface within "
                         f"{reach:.3g} m (search_distance); check the boundaries, or increase the search distance")
    # dg_j/du: the weights of node k times n_j on its component dofs (P1: node = scalar dof)
    W = (coupling.master_weights - coupling.slave_weights).tocoo()
    vd = disc.vector_dofs()
    rows = sp.csr_matrix((np.concatenate([W.data * coupling.normals[W.row, i] for i in range(d)]),
                          (np.tile(W.row, d), np.concatenate([vd[i, W.col] for i in range(d)]))),
                         shape=(coupling.nodes.size, disc.n_dofs))
    gap0 = np.repeat(coupling.gaps(X)[None, :], n_steps, axis=0)
    surface = mortar.MasterSurface(name=c.name, dimension=d, facets=master, facet_pairs=coupling.facet_pairs,
                                   dropped=coupling.dropped, search_distance=reach)
    return PairSet(coupling.nodes, X[coupling.nodes], coupling.normals, coupling.area, gap0, rows, slave, surface)


#: How each kind of contact record (``Contact.kind``) becomes pairs.
PAIR_BUILDERS = {"obstacle": _obstacle_pairs, "bodies": _body_pairs}


def _facets_of(disc: fem.Discretisation, where, label: str) -> np.ndarray:
    facets = select_facets(disc.mesh, where)
    if not facets.size:
        # a name or a FacetBox / FacetPlane (dataclasses) shows itself; a bare function does not
        shown = repr(where) if isinstance(where, str) or hasattr(where, "__dataclass_fields__") else "its facet test"
        raise InputError(f"{label}: boundary {shown} matches no boundary facet of the mesh")
    return facets


def contact_pairs(disc: fem.Discretisation, contacts: Sequence[Contact | BodyContact], free: np.ndarray,
                   n_steps: int, size: float) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray, list, dict]:
    """The complementarity pairs of every contact record: one per boundary dof against a rigid
    obstacle, one per covered slave node between two bodies (:data:`PAIR_BUILDERS`).

    Returns
    -------
    G_all : sparse (nc, n_dofs)
        Gap operator ``dg/du`` over every vector dof of the mesh (the model keeps the free
        columns; a hard device's prescribed columns move the gaps too).
    area : (nc,) ndarray
        The areas the pressures act on.
    gap0 : (n_steps, nc) ndarray
        Gaps of the reference configuration per step.
    counterparts : list
        What each record's pairs touch (an obstacle or a master surface), in the order of ``contacts``.
    contact : dict
        The :class:`ContinuumModel` fields ``contact_dofs``, ``contact_points``,
        ``contact_normals``, ``contact_obstacle`` (the record of each pair) and
        ``contact_facets`` (the boundary facets of each record's pairs).
    """
    d = disc.dimension
    if contacts and d == 3 and disc.degree == 2:
        # int_f phi_vertex = 0 on a quadratic triangle: a uniform pressure puts no force on the
        # vertices, so nodal contact would leave them biactive and their pressures meaningless.
        raise InputError("contact on quadratic tetrahedra is not supported (a quadratic triangle's vertices "
                         "carry no share of a pressure); use degree = 1 in 3-D")
    sets = [PAIR_BUILDERS[c.kind](disc, c, i, n_steps, size) for i, c in enumerate(contacts)]
    counterparts = [s.counterpart for s in sets]
    facet_sets = tuple(s.facets for s in sets)
    nc = int(sum(s.dofs.size for s in sets))
    if not nc:
        contact = dict(contact_dofs=np.zeros(0, np.int64), contact_points=np.zeros((0, d)),
                       contact_normals=np.zeros((0, d)), contact_obstacle=np.zeros(0, np.int64),
                       contact_facets=facet_sets)
        return sp.csr_matrix((0, disc.n_dofs)), np.zeros(0), np.zeros((n_steps, 0)), counterparts, contact
    G_all = sp.vstack([s.rows for s in sets]).tocsr()
    gap0 = np.concatenate([s.gap0 for s in sets], axis=1)
    owner = np.concatenate([np.full(s.dofs.size, i) for i, s in enumerate(sets)])
    points = np.concatenate([s.points for s in sets])
    _check_movable(np.asarray(abs(G_all[:, free]).sum(axis=1)).ravel() > 0, gap0, points, owner, counterparts, size)
    contact = dict(contact_dofs=np.concatenate([s.dofs for s in sets]), contact_points=points,
                   contact_normals=np.concatenate([s.normals for s in sets]), contact_obstacle=owner,
                   contact_facets=facet_sets)
    return G_all, np.concatenate([s.area for s in sets]), gap0, counterparts, contact
