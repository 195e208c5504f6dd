r"""Contact results of a continuum: the contact pressure as a field, and the resultant forces.

The solvers' pressure ``p_j`` of a pair is a nodal multiplier: ``a_j p_j`` is the nodal contact
force, ``a_j`` the pair's lumped tributary area (:func:`~ddcm_casadi.models.continuum.fem.tributary_areas`).
On unstructured linear tetrahedra the nodal forces inherit the element-to-element noise of the
constant-strain elements, and ``p_j`` scatters by several per cent from node to node inside the
contact zone; its largest value is biased upwards (``docs/maths.md``, "Contact pressure as a field").

:func:`pressure_field` recovers the pressure from the stresses of the boundary elements instead,
the normal traction ``t_n = -n . sigma . n`` (``n`` the outward unit normal of each contact facet,
``sigma`` the material points' stresses, fitted linearly per element for P2), and projects it on
the trace of the element space with the same lumped boundary mass the pairs use:

.. math::  \hat p_i = \frac{1}{a_i} \int_{\Gamma_c} \varphi_i\, t_n \,\mathrm{d}s ,
           \qquad a_i = \sum_f |f| \frac{M^f_{ii}}{\sum_j M^f_{jj}}

(for P1 and for quadratic segments ``a_i = \int \varphi_i``: a uniform traction is reproduced
exactly). The field is zero at the pairs that carry no force (complementarity: no traction where
the gap is open). Measured on the 3-D P1 Hertz case (``docs/maths.md``), it has less scatter than
the nodal pressure and than the consistent-mass projection of the nodal forces (``M p = a p``),
which amplifies the node-to-node noise about fourfold.

:func:`measured_pressure` is the pressure every measure uses (Hertz ``p0``, ``a``, profile error,
the profile figure, ``ddcm-validate``): the recovered field on linear tetrahedra, where it was
measured better, and the nodal pressure on triangles (P1 and P2), where the nodal pressure was
measured better (no scatter on the structured meshes, and the constant stress of a boundary
triangle reads 2-5 % high: ``docs/maths.md``). Both are written to the outputs.

Forces stay the nodal forces': :func:`surface_forces` sums ``a_j p_j n_j`` per contact surface, the
resultant the solution is in equilibrium with.

Contact surfaces are the model's ``contact_facets``; the pairs of surface ``s`` are those with
``contact_obstacle == s`` (one surface per ``[[contact]]``), so nothing here assumes the other
side is a rigid obstacle.
"""

from __future__ import annotations

import numpy as np
import skfem

from ddcm_casadi.errors import InputError
# the functions take a ContinuumModel, which imports this module: annotated with its base class
from ddcm_casadi.models.base import ContactModel

_SQRT2 = np.sqrt(2.0)


def normal_projector(normals: np.ndarray) -> np.ndarray:
    """``(..., k)`` the Mandel row ``m(n)`` with ``m(n) . sigma = n . sigma . n`` for unit normals
    ``(..., d)``: ``[n1^2, n2^2, sqrt2 n1 n2]`` (2-D), ``[n1^2, n2^2, n3^2, sqrt2 n2 n3, sqrt2 n1 n3,
    sqrt2 n1 n2]`` (3-D); the off-diagonal Mandel components are ``sqrt2 sigma_ij``, and
    ``n_i n_j`` appears twice in the double sum."""
    n = np.asarray(normals, float)
    if n.shape[-1] == 2:
        return np.stack([n[..., 0] ** 2, n[..., 1] ** 2, _SQRT2 * n[..., 0] * n[..., 1]], axis=-1)
    return np.stack([n[..., 0] ** 2, n[..., 1] ** 2, n[..., 2] ** 2, _SQRT2 * n[..., 1] * n[..., 2],
                     _SQRT2 * n[..., 0] * n[..., 2], _SQRT2 * n[..., 0] * n[..., 1]], axis=-1)


def _facet_basis(model: ContactModel, surface: int) -> skfem.FacetBasis:
    """The scalar basis on contact surface ``surface``'s facets (built once per model), with the
    quadrature of the tributary areas, so that ``a_i`` and the projection integrate alike."""
    key = ("contact_facet_basis", surface)
    fb = model._cache.get(key)
    if fb is None:
        disc = model.discretisation
        fb = skfem.FacetBasis(disc.mesh, disc.scalar_basis.elem, facets=model.contact_facets[surface],
                              intorder=max(2, 2 * disc.degree))
        model._cache[key] = fb
    return fb


def _stress_at(model: ContactModel, stress: np.ndarray, elements: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``(n_steps, nf, nq, k)`` the stresses of ``elements`` at the points ``x`` ``(d, nf, nq)``.

    One material point per element (P1): its constant stress. Several (P2: ``d + 1`` points of a
    degree-2 rule, on which a linear field is determined): the linear field through them, the
    stress of a quadratic displacement."""
    disc = model.discretisation
    nq_e, k, d = disc.points_per_element, model.strain_components, model.dimension
    s = stress.reshape(stress.shape[0], -1, nq_e, k)[:, elements]  # (n_steps, nf, nq_e, k)
    if nq_e == 1:
        return np.repeat(s, x.shape[2], axis=2)
    X = disc.quadrature_points().reshape(-1, nq_e, d)[elements]  # (nf, nq_e, d)
    A = np.concatenate([np.ones(X.shape[:2] + (1,)), X], axis=2)  # (nf, nq_e, d + 1)
    coef = np.einsum("fcq,tfqk->tfck", np.linalg.pinv(A), s)  # least squares; exact when nq_e = d + 1
    at = np.concatenate([np.ones((1,) + x.shape[1:]), x], axis=0)  # (d + 1, nf, nq)
    return np.einsum("cfq,tfck->tfqk", at, coef)


def pressure_field(model: ContactModel, pressure: np.ndarray, stress: np.ndarray) -> np.ndarray:
    r"""The recovered contact pressure ``\hat p`` of every pair (Pa), see the module.

    Parameters
    ----------
    model : ContinuumModel
        Small kinematics (at finite strain the reference-configuration projection of ``S`` is no
        traction of the deformed body: refused).
    pressure : ndarray, shape (nc,) or (n_steps, nc)
        The solvers' nodal pressures (they say which pairs carry a force).
    stress : ndarray, shape (m k,) or (n_steps, m k)
        The material points' Mandel stresses of the same steps (DDCM: the state's, which is in
        equilibrium with the contact forces).

    Returns
    -------
    ndarray, the shape of ``pressure``
        ``\hat p_j``; zero at the pairs without force. A non-finite step gives NaN.
    """
    if model.finite:
        raise InputError("the recovered contact pressure is defined at small kinematics only")
    p = np.asarray(pressure, float)
    sig = np.asarray(stress, float)
    single = p.ndim == 1
    p, sig = np.atleast_2d(p), np.atleast_2d(sig)
    out = np.zeros_like(p)
    if not model.n_contacts:
        return out[0] if single else out
    n_scalar = model.discretisation.scalar_basis.N
    for s, facets in enumerate(model.contact_facets):
        pairs = np.flatnonzero(np.asarray(model.contact_obstacle) == s)
        if not pairs.size or not len(facets):
            continue
        fb = _facet_basis(model, s)
        normals = np.moveaxis(np.asarray(fb.normals), 0, -1)  # (nf, nq, d), outward
        x = np.asarray(fb.global_coordinates())
        t_n = -np.einsum("fqk,tfqk->tfq", normal_projector(normals), _stress_at(model, sig, fb.tind, x))
        dx = np.asarray(fb.dx)
        rhs = np.zeros((p.shape[0], n_scalar))
        for i, phi in enumerate(fb.basis):  # int phi_i t_n over each facet, added into its dof
            contribution = np.sum(np.asarray(phi[0]) * dx * t_n, axis=2)  # (n_steps, nf)
            for t in range(p.shape[0]):
                np.add.at(rhs[t], fb.element_dofs[i], contribution[t])
        out[:, pairs] = rhs[:, model.contact_dofs[pairs]] / model.contact_area[pairs]
    out[~model.active_contacts(p)] = 0.0
    out[~np.all(np.isfinite(p), axis=1) | ~np.all(np.isfinite(sig), axis=1)] = np.nan
    return out[0] if single else out


def surface_forces(model: ContactModel, u: np.ndarray, p: np.ndarray, steps=None) -> np.ndarray:
    """``(n_steps, n_surfaces, d)`` the resultant contact force on the body per step and contact
    surface, as modelled: ``sum a_0 p n`` over the surface's pairs, ``a_0 p`` the nodal force and
    ``n`` the normal it acts along (:meth:`~ddcm_casadi.models.continuum.model.ContinuumModel.current_normals`:
    the obstacle's at the reference configuration at small kinematics, at the current contact
    point at finite strain, with the obstacle where load step ``steps[k]`` puts it; default: row
    ``k`` is step ``k``). N (N per unit thickness in 2-D); NaN at a step with non-finite fields."""
    u, p = np.atleast_2d(np.asarray(u, float)), np.atleast_2d(np.asarray(p, float))
    steps = range(u.shape[0]) if steps is None else steps
    n_surfaces, d = len(model.contact_facets), model.dimension
    owner = np.asarray(model.contact_obstacle, dtype=int)
    out = np.full((u.shape[0], n_surfaces, d), np.nan)
    for k, step in enumerate(steps):
        if np.all(np.isfinite(u[k])) and np.all(np.isfinite(p[k])):
            pair_forces = (model.contact_area * p[k])[:, None] * model.current_normals(u[k], step)
            for s in range(n_surfaces):
                out[k, s] = pair_forces[owner == s].sum(axis=0)
    return out



#: ``(dimension, degree)`` of the discretisations whose measures use the recovered field
#: (:func:`measured_pressure`): linear tetrahedra (measured, ``docs/maths.md``).
RECOVERED_MEASURE = frozenset({(3, 1)})


def uses_recovered(model: ContactModel) -> bool:
    """Whether the measures of ``model`` use :func:`pressure_field` (small kinematics on a
    discretisation of :data:`RECOVERED_MEASURE`), not the nodal pressures."""
    disc = model.discretisation
    return not model.finite and (disc.dimension, disc.degree) in RECOVERED_MEASURE


def measured_pressure(model: ContactModel, pressure: np.ndarray, stress: np.ndarray | None) -> np.ndarray:
    """The pressure per pair every measure uses: :func:`pressure_field` where :func:`uses_recovered`
    (``stress`` is then required), else the nodal ``pressure`` itself."""
    if not uses_recovered(model):
        return np.asarray(pressure, float)
    if stress is None:
        raise InputError("the contact pressure of linear tetrahedra is measured from the stresses: pass the step's stress")
    return pressure_field(model, pressure, stress)


# ------------------------------------------------------------------------ symmetry and results
def check_symmetry_factor(symmetry_factor: float, reference=None) -> None:
    """A symmetry factor is a number >= 1 (the full body's force over the modelled part's), and
    the one setting of a model: a reference with another ``force_factor`` is refused."""
    f = symmetry_factor
    if isinstance(f, bool) or not isinstance(f, (int, float, np.floating)) or not (np.isfinite(f) and f >= 1):
        raise InputError(f"symmetry_factor must be a number >= 1 (2 for a half model, 4 for a quarter), got {f!r}")
    other = getattr(reference, "force_factor", None)
    if other is not None and float(other) != float(f):
        raise InputError(f"[hertz] force_factor = {other:g} differs from the model's symmetry_factor = {f:g}; "
                         "give one symmetry factor ([mesh] symmetry_factor)")


def _names(model: ContactModel) -> list[str]:
    return [getattr(ob, "name", f"contact {s}") for s, ob in enumerate(model.obstacles)]


def _directions(model: ContactModel) -> np.ndarray:
    """``(n_surfaces, d)`` the unit direction of travel of each surface's obstacle."""
    d = model.dimension
    return np.array([ob.offset(1.0) for ob in model.obstacles], dtype=float).reshape(len(model.obstacles), d)


def contact_force_columns(model: ContactModel, u: np.ndarray, p: np.ndarray, step: int) -> dict:
    """The columns of ``results.csv`` on the contact forces of load step ``step``: per contact surface,
    ``contact_force_along_travel_as_modelled`` (:func:`surface_forces` resolved along the
    obstacle's direction of travel, of the modelled part) and ``contact_force_along_travel_full_body``
    (times the model's ``symmetry_factor``: the symmetric parts' forces along the travel add up,
    their components across the symmetry planes cancel). With several surfaces the names end in
    ``[<obstacle name>]``."""
    along = np.einsum("sd,sd->s", surface_forces(model, u, p, [step])[0], _directions(model))
    names = _names(model)
    out = {}
    for s, name in enumerate(names):
        tag = "" if len(names) == 1 else f"[{name}]"
        out[f"contact_force_along_travel_as_modelled{tag}"] = float(along[s])
        out[f"contact_force_along_travel_full_body{tag}"] = float(model.symmetry_factor * along[s])
    return out


def contact_results(model: ContactModel, fields: dict) -> dict:
    """What ``results.json`` keeps of one run's fields (:meth:`Comparison.fields`), every number
    named by what it is and said in words in ``notes``.

    Per step and pair: ``contact_pressure`` (the solvers' nodal pressure ``p``; at finite strain
    ``contact_pressure_nominal``, per reference area, and ``contact_pressure_true``, per current
    area, with ``contact_area_reference`` and ``contact_area_current``), at small kinematics
    ``contact_pressure_recovered`` (:func:`pressure_field`), and ``contact_gap``. Per step and
    contact surface (``obstacle_names``, ``obstacle_travel_directions``): the resultant
    ``contact_force_vector_as_modelled`` ``(n_steps, n_surfaces, d)`` (:func:`surface_forces`),
    ``contact_force_along_travel_as_modelled`` and ``contact_force_along_travel_full_body``
    (times ``symmetry_factor``). Per step: ``total_contact_force`` (``sum a_0 p``, the magnitudes
    of the nodal forces summed) and ``converged``. A failed step gives NaN (``null``).
    """
    p = np.atleast_2d(np.asarray(fields["contact_pressure"], dtype=float))
    u = np.atleast_2d(np.asarray(fields["u"], dtype=float))
    d, sf = model.dimension, float(model.symmetry_factor)
    unit = "N per unit thickness" if d == 2 else "N"
    gaps = np.full(p.shape, np.nan)
    for k in range(p.shape[0]):
        if np.all(np.isfinite(u[k])):
            gaps[k] = model.gap(u[k], k)
    vectors = surface_forces(model, u, p)
    directions = _directions(model)
    along = np.einsum("ksd,sd->ks", vectors, directions)
    notes = dict(
        contact_gap="m; per step and pair: the gap to the obstacle (negative: penetration)",
        total_contact_force=f"{unit}; sum of a_0 p over the pairs: the magnitudes of the nodal contact forces "
                            "added, of the modelled part, along no direction",
        contact_force_vector_as_modelled=f"{unit}; per step and obstacle: sum of a_0 p n over its pairs, n the "
                                         "obstacle normal (at finite strain at the current contact point): the "
                                         "force on the modelled part",
        contact_force_along_travel_as_modelled=f"{unit}; that vector resolved along the obstacle's direction "
                                               "of travel (positive: pushing the body the way it moves)",
        contact_force_along_travel_full_body=f"{unit}; that times symmetry_factor = {sf:g} (the full body's "
                                             "force; the components across symmetry planes cancel in the full body, "
                                             "so only the resolved force is scaled)",
    )
    out = dict(contact_coordinates=model.contact_points, contact_obstacle=model.contact_obstacle)
    if model.finite:
        true, area = np.full(p.shape, np.nan), np.full(p.shape, np.nan)
        for k in range(p.shape[0]):
            if np.all(np.isfinite(u[k])) and np.all(np.isfinite(p[k])):
                area[k] = model.current_contact_area(u[k])
                true[k] = model.true_pressure(u[k], p[k])
        out.update(contact_pressure_nominal=p, contact_pressure_true=true,
                   contact_area_reference=model.contact_area, contact_area_current=area)
        notes.update(contact_pressure_nominal="Pa; the solver's p: contact force per reference (undeformed) area",
                     contact_pressure_true="Pa; contact force per current (deformed) area: a_0 p / a",
                     contact_area_reference="the lumped area a_0 of each pair in the reference configuration",
                     contact_area_current="the same lumping on the deformed mesh, per step: a")
    else:
        out.update(contact_pressure=p, contact_pressure_recovered=pressure_field(model, p, fields["stress"]))
        notes.update(contact_pressure="Pa; the solver's nodal pressure p (a p is the nodal contact force)",
                     contact_pressure_recovered="Pa; -n.sigma.n of the boundary elements projected on the "
                                                "contact nodes with the lumped areas (docs/maths.md); zero where "
                                                "p is zero")
    if model.frictional:
        traction, slip = (np.atleast_2d(np.asarray(fields[k], float)) for k in ("tangential_traction", "slip"))
        friction = model.tangential_force_vectors(traction)  # (n_steps, nc, d)
        out.update(friction_coefficient=model.friction, tangential_traction=traction, slip=slip,
                   contact_status=fields["contact_status"], total_tangential_force=friction.sum(axis=1))
        notes.update(friction_coefficient="Coulomb's mu per pair",
                     tangential_traction="Pa; per step, tangent and pair (component-major: all pairs' first "
                                         "tangent, then the second in 3-D): the friction traction on the body "
                                         "along the pair's tangent (t = (n_y, -n_x) in 2-D)",
                     slip="m; per step, tangent and pair: the step's tangential displacement relative to the "
                          "obstacle (the opposite of the traction's direction where the pair slips)",
                     contact_status="per step and pair: 0 open, 1 stick, 2 slip",
                     total_tangential_force=f"{unit}; per step: the resultant vector of the nodal friction "
                                            "forces a r_T t of the modelled part")
    return dict(out, contact_gap=gaps, total_contact_force=np.sum(model.contact_area * p, axis=-1),
                obstacle_names=_names(model), obstacle_travel_directions=directions,
                contact_force_vector_as_modelled=vectors, contact_force_along_travel_as_modelled=along,
                symmetry_factor=sf, contact_force_along_travel_full_body=sf * along,
                converged=fields["converged"], notes=notes)
