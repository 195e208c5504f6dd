"""Reference scales of a model's problems, and what is physically odd about its load path.

:func:`reference_scales` derives the magnitudes (displacement, strain, stress, force, energy,
modulus, metric) of the classical or the data-driven problem from the model itself, by one or two
linear solves; :meth:`ContactModel.scales_for <ddcm_casadi.models.base.ContactModel.scales_for>`
caches them. The same solves estimate the strain the obstacles impose, which
:func:`load_path_warnings` compares with :data:`LARGE_STRAIN`
(:meth:`ContactModel.path_warnings <ddcm_casadi.models.base.ContactModel.path_warnings>`).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
import scipy.sparse as sp

from ddcm_casadi.errors import InputError
from ddcm_casadi.linalg import SingularMatrix, factorize, factorize_definite
from ddcm_casadi.models.stiffness import Scaled, StiffnessFactor

#: The model's cache key of its kept :class:`~ddcm_casadi.models.stiffness.StiffnessFactor`.
STIFFNESS_FACTOR = "stiffness_factor"



class ContactModel(Protocol):
    """What the scales read of a :class:`~ddcm_casadi.models.base.ContactModel` (a protocol, so
    that this module, which the model class calls, does not import it back)."""

    strain_operator: sp.csr_matrix
    volumes: np.ndarray
    gap_operator: sp.csr_matrix
    contact_area: np.ndarray
    gap_offsets: np.ndarray
    loads: np.ndarray
    load_parameter: np.ndarray
    load_parameter_name: str
    youngs_modulus: np.ndarray | None
    dataset: Any
    length_scale: float
    strain_components: int
    kinematics: str
    prescribed: Any
    _cache: dict

    @property
    def n_dofs(self) -> int: ...

    @property
    def n_points(self) -> int: ...

    @property
    def n_contacts(self) -> int: ...

    def point_stiffness(self, kind: str) -> np.ndarray: ...

    def scales_for(self, kind: str) -> dict: ...

    def near_null_space(self) -> np.ndarray | None: ...

    def representative_law(self, kind: str) -> sp.csr_matrix: ...

    def delassus_rows(self) -> sp.csr_matrix | None: ...

#: Imposed strain beyond which :func:`load_path_warnings` warns: small-strain kinematics then
#: differ from finite-strain ones by more than ~5 % (Green-Lagrange ``e + e^2/2`` vs ``e``).
LARGE_STRAIN = 0.1
#: A load's displacement beyond this many body sizes means the stiffness was singular (the body
#: rests on its contact only; :func:`reference_scales` then adds springs on the pairs).
SINGULAR_DISPLACEMENT = 1e3


def reference_scales(model: ContactModel, kind: str) -> dict:
    """Reference magnitudes of the ``"classical"`` or the ``"ddcm"`` problem of ``model``.

    See :meth:`ContactModel.scales_for <ddcm_casadi.models.base.ContactModel.scales_for>` for
    what they are. Records the strain the obstacles impose, if any, in the model's cache under
    ``("imposed_strain", kind)`` (read by :func:`load_path_warnings`).

    Raises
    ------
    InputError
        A scale outside ``1e-150 .. 1e150`` (its square would not be representable).
    """
    D = model.point_stiffness(kind)
    B, G, a = model.strain_operator, model.gap_operator, model.contact_area
    stiffness = _stiffness(model, kind)
    load_step = int(np.argmax(np.max(np.abs(model.loads), axis=1))) if model.loads.size else 0
    f = model.loads[load_step] if model.loads.size else np.zeros(model.n_dofs)
    penetration = np.maximum(-model.gap_offsets, 0.0)
    pen = float(np.max(penetration)) if penetration.size else 0.0
    kappa = stiffness.kappa
    GA = G.T @ sp.diags(a) if model.n_contacts else None
    spring = stiffness.spring

    u_f = np.zeros(model.n_dofs)
    strain = 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        if np.any(f):
            try:
                u_f = stiffness.solve(f)
            except SingularMatrix:
                u_f = np.full(model.n_dofs, np.inf)
            # a body held only by its contact (a cylinder pressed on a block by a force) leaves K
            # singular, which the factorisation may miss by roundoff: a displacement beyond
            # SINGULAR_DISPLACEMENT body sizes is that, not a small-strain solution
            if not float(np.max(np.abs(u_f), initial=0.0)) <= SINGULAR_DISPLACEMENT * model.length_scale:
                stiffness.singular = True  # the spring's solves from its own factor, not K's
                u_f = spring().solve(f)
            strain = float(np.max(np.abs(B @ u_f), initial=0.0))
        if pen > 0:
            worst = int(np.argmax(np.max(penetration, axis=1)))
            u_g = spring().solve(kappa * (GA @ penetration[worst]))
            normal = float(np.max(np.abs(G @ u_g), initial=0.0))
            if not np.isfinite(normal):  # the solve overflowed: the scale check below says what is out of range
                strain = np.inf
            if normal > 0:
                imposed = float(np.max(np.abs(B @ u_g), initial=0.0)) * pen / normal
                model._cache[("imposed_strain", kind)] = imposed
                strain = max(strain, imposed)
        if model.prescribed is not None:  # the hard device's largest step, alone
            U_D, strain_D = _prescribed_response(model, stiffness, spring)
            model._cache[("prescribed_strain", kind)] = strain_D
            strain = max(strain, strain_D)
            pen = max(pen, U_D)
    U = max(float(np.max(np.abs(u_f), initial=0.0)), pen)
    if not (U > 0 and strain > 0):
        U, strain = 1e-3 * model.length_scale, 1e-3  # nothing moves: any unit will do
    return _checked(kind, _magnitudes(model, kind, D, U, strain))



class _Stiffness:
    """The representative stiffness ``K = B^T W D B`` of :func:`reference_scales` for one kind's
    law ``W D`` (:meth:`~ddcm_casadi.models.base.ContactModel.representative_law`: the classical
    law, so that the classical kind's ``K`` is the classical stiffness; the data's secant modulus
    on every component), with ``kappa`` (a stiff spring per pair, ``1e3 max diag(K) / max a``)
    and solves with ``K`` and ``K + kappa G^T A G``, each factorised on first use.

    Where the model's classical condensation may apply
    (:meth:`~ddcm_casadi.models.base.ContactModel.delassus_rows`), the factor of ``K`` is the
    condensation's (:class:`~ddcm_casadi.models.stiffness.StiffnessFactor`, kept by the model
    for it), and the spring's solves follow from it by Woodbury: ``(K + G^T S G)^-1 = K^-1 -
    K^-1 G^T (S^-1 + D)^-1 G K^-1``, ``S = kappa diag(a)``, ``D = G K^-1 G^T`` (one factorisation
    of ``K`` for the scales and the condensation: 15-25 s at 1e6 unknowns). Not where ``K`` is
    singular (:attr:`singular`: the spring then holds a body that ``K`` alone does not).

    A kind whose law is ``beta`` times another's (one-component points: the data's secant modulus
    against ``E``, one material) reuses its factors: ``K = beta K_1`` and ``kappa = beta kappa_1``, so both inverses
    are ``1 / beta`` of the first kind's (one factorisation instead of two: 23 s at 1e6 unknowns).
    """

    def __init__(self, model: ContactModel, law: sp.csr_matrix, base: "_Stiffness | None" = None,
                 beta: float = 1.0, *, classical: bool = False) -> None:
        self.model, self.beta, self.base = model, beta, base
        #: ``W D`` (:meth:`~ddcm_casadi.models.base.ContactModel.representative_law`), kept by the
        #: first kind only (a later kind's is ``beta`` times it).
        self.law = law if base is None else None
        #: Whether ``K`` is the model's classical stiffness (handed over to its classical problem).
        self.classical = classical
        #: Set where the load's solve shows ``K`` singular (a body held only by its contacts).
        self.singular = False
        if base is None:
            self.K = (model.strain_operator.T @ law @ model.strain_operator).tocsc()
            k_max = float(np.max(self.K.diagonal())) if self.K.shape[0] else 1.0
            self.kappa = 1e3 * k_max / float(np.max(model.contact_area)) if model.n_contacts else 0.0
        else:
            self.K, self.kappa = None, beta * base.kappa
        self._lu = self._spring_lu = self._shared = None

    def law_times(self, strain: np.ndarray) -> np.ndarray:
        """``W D strain``."""
        return self.beta * self.base.law_times(strain) if self.base is not None else self.law @ strain

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``K^-1 rhs`` (:class:`~ddcm_casadi.linalg.SingularMatrix` if ``K`` is singular)."""
        if self.base is not None:
            return self.base.solve(rhs) / self.beta
        return self._factor().solve(rhs)

    def _factor(self):
        """The factor of ``K``, made on first use: the selected solver of definite systems
        (direct, or AMG), with the Delassus matrix where the model's classical condensation may
        apply (kept by the model for it)."""
        if self._lu is None:
            model = self.model
            # the condensation's factor where it may apply, and no kind made it already
            rows = model.delassus_rows() if model.stiffness_factor() is None else None
            if rows is None:
                self._lu = factorize_definite(self.K, near_null=model.near_null_space())
            else:
                self._lu = self._shared = StiffnessFactor(self.K, rows, model.near_null_space(),
                                                          classical=self.classical)
                model._cache[STIFFNESS_FACTOR] = self._shared
        return self._lu

    def spring(self):
        """The factor of ``K`` with a stiff spring on every pair (bodies resting on obstacles only)."""
        if self.base is not None:
            self.base.singular |= self.singular
            return Scaled(self.base.spring(), self.beta)
        if self._spring_lu is None:
            model = self.model
            if not self.singular and self._lu is None and model.delassus_rows() is not None \
                    and model.stiffness_factor() is None:
                try:  # K's factor first (the condensation's), the spring's from it
                    self._factor()
                except SingularMatrix:  # a body held only by its contacts
                    self.singular = True
            if self._shared is not None and not self.singular:
                self._spring_lu = self._shared.with_springs(self.kappa * model.contact_area)
            if self._spring_lu is None:
                GA = model.gap_operator.T @ sp.diags(model.contact_area) if model.n_contacts else None
                self._spring_lu = factorize_definite(self.K + self.kappa * (GA @ model.gap_operator)
                                                     if model.n_contacts else self.K,
                                                     near_null=model.near_null_space())
        return self._spring_lu


def _stiffness(model: ContactModel, kind: str) -> _Stiffness:
    """The :class:`_Stiffness` of ``kind``, sharing the model's first one where its law
    (:meth:`~ddcm_casadi.models.base.ContactModel.representative_law`) is a multiple of that
    one's: the same pattern, the entries' ratio equal to ``4 eps`` (cached in the model)."""
    law = model.representative_law(kind)
    first = model._cache.get("scale_stiffness")
    if first is not None and law.shape == first.law.shape and law.nnz and law.nnz == first.law.nnz \
            and np.array_equal(law.indptr, first.law.indptr) and np.array_equal(law.indices, first.law.indices) \
            and np.all(first.law.data > 0):
        ratio = law.data / first.law.data
        beta = float(ratio[0])
        if np.array_equal(law.data, first.law.data):
            return first
        if beta > 0 and np.allclose(ratio, beta, rtol=4 * np.finfo(float).eps, atol=0):
            return _Stiffness(model, law, first, beta)
    out = _Stiffness(model, law, classical=kind == "classical")
    if first is None:
        model._cache["scale_stiffness"] = out
    return out


def _prescribed_response(model: ContactModel, stiffness: "_Stiffness", spring) -> tuple[float, float]:
    """``(displacement, strain)`` magnitudes of the step with the largest prescribed displacement:
    ``K u = -B^T W D B_D u_D`` (``W D`` the model's
    :meth:`~ddcm_casadi.models.base.ContactModel.representative_law`; no load, no obstacle), the
    displacement ``max(|u|, |u_D|)`` and the strain ``max |B u + B_D u_D|``."""
    pr = model.prescribed
    if not pr.size or not np.any(pr.values):
        return 0.0, 0.0
    step = int(np.argmax(np.max(np.abs(pr.values), axis=1)))
    u_D = pr.values[step]
    offset = pr.strain_operator @ u_D
    u = np.zeros(model.n_dofs)
    if model.n_dofs:
        rhs = -(model.strain_operator.T @ (stiffness.law_times(offset)))
        try:
            u = stiffness.solve(rhs)
        except SingularMatrix:
            u = spring().solve(rhs)
    strain = float(np.max(np.abs(model.strain_operator @ u + offset), initial=0.0))
    if not np.isfinite(strain):
        strain = np.inf
    elif strain <= 64 * np.finfo(float).eps * float(np.max(np.abs(offset), initial=0.0)):
        strain = 0.0  # roundoff: the device moves the body without straining it (a mechanism's motion)
    return max(float(np.max(np.abs(u), initial=0.0)), float(np.max(np.abs(u_D)))), strain


def _magnitudes(model: ContactModel, kind: str, D: np.ndarray, U: float, strain: float) -> dict:
    """The scales from a displacement ``U`` and a strain ``strain``: stress ``D_max strain``,
    force ``stress x`` a representative section, the energy unit and the metric."""
    B, w, a = model.strain_operator, model.volumes, model.contact_area
    k = model.strain_components
    modulus = float(np.max(D))
    rows = abs(B).max(axis=1).toarray().ravel() if B.nnz else np.zeros(0)
    section = (float(np.mean(a)) if model.n_contacts else
               float(np.median(np.repeat(w, k)[rows > 0] * rows[rows > 0])) if np.any(rows > 0)
               else float(np.mean(w)) / model.length_scale)
    stress = modulus * strain
    if kind == "classical":
        metric, energy = modulus, float(np.sum(w)) * modulus * strain ** 2
    else:
        metric = max(m.modulus for m in model.dataset.point_materials(model.n_points)[0])
        energy = float(np.sum(w)) * 0.5 * (metric * strain ** 2 + stress ** 2 / metric)
    return dict(length=model.length_scale, displacement=U, strain=strain, stress=stress,
                force=stress * section, energy=energy, modulus=modulus, metric=metric)


def _checked(kind: str, scales: dict) -> dict:
    """``scales``, unless one is out of range."""
    # Squares and products of scales (energies, d^2) must stay representable: each within 1e+-150.
    bad = {k: v for k, v in scales.items() if not (np.isfinite(v) and 1e-150 <= v <= 1e150)}
    if bad:
        name, value = next(iter(bad.items()))
        raise InputError(f"obstacle positions, loads or moduli are out of range: the {kind} problem's {name} "
                         f"scale is {value:.3g}, outside 1e-150 to 1e150")
    return scales


def load_path_warnings(model: ContactModel) -> list[str]:
    """What is physically odd about the load path of ``model``, one line each; refuses what is
    meaningless.

    - The obstacles already penetrate the body at the first step, and not because the load
      parameter moved them there: where the gaps change along the path, they are extrapolated
      linearly to a load parameter of zero (a continuum's obstacle travel starting above zero is
      the load, not an obstacle on the wrong side). The body then starts with contact forces and no
      load (often an obstacle placed on the wrong side).
    - The strain at the step of deepest penetration beyond :data:`LARGE_STRAIN`: far outside the
      small-strain model. The quick estimate of the scales (:func:`reference_scales`, every
      pair held) only selects the paths to look at; the strain reported is that of the computed
      state of that step (:func:`computed_strain`: a linear elastic solve with the contacts found
      by an active set), so a stop that closes only part way is accounted for.
    - Likewise the strain a hard device imposes at its largest prescribed displacement
      (:func:`_prescribed_warnings`).

    The strain checks apply to small kinematics only.

    Raises
    ------
    InputError
        A computed compression of 1 or more (an obstacle pushed past a fixed end, through the
        body, or a hard device that shortens a member to nothing): a member's strain, a
        continuum's smallest principal strain (:func:`_compression`). A stretch of any size is a
        warning, not a refusal (a bar pulled to strain 1 by a hard device, E = 1 and a
        displacement equal to its length, is well posed).
    """
    out = []
    starting = _starting_penetration(model)
    if starting is not None:
        n, first = starting
        out.append(f"the obstacles start inside the body: {n} contact pair(s) penetrate by up to {first:.3g} m "
                   f"at the first step ({model.load_parameter_name}={model.load_parameter[0]:.6g}), so there are "
                   f"contact forces before any load (unless a body held only by its contacts is free to move out "
                   f"of the overlap)")
    if model.kinematics != "small":  # large strains and rotations are what finite kinematics model
        return out
    kind = "classical" if model.youngs_modulus is not None else "ddcm"
    model.scales_for(kind)
    imposed = max((v for k, v in model._cache.items() if isinstance(k, tuple) and k[0] == "imposed_strain"),
                  default=0.0)
    if imposed > LARGE_STRAIN:  # else the quick estimate (every pair held) is the larger: nothing to look at
        worst = int(np.argmin(np.min(model.gap_offsets, axis=1))) if model.n_contacts else 0
        out += _imposed_strain(
            model, kind, worst,
            lambda c, where: (f"the obstacles impose a strain of about {c:.2g} at {where} (penetration "
                              f"{-np.min(model.gap_offsets):.3g} m): pushed past a fixed end or through the body; "
                              f"a small-strain model is meaningless there"),
            lambda e, where: (f"the obstacles impose a strain of about {e:.2g} at {where} (a linear elastic solve of "
                              f"that step): far beyond the small-strain model (> {LARGE_STRAIN:g})"))
    out += _prescribed_warnings(model, kind)
    return out


def _imposed_strain(model: ContactModel, kind: str, step: int, refusal, warning) -> list[str]:
    """The strain of a linear elastic solve of ``step`` (contacts by an active set): an
    ``InputError`` of ``refusal(compression, where)`` where it shortens a fibre to zero length or
    beyond (the body inverted, meaningless under small kinematics), ``[warning(strain, where)]``
    beyond :data:`LARGE_STRAIN` (a well-posed stretch, however large, is a warning only), else ``[]``."""
    where = f"{model.load_parameter_name}={model.load_parameter[step]:.6g}"
    state = _linear_state(model, kind, step)
    compression = _compression(model, state)
    if compression >= 1.0 - 1e-4:
        raise InputError(refusal(compression, where))
    strain = max(compression, float(np.max(np.abs(state), initial=0.0)))
    return [warning(strain, where)] if strain > LARGE_STRAIN else []


def _compression(model: ContactModel, strain: np.ndarray) -> float:
    """The largest compression of a state (a positive number): ``-min strain`` of one-component
    points; of a continuum's points, ``-min`` of their principal strains (a fibre shortened by
    that fraction of its length: 1 or more is the body inverted under small kinematics)."""
    e = np.asarray(strain, dtype=float)
    if not e.size:
        return 0.0
    k = model.strain_components
    if k == 1:
        return float(-np.min(e))
    from ddcm_casadi.data.metric import mandel_to_tensor

    dim = {3: 2, 6: 3}[k]
    t = mandel_to_tensor(e.reshape(-1, k), dim)[:, :dim, :dim]
    return float(-np.min(np.linalg.eigvalsh(t)))


def _prescribed_warnings(model: ContactModel, kind: str) -> list[str]:
    """The strain a hard device imposes at its largest step (a linear elastic solve, contacts
    by an active set): refused where it compresses the body to nothing or beyond (a fibre's
    length reversed: the body inverted), a warning beyond :data:`LARGE_STRAIN` (a well-posed
    stretch, however large, is a warning only)."""
    pr = model.prescribed
    if pr is None or model._cache.get(("prescribed_strain", kind), 0.0) <= LARGE_STRAIN:
        return []
    step = int(np.argmax(np.max(np.abs(pr.values), axis=1)))
    largest = float(np.max(np.abs(pr.values[step])))
    return _imposed_strain(
        model, kind, step,
        lambda c, where: (f"the prescribed displacements compress the body to a strain of about {-c:.2g} at {where} "
                          f"(largest prescribed displacement {largest:.3g} m): shortened past zero length, the body "
                          f"inverted; a small-strain model is meaningless there"),
        lambda e, where: (f"the prescribed displacements impose a strain of about {e:.2g} at {where} (a linear "
                          f"elastic solve of that step): far beyond the small-strain model (> {LARGE_STRAIN:g}); "
                          f"kinematics = \"finite\" models large strains"))


def _starting_penetration(model: ContactModel) -> tuple[int, float] | None:
    """The pairs that penetrate at a load parameter of zero, and by how much: the first step's
    gaps, extrapolated linearly to a load parameter of zero where they change along the path and
    the load parameter with them (``None``: none penetrate, or the first step is not penetrated)."""
    g0 = model.gap_offsets[0] if model.n_contacts else np.zeros(0)
    tol = 1e-12 * model.length_scale
    if not np.any(g0 < -tol):
        return None
    lam = np.asarray(model.load_parameter, dtype=float)
    gaps = model.gap_offsets
    if lam.size >= 2 and gaps.shape[0] >= 2 and lam[1] != lam[0] and np.any(gaps[1] != gaps[0]):
        rate = (gaps[1] - gaps[0]) / (lam[1] - lam[0])
        at_zero = g0 - lam[0] * rate
        moved_in = (rate * (lam[1] - lam[0]) < 0) & (at_zero >= -tol)  # brought into contact by the path
        still = (g0 < -tol) & ~moved_in
    else:
        still = g0 < -tol
    if not np.any(still):
        return None
    return int(np.sum(still)), float(-np.min(g0[still]))


def computed_strain(model: ContactModel, kind: str, step: int) -> tuple[float, float]:
    """The smallest and largest strain component of a linear elastic solve of step ``step``
    (:func:`_linear_state`).

    Returns
    -------
    tuple of float
        ``(min, max)`` over every strain component of every point (signed: compression < 0).
    """
    e = _linear_state(model, kind, step)
    if not e.size:
        return 0.0, 0.0
    return float(np.min(e)), float(np.max(e))


def _linear_state(model: ContactModel, kind: str, step: int) -> np.ndarray:
    """The strains (flat, point-major) of a linear elastic solve of step ``step``.

    The load, the obstacles and the prescribed displacements of the step (strains ``B u + B_D
    u_D``, gaps ``G u + G_D u_D + gap0``), with a representative modulus per point
    (:meth:`~ddcm_casadi.models.base.ContactModel.point_stiffness`); contacts by a penalty active
    set (a pair is active while it penetrates; a stiff spring, ``1e6`` times the stiffest
    diagonal of ``K``, holds it), at most 30 passes. A singular system (a body held by nothing)
    falls back on every pair held, as :func:`reference_scales` does. Empty where no state is
    found (a singular system even then, or non-finite strains).
    """
    D = model.point_stiffness(kind)
    B, G, w, a = model.strain_operator, model.gap_operator, model.volumes, model.contact_area
    k = model.strain_components
    K = (B.T @ sp.diags(np.repeat(w * D, k)) @ B).tocsc()
    k_max = float(np.max(K.diagonal())) if K.shape[0] else 1.0
    f = model.loads[step] if model.loads.size else np.zeros(model.n_dofs)
    g0 = model.gap_offsets[step] if model.n_contacts else np.zeros(0)
    offset = np.zeros(B.shape[0])
    if model.prescribed is not None:  # the hard device: a strain offset and a gap offset
        u_D = model.prescribed.values[step]
        offset = model.prescribed.strain_operator @ u_D
        f = f - B.T @ (np.repeat(w * D, k) * offset)
        if model.n_contacts:
            g0 = g0 + model.prescribed.gap_operator @ u_D
    kappa = 1e6 * k_max / float(np.max(a)) if model.n_contacts else 0.0
    active = g0 < 0
    u = np.zeros(model.n_dofs)
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(30):
            if not model.n_dofs:
                break
            held = sp.diags(kappa * a * active)
            try:
                u = factorize((K + G.T @ held @ G).tocsc() if model.n_contacts else K).solve(
                    f - (G.T @ (held @ g0) if model.n_contacts else 0.0))
            except SingularMatrix:
                held = sp.diags(kappa * a)
                try:
                    u = factorize((K + G.T @ held @ G).tocsc()).solve(f - G.T @ (held @ np.minimum(g0, 0.0)))
                except SingularMatrix:
                    return np.zeros(0)
                break
            now = (g0 + G @ u < 0) if model.n_contacts else active
            if np.array_equal(now, active):
                break
            active = now
        e = B @ u + offset
    if not e.size or not np.all(np.isfinite(e)):
        return np.zeros(0)
    return e
