"""The continuum rungs of ``ddcm-validate``: Hertz in plane strain, and DDCM on continua.

- Hertz (``docs/maths.md``, section 8): the example's default mesh (P2, ``examples/cases/hertz2d.toml``)
  must give ``p0`` and ``a`` within 2 % for classical Fischer-Burmeister; a P1 refinement sequence
  of the same body gives the fitted rates of the errors in ``p0``, ``a`` and the pressure profile
  (L2), which must fall with the element size.
- Hertz in 3-D (``examples/cases/hertz3d.toml``, linear tetrahedra): the recovered contact
  pressure's ``p0`` within 3 % and its scatter within 2 % on the finest of three meshes, the
  profile's L2 error and scatter falling at every refinement.
- DDCM on a continuum: a block indented by a cylinder, Hookean data on grids of ``n^3`` Mandel
  strains; the error against the classical solution must fall as the data spacing, i.e. with the
  fitted slope ``-1/3`` against the number of data points ``N = n^3``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ddcm_casadi import cases
from ddcm_casadi.casefiles.base import read_document
from ddcm_casadi.casefiles.config import case_from_dict, load_case
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.drivers.harness import compare
from ddcm_casadi.data.metric import Metric, isotropic_elasticity
from ddcm_casadi.validation.verification import Check
from ddcm_casadi.models.continuum.obstacles import Circle

FB = "fischer_burmeister"
#: The Hertz example, ``examples/cases/hertz2d.toml``, installed as package data (``ddcm_casadi.cases``).
EXAMPLE = Path(cases.__file__).resolve().parent / "hertz2d.toml"
#: The 3-D Hertz example, ``examples/cases/hertz3d.toml``.
EXAMPLE_3D = EXAMPLE.parent / "hertz3d.toml"
E, NU, R = 200e9, 0.3, 0.05


def hertz_block(levels: int, *, degree: int = 1, data: bool = False):
    """The Hertz example (``examples/cases/hertz2d.toml``) with ``degree`` elements and ``levels``
    gradings of the contact zone (element size ``2 mm / 2^levels`` there), classical only unless
    ``data`` (then with the example's Hookean data)."""
    doc = read_document(EXAMPLE)
    if not data:
        doc.pop("data", None)
    doc["mesh"]["degree"] = degree
    doc["mesh"]["refine_near"]["levels"] = levels
    return case_from_dict(doc, base_dir=EXAMPLE.parent, source=f"hertz P{degree} L{levels}.toml").model


def _fit(h, e) -> float:
    return float(np.polyfit(np.log(h), np.log(e), 1)[0])


def rung_hertz(*, levels=(2, 3, 4, 5)) -> list[Check]:
    out = []
    model = load_case(EXAMPLE).model  # the example as it is, with its default mesh
    r = compare(model, [FB], variants=("classical",))["classical", FB]
    m = model.reference.measure(model, r.steps[-1].p, r.steps[-1].stress)
    name = "Hertz 2-D, example mesh (P2) / classical / fischer_burmeister"
    out.append(Check.make(name, "converged steps", sum(s.converged for s in r.steps), model.n_steps, 0))
    note = f"F = {m['force']:.4g} N/m, a = {m['a_hertz'] * 1e3:.4g} mm, p0 = {m['p0_hertz'] / 1e6:.4g} MPa (Hertz)"
    out.append(Check.make(name, "rel. error of p0 vs Hertz (measured force)", m["error_p0"], 0.0, 0.02, note=note))
    out.append(Check.make(name, "rel. error of a vs Hertz (second moment)", m["error_a"], 0.0, 0.02))
    rows = []
    for lev in levels:
        mod = hertz_block(lev)
        res = compare(mod, [FB], variants=("classical",))["classical", FB]
        meas = mod.reference.measure(mod, res.steps[-1].p, res.steps[-1].stress)
        rows.append((0.002 / 2 ** lev, meas, res.converged, mod.n_dofs))
    h = np.array([row[0] for row in rows])
    ok = all(row[2] for row in rows)
    seq = "; ".join(f"h={row[0] * 1e6:.0f} um ({row[3]} dofs): p0 {row[1]['error_p0']:.2%}, a {row[1]['error_a']:.2%}, "
                    f"L2 {row[1]['error_l2']:.2%}" for row in rows)
    name = "Hertz 2-D, P1 refinement / classical / fischer_burmeister"
    out.append(Check.make(name, "converged runs", sum(row[2] for row in rows), len(rows), 0))
    for key, label in (("error_l2", "pressure L2"), ("error_p0", "p0"), ("error_a", "a")):
        e = np.array([row[1][key] for row in rows])
        rate = _fit(h, e) if ok and np.all(e > 0) else float("nan")
        # Linear elements resolve the square-root edge of the pressure at rate 1/2 at least
        # (code_aster asserts 0.5 for the pressure in L2); a rate <= 0 means no convergence. The
        # window [0.5, 2.5] is a lower bound: 2 is the best rate of P1 even for smooth fields.
        out.append(Check.make(name, f"fitted rate of the {label} error (d log e / d log h), >= 0.5", rate, 1.5, 1.0,
                              note=seq if key == "error_l2" else ""))
    return out


def hertz_block_3d(levels: int):
    """The 3-D Hertz example (``examples/cases/hertz3d.toml``, a quarter model on linear
    tetrahedra), classical only, with ``levels`` gradings of the contact zone (element size
    ``2 mm / 2^levels`` there)."""
    doc = read_document(EXAMPLE_3D)
    doc.pop("data", None)
    doc["mesh"]["refine_near"]["levels"] = levels
    return case_from_dict(doc, base_dir=EXAMPLE_3D.parent, source=f"hertz3d P1 L{levels}.toml").model


def rung_hertz_3d(*, levels=(3, 4, 5)) -> list[Check]:
    """Hertz in 3-D on linear tetrahedra, the pressure recovered from the boundary elements'
    stresses (:func:`~ddcm_casadi.models.continuum.pressure.pressure_field`): the issue's targets
    on the finest mesh (under 1e5 unknowns): ``p0`` within 3 %, scatter (:func:`~ddcm_casadi.models.continuum.hertz.scatter`)
    within 2 %, and the profile's L2 error and scatter falling at every refinement."""
    rows = []
    for lev in levels:
        mod = hertz_block_3d(lev)
        res = compare(mod, [FB], variants=("classical",))["classical", FB]
        last = res.steps[-1]
        rows.append((0.002 / 2 ** lev, mod.reference.measure(mod, last.p, last.stress), res.converged, mod.n_dofs))
    name = "Hertz 3-D (quarter), P1 refinement / classical / fischer_burmeister"
    seq = "; ".join(f"h={h * 1e6:.1f} um ({n} dofs): p0 {m['error_p0']:.2%} (largest nodal "
                    f"{m['p0_nodal'] / m['p0_hertz'] - 1:+.2%}), scatter {m['scatter']:.2%}, L2 {m['error_l2']:.2%}"
                    for h, m, _, n in rows)
    h, finest, _, n = rows[-1]
    out = [Check.make(name, "converged runs", sum(row[2] for row in rows), len(rows), 0, note=seq),
           Check.make(name, "unknowns of the finest mesh, < 1e5", n, 0.0, 1e5),
           Check.make(name, "rel. error of p0 (recovered pressure) on the finest mesh", finest["error_p0"], 0.0, 0.03),
           Check.make(name, "pressure scatter for r < 0.8 a on the finest mesh", finest["scatter"], 0.0, 0.02)]
    for key, label in (("error_l2", "pressure L2 error"), ("scatter", "pressure scatter")):
        e = np.array([row[1][key] for row in rows])
        out.append(Check.make(name, f"refinements where the {label} grows", int(np.sum(~(np.diff(e) < 0))), 0, 0))
    return out


def rung_continuum_ddcm(*, points=(9, 17, 33, 65)) -> list[Check]:
    """DDCM error against the classical solution on a 2-D indented block as the data grid refines."""
    from ddcm_casadi.models.continuum import mesh  # scikit-fem (0.4 s) only when a continuum is built, as the package does
    from ddcm_casadi.models.continuum.model import Contact, Material, Support, continuum_model

    C = isotropic_elasticity(E, NU, 2)[0]

    def build(data=None):
        body = mesh.rectangle(0.01, 0.01, nx=6, ny=6)
        mat = Material(youngs_modulus=E, poisson_ratio=NU, data=None if data is None else 0)
        return continuum_model(body, materials=[mat], supports=[Support("ymin", "xy")],
                               contacts=[Contact(Circle((0.005, 0.01 + R), R, travel=[0.0, 1e-6, 2e-6, 3e-6]),
                                                 "ymax")], datasets=[] if data is None else [data])

    exact = compare(build(), [FB], variants=("classical",))["classical", FB]
    span = 1.2 * float(np.max(np.abs(exact.array("strain"))))
    errs, conv = [], []
    for n in points:
        data = MaterialDataset.hookean_grid(C, -span, span, n, c=Metric(C))
        r = compare(build(data), [FB], variants=("ddcm",))["ddcm", FB]
        conv.append(r.converged)
        errs.append(float(np.max(np.abs(r.array("u") - exact.array("u"))) / np.max(np.abs(exact.array("u")))))
    N = np.array(points, float) ** 3
    slope = _fit(N, np.array(errs)) if all(e > 0 for e in errs) else float("nan")
    note = ("errors " + ", ".join(f"N={int(n)}: {e:.2e}" for n, e in zip(N, errs))
            + "; expected -1/3: the error follows the data spacing, N^(-1/k) with k = 3 Mandel components")
    name = "2-D indented block / ddcm / fischer_burmeister"
    return [Check.make(name, "converged data sizes", sum(conv), len(points), 0),
            Check.make(name, "fitted rate d log(error u) / d log(N)", slope, -1.0 / 3.0, 0.15, note=note)]


__all__ = ["rung_hertz", "rung_hertz_3d", "rung_continuum_ddcm", "hertz_block", "hertz_block_3d"]
