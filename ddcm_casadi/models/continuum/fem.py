r"""Finite-element operators of a small-strain solid, from scikit-fem bases.

scikit-fem supplies the elements, the quadrature and the basis gradients; this module only
arranges them into the sparse operators a :class:`~ddcm_casadi.models.base.ContactModel` needs:

- the strain at every quadrature point in Mandel notation (``k = 3`` in plane strain,
  ``k = 6`` in 3-D), ``eps = B u``, with ``B`` sparse ``(m k, N)``, ``m`` = elements x
  quadrature points, and the quadrature weights ``w`` (the volume each point stands for);
- load vectors from body forces and surface tractions;
- the boundary dofs of contact and their tributary areas.

Mandel strain from the displacement gradient ``G_ab = du_a / dx_b``:

.. math::  \varepsilon = [G_{11}, G_{22}, (G_{12} + G_{21})/\sqrt 2]
           \quad\text{(2-D)},\qquad
           [G_{11}, G_{22}, G_{33}, (G_{23} + G_{32})/\sqrt 2, (G_{13} + G_{31})/\sqrt 2,
           (G_{12} + G_{21})/\sqrt 2] \quad\text{(3-D)},

so that ``eps . sigma`` is the tensor product and ``K = B^T W C B`` the stiffness
(``docs/maths.md``, "Continua").

The quadrature is the lowest that integrates the stiffness exactly (the centroid for linear
elements, order 2 for quadratic ones): every quadrature point is a DDCM material point, so a higher order would
only add unknowns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
import skfem
from skfem.quadrature import get_quadrature

from ddcm_casadi.errors import InputError
from ddcm_casadi.data.metric import COMPONENTS, MANDEL_INDEX

_ELEMENTS = {
    (2, 1): skfem.ElementTriP1, (2, 2): skfem.ElementTriP2,
    (3, 1): skfem.ElementTetP1, (3, 2): skfem.ElementTetP2,
}
_SQRT2 = math.sqrt(2.0)


def scalar_element(dimension: int, degree: int) -> skfem.Element:
    """The Lagrange element of ``degree`` (1 or 2) on triangles or tetrahedra."""
    try:
        return _ELEMENTS[(dimension, degree)]()
    except KeyError:
        raise InputError(f"elements of degree {degree!r} in {dimension}-D are not available; use 1 or 2") from None


@dataclass(frozen=True, eq=False)
class Discretisation:
    """A mesh with vector-valued Lagrange elements of one degree and its quadrature.

    The scikit-fem bases (:attr:`basis`, :attr:`scalar_basis`) hold every basis function's values
    and gradients at every quadrature point (40 MB at 1e5 P1 triangles), which only the
    assembly reads: :meth:`release` drops them once a model is assembled, and they are made
    again, the same, if anything asks for them later (outputs, a contact pressure); the sizes
    and dof locations a run reads are kept.

    Parameters
    ----------
    mesh : skfem.MeshTri1 or skfem.MeshTet1
    degree : {1, 2}
    """

    mesh: skfem.Mesh
    degree: int

    @classmethod
    def create(cls, mesh: skfem.Mesh, degree: int) -> "Discretisation":
        return cls(mesh=mesh, degree=degree)

    @cached_property
    def _bases(self) -> dict:
        return {}

    def _basis(self, vector: bool) -> skfem.CellBasis:
        basis = self._bases.get(vector)
        if basis is None:
            element = scalar_element(self.dimension, self.degree)
            quadrature = _quadrature(element.refdom, 2 * (self.degree - 1))
            basis = self._bases[vector] = skfem.Basis(
                self.mesh, skfem.ElementVector(element, dim=self.dimension) if vector else element,
                quadrature=quadrature)
        return basis

    @property
    def basis(self) -> skfem.CellBasis:
        """The vector-valued basis (made on first use, again after :meth:`release`)."""
        return self._basis(True)

    @property
    def scalar_basis(self) -> skfem.CellBasis:
        """The scalar basis of the same element (made on first use, again after :meth:`release`)."""
        return self._basis(False)

    def release(self) -> None:
        """Drop the bases (after assembly; the sizes and dof locations stay)."""
        for kept in ("n_dofs", "points_per_element", "_dof_locations", "_vector_dofs"):
            getattr(self, kept)  # computed while the bases are here (a run's rigid-body modes read them)
        self._bases.clear()

    @property
    def dimension(self) -> int:
        return self.mesh.p.shape[0]

    @property
    def components(self) -> int:
        """Mandel strain components per material point."""
        return COMPONENTS[self.dimension]

    @cached_property
    def n_dofs(self) -> int:
        return self.basis.N

    @cached_property
    def points_per_element(self) -> int:
        return self.basis.X.shape[1]

    @cached_property
    def _vector_dofs(self) -> np.ndarray:
        sb, vb = self.scalar_basis, self.basis
        out = np.full((self.dimension, sb.N), -1, dtype=np.int64)
        for name in ("nodal_dofs", "facet_dofs", "edge_dofs", "interior_dofs"):
            s, v = getattr(sb, name, None), getattr(vb, name, None)
            if s is not None and s.size:
                out[:, s.ravel()] = v.reshape(self.dimension, -1)
        if np.any(out < 0):  # pragma: no cover - an element with dofs of another kind
            raise InputError("cannot map the scalar dofs of this element to its vector dofs")
        return out

    def vector_dofs(self) -> np.ndarray:
        """``(d, N_scalar)``: the vector dofs at each scalar dof's location (one per component;
        computed once)."""
        return self._vector_dofs

    @cached_property
    def _dof_locations(self) -> np.ndarray:
        return self.scalar_basis.doflocs.T.copy()

    def dof_locations(self) -> np.ndarray:
        """``(N_scalar, d)`` coordinates of the scalar dofs (nodes, then edge midpoints)."""
        return self._dof_locations.copy()

    def rigid_body_modes(self) -> np.ndarray:
        """``(N, 3)`` in 2-D, ``(N, 6)`` in 3-D: the translations, then the rotations in the
        ``(x, y)`` (and ``(y, z)``, ``(x, z)``) planes about the dofs' centroid, as columns over
        all vector dofs (the near-null space of an elastic stiffness)."""
        d = self.dimension
        X = self.dof_locations()
        X = X - X.mean(axis=0)
        vd = self.vector_dofs()
        planes = [(0, 1)] if d == 2 else [(0, 1), (1, 2), (0, 2)]
        modes = np.zeros((self.n_dofs, d + len(planes)))
        for c in range(d):
            modes[vd[c], c] = 1.0
        for j, (a, b) in enumerate(planes, start=d):
            modes[vd[a], j], modes[vd[b], j] = -X[:, b], X[:, a]
        return modes

    def quadrature_points(self) -> np.ndarray:
        """``(m, d)`` global coordinates of the material points (element-major)."""
        x = self.basis.mapping.F(self.basis.X)  # (d, nelems, nqp)
        return x.reshape(self.dimension, -1).T.copy()

    def element_of_point(self) -> np.ndarray:
        """``(m,)`` the element of each material point."""
        return np.repeat(np.arange(self.mesh.t.shape[1]), self.points_per_element)


def _quadrature(refdom, order: int) -> tuple[np.ndarray, np.ndarray]:
    """The rule of ``order`` on the reference simplex; order 0 is the one-point centroid rule
    (scikit-fem's lowest rule on triangles has three points)."""
    if order == 0:
        d = refdom.dim()
        return np.full((d, 1), 1.0 / (d + 1)), np.array([1.0 / math.factorial(d)])
    return get_quadrature(refdom, order)


def strain_operator(disc: Discretisation) -> tuple[sp.csr_matrix, np.ndarray]:
    """``B`` (Mandel strains at the quadrature points, ``(m k, N)``) and the weights ``w`` (m,).

    Rows are point-major: the ``k`` components of point ``i`` are rows ``i k .. i k + k - 1``;
    points are element-major (``i = element * nqp + q``). Built from the basis gradients without a
    loop over elements (one pass per local basis function).
    """
    basis, d, k = disc.basis, disc.dimension, disc.components
    ne, nq = basis.nelems, disc.points_per_element
    pairs = MANDEL_INDEX[d]
    rows_base = (np.arange(ne * nq).reshape(ne, nq) * k)  # first row of each point
    rows, cols, vals = [], [], []
    for i, phi in enumerate(basis.basis):
        G = phi[0].grad  # (d, d, ne, nq): G[a, b] = d phi_a / d x_b
        col = np.broadcast_to(basis.element_dofs[i][:, None], (ne, nq))
        for c, (a, b) in enumerate(pairs):
            v = G[a, a] if a == b else (G[a, b] + G[b, a]) / _SQRT2
            keep = v != 0.0
            if not np.any(keep):
                continue
            rows.append((rows_base + c)[keep])
            cols.append(col[keep])
            vals.append(v[keep])
    B = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(ne * nq * k, disc.n_dofs))
    B.sum_duplicates()
    return B, np.asarray(basis.dx, dtype=float).ravel().copy()


def gradient_operator(disc: Discretisation) -> sp.csr_matrix:
    """``H = G u``: the displacement gradient ``H_ab = du_a / dX_b`` at every quadrature point,
    sparse ``(m d^2, N)``, rows point-major (``i d^2 + a d + b``), points as in
    :func:`strain_operator` (finite kinematics: ``F = I + H``): the blocks of
    :func:`element_gradients` placed at their elements' dofs."""
    blocks = element_gradients(disc)  # (ne, nq, d^2, n_loc)
    ne, nq, dd, n_loc = blocks.shape
    rows = np.broadcast_to(np.arange(ne * nq * dd).reshape(ne, nq, dd, 1), blocks.shape)
    cols = np.broadcast_to(disc.basis.element_dofs.T[:, None, None, :], blocks.shape)
    keep = blocks != 0.0
    H = sp.csr_matrix((blocks[keep], (rows[keep], cols[keep])), shape=(ne * nq * dd, disc.n_dofs))
    H.sum_duplicates()
    return H


def element_gradients(disc: Discretisation) -> np.ndarray:
    """``(ne, nq, d^2, n_loc)``: per element and quadrature point, ``H_ab`` (index ``a d + b``)
    from the element's ``n_loc`` local vector dofs (in ``basis.element_dofs`` order): the blocks
    of :func:`gradient_operator`, element by element."""
    basis, d = disc.basis, disc.dimension
    ne, nq = basis.nelems, disc.points_per_element
    out = np.zeros((ne, nq, d * d, len(basis.basis)))
    for i, phi in enumerate(basis.basis):
        G = phi[0].grad  # (d, d, ne, nq)
        for a in range(d):
            for b in range(d):
                out[:, :, a * d + b, i] = G[a, b]
    return out


def body_load(disc: Discretisation, force_density, elements: np.ndarray | None = None) -> np.ndarray:
    """``int b . v dx`` over ``elements`` (all by default): a constant body force (N/m^3)."""
    b = np.asarray(force_density, dtype=float)
    basis = disc.basis if elements is None else skfem.Basis(disc.mesh, disc.basis.elem, elements=elements,
                                                             intorder=max(1, 2 * (disc.degree - 1)))

    @skfem.LinearForm
    def form(v, w):
        return sum(b[i] * v[i] for i in range(disc.dimension))

    return np.asarray(form.assemble(basis), dtype=float)


def surface_load(disc: Discretisation, facets: np.ndarray, traction) -> np.ndarray:
    """``int t . v ds`` over boundary ``facets``: a constant traction (Pa)."""
    t = np.asarray(traction, dtype=float)
    fb = skfem.FacetBasis(disc.mesh, disc.basis.elem, facets=facets, intorder=max(2, 2 * disc.degree))

    @skfem.LinearForm
    def form(v, w):
        return sum(t[i] * v[i] for i in range(disc.dimension))

    return np.asarray(form.assemble(fb), dtype=float)


def boundary_dofs(disc: Discretisation, facets: np.ndarray) -> np.ndarray:
    """The scalar dofs on boundary ``facets`` (their nodes, and edge midpoints for P2)."""
    dofs = disc.scalar_basis.get_dofs(facets)
    return np.unique(dofs.all()).astype(np.int64)


def tributary_areas(disc: Discretisation, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""The scalar dofs on ``facets`` and the boundary area each stands for (lumped, HRZ).

    On every facet ``f`` of area ``|f|`` each local basis function gets
    ``|f| M_ii / sum_j M_jj`` with ``M_ii = int_f phi_i^2``: positive for any element degree
    (row sums give zero vertex areas for quadratic triangles) and equal shares for linear ones.
    A dof's area sums over its facets, so the areas add up to the boundary's area.
    """
    fb = skfem.FacetBasis(disc.mesh, disc.scalar_basis.elem, facets=facets, intorder=max(2, 2 * disc.degree))
    dx = fb.dx  # (nf, nq)
    diag = np.stack([np.sum(np.asarray(phi[0]) ** 2 * dx, axis=1) for phi in fb.basis])  # (nbf, nf)
    area = np.sum(dx, axis=1)
    share = diag / np.sum(diag, axis=0) * area
    total = np.bincount(fb.element_dofs.ravel(), weights=share.ravel(), minlength=disc.scalar_basis.N)
    used = boundary_dofs(disc, facets)  # the element's other dofs have phi = 0 on the facet
    return used, total[used]


def boundary_triangles(mesh: skfem.Mesh) -> np.ndarray:
    """``(nf, 3)`` the boundary faces of a tetrahedral mesh (for drawing its surface)."""
    return mesh.facets[:, mesh.boundary_facets()].T.copy()


# ------------------------------------------------------------------------- size before building
#: Nonzeros of the stiffness pattern (``|B|^T |B|``) per unknown inside a mesh, by (dimension,
#: degree): P1 triangles couple a node with about 6 neighbours, P1 tetrahedra with about 14
#: (measured on small meshes, whose boundaries lower them: 11, 21, 27, 63).
STIFFNESS_NONZEROS = {(2, 1): 14, (2, 2): 26, (3, 1): 45, (3, 2): 90}


@dataclass(frozen=True)
class BuildSize:
    """What building a continuum will hold, estimated from its mesh before any assembly
    (:func:`estimate_size`).

    Attributes
    ----------
    dimension, degree : int
        2 or 3; 1 (P1) or 2 (P2).
    elements, dofs, points : int
        Elements (after refinement), displacement unknowns (supports not removed) and material points.
    data_points : int
        Material data points over every data set.
    bytes : float
        Estimated memory of one run: the factor of the stiffness (:func:`ddcm_casadi.linalg.factor_bytes`)
        and the data (:data:`ddcm_casadi.linalg.DATA_BYTES_PER_VALUE`).
    """

    dimension: int
    degree: int
    elements: int
    dofs: int
    points: int
    data_points: int
    bytes: float

    @property
    def stress_unknowns(self) -> int:
        """Mandel stress (and strain) components of every material point: the data-driven unknowns."""
        return COMPONENTS[self.dimension] * self.points

    def describe(self) -> str:
        """One line: ``2-D continuum (P1): 19 600 elements, 20 000 unknowns, ...``."""
        data = f", {_count(self.data_points)} data points" if self.data_points else ""
        return (f"{self.dimension}-D continuum (P{self.degree}): {_count(self.elements)} elements, "
                f"{_count(self.dofs)} unknowns, {_count(self.stress_unknowns)} stress unknowns{data}, "
                f"about {_bytes(self.bytes)} per run")


def _count(n: int) -> str:
    """``99 687``, ``1.0 M``: a count as a reader takes it in."""
    return f"{n / 1e6:.1f} M" if n >= 10**6 else f"{n:,}".replace(",", " ")


def _bytes(b: float) -> str:
    return f"{b / 2**30:.2g} GiB" if b >= 2**30 else f"{max(b, 2**20) / 2**20:.0f} MiB"


def estimate_size(mesh: skfem.Mesh, degree: int, data_points: int = 0) -> BuildSize:
    """The size of a continuum on ``mesh``, from its counts alone (no basis, no assembly).

    Parameters
    ----------
    mesh : skfem.MeshTri1 or skfem.MeshTet1
        The mesh, refined.
    degree : {1, 2}
        Lagrange degree.
    data_points : int
        Material data points over every data set (0: classical only).

    Returns
    -------
    BuildSize
    """
    from ddcm_casadi.linalg import DATA_BYTES_PER_VALUE, factor_bytes

    d = mesh.p.shape[0]
    elements = int(mesh.t.shape[1])
    nodes = int(mesh.p.shape[1])
    if degree == 2:  # a node on each edge (the facets of triangles)
        nodes += int(mesh.facets.shape[1] if d == 2 else mesh.edges.shape[1])
    dofs = d * nodes
    points = elements * len(_quadrature(scalar_element(d, degree).refdom, 2 * (degree - 1))[1])
    k = COMPONENTS[d]
    size = factor_bytes(dofs, STIFFNESS_NONZEROS[(d, degree)] * dofs, d == 3) + DATA_BYTES_PER_VALUE * k * data_points
    return BuildSize(d, degree, elements, dofs, points, int(data_points), size)
