"""Assembling a truss: the checked pieces :func:`~ddcm_casadi.models.truss.truss_model` is built from.

One function per piece, each checking its own input with a one-line :class:`InputError`:

- geometry: :func:`node_coordinates`, :func:`member_geometry`, :func:`per_member` (sections, moduli);
- kinematics and supports: :func:`fixed_directions`, :func:`strain_operator` (``B``, free columns),
  :func:`prescribed_supports` (a hard device: supports with a displacement);
- loads: :func:`reference_loads` (nodal and distributed, lumped to the nodes);
- contact: :func:`contact_pairs` (one per obstacle and node), :func:`load_path` (load factors and
  the number of steps), :func:`gap_operator` (``G`` and ``gap0``), :func:`contact_areas`;
- checks and data: :func:`check_not_mechanism`, :func:`member_data`.

Every operator is built from index arrays, without a loop over members.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ddcm_casadi.data.dataset import MaterialDataset, PointData
from ddcm_casadi.errors import InputError
from ddcm_casadi.models import coulomb

@dataclass(frozen=True)
class Obstacle:
    """A rigid plane ``n . x = d`` acting on ``nodes``; the admissible side is ``n . x >= d``.

    Parameters
    ----------
    normal : sequence of float
        Outward normal of the obstacle (normalised here).
    offset : float or sequence of float
        ``d`` (m): a constant, or one value per load step (a moving obstacle).
    nodes : sequence of int
        Nodes that may touch this obstacle (one contact pair each).
    friction : float, optional
        Coulomb's ``mu >= 0`` (2-D and 3-D trusses; ``None``: frictionless). The obstacle moves
        along its normal only, so the slip of a step is the node's tangential displacement.
    """

    normal: Sequence[float]
    offset: float | Sequence[float]
    nodes: Sequence[int]
    friction: float | None = None



#: Axis letters of supports (``"xy"``, ``"z"``, ...).
AXES = "xyz"

#: Up to this many unknowns the mechanism check is an exact eigenvalue count (dense, n x n).
EXACT_RANK_LIMIT = 1000


# ------------------------------------------------------------------------------ geometry
def node_coordinates(nodes) -> np.ndarray:
    """The ``(nn, d)`` node coordinates, ``d`` in {1, 2, 3}; a flat list is a 1-D truss."""
    X = np.asarray(nodes, dtype=float)
    if X.ndim == 1:
        X = X[:, None]
    if X.ndim != 2 or X.shape[1] not in (1, 2, 3) or X.shape[0] < 2:
        raise InputError("nodes must be a list of at least two points with 1, 2 or 3 coordinates each")
    if not np.all(np.isfinite(X)):
        raise InputError("node coordinates must be finite")
    return X


def member_geometry(members, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Members as node pairs, their lengths and unit vectors.

    Parameters
    ----------
    members : (ne, 2) array_like of int
        Node pairs ``(i, j)``.
    X : (nn, d) ndarray
        Node coordinates.

    Returns
    -------
    M : (ne, 2) ndarray of int
        The node pairs.
    length : (ne,) ndarray
        Member lengths (all positive).
    unit : (ne, d) ndarray
        Unit vectors from node ``i`` to node ``j``.
    """
    nn = X.shape[0]
    M = np.asarray(members)
    if M.ndim != 2 or M.shape[1] != 2 or M.shape[0] == 0 or not np.issubdtype(M.dtype, np.integer):
        raise InputError("members must be a non-empty list of [node_i, node_j] integer pairs")
    if M.min() < 0 or M.max() >= nn:
        raise InputError(f"member refers to a node outside 0..{nn - 1}")
    vec = X[M[:, 1]] - X[M[:, 0]]
    length = np.linalg.norm(vec, axis=1)
    if np.any(length <= 0):
        raise InputError(f"member {int(np.argmin(length))} has zero length")
    return M, length, vec / length[:, None]


def per_member(name: str, value, ne: int) -> np.ndarray:
    """One finite, positive number per member from one number or ``ne`` of them."""
    a = np.asarray(value, dtype=float)
    if a.ndim == 0:
        a = np.full(ne, float(a))
    if a.shape != (ne,):
        raise InputError(f"{name} must be one number or one per member ({ne}), got {a.size}")
    if not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise InputError(f"{name} must be finite and positive for every member")
    return a


# ------------------------------------------------------------------ supports and kinematics
def fixed_directions(supports, nn: int, d: int) -> np.ndarray:
    """The ``(nn, d)`` mask of fixed directions.

    Parameters
    ----------
    supports : (nn, d) array_like of bool, or sequence of (node, axes) or (node, axes, displacement)
        The mask itself, or fixed directions by node such as ``[(0, "xy"), (4, "y")]``; a
        support with a displacement (:func:`prescribed_supports`) holds its axes too.
    nn, d : int
        Number of nodes and dimension.
    """
    if _is_mask(supports, nn, d):
        return np.asarray(supports, dtype=bool)
    fixed = np.zeros((nn, d), dtype=bool)
    for entry in supports:
        try:
            node, axes = entry[:2] if isinstance(entry, (list, tuple)) and len(entry) == 3 else entry
            node = int(node)
        except (TypeError, ValueError):
            raise InputError(f"support {entry!r} must be (node, axes) such as (0, 'xy')") from None
        if not 0 <= node < nn:
            raise InputError(f"support at node {node}: nodes are numbered 0..{nn - 1}")
        axes = str(axes).lower()
        bad = [a for a in axes if a not in AXES[:d]]
        if bad or not axes:
            raise InputError(f"support at node {node}: axes must be letters from {AXES[:d]!r}, got {axes!r}")
        for a in axes:
            fixed[node, AXES.index(a)] = True
    return fixed


def _is_mask(supports, nn: int, d: int) -> bool:
    """Whether ``supports`` is the ``(nn, d)`` boolean mask form."""
    try:
        arr = np.asarray(supports, dtype=object)
    except ValueError:  # ragged: entries with displacements
        return False
    return arr.shape == (nn, d) and all(isinstance(v, (bool, np.bool_)) for v in arr.ravel())


def prescribed_supports(supports, nn: int, d: int) -> list[tuple[int, list[int], object]]:
    """The supports with a displacement (a hard device): ``(node, axes, displacement)`` for each
    ``(node, axes, displacement)`` entry of ``supports``, ``axes`` as indices; the displacement as
    given (one ``d``-vector scaled by the load factors, or one per step: checked by
    :func:`~ddcm_casadi.models.prescribed.displacement_path`)."""
    if _is_mask(supports, nn, d):
        return []
    out, seen = [], {}
    for entry in supports:
        if not (isinstance(entry, (list, tuple)) and len(entry) == 3):
            continue
        node, axes, value = entry
        node = int(node)
        idx = [AXES.index(a) for a in str(axes).lower()]
        for c in idx:
            if (node, c) in seen:
                raise InputError(f"support at node {node}: two displacements prescribed along {AXES[c]}")
            seen[node, c] = True
        out.append((node, sorted(set(idx)), value))
    return out


def strain_operator(M: np.ndarray, unit: np.ndarray, length: np.ndarray, nn: int,
                    free: np.ndarray) -> sp.csr_matrix:
    """``B`` (ne x free dofs): member strains ``e . (u_j - u_i) / L`` from the free displacements."""
    ne, d = unit.shape
    # -e/L at node i, +e/L at node j over all nn d dofs; then keep the free columns.
    rows = np.repeat(np.arange(ne), 2 * d)
    cols = np.concatenate([M[:, [0]] * d + np.arange(d), M[:, [1]] * d + np.arange(d)], axis=1).ravel()
    vals = np.concatenate([-unit / length[:, None], unit / length[:, None]], axis=1).ravel()
    return sp.csr_matrix((vals, (rows, cols)), shape=(ne, nn * d))[:, free]


# ------------------------------------------------------------------------------ loads
def nodal_array(name: str, value, nn: int, d: int) -> np.ndarray:
    """A finite ``(nn, d)`` array, one vector per node (a flat list in 1-D)."""
    a = np.asarray(value, dtype=float)
    if a.ndim == 1 and d == 1:
        a = a[:, None]
    if a.shape != (nn, d) or not np.all(np.isfinite(a)):
        raise InputError(f"{name} must be finite, one {d}-vector per node")
    return a


def reference_loads(loads, distributed_loads, M: np.ndarray, length: np.ndarray, nn: int,
                    d: int) -> np.ndarray:
    """The ``(nn, d)`` reference nodal forces: ``loads`` plus ``distributed_loads`` (per unit
    length of each member) lumped half to each end node."""
    f_ref = np.zeros((nn, d))
    if loads is not None:
        f_ref += nodal_array("loads", loads, nn, d)
    if distributed_loads is not None:
        q = np.asarray(distributed_loads, dtype=float)
        if q.shape != (M.shape[0], d) or not np.all(np.isfinite(q)):
            raise InputError(f"distributed_loads must be finite, one {d}-vector per member")
        half = 0.5 * q * length[:, None]
        np.add.at(f_ref, M[:, 0], half)
        np.add.at(f_ref, M[:, 1], half)
    return f_ref


# ------------------------------------------------------------------------------ contact
@dataclass(frozen=True)
class ContactPairs:
    """The contact pairs of a truss, one per (obstacle, node), in obstacle order.

    Parameters
    ----------
    normals : list of (d,) ndarray
        The obstacle's unit normal of each pair.
    nodes : list of int
        The node of each pair.
    offsets : list of ndarray
        The obstacle's offset of each pair: one value, or one per step.
    n_steps : int or None
        The number of steps the offsets per step give (``None``: all constant).
    frictions : list of float or None
        The obstacle's Coulomb coefficient of each pair (``None``: frictionless).
    """

    normals: list
    nodes: list
    offsets: list
    n_steps: int | None
    frictions: list = field(default_factory=list)

    def friction_fields(self, X: np.ndarray, free: np.ndarray) -> dict:
        """The :class:`~ddcm_casadi.models.base.ContactModel` fields of Coulomb friction if an
        obstacle has a ``friction``, else none: per pair its unit tangents
        (:func:`~ddcm_casadi.models.coulomb.tangent_basis`) on its node's dofs, component-major."""
        if not any(f is not None for f in self.frictions):
            return {}
        nn, d = X.shape
        tangents = coulomb.tangent_basis(np.asarray(self.normals))  # (nc, d - 1, d)
        dof = (self.node_indices()[:, None] * d + np.arange(d)).ravel()
        rows = [sp.csr_matrix((tangents[:, j].ravel(), (np.repeat(np.arange(self.count), d), dof)),
                              shape=(self.count, nn * d)) for j in range(d - 1)]
        return dict(tangent_operator=sp.vstack(rows).tocsr()[:, free],
                    friction=np.array([f or 0.0 for f in self.frictions], float))

    @property
    def count(self) -> int:
        return len(self.nodes)

    def node_indices(self) -> np.ndarray:
        return np.asarray(self.nodes, dtype=np.intp)


def contact_pairs(obstacles: Sequence[Obstacle], nn: int, d: int) -> ContactPairs:
    """Check the obstacles and list their contact pairs (normals normalised)."""
    normals, pair_nodes, offsets, frictions = [], [], [], []
    steps_from_obstacles = None
    for k, ob in enumerate(obstacles):
        n = np.asarray(ob.normal, dtype=float).ravel()
        if n.size != d or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
            raise InputError(f"obstacle {k}: normal must be a non-zero {d}-vector")
        n = n / np.linalg.norm(n)
        nodes_k = np.asarray(ob.nodes).ravel()
        if nodes_k.size == 0 or not np.issubdtype(nodes_k.dtype, np.integer) or nodes_k.min() < 0 or nodes_k.max() >= nn:
            raise InputError(f"obstacle {k}: nodes must be a non-empty list of node indices 0..{nn - 1}")
        if np.unique(nodes_k).size != nodes_k.size:
            raise InputError(f"obstacle {k}: a node is listed twice")
        off = np.asarray(ob.offset, dtype=float).ravel()
        if not np.all(np.isfinite(off)) or off.size == 0:
            raise InputError(f"obstacle {k}: offset must be finite")
        if off.size > 1:
            if steps_from_obstacles not in (None, off.size):
                raise InputError("obstacles with offsets per step must all have the same number of steps")
            steps_from_obstacles = off.size
        if ob.friction is not None and not (np.isfinite(ob.friction) and ob.friction >= 0):
            raise InputError(f"obstacle {k}: friction must be a number >= 0, got {ob.friction!r}")
        if ob.friction is not None and d == 1:
            raise InputError(f"obstacle {k}: friction needs a 2-D or 3-D truss (a 1-D one has no tangent)")
        for node in nodes_k:
            normals.append(n)
            pair_nodes.append(int(node))
            offsets.append(off)
            frictions.append(ob.friction)
    return ContactPairs(normals, pair_nodes, offsets, steps_from_obstacles, frictions)


def load_path(load_factors, steps_from_obstacles: int | None) -> tuple[np.ndarray, int]:
    """The load factor of every step and the number of steps.

    Default: ones, as many steps as the obstacle offsets (or the prescribed displacements given
    per step) have, or one. Given load factors must agree with that number of steps.
    """
    lf = None if load_factors is None else np.asarray(load_factors, dtype=float).ravel()
    if lf is not None and (lf.size == 0 or not np.all(np.isfinite(lf))):
        raise InputError("load_factors must be a non-empty list of finite numbers")
    n_steps = lf.size if lf is not None else (steps_from_obstacles or 1)
    if steps_from_obstacles is not None and steps_from_obstacles != n_steps:
        raise InputError(f"{n_steps} load factors but obstacle offsets for {steps_from_obstacles} steps")
    if lf is None:
        lf = np.ones(n_steps)
    return lf, n_steps


def gap_operator(pairs: ContactPairs, X: np.ndarray, free: np.ndarray,
                 n_steps: int) -> tuple[sp.csr_matrix, np.ndarray]:
    """``G`` (nc x free dofs, ``n . u`` at each pair's node) and ``gap0`` (n_steps x nc),
    ``n . X - d`` with the obstacle's offset ``d`` of each step."""
    nn, d = X.shape
    nc = pairs.count
    dof = (pairs.node_indices()[:, None] * d + np.arange(d)).ravel() if nc else np.zeros(0, np.intp)
    G_full = sp.csr_matrix((np.asarray(pairs.normals).ravel() if nc else np.zeros(0),
                            (np.repeat(np.arange(nc), d), dof)), shape=(nc, nn * d))
    if nc:
        base = np.einsum("ij,ij->i", np.asarray(pairs.normals), X[np.asarray(pairs.nodes)])
        off = np.column_stack([np.broadcast_to(o, (n_steps,)) for o in pairs.offsets])
        gap0 = base[None, :] - off
    else:
        gap0 = np.zeros((n_steps, 0))
    return G_full[:, free], gap0


def contact_areas(M: np.ndarray, A: np.ndarray, nn: int, pairs: ContactPairs) -> np.ndarray:
    """The area of each pair: the mean section of the members at its node, so that pressures
    stay stress-like (well scaled)."""
    section_sum = np.bincount(M.ravel(), weights=np.repeat(A, 2), minlength=nn)
    member_count = np.bincount(M.ravel(), minlength=nn)
    loose = [node for node in pairs.nodes if member_count[node] == 0]
    if loose:
        raise InputError(f"contact node {loose[0]} belongs to no member")
    node_area = section_sum / np.maximum(member_count, 1)
    return node_area[pairs.node_indices()] if pairs.count else np.zeros(0)


# ------------------------------------------------------------------------------ checks and data
def check_not_mechanism(B: sp.spmatrix, volumes: np.ndarray) -> None:
    """Raise :class:`InputError` if members and supports leave a free degree of freedom
    unrestrained (``K = B^T W B`` singular).

    Small models: eigenvalues of ``K`` below ``1e-12 max`` (roundoff is ``n eps ||K||``, below
    that for ``n <= 1000``, while a slender real structure stays above ``1/n^2``). Larger ones:
    the same test on the pivots of a sparse LU of ``K``.
    """
    n = B.shape[1]
    K = (B.T @ sp.diags(volumes) @ B).tocsc()
    if n <= EXACT_RANK_LIMIT:
        ev = np.linalg.eigvalsh(K.toarray())
        free = int(np.sum(ev <= 1e-12 * max(float(ev[-1]), 1e-300)))
    else:
        try:
            pivots = np.abs(spla.splu(K).U.diagonal())
            free = int(np.sum(pivots <= 1e-12 * pivots.max()))
        except RuntimeError:  # exactly singular
            free = 1
    if free:
        raise InputError(f"the structure is a mechanism: members and supports leave {free} of its {n} free "
                         "degrees of freedom unrestrained (add supports or members)")


def member_data(dataset, material):
    """The data of a truss's members: one set (shared), a list of sets with a ``material`` index
    per member (:class:`PointData`), or ``None``."""
    if dataset is None:
        return None
    if isinstance(dataset, (MaterialDataset, PointData)):
        if material is not None and not isinstance(dataset, PointData):
            return PointData([dataset], material)
        return dataset
    sets = list(dataset)
    if len(sets) == 1 and material is None:
        return sets[0]
    if material is None:
        raise InputError("several data sets need a 'material' index per member")
    return PointData(sets, material)
