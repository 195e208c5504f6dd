r"""Coulomb friction against closed forms: the models, their measures and the ``ddcm-validate`` rungs.

- **Frictionless limit**: ``friction = 0`` (the Coulomb law with ``mu = 0``, tangential
  unknowns and all) gives the frictionless (Signorini) results to the solvers' tolerance
  (:func:`rung_frictionless_limit`).
- **A block on a rigid plane**, pressed, then pushed sideways by the plane (``nu = 0``: pressing
  alone slides nothing): while every contact sticks, the solution is the bonded one (the block's
  bottom moved with the plane: an independent solve with prescribed displacements, no contact);
  the tangential force never exceeds ``mu N``; partial slip spreads from the edges; once every
  contact slips, the tangential force is ``mu N`` (:func:`rung_block_stick_slip`).
- **Frictional patch test**: a block on a plane inclined at ``alpha``, pressed by a vertical
  load ``G`` and held horizontally at its top, the plane pushed under it: at the slip limit the
  horizontal force is ``F = G (tan alpha + mu) / (1 - mu tan alpha)`` (0.412371 G for
  ``tan alpha = 0.1, mu = 0.3``), whatever the stresses inside (:func:`rung_inclined_patch`).
- **DDCM on Hookean data** converges to the classical frictional solution as the data are refined,
  at the data spacing's rate (:func:`rung_ddcm_rate`).
- **Cattaneo--Mindlin partial slip**: :mod:`ddcm_casadi.validation.mindlin`.
"""

from __future__ import annotations


import numpy as np

from ddcm_casadi import formulations
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.data.metric import Metric, isotropic_elasticity
from ddcm_casadi.models.continuum import mesh as meshes
from ddcm_casadi.models.continuum.inputs import Contact, Material, Support, Traction
from ddcm_casadi.models.continuum.model import ContinuumModel, continuum_model
from ddcm_casadi.models.continuum.obstacles import Plane, moving
from ddcm_casadi.models.base import CONTACT_STATUS
from ddcm_casadi.models.coulomb import blocks, tangent_basis
from ddcm_casadi.validation.verification import Check, fitted_rate

#: The block's modulus (Pa), size (m) and the press (m): a strain of 1e-3.
BLOCK = dict(youngs_modulus=1e3, size=1.0, press=1e-3)
#: Newton's residual tolerance of the formulations (their default ``residual_tol``): two solves
#: of one problem agree to a few times this, relative to the solution's size.
SOLVER_TOL = 1e-9
#: Agreement allowed between two solves, relative: ten times :data:`SOLVER_TOL` (each solve is
#: within it of the exact root; the conditioning of these small blocks is O(10)).
AGREEMENT = 10 * SOLVER_TOL


def frictional_formulations(law: str = "coulomb") -> list[str]:
    """The registered formulations that enforce ``law``."""
    return formulations.enforcing(law)


def hookean_data(dimension: int, youngs_modulus: float, poisson_ratio: float, strain: float,
                 points: int) -> MaterialDataset:
    """A Hookean data set on a regular grid of ``points`` per Mandel axis over ``[-strain, strain]``."""
    C = isotropic_elasticity(youngs_modulus, poisson_ratio, dimension)[0]
    return MaterialDataset.hookean_grid(C, -strain, strain, points, c=Metric(C))


# ------------------------------------------------------------------------------ the models
def block_model(*, friction: float | None = 0.3, divisions: int = 6, shear=(1e-5, 4e-4, 8e-4, 1.5e-3, 3e-3),
                poisson_ratio: float = 0.0, data: MaterialDataset | None = None, bonded: bool = False) -> ContinuumModel:
    """A square block (side 1 m, ``E = 1e3`` Pa) clamped at its top, on a rigid plane that presses
    it by 1e-3 m in two steps and then moves sideways by ``shear`` (m, one step each).

    ``bonded=True``: the same path with the block's bottom moved with the plane (prescribed
    displacements, no contact): the sticking solution.
    """
    L, press = BLOCK["size"], BLOCK["press"]
    motion = [[0.0, press / 2], [0.0, press]] + [[float(s), press] for s in shear]
    mesh = meshes.rectangle(L, L, nx=divisions, ny=divisions)
    material = Material(youngs_modulus=BLOCK["youngs_modulus"], poisson_ratio=poisson_ratio,
                        data=None if data is None else 0)
    supports = [Support("ymax", "xy")]
    contacts = []
    if bonded:
        supports.append(Support("ymin", "xy", displacement=motion))
    else:
        plane = moving(Plane(point=(0.0, 0.0), normal=(0.0, 1.0), name="plane"), motion)
        contacts.append(Contact(plane, "ymin", friction=friction))
    return continuum_model(mesh, materials=[material], supports=supports, contacts=contacts,
                           datasets=[] if data is None else [data], name="block on a plane")


def inclined_model(*, slope: float = 0.1, friction: float = 0.3, divisions: int = 6, load: float = 1.0,
                   push=(2e-4, 5e-3, 1e-2), data: MaterialDataset | None = None) -> ContinuumModel:
    """A square block (side 1 m, ``E = 1e3`` Pa, ``nu = 0.3``) resting on a plane of slope
    ``tan alpha = slope``, its top held horizontally (``x`` fixed) and pressed by a vertical
    traction ``load`` (Pa); the plane then moves by ``-push`` along ``x`` (m, one step each), so
    that the block climbs it."""
    alpha = np.arctan(slope)
    R = np.array([[np.cos(alpha), -np.sin(alpha)], [np.sin(alpha), np.cos(alpha)]])
    base = meshes.rectangle(1.0, 1.0, nx=divisions, ny=divisions)
    mesh = type(base)(R @ base.p, base.t, _boundaries=base.boundaries)
    normal = (-np.sin(alpha), np.cos(alpha))
    steps = 1 + len(push)
    plane = moving(Plane(point=(0.0, 0.0), normal=normal, name="incline"),
                   [[0.0, 0.0]] + [[-float(s), 0.0] for s in push])
    material = Material(youngs_modulus=BLOCK["youngs_modulus"], poisson_ratio=0.3, data=None if data is None else 0)
    return continuum_model(mesh, materials=[material], supports=[Support("ymax", "x")],
                           contacts=[Contact(plane, "ymin", friction=friction)],
                           tractions=[Traction("ymax", (0.0, -load))], load_factors=np.ones(steps),
                           datasets=[] if data is None else [data], name="block on an incline")


# ------------------------------------------------------------------------------ measures
def contact_resultant(model: ContinuumModel, step) -> np.ndarray:
    """The resultant force of the contacts on the body, ``sum a (p n + r_T . t)`` (N per m)."""
    a, n = model.contact_area, model.contact_normals
    t = tangent_basis(n)  # (nc, d - 1, d)
    r = blocks(step.traction, model.contact_block - 1) if model.frictional else np.zeros((a.size, 0))
    force = a[:, None] * (np.asarray(step.p)[:, None] * n + np.einsum("cj,cjd->cd", r, t))
    return force.sum(axis=0)


def statuses(model: ContinuumModel, step) -> np.ndarray:
    """Per contact ``open``, ``stick`` or ``slip`` (:meth:`~ddcm_casadi.models.base.ContactModel.contact_status`)."""
    return np.asarray(CONTACT_STATUS)[model.contact_status(step.p, step.traction, step.slip)[0]]


def tangential_ratio(model: ContinuumModel, step) -> float:
    """``|sum a r_T| / (mu sum a p)``: 1 in full slip."""
    a = model.contact_area
    T = np.linalg.norm(blocks(step.traction, model.contact_block - 1).T @ a)
    return float(T / (float(np.max(model.friction)) * float(a @ step.p)))


# ------------------------------------------------------------------------------ rungs
def rung_frictionless_limit() -> list[Check]:
    """``friction = 0`` against no friction at all on the pressed block (``nu = 0.3``: pressing
    makes its bottom spread), every frictional formulation, classical and DDCM: the largest
    displacement and pressure differences relative to the frictionless run's largest."""
    from ddcm_casadi.drivers.harness import compare

    data = hookean_data(2, BLOCK["youngs_modulus"], 0.3, 3e-3, 13)
    kw = dict(poisson_ratio=0.3, shear=(), data=data)
    names = frictional_formulations()
    with_mu0 = compare(block_model(friction=0.0, **kw), names)
    without = compare(block_model(friction=None, **kw), names)
    out = []
    for key, r in with_mu0.results.items():
        ref = without.results[key]
        du = max(np.max(np.abs(s.u - q.u)) / max(np.max(np.abs(q.u)), 1e-300) for s, q in zip(r.steps, ref.steps))
        dp = max(np.max(np.abs(s.p - q.p)) / max(np.max(np.abs(q.p)), 1e-300) for s, q in zip(r.steps, ref.steps))
        ok = all(s.converged for s in r.steps) and all(s.converged for s in ref.steps)
        out.append(Check.make(f"friction = 0 against frictionless / {key[0]} / {key[1]}",
                              "max rel. difference of displacements and pressures",
                              max(du, dp) if ok else float("nan"), 0.0, AGREEMENT,
                              note="tolerance: 10 x the Newton residual tolerance 1e-9"))
    return out


def rung_block_stick_slip() -> list[Check]:
    """The block pressed, then pushed sideways by the plane (see the module), every frictional
    formulation; classical: sticking = bonded solution, ``T <= mu N``, a partial-slip step,
    ``T = mu N`` in full slip; DDCM (the exact formulations): every step a fixed point, the force
    bound and full slip. The penalty's DDCM alternation cycles at this block's stick-slip
    transition (its compliant law admits a whole block sliding with the data's stresses, and the
    alternation flips between sliding both ways: measured, docs/maths.md), so it is left out."""
    from ddcm_casadi.drivers.harness import compare

    data = hookean_data(2, BLOCK["youngs_modulus"], 0.0, 4e-3, 33)
    model, bonded = block_model(data=data), block_model(bonded=True)
    names = frictional_formulations()
    exact = [n for n in names if type(formulations.get(n)).exact]
    cmp = compare(model, names, variants=("classical",))
    cmp.results.update(compare(model, exact, variants=("ddcm",)).results)
    ref = compare(bonded, ["fischer_burmeister"], variants=("classical",))["classical", "fischer_burmeister"]
    out = []
    for (variant, name), r in cmp.results.items():
        label = f"block on a plane, pressed then pushed (mu = 0.3) / {variant} / {name}"
        penalty = not type(formulations.get(name)).exact
        status = [statuses(model, s) for s in r.steps]
        ratio = [tangential_ratio(model, s) for s in r.steps]
        converged = all(s.converged for s in r.steps)
        out.append(Check.make(label, "converged steps", sum(s.converged for s in r.steps), len(r.steps), 0))
        out.append(Check.make(label, "max T / (mu N) over the path (<= 1)", max(max(ratio), 1.0), 1.0, AGREEMENT))
        full = [i for i, st in enumerate(status) if np.all(st != "stick") and np.any(st == "slip")]
        mixed = [i for i, st in enumerate(status) if np.any(st == "slip") and np.any(st == "stick")]
        out.append(Check.make(label, "T / (mu N) in full slip (last step; every closed contact slipping)",
                              ratio[-1] if full and full[-1] == len(r.steps) - 1 and converged else float("nan"),
                              1.0, AGREEMENT, note=f"steps all slipping: {full}; partial slip: {mixed}"))
        if variant != "classical":
            continue
        out.append(Check.make(label, "partial-slip steps (stick -> slip)", float(len(mixed) > 0), 1.0, 0,
                              note="statuses per step (stick/slip): "
                                   + ", ".join(f"{np.sum(st == 'stick')}/{np.sum(st == 'slip')}" for st in status)))
        stuck = [i for i, st in enumerate(status) if np.all(st == "stick")]
        # the penalty's stick spring lets a sticking contact slip by r_T / gamma: O(1/gamma)
        tol = 1e-3 if penalty else AGREEMENT
        dev = max((np.max(np.abs(model.full_displacement(r.steps[i].u, i) - bonded.full_displacement(ref.steps[i].u, i)))
                   / np.max(np.abs(bonded.full_displacement(ref.steps[i].u, i))) for i in stuck), default=float("nan"))
        out.append(Check.make(label, "sticking steps against the bonded solution (max rel. displacement difference)",
                              dev, 0.0, tol, note=f"sticking steps: {stuck}" + ("; penalty: O(1/gamma) = 1e-4 x 10"
                                                                                 if penalty else "")))
    return out


#: The slip limit of the frictional patch test for ``tan alpha = 0.1, mu = 0.3``.
INCLINED_LIMIT = (0.1 + 0.3) / (1 - 0.3 * 0.1)


def rung_inclined_patch() -> list[Check]:
    """The frictional patch test (see the module): at full slip ``F / G = 0.412371`` to the
    solvers' tolerance, every frictional formulation, classical and DDCM."""
    from ddcm_casadi.drivers.harness import compare

    data = hookean_data(2, BLOCK["youngs_modulus"], 0.3, 3e-3, 17)
    model = inclined_model(data=data)
    cmp = compare(model, frictional_formulations())
    out = []
    for (variant, name), r in cmp.results.items():
        last = r.steps[-1]
        Fx, Fy = contact_resultant(model, last)
        status = statuses(model, last)
        slipping = bool(np.all(status != "stick") and np.any(status == "slip"))
        value = -Fx / Fy if last.converged and slipping else float("nan")
        out.append(Check.make(f"frictional patch test, incline tan a = 0.1, mu = 0.3 / {variant} / {name}",
                              "F / G at the slip limit", value, INCLINED_LIMIT, AGREEMENT * INCLINED_LIMIT,
                              note=f"(tan a + mu) / (1 - mu tan a) = 0.412371; every closed contact slipping "
                                   f"({np.sum(status == 'slip')} slip, {np.sum(status == 'open')} open)"))
    return out


def rung_ddcm_rate(points=(33, 65, 129)) -> list[Check]:
    """DDCM on Hookean data of ``points`` per axis (spacing halved each time) against the classical
    frictional solution of the block pushed into partial slip (Alart--Curnier, the same
    formulation): the displacement error falls at the fitted rate ~1 of the data spacing."""
    from ddcm_casadi.drivers.harness import compare

    shear = (4e-4, 8e-4)
    classical = compare(block_model(shear=shear), ["augmented_lagrangian"], variants=("classical",))
    ref = classical["classical", "augmented_lagrangian"].steps[-1]
    spacing, errors, notes = [], [], []
    for n in points:
        data = hookean_data(2, BLOCK["youngs_modulus"], 0.0, 4e-3, n)
        model = block_model(shear=shear, data=data)
        r = compare(model, ["augmented_lagrangian"], variants=("ddcm",))["ddcm", "augmented_lagrangian"]
        last = r.steps[-1]
        err = float(np.max(np.abs(last.u - ref.u)) / np.max(np.abs(ref.u))) if last.converged else float("nan")
        spacing.append(8e-3 / (n - 1))
        errors.append(err)
        notes.append(f"{n} points: {err:.2e}")
    rate, se = fitted_rate(spacing, errors) if np.all(np.isfinite(errors)) else (float("nan"), float("nan"))
    name = "block pushed into partial slip, DDCM against classical / augmented_lagrangian"
    return [Check.make(name, "fitted rate d log(error u) / d log(data spacing)", rate, 1.0, 0.5,
                       note="; ".join(notes) + f"; standard error {se:.2f}")]


#: The rungs ``ddcm-validate`` runs (registered in :mod:`ddcm_casadi.validation.ladder`).
RUNGS = {
    "Coulomb friction: friction = 0 reproduces frictionless contact": rung_frictionless_limit,
    "Coulomb friction: block pressed, then pushed (stick -> slip)": rung_block_stick_slip,
    "Coulomb friction: frictional patch test on an incline": rung_inclined_patch,
    "Coulomb friction: DDCM converges at the data-spacing rate": rung_ddcm_rate,
}
