r"""Contact between two deformable bodies, against closed forms: the models and their measures.

- **NAFEMS benchmark 1** (cylinder on a block, plane strain): a half cylinder ``R = 50 mm``
  (``E = 210 GPa``) pressed by ``F = 35 kN`` per mm of thickness on its flat face onto a block
  (``E = 70 GPa``), ``nu = 0.3``. Hertz with the combined modulus
  ``1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2`` gives ``a = 2 sqrt(R F / (pi E*)) = 6.21 mm`` and
  ``p0 = 2 F / (pi a) = 3585 MPa`` (:func:`nafems_model`).
- **Two spheres** (3-D, quarter models with symmetry planes): two equal octants of balls
  touching at the origin, the upper pressed by a traction on its flat equatorial face; Hertz with
  ``1/R* = 1/R1 + 1/R2`` (:func:`two_spheres_model`).
- **Contact patch test** across non-matching meshes: two blocks of different materials and
  element sizes, one pressed onto the other by a uniform traction; the uniform stress state must
  cross the interface to round-off (:func:`patch_model`).

:func:`hertz_measure` compares one step's pressures of a pair with Hertz: ``p0`` the largest
pressure, ``a`` from the pressure's second moment (``int x^2 p / int p = a^2/4`` in 2-D,
``int r^2 p dA / int p dA = 2 a^2 / 5`` in 3-D), the force the resultant of ``a_j p_j n_j``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ddcm_casadi.models.continuum import mesh as meshes
from ddcm_casadi.models.continuum.bodies import join
from ddcm_casadi.models.continuum.hertz import hertz_2d, hertz_3d
from ddcm_casadi.models.continuum.inputs import BodyContact, Material, Support, Traction
from ddcm_casadi.models.continuum.model import ContinuumModel, continuum_model
from ddcm_casadi.models.continuum.mortar import Surface, element_centroids, mortar_coupling

#: NAFEMS benchmark 1, SI units: radius (m), moduli (Pa), Poisson's ratio, load (N per m of thickness).
NAFEMS = dict(radius=0.05, cylinder_modulus=210e9, block_modulus=70e9, poisson_ratio=0.3, load=3.5e7)
#: The two spheres' grading: the refined radius shrinks by this per level, from ``0.3 R`` to the
#: contact radius (``0.07 R`` at the default load) after four levels.
SPHERE_SHRINK = 0.7
#: Its published reference values: contact half-width (m), peak pressure (Pa).
NAFEMS_REFERENCE = dict(a=6.21e-3, p0=3585e6)


def combined_modulus(e1: float, nu1: float, e2: float, nu2: float) -> float:
    """``E*`` of two elastic bodies: ``1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2``."""
    return 1.0 / ((1.0 - nu1 ** 2) / e1 + (1.0 - nu2 ** 2) / e2)


@dataclass(frozen=True)
class TwoBodyHertz:
    """Hertz's solution for the pairs of one contact between two round bodies.

    Parameters
    ----------
    radius : float
        The effective radius ``R*`` (``1/R* = 1/R1 + 1/R2``; a flat block: ``R1``).
    e_star : float
        The combined modulus (:func:`combined_modulus`).
    contact : int
        The index of the contact pair among the model's contacts.
    force_factor : float
        The full bodies' force over the modelled part's (4 for a quarter model).
    """

    radius: float
    e_star: float
    contact: int = 0
    force_factor: float = 1.0


def hertz_measure(model: ContinuumModel, pressure: np.ndarray, ref: TwoBodyHertz, axis: np.ndarray) -> dict:
    """Compare one step's pressures of ``ref.contact`` with Hertz for the measured force.

    ``axis``: the line of centres, through the origin (the first point of contact). Returns
    ``force``, ``a_hertz``, ``p0_hertz``, ``a_fe``, ``p0_fe``, ``error_a``, ``error_p0`` and
    ``nodes_in_contact``.
    """
    pairs = np.flatnonzero(model.contact_obstacle == ref.contact)
    p = np.asarray(pressure, float)[pairs]
    w = model.contact_area[pairs] * p
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    # along the line of centres: the lateral components of a symmetric part's pairs are borne
    # by its symmetry supports
    force = ref.force_factor * abs(float(w @ model.contact_normals[pairs] @ axis))
    x = model.contact_points[pairs]
    lateral = np.linalg.norm(x - np.outer(x @ axis, axis), axis=1)
    moment = float(np.sum(w * lateral ** 2) / np.sum(w)) if np.sum(w) > 0 else 0.0
    if model.dimension == 2:
        a_h, p0_h = hertz_2d(force, ref.radius, ref.e_star)
        a_fe = 2.0 * math.sqrt(moment)
    else:
        a_h, p0_h = hertz_3d(force, ref.radius, ref.e_star)
        a_fe = math.sqrt(2.5 * moment)
    p0_fe = float(np.max(p)) if p.size else 0.0
    return dict(force=force, a_hertz=a_h, p0_hertz=p0_h, a_fe=a_fe, p0_fe=p0_fe,
                error_a=abs(a_fe - a_h) / a_h if a_h > 0 else float("nan"),
                error_p0=abs(p0_fe - p0_h) / p0_h if p0_h > 0 else float("nan"),
                nodes_in_contact=int(np.sum(model.active_contacts(p))))


def touching(bodies: dict, slave: str, master: str, reach: float):
    """The bodies joined (:func:`~ddcm_casadi.models.continuum.bodies.join`) with the first one
    (the slave's) moved along ``-n`` by the smallest weighted gap, so that the closest pair
    touches (gap 0) and holds it at the first step. A weighted gap averages over the node's
    facets: on a curved slave it is ``O(h^2 / R)`` above the nodal distance, which is zero."""
    mesh = join(bodies)
    s_f, m_f = mesh.boundaries[slave], mesh.boundaries[master]
    c = mortar_coupling(mesh.p.T, Surface.of(mesh, s_f), element_centroids(mesh, s_f), Surface.of(mesh, m_f),
                        element_centroids(mesh, m_f), reach)
    gaps = c.gaps(mesh.p.T)
    j = int(np.argmin(gaps))
    first, *rest = bodies
    moved = replace(bodies[first], doflocs=bodies[first].doflocs - gaps[j] * c.normals[j][:, None])
    return join({first: moved, **{k: bodies[k] for k in rest}})


def nafems_model(levels: int, *, steps: int = 1, refine: int = 3, block_divisions: int = 8,
                 datasets=(), name: str = "nafems1") -> tuple[ContinuumModel, TwoBodyHertz]:

    """NAFEMS benchmark 1 (see the module), graded ``levels`` times towards the contact point.

    A half model (symmetry plane ``x = 0``, ``u_x = 0`` there on both bodies): the quarter
    cylinder (of the disc of radius ``R`` centred at ``(0, R)``) is the slave, the block
    ``[0, 2R] x [-2R, 0]`` the master; the block's base is held vertically, the cylinder's flat
    face carries the load as a uniform traction (``F / 2R``) in ``steps`` equal increments. The cylinder rests on the block only: the pair
    at the touching point holds it vertically (:func:`touching`).
    """
    R, nu, F = NAFEMS["radius"], NAFEMS["poisson_ratio"], NAFEMS["load"]
    cyl = meshes.quarter_disc(R, center=(0.0, R), refine=refine)
    block = meshes.rectangle(2 * R, 2 * R, nx=block_divisions, ny=block_divisions, origin=(0.0, -2 * R))
    if levels:
        cyl = meshes.refine_near(cyl, (0.0, 0.0), 0.3 * R, levels=levels, shrink=1.0)
        block = meshes.refine_near(block, (0.0, 0.0), 0.3 * R, levels=levels, shrink=1.0)
    mesh = touching({"cylinder": cyl, "block": block}, "cylinder/arc", "block/ymax", 0.2 * R)
    data = {} if not datasets else dict(data=0)
    materials = [Material("cylinder", NAFEMS["cylinder_modulus"], nu, **data),
                 Material("block", NAFEMS["block_modulus"], nu, **data)]
    model = continuum_model(
        mesh, materials=materials, degree=1, datasets=datasets, name=name,
        supports=[Support("block/ymin", "y"), Support("block/xmin", "x"), Support("cylinder/axis", "x")],
        tractions=[Traction("cylinder/flat", (0.0, -F / (2 * R)))],
        contacts=[BodyContact("cylinder/arc", "block/ymax", name="cylinder on block", search_distance=0.2 * R)],
        load_factors=[(i + 1) / steps for i in range(steps)])
    e_star = combined_modulus(NAFEMS["cylinder_modulus"], nu, NAFEMS["block_modulus"], nu)
    return model, TwoBodyHertz(R, e_star, force_factor=2.0)


def two_spheres_model(levels: int, *, radius: float = 0.01, youngs_modulus: float = 200e9,
                      poisson_ratio: float = 0.3, force: float = 1e4, refine: int = 2,
                      datasets=(), name: str = "two spheres") -> tuple[ContinuumModel, TwoBodyHertz]:

    """Two equal spheres touching at the origin (:func:`touching`), a quarter model (symmetry planes ``x = 0`` and
    ``y = 0``): octants of balls (:func:`~ddcm_casadi.models.continuum.mesh.ball_octant`) graded
    ``levels`` times towards the origin. The lower octant's flat face ``z = -R`` is held
    vertically, the upper's ``z = R`` carries ``force / 4`` as a uniform traction; the upper
    sphere is the slave."""
    R = radius
    upper = meshes.ball_octant(R, center=(0.0, 0.0, R), signs=(1, 1, -1), refine=refine)
    lower = meshes.ball_octant(R, center=(0.0, 0.0, -R), signs=(1, 1, 1), refine=refine)
    if levels:
        upper = meshes.refine_near(upper, (0.0, 0.0, 0.0), 0.3 * R, levels=levels, shrink=SPHERE_SHRINK)
        lower = meshes.refine_near(lower, (0.0, 0.0, 0.0), 0.3 * R, levels=levels, shrink=SPHERE_SHRINK)
    mesh = touching({"upper": upper, "lower": lower}, "upper/surface", "lower/surface", 0.3 * R)
    data = {} if not datasets else dict(data=0)
    materials = [Material(None, youngs_modulus, poisson_ratio, **data)]
    supports = [Support(f"{b}/x0", "x") for b in ("upper", "lower")] + \
               [Support(f"{b}/y0", "y") for b in ("upper", "lower")] + [Support("lower/z0", "z")]
    model = continuum_model(
        mesh, materials=materials, degree=1, datasets=datasets, name=name, supports=supports,
        tractions=[Traction("upper/z0", (0.0, 0.0, -force / (math.pi * R ** 2)))],
        contacts=[BodyContact("upper/surface", "lower/surface", name="sphere on sphere", search_distance=0.3 * R)],
        load_factors=[1.0])
    e_star = combined_modulus(youngs_modulus, poisson_ratio, youngs_modulus, poisson_ratio)
    return model, TwoBodyHertz(R / 2, e_star, force_factor=4.0)
