"""The model description: what the problem is, independent of how contact is enforced.

A :class:`ContactModel` describes a small-strain, linear structure with ``n`` displacement unknowns
``u``, ``m`` material points (elements) and ``nc`` unilateral contact pairs:

- kinematics ``strain = B u`` with a sparse ``B`` (m x n) and material-point volumes ``w`` (m);
- equilibrium ``B^T W stress - G^T (a * p) = f`` with loads ``f``;
- contact pairs ``gap = G u + gap0 >= 0``, ``p >= 0``, ``gap * p = 0`` with contact areas ``a``;
- a material law ``stress = E strain`` (classical) and/or a material data set (DDCM);
- optionally prescribed displacements ``u_D`` (a hard device, :mod:`ddcm_casadi.models.prescribed`):
  strains ``B u + B_D u_D`` and gaps ``G u + G_D u_D + gap0``, ``u_D`` a step parameter.

The load path is a sequence of steps, each with its own ``gap0`` (obstacle positions), ``f`` and,
with a hard device, ``u_D``.
Both the classical and the data-driven problem are built from this one object
(see :mod:`ddcm_casadi.problems.contract`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ddcm_casadi.models.contact_laws import get_contact_law
from ddcm_casadi.models import coulomb
from ddcm_casadi.data.dataset import MaterialDataset, PointData, check_positive
from ddcm_casadi.errors import InputError
from ddcm_casadi.linalg import to_casadi
from ddcm_casadi.models.prescribed import PARAMETER as PRESCRIBED, Prescribed
from ddcm_casadi.models.scales import LARGE_STRAIN, STIFFNESS_FACTOR, load_path_warnings, reference_scales
from ddcm_casadi.models.stiffness import StiffnessFactor, condensation_size_refusal


#: Kinematics a model may declare: ``small`` (linear strains and gaps: the problems are affine) or
#: ``finite`` (a nonlinear strain measure; the problems are nonlinear).
KINEMATICS = ("small", "finite")
#: The status of a frictional contact, by code (:meth:`ContactModel.contact_status`).
CONTACT_STATUS = ("open", "stick", "slip")

# LARGE_STRAIN (the imposed strain beyond which path_warnings warns) lives with the scales; kept
# importable from here.
__all__ = ["KINEMATICS", "LARGE_STRAIN", "ContactModel", "FigureSpec", "drawn_formulation"]


@dataclass(frozen=True)
class FigureSpec:
    """One figure of a model kind, as data: which drawing makes it, with which options.

    A model kind says *which* figures it has (:meth:`ContactModel.figures`); the output layer owns
    the functions that draw them, looked up by ``drawing`` in its registry
    (:func:`ddcm_casadi.outputs.drawings.drawing`) and called as ``drawing(comparison, **options)``. So a
    model never imports the plotting code (nor matplotlib).

    Parameters
    ----------
    drawing : str
        The name of the drawing function in the registry, e.g. ``"contact_history"``.
    options : mapping
        Keyword arguments of the drawing function, e.g. ``{"variant": "ddcm"}``.
    """

    drawing: str
    options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class LocalKinematics:
    """The finite-element structure of a nonlinear model's strains, for assembly item by item
    (:class:`~ddcm_casadi.problems.maps.LocalTerms`) instead of one expression of every point.

    Attributes
    ----------
    dofs : (items, q) int array
        Per item (an element), the free dof of each of its ``q`` local displacements; ``-1``
        where it is fixed (zero).
    geometry : (items, q_g) array
        Per item, the constants of its strains (shape-function gradients).
    points_per_item : int
        Material points per item; item ``e`` holds points ``e n_q .. (e + 1) n_q - 1``.
    strain : callable
        ``(u_e, geometry_e) -> E_e``: CasADi symbols, the item's points' strains (``n_q k``,
        point-major) of its local displacements.
    laws : tuple of (items, constants, energy)
        The classical law by groups of items: their indices, per-item constants ``(len, q_l)``,
        and ``energy(E_e, constants_e)``, the stored energy of the item's points with their
        quadrature weights (a symbol), whose derivative in ``E_e`` is ``w S``.
    volume_ratio : callable, optional
        ``(u_e, geometry_e) -> J_e``: the item's points' ``J = det F`` (symbols). Where one is
        not positive the item's terms are NaN, so that Newton's line search never steps into an
        inverted element (``E`` cannot tell a point from its mirror image).
    """

    dofs: np.ndarray
    geometry: np.ndarray
    points_per_item: int
    strain: Any
    laws: tuple = ()
    volume_ratio: Any = None


def drawn_formulation(runs: Iterable[tuple[str, str]], variant: str) -> str | None:
    """The formulation whose run of ``variant`` a one-run figure shows: Fischer-Burmeister if it
    was run, else the first formulation run in that variant (``None`` if the variant was not run).

    Parameters
    ----------
    runs : iterable of (str, str)
        The ``(variant, formulation)`` keys of the runs made.
    variant : str
        ``"classical"`` or ``"ddcm"``.
    """
    names = [name for v, name in runs if v == variant]
    if not names:
        return None
    return "fischer_burmeister" if "fischer_burmeister" in names else names[0]


def _check_prescribed(prescribed: Prescribed, rows: int, G: sp.csr_matrix, gap0: np.ndarray, length: float) -> None:
    """Refuse prescribed displacements that do not fit the model, or that push a contact pair no
    free dof moves into its obstacle (its gap is prescribed: nothing could open it) (one line)."""
    nc, n_steps = G.shape[0], gap0.shape[0]
    if not isinstance(prescribed, Prescribed):
        raise InputError(f"prescribed must be a Prescribed record, got {type(prescribed).__name__}")
    if prescribed.strain_operator.shape[0] != rows or prescribed.gap_operator.shape[0] != nc:
        raise InputError(f"prescribed displacements: operators of {prescribed.strain_operator.shape[0]} strain rows "
                         f"and {prescribed.gap_operator.shape[0]} gap rows, the model has {rows} and {nc}")
    if prescribed.n_steps != n_steps:
        raise InputError(f"prescribed displacements are given for {prescribed.n_steps} steps, the load path has "
                         f"{n_steps}")
    if nc and prescribed.gap_operator.nnz:
        held = (np.diff(G.indptr) == 0) & (np.diff(prescribed.gap_operator.tocsr().indptr) > 0)
        gaps = gap0 + np.asarray(prescribed.gap_operator @ prescribed.values.T).T
        stuck = held & np.any(gaps < -1e-12 * length, axis=0)
        if np.any(stuck):
            j = int(np.flatnonzero(stuck)[0])
            step = int(np.argmin(gaps[:, j]))
            raise InputError(f"the prescribed displacements push contact pair {j} into its obstacle (gap "
                             f"{gaps[step, j]:.3g} m at step {step}) and no free displacement can open it: "
                             f"keep the obstacle off the prescribed dofs or prescribe less")


def _finite(name: str, a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name} must be finite (no NaN or infinity)")
    return a


@dataclass(frozen=True, eq=False)
class ContactModel:
    """A linear small-strain structure with unilateral contact pairs and a load path.

    Parameters
    ----------
    strain_operator : sparse (m, n)
        ``B``: material-point strains from free displacements.
    volumes : (m,)
        Material-point volumes ``w`` (area x length for bars).
    gap_operator : sparse (nc, n)
        ``G``: gap ``g = G u + gap0``.
    contact_area : (nc,)
        Area on which each contact pressure acts.
    gap_offsets : (n_steps, nc)
        ``gap0`` per load step.
    loads : (n_steps, n)
        External loads ``f`` per load step.
    load_parameter : (n_steps,)
        A scalar per step used to label results and plots (obstacle position for the bar).
    youngs_modulus : (m,) or None
        Classical material law; needed for the classical variant.
    dataset : MaterialDataset, PointData or None
        Material data; needed for the data-driven variant. One :class:`MaterialDataset` is shared
        by every material point; :class:`PointData` gives each point its own data set and metric.
    length_scale : float
        Characteristic length, used only to nondimensionalise.
    name : str
        Human-readable name.
    prescribed : Prescribed, optional
        Prescribed displacements (a hard device): dofs that are not unknowns but move by given
        values per step (:mod:`ddcm_casadi.models.prescribed`). ``None``: every dof that is not
        an unknown is fixed at zero.
    tangent_operator : sparse (nc (d - 1), n), optional
        ``T``: Coulomb friction (the contact law ``"coulomb"``). Row ``j nc + c`` is the
        displacement of contact ``c`` along its ``j``-th unit tangent (component-major,
        :mod:`ddcm_casadi.models.coulomb`); the slip of a step is ``s = T (u - u_prev) - (tau -
        tau_prev)`` with ``tau`` the obstacle's displacement along the same tangent.
    friction : (nc,), optional
        Coulomb coefficients ``mu >= 0`` per contact (with ``tangent_operator``; 0 is frictionless).
    slip_offsets : (n_steps, nc (d - 1)), optional
        ``-tau`` per step: minus the obstacle's displacement along each contact's tangents
        (default 0: the obstacles do not move tangentially).
    """

    strain_operator: sp.csr_matrix
    volumes: np.ndarray
    gap_operator: sp.csr_matrix
    contact_area: np.ndarray
    gap_offsets: np.ndarray
    loads: np.ndarray
    load_parameter: np.ndarray
    youngs_modulus: np.ndarray | None = None
    dataset: MaterialDataset | PointData | None = None
    length_scale: float = 1.0
    name: str = "model"
    load_parameter_name: str = "load parameter"
    strain_components: int = 1
    kinematics: str = "small"
    contact_law: str = "signorini"
    prescribed: Prescribed | None = None
    tangent_operator: sp.csr_matrix | None = None
    friction: np.ndarray | None = None
    slip_offsets: np.ndarray | None = None
    _cache: dict = field(init=False, repr=False)

    def __post_init__(self) -> None:
        B = sp.csr_matrix(self.strain_operator, dtype=float)
        G = sp.csr_matrix(self.gap_operator, dtype=float)
        get_contact_law(self.contact_law)
        if self.kinematics not in KINEMATICS:
            raise InputError(f"kinematics must be one of {', '.join(map(repr, KINEMATICS))}, got {self.kinematics!r}")
        k = self.strain_components
        if isinstance(k, bool) or int(k) != k or k < 1:
            raise InputError(f"strain_components must be a positive integer, got {k!r}")
        if B.shape[0] % k:
            raise InputError(f"strain operator has {B.shape[0]} rows, not a multiple of {k} components")
        m, n = B.shape[0] // k, B.shape[1]
        nc = G.shape[0]
        if G.shape[1] != n:
            raise InputError(f"gap operator has {G.shape[1]} columns, expected {n}")
        w = _finite("volumes", np.broadcast_to(self.volumes, (m,)).copy())
        a = _finite("contact_area", np.broadcast_to(self.contact_area, (nc,)).copy())
        if np.any(w <= 0):
            raise InputError("volumes (area x length) must be positive")
        if np.any(a <= 0):
            raise InputError("contact_area must be positive")
        g0 = _finite("obstacle positions", np.atleast_2d(self.gap_offsets))
        n_steps = g0.shape[0]
        if n_steps == 0:
            raise InputError("the load path has no steps")
        if g0.shape[1] != nc:
            raise InputError(f"gap offsets have {g0.shape[1]} columns, expected {nc}")
        f = _finite("loads", np.broadcast_to(self.loads, (n_steps, n)).copy())
        lp = _finite("load parameter", np.broadcast_to(self.load_parameter, (n_steps,)).copy())
        E = None
        if self.youngs_modulus is not None:
            E = _finite("youngs_modulus", np.broadcast_to(self.youngs_modulus, (m,)).copy())
            if np.any(E <= 0):
                raise InputError("youngs_modulus must be positive")
        if E is None and self.dataset is None:
            raise InputError("a model needs a Young's modulus, a material data set, or both")
        L = check_positive("length", self.length_scale)
        if self.dataset is not None:
            if not isinstance(self.dataset, (MaterialDataset, PointData)):
                raise InputError("dataset must be a MaterialDataset or PointData")
            self.dataset.point_materials(m)  # checks a per-point material list against the model
            if self.dataset.k != k:
                raise InputError(f"the data set has {self.dataset.k} strain components per point, "
                                 f"the model's material points have {k}")
        if self.prescribed is not None:
            _check_prescribed(self.prescribed, m * k, G, g0, float(self.length_scale))
        self._check_friction(nc, n, n_steps)
        for k, v in dict(strain_operator=B, gap_operator=G, volumes=w, contact_area=a,
                         gap_offsets=g0, loads=f, load_parameter=lp, youngs_modulus=E,
                         length_scale=L).items():
            object.__setattr__(self, k, v)
        object.__setattr__(self, "_cache", {})

    def _check_friction(self, nc: int, n: int, n_steps: int) -> None:
        """Check and normalise the frictional fields; set the contact law they imply."""
        if self.tangent_operator is None:
            if self.contact_law == "coulomb":
                raise InputError("Coulomb friction needs a tangent operator (the contacts' tangential displacements)")
            if self.friction is not None or self.slip_offsets is not None:
                raise InputError("friction coefficients or tangential obstacle motion need a tangent operator")
            return
        if self.kinematics != "small":
            raise InputError("Coulomb friction needs small kinematics for now (kinematics = \"small\")")
        T = sp.csr_matrix(self.tangent_operator, dtype=float)
        if nc == 0 or T.shape[1] != n or T.shape[0] % nc or T.shape[0] == 0:
            raise InputError(f"tangent operator has shape {T.shape}: expected (a multiple of {nc} contacts, {n})")
        mu = _finite("friction", np.broadcast_to(0.0 if self.friction is None else self.friction, (nc,)).copy())
        if np.any(mu < 0):
            raise InputError(f"friction coefficients must be >= 0, got {float(mu.min()):g}")
        nt = T.shape[0]
        offsets = np.zeros((n_steps, nt)) if self.slip_offsets is None else self.slip_offsets
        offsets = _finite("tangential obstacle motion", np.broadcast_to(offsets, (n_steps, nt)).copy())
        if self.prescribed is not None and self.prescribed.gap_operator.nnz:
            raise InputError("Coulomb friction at nodes whose displacements are prescribed is not supported")
        for key, value in dict(tangent_operator=T, friction=mu, slip_offsets=offsets, contact_law="coulomb").items():
            object.__setattr__(self, key, value)

    # ------------------------------------------------------------------ sizes
    @property
    def frictional(self) -> bool:
        """Whether the contacts carry Coulomb friction (:attr:`tangent_operator`)."""
        return self.tangent_operator is not None

    @property
    def contact_block(self) -> int:
        """Components per contact: 1, or ``1 + (d - 1)`` with friction."""
        return 1 + (self.tangent_operator.shape[0] // self.n_contacts if self.frictional else 0)

    @property
    def contact_operator(self) -> sp.csr_matrix:
        """``[G; T]``: the normal gaps' and (with friction) the tangential displacements' operator,
        component-major (cached)."""
        if not self.frictional:
            return self.gap_operator
        C = self._cache.get("contact_operator")
        if C is None:
            C = self._cache["contact_operator"] = sp.vstack([self.gap_operator, self.tangent_operator]).tocsr()
        return C

    @property
    def n_dofs(self) -> int:
        return self.strain_operator.shape[1]

    @property
    def n_points(self) -> int:
        """Number of material points (elements)."""
        return self.strain_operator.shape[0] // self.strain_components

    @property
    def n_contacts(self) -> int:
        return self.gap_operator.shape[0]

    @property
    def n_steps(self) -> int:
        return self.gap_offsets.shape[0]

    # ----------------------------------------------------------------- scales
    @property
    def metric(self) -> np.ndarray:
        """DDCM metric constant ``c`` per (one-component) material point."""
        if self.dataset is None:
            raise InputError("this model has no material data set")
        return self.dataset.point_metric(self.n_points)

    def near_null_space(self) -> np.ndarray | None:
        """The near-null space of the stiffness in the free dofs, ``(n_dofs, r)``, for an algebraic
        multigrid solver (:func:`~ddcm_casadi.linalg.factorize_definite`), or ``None`` (constants):
        a continuum gives its rigid-body modes."""
        return None

    def representative_law(self, kind: str) -> sp.csr_matrix:
        """``W D``: the volumes times a representative law per point (``(m k, m k)``, block
        diagonal), from which the reference scales of the ``"classical"`` or ``"ddcm"`` problem
        assemble their stiffness ``B^T W D B`` (:mod:`~ddcm_casadi.models.scales`): a modulus
        per point on every strain component (:meth:`point_stiffness`: ``E``, or the data's secant
        modulus). Where the classical condensation may use the scales' factor
        (:meth:`delassus_rows`), the classical kind's is the classical law itself
        (:meth:`material_matrix`: ``B^T W D B`` is then :meth:`stiffness`, the same arithmetic),
        so that one factorisation serves both; for one-component points the two are the same."""
        w, k = np.asarray(self.volumes, float), self.strain_components
        if kind == "classical" and self.delassus_rows() is not None:
            return (sp.diags(np.repeat(w, k)) @ self.material_matrix()).tocsr()
        return sp.diags(np.repeat(w * self.point_stiffness(kind), k)).tocsr()

    def delassus_rows(self) -> sp.csr_matrix | None:
        """The contact rows ``G`` whose Delassus matrix ``G K^-1 G^T`` the first factorisation of
        the reference scales' stiffness ``K`` also gives, for the classical problem's
        condensation on its pairs (:class:`~ddcm_casadi.problems.reduction.ClassicalReduction`,
        which takes it: :meth:`stiffness_factor`), or ``None`` where that condensation cannot
        apply: no classical law, finite kinematics, friction, or sizes it refuses
        (:func:`~ddcm_casadi.models.stiffness.condensation_size_refusal`)."""
        if self.youngs_modulus is None or self.kinematics != "small" or self.frictional or \
                condensation_size_refusal(self.n_dofs, self.n_contacts):
            return None
        return self.gap_operator

    def stiffness_factor(self) -> StiffnessFactor | None:
        """The factor of the scales' stiffness with its Delassus matrix
        (:class:`~ddcm_casadi.models.stiffness.StiffnessFactor`, made where :meth:`delassus_rows`
        says), kept for the model's reductions, or ``None`` (not made, or let go: a reduction that
        cannot use it releases it before its own factorisation)."""
        factor = self._cache.get(STIFFNESS_FACTOR)
        if factor is not None and factor.released:
            del self._cache[STIFFNESS_FACTOR]
            return None
        return factor

    def point_stiffness(self, kind: str) -> np.ndarray:
        """A representative modulus per material point: ``E`` (``"classical"``), or for the data
        (``"ddcm"``) the secant modulus of each point's data set, ``std(stress) / std(strain)``
        (exactly ``E`` for Hookean data), never the metric: the states a projection reaches
        follow the data, whatever ``c`` is."""
        if kind == "classical":
            if self.youngs_modulus is None:
                raise InputError("this model has no Young's modulus (classical variant unavailable)")
            return self.youngs_modulus
        _, material = self.dataset.point_materials(self.n_points)
        return np.array([d.secant_modulus for d in self.dataset.datasets])[material]

    def scales_for(self, kind: str) -> dict:
        """Reference magnitudes of the ``"classical"`` or the ``"ddcm"`` problem (cached).

        Derived from the problem itself, by a linear solve with a representative stiffness
        ``K = B^T W D B`` (``W D`` from :meth:`representative_law`: ``E`` or the data's secant
        modulus from :meth:`point_stiffness` on every component; the classical law itself where
        the classical condensation shares the scales' factor):

        - the response to the largest load, ``K u_f = f``;
        - the displacement the obstacles impose where they penetrate the undeformed body
          (``gap0 < 0``): ``(K + kappa G^T A G) u_g = -kappa G^T A gap0^-`` with a stiff spring
          ``kappa``, rescaled so that the imposed normal displacement is the penetration.

        Displacement ``max(|u_f|, max gap0^-)``, strain ``max |B u|`` of both, stress
        ``D_max strain``, force ``stress x`` a representative section (mean contact area, or the
        members' volume over length). An obstacle that never penetrates contributes nothing, and
        the classical scales never see the data: a data set or its metric cannot change a
        classical number. The projection's energy unit is ``sum(w) (c eps^2 + sigma^2 / c) / 2``
        with the metric ``c`` (its largest eigenvalue), the size of a distance at these scales.
        """
        cached = self._cache.get(kind)
        if cached is None:
            cached = reference_scales(self, kind)
            self._cache[kind] = cached
            kinds = [k for k, has in (("classical", self.youngs_modulus is not None),
                                      ("ddcm", self.dataset is not None)) if has]
            if all(k in self._cache for k in kinds):  # the kinds' shared factors are done with
                self._cache.pop("scale_stiffness", None)
        return dict(cached)

    def path_warnings(self) -> list[str]:
        """What is physically odd about the load path, one line each; refuses what is meaningless.

        Obstacles that penetrate the body at the first step, and (small kinematics only) an
        imposed strain beyond :data:`LARGE_STRAIN` (:func:`~ddcm_casadi.models.scales.load_path_warnings`).

        Raises
        ------
        InputError
            An imposed strain of 1 or more (an obstacle pushed past a fixed end, through the
            body): a small-strain model is meaningless there.
        """
        return load_path_warnings(self)

    @property
    def scales(self) -> dict:
        """Reference magnitudes of the classical problem if the model has one, else of the
        projection (see :meth:`scales_for`)."""
        return self.scales_for("classical" if self.youngs_modulus is not None else "ddcm")

    @property
    def contact_stiffness(self) -> float:
        """Reference contact stiffness ``E / length`` (Pa/m), the unit of the penalty parameters."""
        s = self.scales
        return s["modulus"] / s["length"]

    # -------------------------------------------------------------- mechanics
    def material_matrix(self) -> sp.csr_matrix:
        """The classical law ``stress = D strain`` of every material point: sparse ``(m k, m k)``,
        block diagonal (cached). One component per point: ``D = diag(E)``; a model kind whose
        points carry several components (continua) overrides this."""
        D = self._cache.get("material_matrix")
        if D is None:
            if self.youngs_modulus is None:
                raise InputError("this model has no Young's modulus (classical variant unavailable)")
            if self.strain_components != 1:
                raise InputError("a classical law for several strain components is not available for this model")
            D = sp.diags(self.youngs_modulus).tocsr()
            self._cache["material_matrix"] = D
        return D

    def stress(self, strain: np.ndarray) -> np.ndarray:
        """Classical stresses ``D strain`` (flat, point-major, as :meth:`strain` gives them)."""
        return self.material_matrix() @ np.asarray(strain)

    def stress_expression(self, strain):
        """:meth:`stress` for a CasADi symbol ``strain`` (the classical law of the nonlinear
        problems): ``D strain``. A model kind with a nonlinear law (hyperelastic continua)
        overrides both."""
        return ca.mtimes(to_casadi(self.material_matrix()), strain)

    def stiffness(self) -> sp.csr_matrix:
        """Classical stiffness ``K = B^T W D B`` (sparse; ``W`` the volumes on every component):
        the reference scales' (the same arithmetic, :meth:`representative_law`) where their
        :meth:`stiffness_factor` holds it, handed over once (no second assembly: 1.4 s and a
        transient of ``B``'s size at 3e5 unknowns), else assembled."""
        factor = self.stiffness_factor()
        K = None if factor is None else factor.hand_over()
        if K is not None:
            return K.tocsr()
        B = self.strain_operator
        W = sp.diags(np.repeat(self.volumes, self.strain_components))
        return (B.T @ (W @ self.material_matrix()) @ B).tocsr()

    # -------------------------------------------------------------- load steps and their history
    def history_sizes(self) -> dict[str, int]:
        """Names and sizes of the parameters a step takes from the previous converged step, after
        ``gap0`` and ``f``: none without friction; with friction ``slip0 = -(T u_prev - tau_prev)``
        (so that the slip is ``T u + slip_offset + slip0``) and the tangential tractions
        ``traction0`` (Pa) of the last converged step."""
        if not self.frictional:
            return {}
        nt = self.tangent_operator.shape[0]
        return dict(slip0=nt, traction0=nt)

    def friction_sizes(self) -> dict[str, int]:
        """``{friction: nc, slip_offset: nc (d - 1)}`` with friction, else empty."""
        if not self.frictional:
            return {}
        return dict(friction=self.n_contacts, slip_offset=self.tangent_operator.shape[0])

    def step_sizes(self) -> dict[str, int]:
        """Names and sizes of a load step's parameters, in order: ``gap0`` and ``f``, with a hard
        device ``u_prescribed`` (:data:`~ddcm_casadi.models.prescribed.PARAMETER`), those a
        model kind adds (:meth:`load_names`: e.g. an obstacle's travel per pair for gaps at the
        current configuration), then :meth:`history_sizes`."""
        return dict(gap0=self.n_contacts, f=self.n_dofs, **self.prescribed_sizes(), **self.friction_sizes(),
                    **self.history_sizes())

    def prescribed_sizes(self) -> dict[str, int]:
        """``{u_prescribed: nD}`` with a hard device, else empty (the default problems are
        unchanged)."""
        return {} if self.prescribed is None else {PRESCRIBED: self.prescribed.size}

    def load_names(self) -> tuple[str, ...]:
        """The step parameters that grow with the load (linear in the load parameter between two
        steps, so that a sub-step interpolates them): ``gap0`` and ``f``, and with a hard device
        the prescribed displacements ``u_prescribed``."""
        return ("gap0", "f") + tuple(self.prescribed_sizes()) + (("slip_offset",) if self.frictional else ())

    def gap_expression(self, u, values):
        """The gaps (physical, ``nc``) for a CasADi symbol ``u`` (free displacements) with the
        step's parameters ``values(name)`` (symbols): ``G u + gap0`` (``+ G_D u_D`` with a hard
        device), affine. A model kind whose gaps are nonlinear (finite kinematics against curved
        obstacles) overrides this; the contact forces are then ``(dg/du)^T a p``."""
        gap = ca.mtimes(to_casadi(self.gap_operator), u) + values("gap0")
        if self.prescribed is not None and self.n_contacts:
            gap = gap + ca.mtimes(to_casadi(self.prescribed.gap_operator), values(PRESCRIBED))
        return gap

    def local_kinematics(self) -> LocalKinematics | None:
        """The item-by-item structure of a nonlinear model (:class:`LocalKinematics`), or
        ``None``: the problems are then built as one expression of :meth:`strain_expression` (fine
        for a few hundred unknowns; a continuum assembles element by element instead)."""
        return None

    def inadmissible(self, u: np.ndarray) -> str | None:
        """Why a displacement cannot be a solution although it solves the equations (e.g. an
        inverted element, ``det F <= 0``), or ``None``. The drivers reject such a step."""
        return None

    def step_values(self, step: int, previous: dict | None = None) -> dict[str, np.ndarray]:
        """The parameter values of load step ``step`` by name: ``gap0``, ``f`` and those of
        :meth:`history_sizes`. ``previous``: the physical fields (``u``, ``p``, ``traction``; for
        DDCM also ``strain`` and ``stress``) and the index ``step`` of the last converged step,
        ``None`` before the first. The drivers pass it; a model kind whose steps depend on their
        history overrides this."""
        out = dict(gap0=self.gap_offsets[step], f=self.loads[step])
        if self.prescribed is not None:
            out[PRESCRIBED] = self.prescribed.values[step]
        if self.frictional:
            nt = self.tangent_operator.shape[0]
            out.update(friction=self.friction, slip_offset=self.slip_offsets[step], slip0=np.zeros(nt),
                       traction0=np.zeros(nt))
            if previous is not None:  # the slip and the stick spring start at the last converged step
                out["slip0"] = -(self.tangent_operator @ np.asarray(previous["u"], float)
                                 + self.slip_offsets[previous["step"]])
                out["traction0"] = np.asarray(previous["traction"], float)
        return out

    def gap(self, u: np.ndarray, step: int) -> np.ndarray:
        gap = self.gap_operator @ np.asarray(u) + self.gap_offsets[step]
        if self.prescribed is not None and self.n_contacts:
            gap = gap + self.prescribed.gap_operator @ self.prescribed.values[step]
        return gap

    def active_contacts(self, pressure: np.ndarray) -> np.ndarray:
        """Which pairs carry a pressure above 1e-8 of the stress scale (one rule for tables and
        figures); ``pressure`` may be stacked over steps."""
        return np.asarray(pressure) > 1e-8 * self.scales["stress"]

    def strain(self, u: np.ndarray, u_prescribed: np.ndarray | None = None) -> np.ndarray:
        """Material-point strains (flat, point-major) of the free displacements ``u``; with a hard
        device ``B u + B_D u_D`` with the step's prescribed values ``u_prescribed``
        (``prescribed.values[step]``), which it then needs."""
        strain = self.strain_operator @ np.asarray(u)
        if self.prescribed is not None:
            strain = strain + self.prescribed.strain_operator @ self._given_prescribed(u_prescribed)
        return strain

    def _given_prescribed(self, u_prescribed) -> np.ndarray:
        """The prescribed values a strain needs, checked (a programming error otherwise: the strain
        of a model with a hard device depends on the step)."""
        if u_prescribed is None:
            raise ValueError("this model has prescribed displacements: its strains need the step's values "
                             "(u_prescribed)")
        return np.asarray(u_prescribed, dtype=float)

    def strain_expression(self, u, values=None):
        """:meth:`strain` for a CasADi symbol ``u`` (``values(name)``: the step's parameters, as
        symbols; with a hard device ``u_prescribed`` is read from them). Small kinematics: ``B u``
        (``+ B_D u_D``). A model kind with ``kinematics = "finite"`` overrides both with its
        nonlinear strain (Green-Lagrange); the problems then take the nonlinear form
        (:mod:`ddcm_casadi.problems.contract`), and ``B`` is the strain's derivative at the
        reference configuration (used only for reference scales)."""
        strain = to_casadi(self.strain_operator) @ u
        if self.prescribed is not None:
            if values is None:
                raise ValueError("this model has prescribed displacements: its strains need the step's parameters")
            strain = strain + ca.mtimes(to_casadi(self.prescribed.strain_operator), values(PRESCRIBED))
        return strain

    # ------------------------------------------------------------ prescribed displacements
    def prescribed_strain_jacobian(self, u: np.ndarray, u_prescribed: np.ndarray):
        """``d strain / d u_D`` at ``(u, u_D)``: ``B_D`` under small kinematics (a model kind with
        finite kinematics and a hard device overrides it)."""
        return self.prescribed.strain_operator

    def hard_device_forces(self, step: int, u: np.ndarray, stress: np.ndarray, p: np.ndarray) -> np.ndarray | None:
        """``(n_supports, d)``: per prescribed support, the resultant force (N; per unit thickness
        in 2-D continua) the hard device exerts on the body at step ``step``,
        ``sum (B_D^T W sigma - f_D - G_D^T a p)`` over the support's prescribed dofs
        (:meth:`~ddcm_casadi.models.prescribed.Prescribed.nodal_forces`); ``None`` without a hard
        device."""
        if self.prescribed is None:
            return None
        pr = self.prescribed
        if stress is None:  # no state to take it from
            return np.full((len(pr.support_names), pr.dimension), np.nan)
        uD = pr.values[step]
        weighted = np.repeat(self.volumes, self.strain_components) * np.asarray(stress, float).reshape(-1)
        jac = self.prescribed_strain_jacobian(u, uD)
        nodal = pr.nodal_forces(weighted, self.contact_area * np.asarray(p, float).reshape(-1), step, jac)
        return pr.resultants(nodal)

    def hard_device_summary(self, step: int, u: np.ndarray, stress, p: np.ndarray) -> dict:
        """The per-step columns of ``results.csv`` of a hard device
        (:meth:`~ddcm_casadi.models.prescribed.Prescribed.columns`:
        ``hard_device_force_<axis>(<support>)``, N); empty without one or without a stress."""
        if self.prescribed is None or stress is None:
            return {}
        forces = self.hard_device_forces(step, u, stress, p)
        if not np.all(np.isfinite(forces)):
            forces = np.full_like(forces, np.nan)
        return self.prescribed.columns(forces)

    def closed_form(self, step: int):
        """Exact classical solution ``(u, p)`` if the model knows one in closed form, else ``None``."""
        return None

    # ------------------------------------------- self-description (what the front ends need)
    # A model kind overrides these; the harness, CLI, plots and case files call them and never
    # check a model's type.
    def penalty_closed_form(self, step: int, gamma: float):
        """The penalty solution ``(u, p)`` for the penalty stiffness ``gamma`` (Pa/m) if known in
        closed form, else ``None`` (then a penalty run is compared with :meth:`closed_form`)."""
        return None

    def describe(self) -> dict:
        """The model's record in ``results.json`` (small: sizes, names, moduli; no fields)."""
        E = None
        if self.youngs_modulus is not None:
            moduli = np.unique(self.youngs_modulus)
            E = float(moduli[0]) if moduli.size == 1 else self.youngs_modulus.tolist()
        return dict(name=self.name, type=type(self).__name__, n_dofs=self.n_dofs, n_points=self.n_points,
                    n_contacts=self.n_contacts, n_steps=self.n_steps,
                    load_parameter_name=self.load_parameter_name,
                    load_parameter=self.load_parameter.tolist(), youngs_modulus=E, kinematics=self.kinematics,
                    contact_law=self.contact_law,
                    **({} if self.prescribed is None else {"hard_device": self.prescribed.describe()}))

    @property
    def scalar(self) -> bool:
        """One unknown, one material point, at most one pair: tables hold ``u`` and ``p`` themselves."""
        return self.n_dofs == 1 and self.n_contacts <= 1 and self.n_points == 1

    def step_summary(self, u: np.ndarray, p: np.ndarray, stress: np.ndarray | None = None, step: int = 0,
                     traction: np.ndarray | None = None) -> dict:
        """The per-step columns of ``results.csv`` that describe the solution ``(u, p)`` of load step
        ``step`` (and the material points' ``stress``, for model kinds that measure with it).
        ``total_contact_force`` is ``sum a p``: the sum of the pairs' nodal contact forces as
        magnitudes, of the modelled part, resolved along no direction; with friction
        ``total_tangential_force`` likewise ``sum a |r_T|`` (``traction``: the step's tangential
        tractions)."""
        if self.scalar:
            return dict(u=float(u[-1]), p=float(p[0]) if p.size else float("nan"))
        out = dict(max_abs_u=float(np.max(np.abs(u))), total_contact_force=float(np.sum(self.contact_area * p)),
                   active_contacts=int(np.sum(self.active_contacts(p))))
        if self.frictional and traction is not None:
            r = coulomb.blocks(traction, self.contact_block - 1)
            out["total_tangential_force"] = float(self.contact_area @ np.linalg.norm(r, axis=1))
        return out

    def contact_status(self, p: np.ndarray, traction: np.ndarray, slip: np.ndarray) -> np.ndarray:
        """Per contact (stacked over steps if the arguments are) the status code of
        :data:`CONTACT_STATUS` (0 open, 1 stick, 2 slip): open where ``p`` is not above 1e-8 of
        the stress scale, slip where the traction is on the cone within that and the slip exceeds
        1e-8 of the displacement scale (:func:`~ddcm_casadi.models.coulomb.contact_status`)."""
        p = np.atleast_2d(np.asarray(p, float))
        t, s = (np.atleast_2d(np.asarray(v, float)) for v in (traction, slip))
        scales, b = self.scales, self.contact_block
        out = np.zeros(p.shape, dtype=np.int8)
        for k in range(p.shape[0]):
            status = coulomb.contact_status(np.column_stack([np.zeros(p.shape[1]), coulomb.blocks(s[k], b - 1)]),
                                            np.column_stack([p[k], coulomb.blocks(t[k], b - 1)]), self.friction,
                                            1e-8 * scales["stress"], 1e-8 * scales["displacement"])
            out[k] = [CONTACT_STATUS.index(v) for v in status]
        return out

    def extra_fields(self, u: np.ndarray, stress: np.ndarray) -> dict:
        """Model-specific per-step fields (stacked over steps: ``u`` is ``(n_steps, n_dofs)``),
        added to :meth:`ddcm_casadi.drivers.harness.Comparison.fields`."""
        return {}

    def contact_pair_labels(self) -> list[str]:
        """A label per contact pair (legends)."""
        return [f"pair {j}" for j in range(self.n_contacts)]

    def results_fields(self, fields: dict) -> dict:
        """What ``results.json`` keeps of one run's per-step fields (:meth:`Comparison.fields`):
        everything for bars and trusses; a model kind with large fields keeps a summary and
        has the fields written elsewhere (:meth:`field_outputs`)."""
        return fields

    def field_outputs(self) -> tuple[str, ...]:
        """The field files this model kind has besides ``results.csv`` and ``results.json``, as the
        names of writers in the output layer's registry (:func:`ddcm_casadi.outputs.drawings.field_writer`),
        e.g. ``("vtu",)`` for a continuum. Bars and trusses have none."""
        return ()

    def figures(self, runs: Iterable[tuple[str, str]]) -> dict[str, FigureSpec]:
        """The figures this model kind has, as data: ``{file name: FigureSpec}``, drawn by the
        output layer (:func:`ddcm_casadi.outputs.save.save_figures`).

        Parameters
        ----------
        runs : iterable of (str, str)
            The ``(variant, formulation)`` keys of the runs made (a figure of one run picks one).

        Returns
        -------
        dict
            Any model: the contact-force history (``contact_history.png``).
        """
        return {"contact_history.png": FigureSpec("contact_history", {"pair_labels": self.contact_pair_labels()})}
