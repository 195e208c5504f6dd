r"""Cattaneo--Mindlin partial slip: a rigid cylinder pressed into an elastic block, then pulled
sideways, against the closed form (the model, its measures and the ``ddcm-validate`` rung).

A cylinder of radius ``R`` pressed by ``P`` (per unit thickness) carries Hertz's pressure
``p(x) = p0 sqrt(1 - x^2/a^2)`` with ``a = sqrt(4 P R / (pi E*))`` and ``p0 = 2 P / (pi a)``. A
tangential force ``Q < mu P`` applied afterwards, monotonically, leaves a central stick zone
``|x| <= c`` with

.. math::  c = a \sqrt{1 - Q / (\mu P)}, \qquad
           q(x) = \frac{\mu p_0}{a} \left( \sqrt{a^2 - x^2} - \sqrt{c^2 - x^2}\,[|x| \le c] \right)

(Cattaneo 1938, Mindlin 1949; Johnson, *Contact Mechanics*, sections 7.1 to 7.2). The solution is
exact for elastically similar bodies. Here a *rigid* cylinder indents an elastic block, whose
normal and tangential problems couple through ``beta = (1 - 2 nu) / (2 (1 - nu))``: the block is
nearly incompressible, ``nu = 0.49`` (``beta = 0.02``), on quadratic triangles (P2) to avoid
locking. The cylinder is moved, not forced: pressed by a travel ``d``, then moved sideways by
``s``; ``P`` and ``Q`` are the measured resultants of the contact forces, and the closed form is
evaluated for them (its ``a`` and ``p0`` from Hertz's, ``E* = E / (1 - nu^2)``).

The measures (:func:`mindlin_measure`): the stick zone's half-width from the contacts' statuses
(the largest ``|x|`` of a sticking contact, against ``c``) and the error of the tangential
force's distribution, ``max_x |F_FE(x) - F(x)| / Q`` with ``F(x)`` the tangential force on
``[-a, x]`` (:func:`mindlin_force`; ``F_FE`` sums the nodal forces ``a_i q_i`` left of ``x``,
compared half-way between nodes: a nodal force stands for its tributary length). Nodal
tractions themselves are no measure on quadratic elements: their vertex and mid-side values
alternate (as the nodal pressures do). On a sequence of meshes whose elements at the contact
halve per level the error's fitted rate is the check (:func:`rung_mindlin`).
"""

from __future__ import annotations

import math

import numpy as np

from ddcm_casadi.models.continuum import mesh as meshes
from ddcm_casadi.models.continuum.hertz import HertzReference, hertz_2d
from ddcm_casadi.models.continuum.inputs import Contact, Material, Support
from ddcm_casadi.models.continuum.mesh_refinement import refine_near
from ddcm_casadi.models.continuum.model import ContinuumModel, continuum_model
from ddcm_casadi.models.continuum.obstacles import Ball, moving
from ddcm_casadi.models.coulomb import blocks, tangent_basis
from ddcm_casadi.validation.verification import Check, fitted_rate

#: SI units: the cylinder's radius (m), the block's modulus (Pa), Poisson's ratio, Coulomb's mu,
#: the block's half-width and depth (m), the press (m) and the sideways moves (m, one step each).
MINDLIN = dict(radius=0.05, youngs_modulus=200e9, poisson_ratio=0.49, friction=0.3, half_width=0.04,
               depth=0.04, press=4e-5, shear=(5e-6, 1e-5))


def mindlin_model(level: int = 2, **overrides) -> ContinuumModel:
    """The cylinder on the block (full width: the tangential load is not symmetric), P2, graded
    towards the first point of contact by ``level`` rounds (the contact zone's element size halves
    per level); pressed in two steps, then moved sideways by :data:`MINDLIN` ``shear``."""
    c = dict(MINDLIN, **overrides)
    W, H = c["half_width"], c["depth"]
    mesh = meshes.rectangle(2 * W, H, nx=20, ny=10, origin=(-W, -H))  # 4 mm elements, level 0
    # a disc of 1.5 a (Hertz's a = 1.1 mm at the press) uniformly fine, graded outside it
    mesh = refine_near(mesh, (0.0, 0.0), 0.0017, levels=int(level), shrink=1.0, buffer=3)
    motion = [[0.0, -c["press"] / 2], [0.0, -c["press"]]] + [[float(s), -c["press"]] for s in c["shear"]]
    cylinder = moving(Ball(center=(0.0, c["radius"]), radius=c["radius"], name="cylinder"), motion)
    return continuum_model(
        mesh, materials=[Material(youngs_modulus=c["youngs_modulus"], poisson_ratio=c["poisson_ratio"])],
        supports=[Support("ymin", "xy")], contacts=[Contact(cylinder, "ymax", friction=c["friction"])],
        degree=2, reference=HertzReference(c["youngs_modulus"], c["poisson_ratio"]), name="Cattaneo-Mindlin")


def mindlin_traction(x: np.ndarray, a: float, c: float, p0: float, mu: float) -> np.ndarray:
    """``q(x)`` of the module (zero outside ``|x| < a``), magnitude."""
    x = np.abs(np.asarray(x, float))
    outer = np.sqrt(np.clip(a**2 - x**2, 0.0, None))
    inner = np.where(x <= c, np.sqrt(np.clip(c**2 - x**2, 0.0, None)), 0.0)
    return mu * p0 / a * (outer - inner)


def _half_disc_area(x: np.ndarray, r: float) -> np.ndarray:
    """``int_{-r}^{x} sqrt(r^2 - t^2) dt`` (``x`` clipped to ``[-r, r]``)."""
    x = np.clip(np.asarray(x, float), -r, r)
    return 0.5 * (x * np.sqrt(np.clip(r**2 - x**2, 0.0, None)) + r**2 * np.arcsin(x / r)) + 0.25 * math.pi * r**2


def mindlin_force(x: np.ndarray, a: float, c: float, p0: float, mu: float) -> np.ndarray:
    """``F(x) = int_{-a}^{x} q``: the tangential force on ``[-a, x]`` (magnitude)."""
    inner = _half_disc_area(x, c) if c > 0 else 0.0
    return mu * p0 / a * (_half_disc_area(x, a) - inner)


def mindlin_measure(model: ContinuumModel, step) -> dict:
    """One step against Cattaneo--Mindlin: ``P``, ``Q`` (N/m), Hertz's ``a``, ``p0``, the closed
    form's ``c`` and the measured one (the largest ``|x|`` of a sticking contact), its error over
    ``a``, and the force distribution's error (see the module) ``error_force``."""
    ref = model.reference
    pairs, x = ref.coordinates(model)
    area = model.contact_area[pairs]
    p = np.asarray(step.p, float)[pairs]
    t = tangent_basis(model.contact_normals[pairs])[:, 0, :]  # (n, 2)
    r = blocks(step.traction, 1)[pairs, 0]
    qx = r * t[:, 0]  # the traction's x component on the body
    P = float(np.sum(area * p))
    Q = float(np.sum(area * qx))
    radius, e_star = ref.geometry(model)
    a, p0 = hertz_2d(P, radius, e_star)
    mu = float(model.friction[pairs[0]])
    ratio = abs(Q) / (mu * P)
    c = a * math.sqrt(max(0.0, 1.0 - ratio))
    status = model.contact_status(step.p, step.traction, step.slip)[0][pairs]
    stick = status == 1
    c_fe = float(np.max(np.abs(x[stick]))) if np.any(stick) else 0.0
    order = np.argsort(x)
    xs, forces = x[order], (area * qx)[order]
    half_way = 0.5 * (xs[1:] + xs[:-1])
    fe = np.cumsum(forces)[:-1]
    error_force = float(np.max(np.abs(fe - np.sign(Q) * mindlin_force(half_way, a, c, p0, mu)))) / abs(Q)
    return dict(P=P, Q=Q, ratio=ratio, a=a, p0=p0, c=c, c_fe=c_fe, error_c=abs(c_fe - c) / a,
                error_force=error_force, in_contact=int(np.sum(status > 0)), sticking=int(np.sum(stick)),
                h=float(np.min(np.diff(xs))) if x.size > 1 else float("nan"))


def mindlin_sequence(levels, formulation: str = "augmented_lagrangian", *, progress=None) -> list[dict]:
    """Classical runs of :func:`mindlin_model` at each level: the measures of each sideways step."""
    from ddcm_casadi.drivers.harness import compare

    rows = []
    for level in levels:
        model = mindlin_model(level)
        r = compare(model, [formulation], variants=("classical",))["classical", formulation]
        for s in r.steps[2:]:
            row = dict(level=level, unknowns=model.n_dofs, step=s.step, converged=bool(s.converged),
                       **mindlin_measure(model, s))
            rows.append(row)
            if progress is not None:
                progress(row)
    return rows


def rung_mindlin(levels=(3, 4, 5, 6)) -> list[Check]:
    """Cattaneo--Mindlin on meshes refined ``levels`` times at the contact (Alart--Curnier,
    classical): the force distribution's error falls with the element size at a fitted rate
    ~1 (nodal forces standing for their tributary lengths: O(h)), and on the finest mesh it is
    below 5 % of ``Q`` and the stick zone's edge within two elements of ``c``. The error levels
    off at the finite block's share, measured: 6 % with a block of 18 ``a`` (half-width), 2.5 %
    with 36 ``a`` (the model's) at the same mesh; the tolerance is twice the latter."""
    rows = mindlin_sequence(levels)
    last_step = max(r["step"] for r in rows)
    final = [r for r in rows if r["step"] == last_step]
    name = "Cattaneo-Mindlin partial slip (rigid cylinder, P2, nu = 0.49) / classical / augmented_lagrangian"
    rate, se = fitted_rate([r["h"] for r in final], [r["error_force"] for r in final])
    table = "; ".join(f"L{r['level']}: {r['unknowns']} dofs, Q/muP {r['ratio']:.3f}, c/a {r['c'] / r['a']:.3f} "
                      f"(FE {r['c_fe'] / r['a']:.3f}), force error {r['error_force']:.2%}" for r in final)
    last = final[-1]
    return [Check.make(name, "converged steps", sum(r["converged"] for r in rows), len(rows), 0),
            Check.make(name, "fitted rate d log(force distribution error) / d log(h)", rate, 1.0, 0.5,
                       note=f"{table}; standard error {se:.2f}"),
            Check.make(name, "force distribution error / Q, finest mesh", last["error_force"], 0.0, 0.05),
            Check.make(name, "stick zone edge |c_FE - c| / a, finest mesh", last["error_c"], 0.0, 2 * last["h"] / last["a"],
                       note="tolerance: two contact elements")]


#: The rungs ``ddcm-validate`` runs (registered in :mod:`ddcm_casadi.validation.ladder`).
RUNGS = {"Coulomb friction: Cattaneo-Mindlin partial slip (mesh convergence)": rung_mindlin}


def main(argv: list[str] | None = None) -> int:
    """``python -m ddcm_casadi.validation.mindlin [--levels 1,2,3,4]``: the convergence table."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m ddcm_casadi.validation.mindlin", description=main.__doc__)
    parser.add_argument("--levels", default="1,2,3,4")
    parser.add_argument("--formulation", default="augmented_lagrangian")
    args = parser.parse_args(argv)
    print("| level | unknowns | step | P (N/m) | Q/(mu P) | a (mm) | c/a | c_FE/a | force error / Q |")
    print("|---|---|---|---|---|---|---|---|---|")
    mindlin_sequence([int(v) for v in args.levels.split(",") if v], args.formulation, progress=lambda r: print(
        f"| {r['level']} | {r['unknowns']} | {r['step']} | {r['P']:.4g} | {r['ratio']:.3f} | {r['a'] * 1e3:.3f} | "
        f"{r['c'] / r['a']:.3f} | {r['c_fe'] / r['a']:.3f} | {r['error_force']:.2%} |"
        + ("" if r["converged"] else " not converged"), flush=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
