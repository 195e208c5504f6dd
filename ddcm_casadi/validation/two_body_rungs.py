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

The measures are those of :class:`~ddcm_casadi.models.continuum.hertz.BodyHertzReference`
(``p0`` the largest pair pressure, or on linear tetrahedra the largest recovered pressure; ``a``
from the pressure's second moment; the force the resultant along the line of centres).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ddcm_casadi.models.continuum import mesh as meshes
from ddcm_casadi.models.continuum.bodies import join
from ddcm_casadi.models.continuum.hertz import BodyHertzReference
from ddcm_casadi.models.continuum.inputs import BodyContact, Material, Support, Traction
from ddcm_casadi.models.continuum.model import ContinuumModel, continuum_model
from ddcm_casadi.models.continuum.mortar import Surface, mortar_coupling
from ddcm_casadi.validation.verification import Check, fitted_rate

#: NAFEMS benchmark 1, SI units: radius (m), moduli (Pa), Poisson's ratio, load (N per m of thickness).
NAFEMS = dict(radius=0.05, cylinder_modulus=210e9, block_modulus=70e9, poisson_ratio=0.3, load=3.5e7)
#: The two spheres' grading: the refined radius shrinks by this per level, from ``0.3 R`` to the
#: contact radius (``0.07 R`` at the default load) after four levels.
SPHERE_SHRINK = 0.7
#: Its published reference values: contact half-width (m), peak pressure (Pa).
NAFEMS_REFERENCE = dict(a=6.21e-3, p0=3585e6)


def touching(bodies: dict, slave: str, master: str, reach: float):
    """The bodies joined (:func:`~ddcm_casadi.models.continuum.bodies.join`) with the first one
    (the slave's) moved along ``-n`` by the smallest weighted gap, so that the closest pair
    touches (gap 0) and holds it at the first step. A weighted gap averages over the node's
    facets: on a curved slave it is ``O(h^2 / R)`` above the nodal distance, which is zero."""
    mesh = join(bodies)
    s_f, m_f = mesh.boundaries[slave], mesh.boundaries[master]
    c = mortar_coupling(mesh.p.T, Surface.of(mesh, s_f), Surface.of(mesh, m_f), reach)
    gaps = c.gaps(mesh.p.T)
    j = int(np.argmin(gaps))
    first, *rest = bodies
    moved = replace(bodies[first], doflocs=bodies[first].doflocs - gaps[j] * c.normals[j][:, None])
    return join({first: moved, **{k: bodies[k] for k in rest}})


def nafems_model(levels: int, *, steps: int = 1, refine: int = 3, block_divisions: int = 8,
                 datasets=(), name: str = "nafems1") -> ContinuumModel:
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
    data = [{} if not datasets else dict(data=min(i, len(datasets) - 1)) for i in range(2)]  # one set each, or shared
    materials = [Material("cylinder", NAFEMS["cylinder_modulus"], nu, **data[0]),
                 Material("block", NAFEMS["block_modulus"], nu, **data[1])]
    model = continuum_model(
        mesh, materials=materials, degree=1, datasets=datasets, name=name,
        supports=[Support("block/ymin", "y"), Support("block/xmin", "x"), Support("cylinder/axis", "x")],
        tractions=[Traction("cylinder/flat", (0.0, -F / (2 * R)))],
        contacts=[BodyContact("cylinder/arc", "block/ymax", name="cylinder on block", search_distance=0.2 * R)],
        load_factors=[(i + 1) / steps for i in range(steps)], symmetry_factor=2.0,
        reference=BodyHertzReference(R, contact=0, force_factor=2.0, direction_of_centres=(0.0, -1.0)))
    return model


def two_spheres_model(levels: int, *, radius: float = 0.01, youngs_modulus: float = 200e9,
                      poisson_ratio: float = 0.3, force: float = 1e4, refine: int = 2,
                      datasets=(), name: str = "two spheres") -> ContinuumModel:

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
        load_factors=[1.0], symmetry_factor=4.0, reference=BodyHertzReference(R / 2, contact=0, force_factor=4.0,
                                                                         direction_of_centres=(0.0, 0.0, -1.0)))
    return model


#: The patch test's load steps (equal increments of the traction): one, so that DDCM starts at the
#: exact state (:func:`rung_patch_test`; a later step would start from the previous one's data,
#: and on a coarse grid alternating projections may then stop at a local fixed point).
PATCH_STEPS = 1


def patch_model(dimension: int, *, data: bool = False, traction: float = 1e7) -> ContinuumModel:
    """The contact patch test: a punch (``E = 2 GPa``, ``nu = 0.25``) pressed by a uniform
    ``traction`` onto a block (``E = 1 GPa``, ``nu = 0.3``) with non-matching meshes (7 x 4 vs
    5 x 3 elements in 2-D, 4 x 3 x 2 vs 3 x 2 x 2 in 3-D), rollers on the symmetry sides and the
    base, the interface frictionless. The exact state is uniform in each body: ``sigma_nn = -t``,
    every other stress component zero, and the contact pressure ``t`` at every pair. ``data``:
    the data-driven variant too (Hookean grids of each material, with the uniform states)."""
    from ddcm_casadi.data.dataset import MaterialDataset
    from ddcm_casadi.data.metric import isotropic_elasticity

    laws = dict(block=(1e9, 0.3), punch=(2e9, 0.25))
    if dimension == 2:
        bodies = dict(block=meshes.rectangle(1.0, 0.5, nx=7, ny=4, origin=(0.0, -0.5)),
                      punch=meshes.rectangle(1.0, 0.5, nx=5, ny=3, origin=(0.0, 0.0)))
        sym = ["x"]
    else:
        bodies = dict(block=meshes.box(1.0, 1.0, 0.5, nx=4, ny=3, nz=2, origin=(0.0, 0.0, -0.5)),
                      punch=meshes.box(1.0, 1.0, 0.5, nx=3, ny=2, nz=2, origin=(0.0, 0.0, 0.0)))
        sym = ["x", "y"]
    up = "xyz"[dimension - 1]
    supports = [Support(f"block/{up}min", up)] + [Support(f"{b}/{a}min", a) for b in bodies for a in sym]
    factors = np.arange(1, PATCH_STEPS + 1) / PATCH_STEPS
    datasets = ()
    if data:
        # Hookean grids (11 points per axis in 2-D, 5 in 3-D) plus the exact uniform states of
        # each step: the uniform state is then at distance 0, the global minimum
        datasets = []
        for E, nu in laws.values():
            C = isotropic_elasticity(E, nu, dimension)[0]
            grid = MaterialDataset.hookean_grid(C, -0.02, 0.02, 11 if dimension == 2 else 5, c=C)
            stress = np.zeros((len(factors), C.shape[0]))
            stress[:, dimension - 1] = -traction * np.asarray(factors)
            strain = np.linalg.solve(C, stress.T).T
            datasets.append(MaterialDataset(np.vstack([grid.strain, strain]), np.vstack([grid.stress, stress]), c=C))
    materials = [Material(b, E, nu, **(dict(data=i) if data else {})) for i, (b, (E, nu)) in enumerate(laws.items())]
    load = np.zeros(dimension)
    load[-1] = -traction
    return continuum_model(join(bodies), materials=materials, supports=supports, datasets=datasets,
                           tractions=[Traction(f"punch/{up}max", tuple(load))],
                           contacts=[BodyContact(f"punch/{up}min", f"block/{up}max", name="interface")],
                           load_factors=list(factors), name=f"patch test {dimension}-D")


#: The patch test's tolerance on the relative deviation from the uniform state: the solvers stop
#: at scaled residuals of 1e-9 and below (penalty's Newton at 1e-11 of the force unit gives 3e-12
#: in the pressure); round-off of the assembly is ~1e-15.
PATCH_TOL = 1e-9


def patch_deviation(model: ContinuumModel, step, traction: float) -> float:
    """The largest relative deviation of one step from the uniform state (see :func:`patch_model`):
    over the pairs' pressures and every stress component of every material point."""
    d, k = model.dimension, model.strain_components
    t = traction * float(model.load_parameter[step.step])  # the load factor
    stress = np.asarray(step.stress).reshape(-1, k)
    expected = np.zeros(k)
    expected[d - 1] = -t
    return max(float(np.max(np.abs(np.asarray(step.p) - t))), float(np.max(np.abs(stress - expected)))) / t


def rung_patch_test() -> list[Check]:
    """The contact patch test across non-matching meshes, 2-D and 3-D, every formulation,
    classical and DDCM: the uniform state to :data:`PATCH_TOL`."""
    from ddcm_casadi.drivers.ddcm_options import DDCMOptions
    from ddcm_casadi.drivers.harness import compare

    out = []
    for d in (2, 3):
        model = patch_model(d, data=True)
        # DDCM starts at the uniform state (the exact datum of each material, see patch_model),
        # so that the check is of the coupling, not of the data search: the uniform state must
        # be a fixed point
        ds = model.dataset
        start = ds.offsets[ds.material] + np.array([len(s) - PATCH_STEPS for s in ds.datasets])[ds.material]
        cmp = compare(model, ddcm=DDCMOptions(initial=tuple(int(i) for i in start)))
        for (variant, name), r in cmp.results.items():
            dev = max(patch_deviation(model, s, 1e7) for s in r.steps)
            ok = all(s.converged for s in r.steps)
            out.append(Check.make(f"patch test {d}-D, non-matching meshes / {variant} / {name}",
                                  "max rel. deviation from the uniform state (pressures, stresses)",
                                  dev if ok else float("nan"), 0.0, PATCH_TOL,
                                  note=f"{model.n_contacts} pairs, {model.n_dofs} unknowns"))
    return out


def hertz_sequence(build, levels, formulation: str = "fischer_burmeister") -> list[dict]:
    """Classical runs of ``build(level)`` for each level: the Hertz measures of the last step (the
    model's :class:`~ddcm_casadi.models.continuum.hertz.BodyHertzReference`), the size and the
    solver's figures."""
    from ddcm_casadi.drivers.harness import compare

    rows = []
    for level in levels:
        model = build(level)
        r = compare(model, [formulation], variants=("classical",))["classical", formulation]
        last = r.steps[-1]
        rows.append(dict(level=level, unknowns=model.n_dofs, pairs=model.n_contacts,
                         converged=all(s.converged for s in r.steps), iterations=last.iterations,
                         **model.reference.measure(model, last.p, last.stress)))
    return rows


def rung_nafems(levels=(3, 4, 5, 6)) -> list[Check]:
    """NAFEMS benchmark 1 on a sequence of gradings (the element size at the contact halves per
    level): the peak pressure's error falls at the fitted rate ~1 (the largest nodal pressure
    carries an O(h) bias), and on the finest mesh ``p0`` is within 3 % and ``a`` within 1 % of
    Hertz (``a`` levels off near 0.3 %: the block is finite, Hertz's half-space is not)."""
    rows = hertz_sequence(nafems_model, levels)
    name = "NAFEMS 1 cylinder on block (mortar, P1) / classical / fischer_burmeister"
    h = 2.0 ** -np.asarray(levels, float)
    rate, se = fitted_rate(h, [r["error_p0"] for r in rows])
    table = "; ".join(f"L{r['level']}: {r['unknowns']} dofs, p0 {r['p0_fe'] / 1e6:.0f} MPa ({r['error_p0']:.2%}), "
                      f"a {r['a_fe'] * 1e3:.3f} mm ({r['error_a']:.2%})" for r in rows)
    last = rows[-1]
    ref = f"Hertz: p0 = {last['p0_hertz'] / 1e6:.0f} MPa, a = {last['a_hertz'] * 1e3:.3f} mm (NAFEMS: 3585 MPa, 6.21 mm)"
    return [Check.make(name, "converged meshes", sum(r["converged"] for r in rows), len(rows), 0, note=table),
            Check.make(name, "fitted rate d log(error p0) / d log(h)", rate, 1.0, 0.5, note=f"standard error {se:.2f}"),
            Check.make(name, "rel. error of p0, finest mesh", last["error_p0"], 0.0, 0.03, note=ref),
            Check.make(name, "rel. error of a, finest mesh", last["error_a"], 0.0, 0.01)]


def rung_two_spheres(levels=(4,)) -> list[Check]:
    """Two equal spheres (quarter model, mortar, P1) against Hertz on the finest of ``levels``:
    ``a`` within 2 % and ``p0`` (recovered, :mod:`~ddcm_casadi.models.continuum.pressure`) within 5 %
    (the sequence to 3e4 unknowns, :func:`main`, gives 0.8 % and 1.3 %)."""

    rows = hertz_sequence(two_spheres_model, levels)
    name = "two spheres (mortar, P1, quarter model) / classical / fischer_burmeister"
    last = rows[-1]
    note = (f"{last['unknowns']} dofs; F = {last['force']:.4g} N, Hertz a = {last['a_hertz'] * 1e3:.4f} mm, "
            f"p0 = {last['p0_hertz'] / 1e6:.0f} MPa; FE a = {last['a_fe'] * 1e3:.4f} mm, p0 = {last['p0_fe'] / 1e6:.0f} MPa")
    return [Check.make(name, "converged", float(last["converged"]), 1.0, 0),
            Check.make(name, "rel. error of a", last["error_a"], 0.0, 0.02, note=note),
            Check.make(name, "rel. error of p0", last["error_p0"], 0.0, 0.05)]


#: The rungs ``ddcm-validate`` runs (registered in :mod:`ddcm_casadi.validation.ladder`).
RUNGS = {
    "contact patch test between two bodies (non-matching meshes)": rung_patch_test,
    "NAFEMS benchmark 1, cylinder on block (mesh convergence)": rung_nafems,
    "two spheres against Hertz": rung_two_spheres,
}


def main(argv: list[str] | None = None) -> int:
    """``python -m ddcm_casadi.validation.two_body_rungs [--levels ...] [--sphere-levels ...]``:
    the NAFEMS and two-sphere mesh sequences as tables (minutes for the finest meshes)."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m ddcm_casadi.validation.two_body_rungs", description=main.__doc__)
    parser.add_argument("--levels", default="2,3,4,5,6,7", help="NAFEMS gradings (default 2..7)")
    parser.add_argument("--sphere-levels", default="2,3,4,5", help="two-sphere gradings (default 2..5)")
    args = parser.parse_args(argv)
    for title, build, levels in (("NAFEMS benchmark 1", nafems_model, args.levels),
                                 ("two spheres", two_spheres_model, args.sphere_levels)):
        print(f"\n{title}\n| level | unknowns | pairs | in contact | p0 (MPa) | p0 Hertz | error p0 | a (mm) | a Hertz | error a |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        for r in hertz_sequence(build, [int(v) for v in levels.split(",") if v]):
            print(f"| {r['level']} | {r['unknowns']} | {r['pairs']} | {r['nodes_in_contact']} | {r['p0_fe'] / 1e6:.1f} | "
                  f"{r['p0_hertz'] / 1e6:.1f} | {r['error_p0']:.2%} | {r['a_fe'] * 1e3:.4f} | {r['a_hertz'] * 1e3:.4f} | "
                  f"{r['error_a']:.2%} |" + ("" if r["converged"] else " not converged"), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
