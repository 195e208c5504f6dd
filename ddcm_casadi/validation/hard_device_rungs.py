r"""Validation rungs of prescribed displacements (a hard device), :mod:`ddcm_casadi.models.prescribed`.

Each against a reference written here, independent of the package's operators:

- :func:`rung_hard_device_bar`: the tutorial bar of the data-driven literature, ``E = 1``, ``A =
  1``, ``L = 1``, its tip displaced to 1 in ten steps: classical ``sigma = E u / L`` and ``u(x) =
  U x / L`` exactly (every formulation); DDCM within the data-spacing bound (below); a stretch to
  strain 1 runs (warned), a compression to strain -1 is refused.
- :func:`rung_hard_device_stop`: a bar pulled by a hard device onto a stop ahead of its middle
  node (contact and prescribed displacement together), against the two-segment closed form.
- :func:`rung_hard_device_truss`: a 2-D truss with a prescribed node displacement and a load,
  against the direct stiffness method (:func:`stiffness_method`, numpy, member by member).
- :func:`rung_hard_device_patch`: a plane-strain block stretched by a prescribed displacement:
  the homogeneous state, exact on any mesh.

The DDCM bound. With Hookean data ``sigma* = E eps*`` spaced ``de`` in strain and the metric
``c``, a point whose strain is held at ``eps`` (the hard device) and whose stress is its datum's
projects onto the datum nearest ``eps + delta E^2 / (c^2 + E^2)`` (``delta`` its datum's strain
minus ``eps``); a fixed point needs that rounding to return the same datum, ``|delta| c^2 / (c^2
+ E^2) <= de / 2``: the stress error ``E |delta|`` is at most

.. math::  b = E\, \Delta\varepsilon\, \frac{1 + (E / c)^2}{2}

(``E de`` for ``c = E``), linear in the spacing. Member forces and device forces are checked
against ``b`` times the sections involved, a stop's pressure (the jump of two stresses) against
``2 b``; the continuum's stresses against ``||C||_2 de sqrt(k)`` (its grid's half diagonal
``de sqrt(k) / 2``, doubled as ``b`` is for ``c = C``).
"""

from __future__ import annotations

import warnings

import numpy as np

from ddcm_casadi import formulations as registry
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.data.metric import Metric, isotropic_elasticity
from ddcm_casadi.drivers.harness import compare
from ddcm_casadi.errors import InputError, PhysicsWarning
from ddcm_casadi.models.truss import bar_chain, truss_model
from ddcm_casadi.validation.verification import Check

#: Solver tolerances are 1e-9..1e-11 (scaled); classical results must agree to 1e-8 relative.
EXACT_TOL = 1e-8
#: Roundoff allowance on the DDCM bound (data strains are computed, not exact multiples of the spacing).
BOUND_SLACK = 1e-9


def _rel(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = float(np.max(np.abs(b), initial=0.0)) or 1.0
    return float(np.max(np.abs(a - b), initial=0.0)) / scale


def ddcm_bound(E: float, spacing: float, c: float) -> float:
    """``b = E de (1 + (E / c)^2) / 2``: the largest stress error of a DDCM fixed point of a point
    whose strain a hard device holds (module docstring)."""
    return E * spacing * (1.0 + (E / c) ** 2) / 2.0


def _quiet_compare(model, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsWarning)  # the large strain of the tutorial bar is expected
        return compare(model, **kw)


def _converged(name: str, cmp, variant: str, f: str, n_steps: int) -> Check:
    r = cmp[variant, f]
    return Check.make(f"{name} / {variant} / {f}", "converged steps", sum(s.converged for s in r.steps), n_steps, 0)


# ----------------------------------------------------------------------------- the tutorial bar
def tutorial_bar(*, points: int = 1201, c: float = 1.0):
    """``E = 1``, ``A = 1``, ``L = 1``, 4 elements, the tip displaced 0.1 .. 1 in ten steps;
    Hookean data on ``[-0.1, 1.1]`` (``points`` of them)."""
    return bar_chain(length=1.0, elements=4, area=1.0, youngs_modulus=1.0,
                     tip_displacements=np.linspace(0.1, 1.0, 10),
                     dataset=MaterialDataset.hookean(1.0, -0.1, 1.1, points, c=c), name="tutorial bar")


def rung_hard_device_bar() -> list[Check]:
    """The tutorial bar: classical exact, DDCM within ``b`` at two data spacings, the stretch to
    strain 1 warned and not refused, the compression to -1 refused."""
    out: list[Check] = []
    m = tutorial_bar()
    name = "hard-device bar (E = 1, u = 1)"
    warned = m.path_warnings()
    out.append(Check.make(name, "large-strain warnings (a stretch to strain 1 runs)", len(warned), 1, 0,
                          note=warned[0] if warned else "none"))
    try:
        bar_chain(length=1.0, elements=4, youngs_modulus=1.0, tip_displacements=[-0.5, -1.0]).path_warnings()
        refused = 0
    except InputError:
        refused = 1
    out.append(Check.make(name, "compression to strain -1 refused (the bar inverted)", refused, 1, 0))
    U = m.load_parameter
    x = m.nodes[1:-1, 0]
    cmp = _quiet_compare(m, variants=("classical",))
    for f in registry.available():
        r = cmp["classical", f]
        out.append(_converged(name, cmp, "classical", f, m.n_steps))
        out.append(Check.make(f"{name} / classical / {f}", "max rel. error of stress vs E u / L",
                              _rel(r.array("stress"), np.repeat(U[:, None], 4, axis=1)), 0.0, EXACT_TOL))
        out.append(Check.make(f"{name} / classical / {f}", "max rel. error of u vs U x / L",
                              _rel(r.array("u"), U[:, None] * x[None, :]), 0.0, EXACT_TOL))
        force = cmp.fields("classical", f)["hard_device_force"][:, 0, 0]
        out.append(Check.make(f"{name} / classical / {f}", "max rel. error of the device force vs E A U / L",
                              _rel(force, U), 0.0, EXACT_TOL))
    for points in (121, 1201):
        spacing = 1.2 / (points - 1)
        bound = ddcm_bound(1.0, spacing, 1.0)
        cmp = _quiet_compare(tutorial_bar(points=points), variants=("ddcm",))
        for f in registry.available():
            r = cmp["ddcm", f]
            label = f"{name}, data spacing {spacing:g} / ddcm / {f}"
            out.append(Check.make(label, "converged steps", sum(s.converged for s in r.steps), m.n_steps, 0))
            err = float(np.max(np.abs(r.array("stress") - U[:, None])))
            out.append(Check.make(label, "max |stress - E u / L| (Pa)", err, 0.0, bound * (1 + BOUND_SLACK),
                                  note="tolerance E de (1 + (E/c)^2) / 2, the fixed-point bound of a held strain"))
    return out


# --------------------------------------------------------------- pulled onto a stop on the way
def stop_bar(*, points: int = 601, c: float = 200e9):
    """10 elements, ``E = 200 GPa``, the tip pulled 2 .. 20 mm; a stop 4 mm ahead of node 5."""
    return bar_chain(length=1.0, elements=10, youngs_modulus=200e9, tip_displacements=np.linspace(0.002, 0.02, 10),
                     stops_ahead={5: 0.004}, dataset=MaterialDataset.hookean(200e9, -0.01, 0.05, points, c=c),
                     name="bar pulled onto a stop")


def stop_closed_form(E: float, L: float, xj: float, a: float, U: np.ndarray):
    """``(u_j, p, F)``: the stop's node displacement, its pressure and the device force per area
    of a bar pulled to ``U`` with a stop at clearance ``a`` ahead of the node at ``x_j``: free
    while ``U x_j / L <= a`` (``u_j = U x_j / L``, ``p = 0``, ``F = E U / L``), then held
    (``u_j = a``, ``F = E (U - a) / (L - x_j)``, ``p = F - E a / x_j``)."""
    U = np.asarray(U, float)
    free = U * xj / L <= a
    uj = np.where(free, U * xj / L, a)
    F = np.where(free, E * U / L, E * (U - a) / (L - xj))
    p = np.where(free, 0.0, F - E * a / xj)
    return uj, p, F


def rung_hard_device_stop() -> list[Check]:
    """Contact and a prescribed displacement together, every formulation, both variants."""
    out: list[Check] = []
    m = stop_bar()
    name = "bar pulled onto a stop"
    uj, p_ref, F_ref = stop_closed_form(200e9, 1.0, 0.5, 0.004, m.load_parameter)
    cmp = _quiet_compare(m)
    gamma = next(f for f in cmp.formulations if f.name == "penalty").penalty_stiffness(cmp.problems.classical)
    # a penalty lets the stop in by p / gamma: relative errors up to max diag(K) / (gamma a), the
    # stop node's stiffness over the penalty's (as the ladder's bar with stops)
    penalty_tol = float(m.stiffness().diagonal().max()) / (gamma * float(np.min(m.contact_area)))
    for f in registry.available():
        r = cmp["classical", f]
        tol = penalty_tol if f == "penalty" else EXACT_TOL
        note = "tolerance max diag(K) / (gamma a): the penalty's penetration" if f == "penalty" else ""
        out.append(_converged(name, cmp, "classical", f, m.n_steps))
        out.append(Check.make(f"{name} / classical / {f}", "max rel. error of u at the stop vs closed form",
                              _rel(r.array("u")[:, 4], uj), 0.0, tol, note))
        out.append(Check.make(f"{name} / classical / {f}", "max rel. error of the stop's pressure vs closed form",
                              _rel(r.array("p")[:, 0], p_ref), 0.0, tol, note))
        force = cmp.fields("classical", f)["hard_device_force"][:, 0, 0]
        out.append(Check.make(f"{name} / classical / {f}", "max rel. error of the device force vs closed form",
                              _rel(force, F_ref), 0.0, tol, note))
    spacing = 0.06 / 600
    bound = ddcm_bound(200e9, spacing, 200e9)
    for f in registry.available():
        r = cmp["ddcm", f]
        out.append(_converged(name, cmp, "ddcm", f, m.n_steps))
        force = cmp.fields("ddcm", f)["hard_device_force"][:, 0, 0]
        out.append(Check.make(f"{name} / ddcm / {f}", "max |device force - closed form| (N)",
                              float(np.max(np.abs(force - F_ref))), 0.0, bound * (1 + BOUND_SLACK),
                              note=f"tolerance b A, b = E de (1 + (E/c)^2) / 2, de = {spacing:g}"))
        out.append(Check.make(f"{name} / ddcm / {f}", "max |stop pressure - closed form| (Pa)",
                              float(np.max(np.abs(r.array("p")[:, 0] - p_ref))), 0.0, 2 * bound * (1 + BOUND_SLACK),
                              note="tolerance 2 b: the jump of two stresses"))
    return out


# ------------------------------------------------------------------- a truss: the stiffness method
TRUSS_NODES = np.array([(0.0, 0.0), (-1.0, 1.0), (-0.3, 1.0), (0.4, 1.0), (1.0, 1.0)])
TRUSS_MEMBERS = np.array([(0, 1), (0, 2), (0, 3), (0, 4)])
TRUSS_DEVICE = np.array([0.002, -0.001])  # node 4, m at load factor 1


def device_truss(*, points: int = 2001):
    """A free node tied by four members to three fixed nodes and to node 4, which a hard device
    displaces by ``TRUSS_DEVICE`` times the load factor while the free node carries a load."""
    loads = np.zeros_like(TRUSS_NODES)
    loads[0] = (2e4, -1e5)
    return truss_model(nodes=TRUSS_NODES, members=TRUSS_MEMBERS, area=1e-4, youngs_modulus=200e9,
                       supports=[(1, "xy"), (2, "xy"), (3, "xy"), (4, "xy", TRUSS_DEVICE)], loads=loads,
                       load_factors=[0.25, 0.5, 0.75, 1.0],
                       dataset=MaterialDataset.hookean(200e9, -0.005, 0.005, points, c=200e9),
                       name="truss with a hard device")


def stiffness_method(nodes, members, E, A, fixed, prescribed: dict, loads):
    """The direct stiffness method of a pin-jointed truss, member by member (numpy, dense).

    Parameters
    ----------
    nodes : (nn, d); members : (ne, 2); E, A : (ne,)
    fixed : (nn, d) bool
        Held dofs (at zero unless ``prescribed`` gives a value).
    prescribed : {(node, axis): value}
    loads : (nn, d)

    Returns
    -------
    tuple
        ``(U, N, R)``: nodal displacements (nn, d), member forces (ne,) and the reactions at the
        held dofs (nn, d; zero at free dofs): ``K U - f`` there.
    """
    nodes = np.asarray(nodes, float)
    nn, d = nodes.shape
    K = np.zeros((nn * d, nn * d))
    for (i, j), Ee, Ae in zip(members, E, A):
        v = nodes[j] - nodes[i]
        L = np.linalg.norm(v)
        e = v / L
        k = Ee * Ae / L * np.outer(e, e)
        dofs = np.r_[i * d:i * d + d, j * d:j * d + d]
        K[np.ix_(dofs, dofs)] += np.block([[k, -k], [-k, k]])
    held = np.asarray(fixed, bool).ravel()
    u = np.zeros(nn * d)
    for (node, axis), value in prescribed.items():
        u[node * d + axis] = value
    f = np.asarray(loads, float).ravel()
    F = ~held
    u[F] = np.linalg.solve(K[np.ix_(F, F)], f[F] - K[np.ix_(F, held)] @ u[held])
    R = np.zeros(nn * d)
    R[held] = K[held] @ u - f[held]
    U = u.reshape(nn, d)
    N = np.array([Ee * Ae / np.linalg.norm(nodes[j] - nodes[i]) * (nodes[j] - nodes[i]) @ (U[j] - U[i])
                  / np.linalg.norm(nodes[j] - nodes[i]) for (i, j), Ee, Ae in zip(members, E, A)])
    return U, N, R.reshape(nn, d)


def rung_hard_device_truss() -> list[Check]:
    """Classical against the stiffness method (displacements, member forces, the device's
    reaction), DDCM against the bound."""
    out: list[Check] = []
    m = device_truss()
    name = m.name
    fixed = np.zeros_like(TRUSS_NODES, dtype=bool)
    fixed[1:] = True
    loads = np.zeros_like(TRUSS_NODES)
    loads[0] = (2e4, -1e5)
    ref_U, ref_N, ref_R = [], [], []
    for lf in m.load_parameter:
        U, N, R = stiffness_method(TRUSS_NODES, TRUSS_MEMBERS, np.full(4, 200e9), np.full(4, 1e-4), fixed,
                                   {(4, 0): lf * TRUSS_DEVICE[0], (4, 1): lf * TRUSS_DEVICE[1]}, lf * loads)
        ref_U.append(U[0])
        ref_N.append(N)
        ref_R.append(R[4])
    ref_U, ref_N, ref_R = np.array(ref_U), np.array(ref_N), np.array(ref_R)
    cmp = _quiet_compare(m)
    for f in registry.available():
        out.append(_converged(name, cmp, "classical", f, m.n_steps))
        fields = cmp.fields("classical", f)
        for quantity, value, ref in (("u of the free node", fields["u"], ref_U),
                                     ("member forces", fields["member_force"], ref_N),
                                     ("device force (reaction at node 4)", fields["hard_device_force"][:, 0], ref_R)):
            out.append(Check.make(f"{name} / classical / {f}", f"max rel. error of {quantity} vs stiffness method",
                                  _rel(value, ref), 0.0, EXACT_TOL))
    spacing = 0.01 / 2000
    bound = ddcm_bound(200e9, spacing, 200e9)
    for f in registry.available():
        out.append(_converged(name, cmp, "ddcm", f, m.n_steps))
        fields = cmp.fields("ddcm", f)
        out.append(Check.make(f"{name} / ddcm / {f}", "max |member stress - stiffness method| (Pa)",
                              float(np.max(np.abs(fields["stress"] - ref_N / 1e-4))), 0.0, bound * (1 + BOUND_SLACK),
                              note=f"tolerance b = E de (1 + (E/c)^2) / 2, de = {spacing:g}"))
        out.append(Check.make(f"{name} / ddcm / {f}", "max |device force - stiffness method| (N)",
                              float(np.max(np.abs(fields["hard_device_force"][:, 0] - ref_R))), 0.0,
                              bound * 1e-4 * (1 + BOUND_SLACK), note="tolerance b A (one member at node 4)"))
    return out


# ----------------------------------------------------------------------- a continuum patch
def stretched_block(*, points: int = 21):
    """A plane-strain block 20 x 10 mm (4 x 2 P1 elements), rollers on ``xmin`` and ``ymin``, its
    right edge displaced 20 um along x times the load factor; a Hookean grid of ``points^3``
    states on ``[-0.002, 0.002]`` with the metric ``C``."""
    from ddcm_casadi.models.continuum import mesh as meshes
    from ddcm_casadi.models.continuum.model import Material, Support, continuum_model

    C = isotropic_elasticity(200e9, 0.3, 2)[0]
    data = MaterialDataset.hookean_grid(C, -0.002, 0.002, points, c=Metric(C))
    return continuum_model(meshes.rectangle(0.02, 0.01, nx=4, ny=2),
                           materials=[Material(youngs_modulus=200e9, poisson_ratio=0.3, data=0)],
                           supports=[Support("xmin", "x"), Support("ymin", "y"), Support("xmax", "x", [2e-5, 0.0])],
                           load_factors=[0.3, 0.65, 1.0], datasets=[data], name="block stretched by a hard device")


def rung_hard_device_patch() -> list[Check]:
    """The homogeneous state: ``eps_xx = u / L``, ``eps_yy = -nu / (1 - nu) eps_xx``,
    ``sigma_xx = E eps_xx / (1 - nu^2)``, the device force ``sigma_xx H`` per unit thickness."""
    out: list[Check] = []
    E, nu, points = 200e9, 0.3, 21
    m = stretched_block(points=points)
    name = m.name
    exx = 2e-5 / 0.02 * np.asarray(m.load_parameter)
    strain = np.stack([exx, -nu / (1 - nu) * exx, 0 * exx], axis=1)
    sxx = E / (1 - nu ** 2) * exx
    stress = np.stack([sxx, 0 * sxx, 0 * sxx], axis=1)
    cmp = _quiet_compare(m)
    for f in registry.available():
        out.append(_converged(name, cmp, "classical", f, m.n_steps))
        r = cmp["classical", f]
        k = m.strain_components
        out.append(Check.make(f"{name} / classical / {f}", "max error of the strains vs homogeneous, / max eps_xx",
                              float(np.max(np.abs(r.array("strain").reshape(m.n_steps, -1, k) - strain[:, None])))
                              / float(np.max(exx)), 0.0, EXACT_TOL))
        out.append(Check.make(f"{name} / classical / {f}", "max error of the stresses vs homogeneous, / max sigma_xx",
                              float(np.max(np.abs(r.array("stress").reshape(m.n_steps, -1, k) - stress[:, None])))
                              / float(np.max(sxx)), 0.0, EXACT_TOL))
        force = cmp.fields("classical", f)["hard_device_force"][:, 0, 0]
        out.append(Check.make(f"{name} / classical / {f}", "max rel. error of the device force vs sigma_xx H",
                              _rel(force, sxx * 0.01), 0.0, EXACT_TOL))
    C = isotropic_elasticity(E, nu, 2)[0]
    spacing = 0.004 / (points - 1)
    bound = float(np.linalg.norm(C, 2)) * spacing * np.sqrt(3)
    for f in registry.available():
        out.append(_converged(name, cmp, "ddcm", f, m.n_steps))
        r = cmp["ddcm", f]
        err = float(np.max(np.abs(r.array("stress").reshape(m.n_steps, -1, 3) - stress[:, None])))
        out.append(Check.make(f"{name} / ddcm / {f}", "max |stress - homogeneous| (Pa)", err, 0.0, bound,
                              note=f"tolerance ||C||_2 de sqrt(k), de = {spacing:g}"))
    return out


RUNGS = {
    "hard-device bar (closed form)": rung_hard_device_bar,
    "hard-device bar onto a stop (closed form)": rung_hard_device_stop,
    "hard-device truss (stiffness method)": rung_hard_device_truss,
    "hard-device continuum patch (homogeneous)": rung_hard_device_patch,
}
