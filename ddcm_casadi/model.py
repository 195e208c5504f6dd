"""The model description: what the problem is, independent of how contact is enforced.

A :class:`ContactModel` describes a small-strain, linear structure with ``n`` displacement unknowns
``u``, ``m`` material points (elements) and ``nc`` unilateral contact pairs:

- kinematics ``strain = B u`` with a sparse ``B`` (m x n) and material-point volumes ``w`` (m);
- equilibrium ``B^T W stress - G^T (a * p) = f`` with loads ``f``;
- contact pairs ``gap = G u + gap0 >= 0``, ``p >= 0``, ``gap * p = 0`` with contact areas ``a``;
- a material law ``stress = E strain`` (classical) and/or a material data set (DDCM).

The load path is a sequence of steps, each with its own ``gap0`` (obstacle positions) and ``f``.
Both the classical and the data-driven problem are built from this one object
(see :mod:`ddcm_casadi.problem`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .data import MaterialDataset, PointData, check_positive
from .errors import InputError


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
    _scales: dict = field(init=False, repr=False)

    def __post_init__(self) -> None:
        B = sp.csr_matrix(self.strain_operator, dtype=float)
        G = sp.csr_matrix(self.gap_operator, dtype=float)
        m, n = B.shape
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
            self.dataset.point_metric(m)  # checks a per-point material list against the model
        for k, v in dict(strain_operator=B, gap_operator=G, volumes=w, contact_area=a,
                         gap_offsets=g0, loads=f, load_parameter=lp, youngs_modulus=E,
                         length_scale=L).items():
            object.__setattr__(self, k, v)
        object.__setattr__(self, "_scales", self._reference_scales())

    # ------------------------------------------------------------------ sizes
    @property
    def n_dofs(self) -> int:
        return self.strain_operator.shape[1]

    @property
    def n_points(self) -> int:
        """Number of material points (elements)."""
        return self.strain_operator.shape[0]

    @property
    def n_contacts(self) -> int:
        return self.gap_operator.shape[0]

    @property
    def n_steps(self) -> int:
        return self.gap_offsets.shape[0]

    # ----------------------------------------------------------------- scales
    @property
    def metric(self) -> np.ndarray:
        """DDCM metric constant ``c`` per material point."""
        if self.dataset is None:
            raise InputError("this model has no material data set")
        return self.dataset.point_metric(self.n_points)

    def _reference_scales(self) -> dict:
        # Characteristic strain from the load path: obstacle travel over the length.
        modulus = float(np.max(self.youngs_modulus)) if self.youngs_modulus is not None else self.dataset.max_metric
        metric = self.dataset.max_metric if self.dataset is not None else modulus
        travel = float(np.max(np.abs(self.gap_offsets))) if self.gap_offsets.size else 0.0
        K_diag = (self.strain_operator.T @ sp.diags(self.volumes * modulus) @ self.strain_operator).diagonal()
        k_ref = float(np.max(K_diag)) if K_diag.size else modulus
        load = float(np.max(np.abs(self.loads))) if self.loads.size else 0.0
        # A nodal load strains the members at its node by about (load / k_ref) / l, with l their
        # typical length (1 / |B_ij| for a bar or truss member), not by that over the whole size.
        B = abs(sp.csr_matrix(self.strain_operator))
        row_max = B.max(axis=1).toarray().ravel() if B.nnz else np.zeros(0)
        member = 1.0 / float(np.median(row_max[row_max > 0])) if np.any(row_max > 0) else self.length_scale
        strain = max(travel / self.length_scale, load / k_ref / min(member, self.length_scale), 1e-12)
        if travel == 0.0 and load == 0.0:
            strain = 1e-3
        area = float(np.mean(self.contact_area)) if self.n_contacts else float(np.mean(self.volumes)) / self.length_scale
        with np.errstate(over="ignore"):
            energy = float(np.sum(self.volumes)) * metric * np.float64(strain) ** 2
        if not (np.isfinite(energy) and energy > 0 and np.isfinite(metric * strain * area)):
            raise InputError("obstacle positions, loads or moduli are out of range (scales overflow)")
        return dict(
            length=self.length_scale,
            displacement=strain * self.length_scale,
            stress=metric * strain,
            force=metric * strain * area,
            energy=float(energy),
            modulus=modulus,
            metric=metric,
        )

    @property
    def scales(self) -> dict:
        """Reference magnitudes used to nondimensionalise (displacement, stress, force, energy)."""
        return dict(self._scales)

    @property
    def contact_stiffness(self) -> float:
        """Reference contact stiffness ``E / length`` (Pa/m), the unit of the penalty parameters."""
        return self._scales["modulus"] / self._scales["length"]

    # -------------------------------------------------------------- mechanics
    def stiffness(self) -> sp.csr_matrix:
        """Classical stiffness ``K = B^T W E B`` (sparse)."""
        if self.youngs_modulus is None:
            raise InputError("this model has no Young's modulus (classical variant unavailable)")
        B = self.strain_operator
        return (B.T @ sp.diags(self.volumes * self.youngs_modulus) @ B).tocsr()

    def gap(self, u: np.ndarray, step: int) -> np.ndarray:
        return self.gap_operator @ np.asarray(u) + self.gap_offsets[step]

    def active_contacts(self, pressure: np.ndarray) -> np.ndarray:
        """Which pairs carry a pressure above 1e-8 of the stress scale (one rule for tables and
        figures); ``pressure`` may be stacked over steps."""
        return np.asarray(pressure) > 1e-8 * self._scales["stress"]

    def strain(self, u: np.ndarray) -> np.ndarray:
        return self.strain_operator @ np.asarray(u)

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
                    load_parameter=self.load_parameter.tolist(), youngs_modulus=E)

    @property
    def scalar(self) -> bool:
        """One unknown, one material point, at most one pair: tables hold ``u`` and ``p`` themselves."""
        return self.n_dofs == 1 and self.n_contacts <= 1 and self.n_points == 1

    def step_summary(self, u: np.ndarray, p: np.ndarray) -> dict:
        """The per-step columns of ``results.csv`` that describe the solution ``(u, p)``."""
        if self.scalar:
            return dict(u=float(u[-1]), p=float(p[0]) if p.size else float("nan"))
        return dict(max_abs_u=float(np.max(np.abs(u))), total_contact_force=float(np.sum(self.contact_area * p)),
                    active_contacts=int(np.sum(self.active_contacts(p))))

    def extra_fields(self, u: np.ndarray, stress: np.ndarray) -> dict:
        """Model-specific per-step fields (stacked over steps: ``u`` is ``(n_steps, n_dofs)``),
        added to :meth:`ddcm_casadi.harness.Comparison.fields`."""
        return {}

    def save_figures(self, cmp, out_dir) -> list:
        """Draw the figures that suit this model kind into ``out_dir``; returns the paths.
        Imports matplotlib only here."""
        return []
