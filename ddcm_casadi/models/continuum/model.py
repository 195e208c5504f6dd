r"""Continuum contact models: linear small-strain solids on triangles (plane strain) or tetrahedra.

:func:`continuum_model` turns a mesh, materials, supports, loads and rigid obstacles into a
:class:`ContinuumModel`, a plain :class:`~ddcm_casadi.models.base.ContactModel` with ``k`` Mandel
components per material point, so that every formulation and both variants apply unchanged:

- material points are the quadrature points; ``B`` gives their Mandel strains and ``w`` their
  volumes (per unit thickness in 2-D) (:mod:`ddcm_casadi.models.continuum.fem`);
- the classical law is isotropic per region, ``sigma = C(E, nu) eps``
  (:func:`~ddcm_casadi.data.metric.isotropic_elasticity`); a region may instead (or also) carry a data set;
- every boundary dof a contact surface holds is one contact pair with its obstacle: gap along the
  obstacle normal at the reference configuration (:mod:`ddcm_casadi.models.continuum.obstacles`), and a
  pressure acting on its tributary boundary area (lumped), so that ``a p`` is the nodal force;
- two bodies (disconnected pieces of the mesh, :mod:`ddcm_casadi.models.continuum.bodies`) touch
  through mortar pairs, one per covered slave node, whose weighted gaps couple the slave node to
  the master facets (:mod:`ddcm_casadi.models.continuum.mortar`): the same ``g = G u + gap0``;
- supports fix displacement components on boundaries; body forces and surface tractions are scaled
  by one load factor per step, obstacles move by their own travel per step.

Displacements of fixed dofs are zero; the unknowns ``u`` are the free dofs. The checked pieces
the builder puts together (materials, supports, loads, contact pairs) are in
:mod:`ddcm_casadi.models.continuum.assembly`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.sparse as sp
import skfem
from scipy.sparse.csgraph import connected_components

import casadi as ca

from ddcm_casadi.data import hyperelastic
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.errors import InputError
from ddcm_casadi.data.metric import block_diagonal, isotropic_elasticity
from ddcm_casadi.models.base import ContactModel, FigureSpec, LocalKinematics, drawn_formulation
from ddcm_casadi.models.continuum import fem, finite
from ddcm_casadi.models.coulomb import tangent_basis
from ddcm_casadi.models.continuum.assembly import (contact_pairs, element_materials, free_dofs, friction_fields,
                                                   isotropic_law,
                                                   point_data, reference_loads, step_count)
from ddcm_casadi.models.continuum.inputs import BodyContact, BodyForce, Contact, Material, Support, Traction
from ddcm_casadi.models.continuum.mesh import check_mesh, describe as describe_mesh
from ddcm_casadi.models.continuum.prescribed import check_kinematics, continuum_prescribed, device_step_count
from ddcm_casadi.models.continuum.pressure import check_symmetry_factor, contact_force_columns, contact_results

#: Above this Poisson's ratio, linear (P1) elements lock (:meth:`ContinuumModel.path_warnings`):
#: the bulk modulus over the shear modulus, ``2 (1 + nu) / (3 (1 - 2 nu))``, passes 9.7 at 0.45
#: (it is 2.2 at nu = 0.3), and the constant-strain elements' volumetric constraints start to
#: dominate; measured on a Hertz contact: P1 gives 2.75 x P2's force at nu = 0.4999. The usual
#: threshold of thumb in finite-element practice.
LOCKING_POISSON = 0.45

@dataclass(frozen=True, eq=False)
class ContinuumModel(ContactModel):
    """A :class:`ContactModel` that remembers its mesh, elements and obstacles."""

    discretisation: fem.Discretisation | None = None
    poisson_ratio: np.ndarray | None = None
    free_dofs: np.ndarray | None = None
    point_region: np.ndarray | None = None
    region_names: tuple = ()
    obstacles: tuple = ()
    contact_dofs: np.ndarray | None = None       # scalar dof of each pair
    contact_points: np.ndarray | None = None     # (nc, d) reference coordinates
    contact_normals: np.ndarray | None = None    # (nc, d)
    contact_obstacle: np.ndarray | None = None   # (nc,) obstacle index
    contact_facets: tuple = ()                    # boundary facets of each contact surface
    reference: object | None = None               # e.g. a HertzReference
    laws: tuple = ()                              # the classical law of each region (hyperelastic.LAWS)
    symmetry_factor: float = 1.0                  # the full body's force over the modelled part's

    def __post_init__(self) -> None:
        super().__post_init__()
        check_kinematics(self)
        check_symmetry_factor(self.symmetry_factor, self.reference)
        for law in set(self.laws):
            if hyperelastic.get_law(law).finite != (self.kinematics == "finite") and self.youngs_modulus is not None:
                want = ("\"saint_venant_kirchhoff\" or \"neo_hookean\"" if self.kinematics == "finite"
                        else "\"linear\" (or kinematics = \"finite\")")
                raise InputError(f"material law {law!r} does not fit kinematics = {self.kinematics!r}: use law = {want}")

    # ------------------------------------------------------- finite kinematics
    @property
    def finite(self) -> bool:
        """Whether the kinematics are finite (total Lagrangian, :mod:`~ddcm_casadi.models.continuum.finite`)."""
        return self.kinematics == "finite"

    def near_null_space(self) -> np.ndarray:
        """The body's rigid-body modes in the free dofs (``(n, 3)`` in 2-D, ``(n, 6)`` in 3-D)."""
        return self.discretisation.rigid_body_modes()[self.free_dofs]

    def gradient_operator(self) -> sp.csr_matrix:
        """``H = G u`` at every material point from the free displacements (cached)."""
        G = self._cache.get("gradient_operator")
        if G is None:
            G = fem.gradient_operator(self.discretisation)[:, self.free_dofs].tocsr()
            self._cache["gradient_operator"] = G
        return G

    def displacement_gradient(self, u: np.ndarray) -> np.ndarray:
        """``(m, d, d)`` ``H = du/dX`` at the material points."""
        return finite.displacement_gradient(self.gradient_operator(), u, self.dimension)

    def strain(self, u: np.ndarray, u_prescribed: np.ndarray | None = None) -> np.ndarray:
        """Mandel strains (flat, point-major): ``B u`` (small; ``+ B_D u_D`` with a hard device),
        Green-Lagrange ``E`` (finite)."""
        if not self.finite:
            return super().strain(u, u_prescribed)
        return finite.green_lagrange(self.displacement_gradient(u)).reshape(-1)

    def strain_expression(self, u, values=None):
        if not self.finite:
            return super().strain_expression(u, values)
        return finite.green_lagrange_expression(self.gradient_operator(), u, self.dimension)

    def local_kinematics(self) -> LocalKinematics | None:
        """Finite kinematics: element by element (:class:`~ddcm_casadi.models.base.LocalKinematics`),
        the strains from each element's gradient blocks and the classical law per region as a
        stored energy (:mod:`ddcm_casadi.data.hyperelastic`). ``None`` for small kinematics (the
        problems are affine)."""
        if not self.finite:
            return None
        cached = self._cache.get("local_kinematics")
        if cached is not None:
            return cached
        disc, d, k = self.discretisation, self.dimension, self.strain_components
        nq = disc.points_per_element
        element_dofs = disc.basis.element_dofs.T  # (ne, n_loc) global vector dofs
        index_of = np.full(disc.n_dofs, -1, dtype=np.int64)
        index_of[self.free_dofs] = np.arange(self.free_dofs.size)
        G = fem.element_gradients(disc)
        ne, n_loc = element_dofs.shape
        laws = ()
        if self.youngs_modulus is not None:
            lam, mu = hyperelastic.lame(self.youngs_modulus, self.poisson_ratio)
            w = np.asarray(self.volumes, float)
            constants = np.concatenate([a.reshape(ne, nq) for a in (w, lam, mu)], axis=1)
            law_of_element = np.asarray(self.laws, dtype=object)[self.point_region[::nq]]
            groups = []
            for law in sorted(set(self.laws)):
                items = np.flatnonzero(law_of_element == law)
                if items.size:
                    groups.append((items, constants[items], _element_energy(law, d, k, nq)))
            laws = tuple(groups)
        lk = LocalKinematics(dofs=index_of[element_dofs], geometry=G.reshape(ne, -1), points_per_item=nq,
                             strain=lambda u_e, g: finite.element_strain(u_e, g, d, n_loc, nq), laws=laws,
                             volume_ratio=lambda u_e, g: finite.element_volume_ratio(u_e, g, d, n_loc, nq))
        self._cache["local_kinematics"] = lk
        return lk

    def _law_groups(self) -> list[tuple[str, np.ndarray]]:
        """``(law, points)`` for every law the regions use."""
        law_of_point = np.asarray(self.laws, dtype=object)[self.point_region]
        return [(law, np.flatnonzero(law_of_point == law)) for law in sorted(set(self.laws))]

    def stress(self, strain: np.ndarray) -> np.ndarray:
        """Classical stresses: ``C eps`` (linear) or ``S = dW/dE`` of each region's law
        (:mod:`ddcm_casadi.data.hyperelastic`), flat and point-major like ``strain``."""
        if not self.finite:
            return super().stress(strain)
        k = self.strain_components
        E = np.asarray(strain, float).reshape(-1, self.n_points, k)
        out = np.empty_like(E)
        for law, points in self._law_groups():
            for i in range(E.shape[0]):
                out[i, points] = hyperelastic.second_piola(law, E[i, points], self.youngs_modulus[points],
                                                           self.poisson_ratio[points], self.dimension)
        return out.reshape(np.shape(strain))

    def stress_expression(self, strain):
        if not self.finite:
            return super().stress_expression(strain)
        m, k = self.n_points, self.strain_components
        E = ca.reshape(strain, k, m)
        columns, order = [], []
        for law, points in self._law_groups():
            lam, mu = hyperelastic.lame(self.youngs_modulus[points], self.poisson_ratio[points])
            S = hyperelastic.stress_function(law, self.dimension).map(points.size)
            columns.append(S(E[:, points.tolist()], ca.DM(lam).T, ca.DM(mu).T))
            order.append(points)
        S = ca.horzcat(*columns)[:, np.argsort(np.concatenate(order)).tolist()]
        return ca.reshape(S, m * k, 1)

    def _contact_selection(self) -> sp.csr_matrix:
        """``(nc d, n)``: each pair's displacement vector (fixed components zero) from the free dofs."""
        sel = self._cache.get("contact_selection")
        if sel is None:
            d, nc = self.dimension, self.n_contacts
            vd = self.discretisation.vector_dofs()[:, self.contact_dofs].T  # (nc, d)
            index_of = np.full(self.discretisation.n_dofs, -1, dtype=np.int64)
            index_of[self.free_dofs] = np.arange(self.free_dofs.size)
            cols = index_of[vd].ravel()
            rows = np.arange(nc * d)
            keep = cols >= 0
            sel = sp.csr_matrix((np.ones(int(keep.sum())), (rows[keep], cols[keep])), shape=(nc * d, self.n_dofs))
            self._cache["contact_selection"] = sel
        return sel

    def _directions(self) -> np.ndarray:
        """``(nc, d)`` the direction of travel of each pair's obstacle."""
        return np.stack([ob.offset(1.0) for ob in self.obstacles] or [np.zeros(self.dimension)])[self.contact_obstacle]

    def gap_expression(self, u, values):
        """Small kinematics: ``G u + gap0``. Finite: ``phi(X + u - s_t d)`` per pair, exact at the
        current configuration (``s_t``: the parameter ``travel``, per pair)."""
        if not self.finite or not self.n_contacts:
            return super().gap_expression(u, values)
        from ddcm_casadi.linalg import to_casadi

        d, nc = self.dimension, self.n_contacts
        disp = ca.reshape(ca.mtimes(to_casadi(self._contact_selection()), u), d, nc).T
        x = ca.DM(self.contact_points) + disp - ca.repmat(values("travel"), 1, d) * ca.DM(self._directions())
        gaps = [None] * nc
        for o, ob in enumerate(self.obstacles):
            rows = np.flatnonzero(self.contact_obstacle == o)
            if rows.size:
                g = ob.phi_expression(x[rows.tolist(), :])
                for j, r in enumerate(rows):
                    gaps[r] = g[j]
        return ca.vertcat(*gaps)

    def step_sizes(self) -> dict[str, int]:
        if not self.finite or not self.n_contacts:
            return super().step_sizes()
        return dict(gap0=self.n_contacts, f=self.n_dofs, travel=self.n_contacts, **self.history_sizes())

    def load_names(self) -> tuple[str, ...]:
        if not self.finite or not self.n_contacts:
            return super().load_names()
        return ("gap0", "f", "travel")

    def pair_travels(self, step: int) -> np.ndarray:
        """``s_t`` of each pair's obstacle at ``step``."""
        return np.array([ob.travels(self.n_steps)[step] for ob in self.obstacles], float)[self.contact_obstacle]

    def _current_points(self, u: np.ndarray, step: int) -> np.ndarray:
        """``X + u - s_t d`` per pair: the contact points in the obstacles' reference frame."""
        x = self.contact_points + (self._contact_selection() @ np.asarray(u, float)).reshape(-1, self.dimension)
        return x - self.pair_travels(step)[:, None] * self._directions()

    def step_values(self, step: int, previous: dict | None = None) -> dict[str, np.ndarray]:
        out = super().step_values(step, previous)
        if self.finite and self.n_contacts:
            out["travel"] = self.pair_travels(step)
        return out

    def gap(self, u: np.ndarray, step: int) -> np.ndarray:
        """The gaps at ``step`` for free displacements ``u``: linearised (small) or exact (finite)."""
        if not self.finite or not self.n_contacts:
            return super().gap(u, step)
        x = self._current_points(u, step)
        out = np.empty(self.n_contacts)
        for o, ob in enumerate(self.obstacles):
            rows = self.contact_obstacle == o
            if np.any(rows):
                out[rows] = ob.phi(x[rows])
        return out

    def current_normals(self, u: np.ndarray, step: int) -> np.ndarray:
        """``(nc, d)`` the obstacle normals the pressures act along: at the reference
        configuration (small), at the current contact points (finite)."""
        if not self.finite:
            return self.contact_normals
        x = self._current_points(u, step)
        out = np.empty((self.n_contacts, self.dimension))
        for o, ob in enumerate(self.obstacles):
            rows = self.contact_obstacle == o
            if np.any(rows):
                out[rows] = ob.grad_phi(x[rows])
        return out

    def current_contact_area(self, u: np.ndarray) -> np.ndarray:
        """``(nc,)`` each pair's tributary area in the current configuration (finite kinematics;
        the reference areas otherwise): the same lumping (:func:`~ddcm_casadi.models.continuum.fem.tributary_areas`)
        on the mesh whose vertices moved by ``u`` (straight-sided facets: for P2 the midside
        nodes' own motion is not seen)."""
        if not self.finite or not self.n_contacts:
            return self.contact_area
        disp = self.dof_displacement(u)[:self.mesh.p.shape[1]]
        moved = fem.Discretisation.create(type(self.mesh)(self.mesh.p + disp.T, self.mesh.t), self.discretisation.degree)
        area = np.zeros(self.discretisation.scalar_basis.N)
        for facets in self.contact_facets:
            dofs, a = fem.tributary_areas(moved, facets)
            area[dofs] = a  # a dof on two contact surfaces has one pair per surface: same area each
        return area[self.contact_dofs]

    def true_pressure(self, u: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Contact pressure on the current area, ``a_0 p / a`` (``p``: nominal, per reference area)."""
        return self.contact_area * np.asarray(p) / self.current_contact_area(u)

    def inadmissible(self, u: np.ndarray) -> str | None:
        """Finite kinematics: an inverted material point (``J = det F <= 0``) is no solution."""
        if not self.finite:
            return None
        J = finite.jacobian(self.displacement_gradient(u))
        bad = int(np.sum(~(J > 0)))
        if bad:
            return f"{bad} material point(s) inverted (J = det F <= 0; smallest {float(np.nanmin(J)):.3g})"
        return None

    # --------------------------------------------------------------- geometry
    @property
    def mesh(self) -> skfem.Mesh:
        return self.discretisation.mesh

    @property
    def dimension(self) -> int:
        return self.discretisation.dimension

    def full_displacement(self, u: np.ndarray, step: int | None = None) -> np.ndarray:
        """All dofs (fixed ones zero) from the free unknowns; ``u`` may be stacked over steps.
        With a hard device the prescribed dofs take the values of load step ``step`` (one
        ``u``), which it then needs."""
        u = np.asarray(u)
        out = np.zeros(u.shape[:-1] + (self.discretisation.n_dofs,))
        out[..., self.free_dofs] = u
        if self.prescribed is not None:
            if step is None:
                raise ValueError("the displacements of a continuum with prescribed displacements need the step")
            out[..., self.prescribed.dofs] = self.prescribed.values[step]
        return out

    def dof_displacement(self, u: np.ndarray, step: int | None = None) -> np.ndarray:
        """``(N_scalar, d)`` displacement at every scalar dof location (nodes, P2 midpoints);
        ``step``: the load step of ``u`` (needed with a hard device)."""
        full = self.full_displacement(u, step)
        return full[self.discretisation.vector_dofs()].T

    # ------------------------------------------------------------- mechanics
    def material_matrix(self) -> sp.csr_matrix:
        """Block diagonal of the isotropic Mandel elasticity matrices ``C(E, nu)`` per point."""
        D = self._cache.get("material_matrix")
        if D is None:
            if self.youngs_modulus is None or self.poisson_ratio is None:
                raise InputError("this model has no isotropic law (classical variant unavailable)")
            D = block_diagonal(isotropic_elasticity(self.youngs_modulus, self.poisson_ratio, self.dimension))
            self._cache["material_matrix"] = D
        return D

    def contact_force_vectors(self, p: np.ndarray) -> np.ndarray:
        """Nodal contact forces ``a p n`` (N; N/m in 2-D) per pair, ``(..., nc, d)``."""
        p = np.asarray(p)
        return (self.contact_area * p)[..., None] * self.contact_normals

    def tangential_force_vectors(self, traction: np.ndarray) -> np.ndarray:
        """Nodal friction forces ``a r_T . t`` (N; N/m in 2-D) per pair, ``(..., nc, d)``, from the
        tangential tractions (component-major, :func:`~ddcm_casadi.models.coulomb.tangent_basis`)."""
        t = tangent_basis(self.contact_normals)  # (nc, d - 1, d)
        r = np.asarray(traction, float)
        r = r.reshape(r.shape[:-1] + (self.dimension - 1, self.n_contacts))
        return self.contact_area[:, None] * np.einsum("...jc,cjd->...cd", r, t)

    def path_warnings(self) -> list[str]:
        """:meth:`ContactModel.path_warnings`, plus volumetric locking: near-incompressible
        material (``nu >`` :data:`LOCKING_POISSON`) on linear (P1) elements."""
        out = super().path_warnings()
        if self.discretisation.degree == 1 and self.poisson_ratio is not None:
            nu = float(np.max(self.poisson_ratio))
            if nu > LOCKING_POISSON:
                out.append(f"poisson_ratio {nu:g} > {LOCKING_POISSON:g} on linear (P1) elements: nearly "
                           f"incompressible material locks them (too stiff, forces too high); use degree = 2 (P2)")
        return out

    # ------------------------------------------- self-description for the front ends
    def describe(self) -> dict:
        out = super().describe()
        out.update(dimension=self.dimension, degree=self.discretisation.degree,
                   strain_components=self.strain_components, mesh=describe_mesh(self.mesh),
                   regions=list(self.region_names),
                   poisson_ratio=None if self.poisson_ratio is None else sorted(set(map(float, self.poisson_ratio))),
                   obstacles=[o.describe() for o in self.obstacles])
        if isinstance(out.get("youngs_modulus"), list):
            out["youngs_modulus"] = sorted(set(out["youngs_modulus"]))
        if self.reference is not None:
            out["reference"] = self.reference.describe()
        return out

    def step_summary(self, u: np.ndarray, p: np.ndarray, stress: np.ndarray | None = None, step: int = 0,
                     traction: np.ndarray | None = None) -> dict:
        """:meth:`ContactModel.step_summary` (``total_contact_force`` is ``sum a_0 p``, the sum of
        the nodal contact forces' magnitudes of the modelled part, along no direction), the
        resultant contact force along each obstacle's travel
        (:func:`~ddcm_casadi.models.continuum.pressure.contact_force_columns`: as modelled and for
        the full body, times :attr:`symmetry_factor`), the reference's columns (measured with
        ``stress``), and at finite strain ``min_J`` (the smallest ``det F`` of the material points)
        and ``max_contact_pressure_true`` (the largest pressure per current area, :meth:`true_pressure`)."""
        out = super().step_summary(u, p, traction=traction)
        if self.frictional and traction is not None:  # the resultant of the tangential tractions
            force = self.tangential_force_vectors(traction).sum(axis=0)
            out.update({f"tangential_force_{'xyz'[i]}": float(force[i]) for i in range(self.dimension)})
        if self.n_contacts:
            out.update(contact_force_columns(self, u, p, step))
        if self.reference is not None:
            out.update(self.reference.step_summary(self, p, stress))
        if self.finite:
            finite_u = bool(np.all(np.isfinite(u)))
            out["min_J"] = float(np.min(finite.jacobian(self.displacement_gradient(u)))) if finite_u else float("nan")
            true = self.true_pressure(u, p) if finite_u and self.n_contacts else np.zeros(0)
            out["max_contact_pressure_true"] = float(np.max(true)) if true.size else float("nan")
        return out

    def contact_pair_labels(self) -> list[str]:
        return [f"{self.obstacles[o].name} @ ({', '.join(f'{c:.3g}' for c in x)})"
                for o, x in zip(self.contact_obstacle, self.contact_points)]

    def results_fields(self, fields: dict) -> dict:
        """What ``results.json`` keeps of a run's fields: the contact only, every number named by
        what it is (:func:`~ddcm_casadi.models.continuum.pressure.contact_results`); the full
        fields go to the VTU files."""
        return contact_results(self, fields)

    def field_outputs(self) -> tuple[str, ...]:
        """One VTU file per step and run with a ``.pvd`` series each
        (:func:`ddcm_casadi.outputs.continuum_results.write_vtu`)."""
        return ("vtu",)

    def figures(self, runs) -> dict[str, FigureSpec]:
        """``pressure_profile.png`` (with contact pairs), ``deformed_<variant>.png`` (last step,
        Fischer-Burmeister if it was run, else the first formulation of that variant),
        ``force_indentation.png`` (when an obstacle with contact pairs moves: the contact force
        along its travel against the travel, every run) and ``contact_history.png``; drawn by
        :mod:`ddcm_casadi.outputs.continuum_results`."""
        runs = list(runs)
        specs = {"pressure_profile.png": FigureSpec("pressure_profile")} if self.n_contacts else {}
        for variant in ("classical", "ddcm"):
            name = drawn_formulation(runs, variant)
            if name is not None:
                specs[f"deformed_{variant}.png"] = FigureSpec("deformed_body", {"variant": variant, "formulation": name})
        held = set(np.asarray(self.contact_obstacle, dtype=int).tolist()) if self.n_contacts else set()
        if any(float(np.ptp(ob.travels(self.n_steps))) > 0 for o, ob in enumerate(self.obstacles) if o in held):
            specs["force_indentation.png"] = FigureSpec("force_indentation")
        if self.frictional:
            specs["traction_profile.png"] = FigureSpec("traction_profile")
        return {**specs, **super().figures(runs)}


# ------------------------------------------------------------------------------------ builder
def continuum_model(mesh: skfem.Mesh, *, materials: Sequence[Material], supports: Sequence[Support],
                    contacts: Sequence[Contact] = (), degree: int = 1, tractions: Sequence[Traction] = (),
                    body_forces: Sequence[BodyForce] = (), load_factors: Sequence[float] | None = None,
                    datasets: Sequence[MaterialDataset] = (), name: str = "continuum",
                    reference=None, kinematics: str = "small",
                    symmetry_factor: float | None = None) -> ContinuumModel:
    """Build a :class:`ContinuumModel`.

    Parameters
    ----------
    mesh : skfem.MeshTri1 or skfem.MeshTet1
        With named boundaries/subdomains where the other arguments name them (checked with
        :func:`~ddcm_casadi.models.continuum.mesh.check_mesh`).
    materials : sequence of Material
        One per region; at most one with ``region=None`` (the rest of the mesh).
    supports : sequence of Support
    contacts : sequence of Contact or BodyContact
        Rigid obstacles and the boundaries that may touch them; pairs of boundaries of two bodies
        (:mod:`~ddcm_casadi.models.continuum.mortar`; the bodies are disconnected pieces of the
        mesh, :func:`~ddcm_casadi.models.continuum.bodies.join`).
    degree : {1, 2}
        Lagrange elements (P1 or P2).
    tractions, body_forces : sequences
        Reference loads, scaled by ``load_factors``.
    load_factors : sequence of float, optional
        One per step; default: the loads in full at every step, as many steps as the obstacles'
        travel has values.
    datasets : sequence of MaterialDataset
        The data sets the materials name by index (``Material.data``).
    name : str
    reference : optional
        An independent reference the model reports against (e.g.
        :class:`~ddcm_casadi.models.continuum.hertz.HertzReference`).
    kinematics : {"small", "finite"}
        ``"finite"``: total Lagrangian, Green-Lagrange strains, hyperelastic laws
        (``Material.law``) and gaps at the current configuration
        (:mod:`~ddcm_casadi.models.continuum.finite`).
    symmetry_factor : float, optional
        The full body's force over the modelled part's (a half: 2, a quarter: 4), for the
        full-body forces of the outputs and the Hertz reference; default the reference's
        ``force_factor`` if it has one, else 1. A different ``force_factor`` is refused.
    """
    check_mesh(mesh)
    disc = fem.Discretisation.create(mesh, int(degree) if degree in (1, 2) else _bad_degree(degree))
    d, k = disc.dimension, disc.components
    point_region = np.repeat(element_materials(mesh, materials), disc.points_per_element)
    E, nu = isotropic_law(materials, point_region, d)
    dataset = point_data(materials, datasets, point_region, d, k)
    if E is None and dataset is None:
        raise InputError("a continuum needs an isotropic law (youngs_modulus, poisson_ratio) or data")
    B_all, w = fem.strain_operator(disc)
    free = free_dofs(disc, supports)
    f_ref = reference_loads(disc, tractions, body_forces)
    n_steps = device_step_count(load_factors, contacts, supports, d)
    factors = np.ones(n_steps) if load_factors is None else np.asarray(load_factors, dtype=float)
    size = float(np.max(np.ptp(mesh.p, axis=1)))
    bodies = [c.name for c in contacts if c.kind == "bodies"]
    if kinematics == "finite" and bodies:
        raise InputError(f"contact pair {bodies[0]!r}: contact between bodies is linearised at the reference "
                         "configuration; finite kinematics needs rigid obstacles for now")
    G_all, area_all, gap0, obstacles, contact = contact_pairs(disc, contacts, free, n_steps, size)
    G = G_all[:, free].tocsr()
    friction = friction_fields(disc, contacts, contact, obstacles, free, n_steps)
    loads = factors[:, None] * f_ref[free][None, :]
    travelling = [ob for ob in obstacles if ob.direction is not None]
    by_travel = bool(travelling) and load_factors is None
    load_parameter = travelling[0].travels(n_steps) if by_travel else factors
    lp_name = "obstacle travel (m)" if by_travel else "load factor"
    if by_travel and getattr(travelling[0], "motion", None) is not None:
        lp_name = "obstacle path length (m)"
    prescribed = continuum_prescribed(disc, supports, B_all, G_all, n_steps, load_factors, f_ref)
    if prescribed is not None and load_factors is None and not (by_travel and np.ptp(load_parameter) > 0):
        load_parameter, lp_name = np.arange(n_steps, dtype=float), "load step"  # a path set by the device

    model = ContinuumModel(
        strain_operator=B_all[:, free].tocsr(), volumes=w, gap_operator=G, contact_area=area_all,
        gap_offsets=gap0, loads=loads, load_parameter=load_parameter, youngs_modulus=E, dataset=dataset,
        length_scale=size, name=name, load_parameter_name=lp_name, strain_components=k, discretisation=disc,
        poisson_ratio=nu, free_dofs=free, point_region=point_region,
        region_names=tuple(m.region or "(rest)" for m in materials), obstacles=tuple(obstacles),
        reference=reference, laws=tuple(m.law for m in materials), kinematics=kinematics, prescribed=prescribed,
        symmetry_factor=(getattr(reference, "force_factor", 1.0) if symmetry_factor is None else symmetry_factor),
        **contact, **friction)
    _check_held(model)
    disc.release()  # assembled: the bases' values and gradients are not needed any more
    return model


def _element_energy(law: str, d: int, k: int, nq: int):
    """``W_e(E_e, [w; lambda; mu])``: the stored energy of one element's ``nq`` points with their
    weights, for :class:`~ddcm_casadi.models.base.LocalKinematics`."""
    W = hyperelastic.energy_function(law, d)

    def energy(E_e, c):
        return sum(c[q] * W(E_e[q * k:(q + 1) * k], c[nq + q], c[2 * nq + q]) for q in range(nq))

    return energy


def _bad_degree(degree) -> int:
    raise InputError(f"element degree must be 1 or 2, got {degree!r}")


def _check_held(model: ContinuumModel) -> None:
    """Refuse a body its supports do not hold: on some connected piece of the mesh, some
    rigid-body motion of that piece (translations, rotations) vanishes on every fixed dof. The
    classical problem would be singular wherever the obstacles do not touch. Each connected piece
    (elements linked through shared nodes) is checked on its own: a second body no support holds
    is refused even when the first is held.

    A body pressed onto another (or onto an obstacle) and held only by that contact, as in a
    force-controlled cylinder on a block, is held when the pairs closed at the first step
    (``gap0 <= 0``) take the rigid-body motions the supports leave: their gap rows join the
    fixed dofs in the rank test."""
    disc = model.discretisation
    modes = disc.rigid_body_modes()
    fixed = np.ones(disc.n_dofs, dtype=bool)
    fixed[model.free_dofs] = False
    closed = model.gap_offsets[0] <= 0 if model.n_contacts else np.zeros(0, dtype=bool)
    pieces, piece_of_element = mesh_pieces(disc.mesh)
    element_dofs = disc.basis.element_dofs  # (vector dofs per element, elements)
    for piece in range(pieces):
        dofs = np.unique(element_dofs[:, piece_of_element == piece])
        inside = np.zeros(disc.n_dofs, dtype=bool)
        inside[dofs] = True
        # closed pairs' gap rows on this piece's free dofs, as constraints on its modes
        rows = model.gap_operator[closed][:, inside[model.free_dofs]]
        R = np.vstack([modes[dofs[fixed[dofs]]], rows @ modes[model.free_dofs[inside[model.free_dofs]]]])
        # modes are O(1) (translations) and O(body size) (rotations about the centroid): 1e-9 of
        # the largest entry separates independent columns from roundoff (~1e-16 relative)
        if R.shape[0] == 0 or np.linalg.matrix_rank(R, tol=1e-9 * max(1.0, float(np.abs(R).max()))) < modes.shape[1]:
            where = ""
            if pieces > 1:
                centre = disc.mesh.p[:, disc.mesh.t[:, piece_of_element == piece].ravel()].mean(axis=1)
                where = (f" of body {piece + 1} of {pieces} (disconnected pieces of the mesh; its centre at "
                         f"({', '.join(f'{c:.3g}' for c in centre)}))")
            hint = ""
            if rows.nnz == 0 and model.gap_operator[:, inside[model.free_dofs]].nnz:
                gaps = model.gap_offsets[0][np.asarray(abs(model.gap_operator[:, inside[model.free_dofs]]).sum(axis=1)).ravel() > 0]
                hint = (f", or let it touch or overlap what holds it at the first step (its smallest gap is "
                        f"{float(np.min(gaps)):.3g} m; a body held only by contact is free to move, so an "
                        f"overlap along that motion changes no stress)")
            raise InputError(f"the supports leave a rigid-body motion{where} free; fix more displacement "
                             f"components{hint}")


def mesh_pieces(mesh: skfem.Mesh) -> tuple[int, np.ndarray]:
    """The connected pieces of a mesh (elements linked through shared nodes): their number and
    the piece of every element."""
    t = mesh.t
    n_nodes, n_el = mesh.p.shape[1], t.shape[1]
    # bipartite graph elements -- nodes: elements sharing a node fall into one component
    rows = np.repeat(np.arange(n_el), t.shape[0])
    graph = sp.csr_matrix((np.ones(rows.size), (rows, n_el + t.T.ravel())), shape=(n_el + n_nodes,) * 2)
    count, labels = connected_components(graph, directed=False)
    element_labels = labels[:n_el]
    _, piece = np.unique(element_labels, return_inverse=True)
    return int(piece.max()) + 1, piece.reshape(-1)


def with_reference(model: ContinuumModel, reference) -> ContinuumModel:
    """The same model reporting against ``reference``."""
    return dataclasses.replace(model, reference=reference)
