"""Reference scales of a model's problems, and what is physically odd about its load path.

:func:`reference_scales` derives the magnitudes (displacement, strain, stress, force, energy,
modulus, metric) of the classical or the data-driven problem from the model itself, by one or two
linear solves; :meth:`ContactModel.scales_for <ddcm_casadi.models.base.ContactModel.scales_for>`
caches them. The same solves estimate the strain the obstacles impose, which
:func:`load_path_warnings` compares with :data:`LARGE_STRAIN`
(:meth:`ContactModel.path_warnings <ddcm_casadi.models.base.ContactModel.path_warnings>`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from ddcm_casadi.errors import InputError
from ddcm_casadi.linalg import SingularMatrix, factorize

if TYPE_CHECKING:
    from ddcm_casadi.models.base import ContactModel

#: Imposed strain beyond which :func:`load_path_warnings` warns: small-strain kinematics then
#: differ from finite-strain ones by more than ~5 % (Green-Lagrange ``e + e^2/2`` vs ``e``).
LARGE_STRAIN = 0.1


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
    B, G, w, a = model.strain_operator, model.gap_operator, model.volumes, model.contact_area
    k = model.strain_components
    K = (B.T @ sp.diags(np.repeat(w * D, k)) @ B).tocsc()
    k_max = float(np.max(K.diagonal())) if K.shape[0] else 1.0
    load_step = int(np.argmax(np.max(np.abs(model.loads), axis=1))) if model.loads.size else 0
    f = model.loads[load_step] if model.loads.size else np.zeros(model.n_dofs)
    penetration = np.maximum(-model.gap_offsets, 0.0)
    pen = float(np.max(penetration)) if penetration.size else 0.0
    kappa = 1e3 * k_max / float(np.max(a)) if model.n_contacts else 0.0
    GA = G.T @ sp.diags(a) if model.n_contacts else None
    spring_lu = None

    def spring():  # K with a stiff spring on every pair (bodies resting on obstacles only)
        nonlocal spring_lu
        if spring_lu is None:
            spring_lu = factorize(K + kappa * (GA @ G) if model.n_contacts else K)
        return spring_lu

    u_f = np.zeros(model.n_dofs)
    strain = 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        if np.any(f):
            try:
                lu = factorize(K)
            except SingularMatrix:
                lu = spring()
            u_f = lu.solve(f)
            strain = float(np.max(np.abs(B @ u_f), initial=0.0))
        if pen > 0:
            worst = int(np.argmax(np.max(penetration, axis=1)))
            u_g = spring().solve(kappa * (GA @ penetration[worst]))
            normal = float(np.max(np.abs(G @ u_g), initial=0.0))
            if normal > 0:
                imposed = float(np.max(np.abs(B @ u_g), initial=0.0)) * pen / normal
                model._cache[("imposed_strain", kind)] = imposed
                strain = max(strain, imposed)
    U = max(float(np.max(np.abs(u_f), initial=0.0)), pen)
    if not (U > 0 and strain > 0):
        U, strain = 1e-3 * model.length_scale, 1e-3  # nothing moves: any unit will do
    return _checked(kind, _magnitudes(model, kind, D, U, strain))


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

    - The obstacles already penetrate the body at the first step: the body starts with
      contact forces and no load (often an obstacle placed on the wrong side).
    - The largest strain the obstacles impose (the penetration spread over the body as the
      scales estimate it, :func:`reference_scales`) beyond :data:`LARGE_STRAIN`: far outside the
      small-strain model.

    The strain checks apply to small kinematics only.

    Raises
    ------
    InputError
        An imposed strain of 1 or more (an obstacle pushed past a fixed end, through the
        body): a small-strain model is meaningless there.
    """
    out = []
    first = -np.min(model.gap_offsets[0], initial=0.0)
    if first > 1e-12 * model.length_scale:
        n = int(np.sum(model.gap_offsets[0] < 0))
        out.append(f"the obstacles start inside the body: {n} contact pair(s) penetrate by up to {first:.3g} m "
                   f"at the first step ({model.load_parameter_name}={model.load_parameter[0]:.6g}), so there are "
                   f"contact forces before any load")
    if model.kinematics != "small":  # large strains and rotations are what finite kinematics model
        return out
    model.scales_for("classical" if model.youngs_modulus is not None else "ddcm")
    imposed = max((v for k, v in model._cache.items() if isinstance(k, tuple) and k[0] == "imposed_strain"),
                  default=0.0)
    worst = int(np.argmin(np.min(model.gap_offsets, axis=1))) if model.n_contacts else 0
    where = f"{model.load_parameter_name}={model.load_parameter[worst]:.6g}"
    if imposed >= 1.0:
        raise InputError(f"the obstacles impose a strain of about {imposed:.3g} at {where} (penetration "
                         f"{-np.min(model.gap_offsets):.3g} m): pushed past a fixed end or through the body; "
                         f"a small-strain model is meaningless there")
    if imposed > LARGE_STRAIN:
        out.append(f"the obstacles impose a strain of about {imposed:.3g} at {where}: far beyond the "
                   f"small-strain model (> {LARGE_STRAIN:g})")
    return out
