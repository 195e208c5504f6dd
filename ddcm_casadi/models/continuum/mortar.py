r"""Contact between two deformable bodies: segment-to-segment (mortar) coupling with dual
Lagrange multipliers on linear (P1) surfaces, in 2-D and 3-D.

A contact pair names a *slave* boundary and a *master* surface. Every slave node ``j`` that the
master covers becomes one complementarity pair of the model, with

- the weighted gap (length), the :math:`\psi_j`-weighted mean distance along the nodal normal
  :math:`n_j` from the slave surface to its projection on the master,

  .. math::  g_j = \frac{1}{m_j} \int_{\Gamma_c} \psi_j\,
             (x^{(m)}(\pi(\xi)) - x^{(s)}(\xi)) \cdot n_j \, d\Gamma
           = n_j \cdot \Big(\sum_k \frac{M_{jk}}{m_j} x_k - \sum_l \frac{D_{jl}}{m_j} x_l\Big),

  :math:`M_{jk} = \int \psi_j N^{(m)}_k`, :math:`D_{jl} = \int \psi_j N^{(s)}_l` over the part
  :math:`\Gamma_c` of the slave surface the master covers, :math:`m_j = \int_{\Gamma_c} \psi_j`
  (both rows sum to :math:`m_j`: the gap is the difference of two weighted means);
- the area :math:`a_j = m_j`, so that the contact forces of a pressure ``p_j`` are
  ``a_j p_j dg_j/du``: :math:`-p_j D_{jl} n_j` on slave node ``l`` and :math:`p_j M_{jk} n_j` on
  master node ``k``.

The dual basis :math:`\psi_j = (n_v + 1) N_j - 1` of a simplex facet with ``n_v`` vertices
(:math:`3N_j - 1` on a segment, :math:`4N_j - 1` on a triangle) is biorthogonal to the shape
functions, :math:`\int_f \psi_i N_j = \delta_{ij} \int_f N_j`, and sums to one. Hence a uniform
pressure ``p`` puts the consistent loads :math:`p \int N_l` on the slave nodes and
:math:`p \int N_k^{(m)}` on the master nodes of the covered part, across non-matching meshes: the
contact patch test holds to round-off (``docs/maths.md``, "Contact between bodies").

The integration is segment-based: each slave facet is intersected with the master facets
projected on its plane along its normal (2-D: an interval; 3-D: Sutherland-Hodgman clipping of
a triangle by a triangle), and the products :math:`\psi_j N_k` (quadratic) are integrated
exactly on the pieces (2-point Gauss; a 3-point rule on a fan of triangles).

The contact search (:func:`candidate_facets`) is a KD-tree of the master facets' centroids
queried with each slave facet's reach; :func:`mortar_coupling` takes the node coordinates as an
argument, so that finite kinematics can rerun it at the current configuration. Small
kinematics run it once, at the reference configuration.

Slave nodes whose covered share is small (:math:`m_j < \frac12 \int N_j`: the slave surface runs
past the edge of the master, where :math:`\psi_j` would weigh a gap with the wrong sign) carry
no pair; choose as slave the surface that stays within the other.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ddcm_casadi.errors import InputError

#: Masters whose facet normal makes less than this cosine with minus the slave normal are not
#: candidates (they face away or are seen edge-on: a projection along the slave normal would be
#: degenerate there). 0.2: up to 78 degrees between the facing surfaces.
FACING_COSINE = 0.2
#: A slave node carries a pair when the master covers at least this share of it (``m_j``
#: against ``int N_j``; see the module).
MIN_COVERAGE = 0.5
#: 2-point Gauss on [0, 1]: exact for the quadratic products psi_j N_k on a segment.
_GAUSS_1D = (np.array([0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0)]), np.array([0.5, 0.5]))
#: 3-point rule on a triangle (barycentric points, weights summing to 1): exact for quadratics.
_TRIANGLE_RULE = (np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]]),
                  np.full(3, 1 / 3))


# ------------------------------------------------------------------------------ surfaces
@dataclass(frozen=True)
class Surface:
    """Boundary facets of a linear simplex mesh, oriented outwards.

    Attributes
    ----------
    facets : (nf,) int
        Facet indices of the mesh.
    nodes : (nf, d) int
        Their vertices (mesh node indices).
    elements : (nf, d + 1) int
        The vertices of the element each facet bounds (its centroid fixes the orientation, at
        any configuration).
    """

    facets: np.ndarray
    nodes: np.ndarray
    elements: np.ndarray

    @classmethod
    def of(cls, mesh, facets: np.ndarray) -> "Surface":
        facets = np.asarray(facets, dtype=np.int64)
        return cls(facets, np.asarray(mesh.facets[:, facets].T, dtype=np.int64),
                   np.asarray(mesh.t[:, mesh.f2t[0, facets]].T, dtype=np.int64))

    def geometry(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit outward normals ``(nf, d)``, measures ``(nf,)`` and centroids ``(nf, d)`` at
        node coordinates ``x`` ``(n_nodes, d)``."""
        v = x[self.nodes]  # (nf, nv, d)
        if v.shape[2] == 2:
            t = v[:, 1] - v[:, 0]
            n = np.stack([t[:, 1], -t[:, 0]], axis=1)
            measure = np.linalg.norm(n, axis=1)
        else:
            n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
            measure = 0.5 * np.linalg.norm(n, axis=1)
        n = n / np.linalg.norm(n, axis=1)[:, None]
        inside = x[self.elements].mean(axis=1)
        n[np.einsum("fd,fd->f", n, inside - v[:, 0]) > 0] *= -1.0
        return n, measure, v.mean(axis=1)

    def radii(self, x: np.ndarray, centroids: np.ndarray) -> np.ndarray:
        """``(nf,)`` each facet's bounding radius about its centroid."""
        return np.max(np.linalg.norm(x[self.nodes] - centroids[:, None], axis=2), axis=1)


# ---------------------------------------------------------------------------- search
def candidate_facets(slave_centroids: np.ndarray, slave_radii: np.ndarray, master_centroids: np.ndarray,
                     master_radii: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(slave facet, master facet)`` whose bounding spheres, the slave's grown by
    ``reach``, overlap: a KD-tree of the master centroids, one ball query per slave facet.

    Returns
    -------
    slave, master : (P,) int
    """
    if not len(master_centroids) or not len(slave_centroids):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    tree = cKDTree(master_centroids)
    hits = tree.query_ball_point(slave_centroids, r=slave_radii + float(np.max(master_radii)) + reach)
    counts = np.fromiter((len(h) for h in hits), dtype=np.int64, count=len(hits))
    slave = np.repeat(np.arange(len(hits), dtype=np.int64), counts)
    master = np.fromiter((m for h in hits for m in h), dtype=np.int64, count=int(counts.sum()))
    # the sphere test on the master's own radius (the query used the largest one)
    near = (np.linalg.norm(master_centroids[master] - slave_centroids[slave], axis=1)
            <= slave_radii[slave] + master_radii[master] + reach)
    return slave[near], master[near]


# ----------------------------------------------------------------------- integration
def _segment_points(xs: np.ndarray, xm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """2-D: quadrature on the overlap of slave segments ``xs`` ``(P, 2, 2)`` and master segments
    ``xm`` projected on them. Returns weights ``(P, Q)`` (length) and the slave and master
    barycentric coordinates of the points, ``(P, Q, 2)`` each."""
    a, t = xs[:, 0], xs[:, 1] - xs[:, 0]
    length2 = np.einsum("pd,pd->p", t, t)
    e = np.einsum("pkd,pd->pk", xm - a[:, None], t) / length2[:, None]  # master ends on the slave's axis
    lo = np.clip(np.min(e, axis=1), 0.0, 1.0)
    hi = np.clip(np.max(e, axis=1), 0.0, 1.0)
    g, gw = _GAUSS_1D
    xi = lo[:, None] + (hi - lo)[:, None] * g[None, :]
    w = (hi - lo)[:, None] * gw[None, :] * np.sqrt(length2)[:, None]
    span = e[:, 1] - e[:, 0]
    eta = (xi - e[:, [0]]) / np.where(span == 0, 1.0, span)[:, None]
    return w, np.stack([1 - xi, xi], axis=2), np.stack([1 - eta, eta], axis=2)


def _clip(poly: np.ndarray, count: np.ndarray, f: int) -> tuple[np.ndarray, np.ndarray]:
    """One Sutherland-Hodgman pass, vectorised over polygons: keep the part of each polygon
    (``(P, K, 3)`` barycentric vertices, ``count`` of them) where coordinate ``f`` is >= 0."""
    P, K, _ = poly.shape
    out = np.zeros((P, K + 1, 3))
    n_out = np.zeros(P, dtype=np.int64)
    rows = np.arange(P)
    for k in range(K):
        valid = k < count
        cur = poly[:, k]
        nxt = poly[rows, (k + 1) % np.maximum(count, 1)]
        fc, fn = cur[:, f], nxt[:, f]
        keep = valid & (fc >= 0)
        out[rows[keep], n_out[keep]] = cur[keep]
        n_out += keep
        cross = valid & ((fc >= 0) != (fn >= 0))
        s = np.where(cross, fc / np.where(cross, fc - fn, 1.0), 0.0)
        out[rows[cross], n_out[cross]] = (cur + s[:, None] * (nxt - cur))[cross]
        n_out += cross
    return out, n_out


def _triangle_points(xs: np.ndarray, xm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """3-D: quadrature on the intersection of slave triangles ``xs`` ``(P, 3, 3)`` with master
    triangles ``xm`` projected on their planes along their normals. Returns weights
    ``(P, Q)`` (area) and the slave and master barycentric coordinates, ``(P, Q, 3)`` each."""
    a = xs[:, 0]
    T = np.stack([xs[:, 1] - a, xs[:, 2] - a], axis=2)  # (P, 3, 2)
    Tt = T.transpose(0, 2, 1)  # (P, 2, 3)
    # master corners in slave coordinates: the least-squares (orthogonal) projection on the plane
    lam12 = ((xm - a[:, None]) @ T) @ np.linalg.inv(Tt @ T).transpose(0, 2, 1)
    poly = np.concatenate([1.0 - lam12.sum(axis=2, keepdims=True), lam12], axis=2)  # (P, 3, 3)
    count = np.full(len(xs), 3, dtype=np.int64)
    for f in range(3):
        poly, count = _clip(poly, count, f)
    area2 = np.linalg.norm(np.cross(T[:, :, 0], T[:, :, 1]), axis=1)  # twice the slave's area
    # the master barycentrics of a slave-plane point: invert the projected master triangle
    mu = lam12  # (P, 3, 2)
    J = np.stack([mu[:, 1] - mu[:, 0], mu[:, 2] - mu[:, 0]], axis=2)  # (P, 2, 2)
    det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
    J_inv = np.stack([np.stack([J[:, 1, 1], -J[:, 0, 1]], 1), np.stack([-J[:, 1, 0], J[:, 0, 0]], 1)], 1)
    J_inv = J_inv / np.where(det == 0, 1.0, det)[:, None, None]
    rule, rule_w = _TRIANGLE_RULE
    weights, slave_bary, master_bary = [], [], []
    for k in range(1, poly.shape[1] - 1):  # fan (v0, v_k, v_k+1)
        valid = k + 1 < count
        tri = np.stack([poly[:, 0], poly[:, k], poly[:, k + 1]], axis=1)  # (P, 3 corners, 3 bary)
        d1, d2 = tri[:, 1, 1:] - tri[:, 0, 1:], tri[:, 2, 1:] - tri[:, 0, 1:]
        sub = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) * area2 * valid
        pts = rule @ tri  # (P, 3, 3) slave barycentrics
        rel = pts[:, :, 1:] - mu[:, None, 0]
        beta12 = rel @ J_inv.transpose(0, 2, 1)
        weights.append(sub[:, None] * rule_w[None, :])
        slave_bary.append(pts)
        master_bary.append(np.concatenate([1.0 - beta12.sum(axis=2, keepdims=True), beta12], axis=2))
    return np.concatenate(weights, 1), np.concatenate(slave_bary, 1), np.concatenate(master_bary, 1)


# -------------------------------------------------------------------------- coupling
@dataclass(frozen=True)
class MortarCoupling:
    """The pairs of one slave/master contact (see the module).

    Attributes
    ----------
    nodes : (nc,) int
        The slave node of each pair.
    normals : (nc, d)
        Unit nodal normals (outward from the slave body).
    area : (nc,)
        ``m_j``: each pair's covered, psi-weighted share of the slave surface.
    slave_weights, master_weights : sparse (nc, n_nodes)
        ``D_jl / m_j`` and ``M_jk / m_j``; every row sums to one.
    dropped : int
        Slave nodes the master covers too little to carry a pair.
    facet_pairs : int
        Slave/master facet pairs that overlap.
    """

    nodes: np.ndarray
    normals: np.ndarray
    area: np.ndarray
    slave_weights: sp.csr_matrix
    master_weights: sp.csr_matrix
    dropped: int
    facet_pairs: int

    def gaps(self, x: np.ndarray) -> np.ndarray:
        """``(nc,)`` weighted gaps for node coordinates (or displacements) ``x`` ``(n_nodes, d)``."""
        diff = (self.master_weights - self.slave_weights) @ np.asarray(x, float)
        return np.einsum("jd,jd->j", diff, self.normals)


def mortar_coupling(x: np.ndarray, slave: Surface, master: Surface, reach: float) -> MortarCoupling:
    """Search and integrate one slave/master contact at node coordinates ``x`` ``(n_nodes, d)``.

    Parameters
    ----------
    x : (n_nodes, d)
        Node coordinates (reference, or current for finite kinematics).
    slave, master : Surface
    reach : float
        Search distance (m): master facets farther than this from a slave facet along its normal
        are no candidates.
    """
    x = np.asarray(x, float)
    d = x.shape[1]
    n_s, meas_s, c_s = slave.geometry(x)
    n_m, _, c_m = master.geometry(x)
    r_s, r_m = slave.radii(x, c_s), master.radii(x, c_m)
    s, m = candidate_facets(c_s, r_s, c_m, r_m, reach)
    facing = np.einsum("pd,pd->p", n_s[s], n_m[m]) < -FACING_COSINE
    offset = c_m[m] - c_s[s]
    along = np.einsum("pd,pd->p", offset, n_s[s])
    # within reach along the slave normal, and overlapping across it (bounding circles)
    near = (np.abs(along) <= reach) & (np.linalg.norm(offset - along[:, None] * n_s[s], axis=1) <= r_s[s] + r_m[m])
    s, m = s[facing & near], m[facing & near]
    xs, xm = x[slave.nodes[s]], x[master.nodes[m]]
    if d == 2:
        w, lam, beta = _segment_points(xs, xm)
    else:
        w, lam, beta = _triangle_points(xs, xm)
    overlap = np.sum(w, axis=1) > 1e-14 * meas_s[s]
    s, m, w, lam, beta = s[overlap], m[overlap], w[overlap], lam[overlap], beta[overlap]
    psi = (d + 1) * lam - 1.0  # the dual basis of a simplex facet with d vertices
    n_nodes = x.shape[0]
    rows = np.repeat(slave.nodes[s], d, axis=1).ravel()  # (P, j, k) flattened, j major
    wpsi_t = (w[:, :, None] * psi).transpose(0, 2, 1)  # (P, j, q)
    M = sp.csr_matrix(((wpsi_t @ beta).ravel(),
                       (rows, np.tile(master.nodes[m], (1, d)).ravel())), shape=(n_nodes, n_nodes))
    D = sp.csr_matrix(((wpsi_t @ lam).ravel(),
                       (rows, np.tile(slave.nodes[s], (1, d)).ravel())), shape=(n_nodes, n_nodes))
    covered = np.asarray(M.sum(axis=1)).ravel()
    full = np.bincount(slave.nodes.ravel(), weights=np.repeat(meas_s / d, d), minlength=n_nodes)  # int N_j
    surface_nodes = np.unique(slave.nodes)
    keep = surface_nodes[covered[surface_nodes] >= MIN_COVERAGE * full[surface_nodes]]
    touched = surface_nodes[covered[surface_nodes] != 0]
    # nodal normals: the area-weighted mean of the slave facets' normals
    normal_sum = np.zeros((n_nodes, d))
    np.add.at(normal_sum, slave.nodes.ravel(), np.repeat(n_s * meas_s[:, None], d, axis=0))
    normals = normal_sum[keep] / np.linalg.norm(normal_sum[keep], axis=1)[:, None]
    scale = sp.diags(1.0 / covered[keep])
    return MortarCoupling(nodes=keep, normals=normals, area=covered[keep],
                          slave_weights=(scale @ D[keep]).tocsr(), master_weights=(scale @ M[keep]).tocsr(),
                          dropped=int(np.setdiff1d(touched, keep).size), facet_pairs=int(s.size))


def check_linear(degree: int, name: str) -> None:
    """Contact between bodies is integrated on straight (P1) facets."""
    if degree != 1:
        raise InputError(f"contact pair {name!r}: contact between bodies needs linear elements (degree = 1); "
                         f"got degree = {degree}")


@dataclass(frozen=True, eq=False)
class MasterSurface:
    """What the pairs of a contact between bodies touch, in the model's list of counterparts
    beside the rigid obstacles: it has a name and does not travel (the bodies move by their
    loads and supports)."""

    name: str
    dimension: int
    facets: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # the master's boundary facets
    facet_pairs: int = 0
    dropped: int = 0
    search_distance: float = 0.0

    kind = "surface"
    direction = None

    def travels(self, n_steps: int) -> np.ndarray:
        return np.zeros(n_steps)

    def offset(self, step_travel: float) -> np.ndarray:
        return np.zeros(self.dimension)

    def phi_expression(self, x):
        raise InputError(f"contact pair {self.name!r}: contact between bodies is linearised at the reference "
                         "configuration; finite kinematics needs rigid obstacles for now")

    def describe(self) -> dict:
        return dict(kind=self.kind, name=self.name, facet_pairs=self.facet_pairs,
                    slave_nodes_without_pair=self.dropped, search_distance=self.search_distance)

    def drawing(self, step_travel: float) -> None:
        return None
