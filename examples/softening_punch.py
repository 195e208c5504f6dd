r"""A block pressed by a rigid flat punch, with softening material data (plane strain, DDCM).

The physics: a rigid strip punch of half-width ``a = 5 mm`` with edges rounded to ``r = 1 mm`` is
pressed ``0.12 mm`` into an elastic-softening block, 40 mm wide and 20 mm deep, resting on a rigid
base (half model: symmetry on ``x = 0``). Under a flat punch the pressure is largest at the edges
(for a sharp edge it is singular, ``p ~ 1 / sqrt(a^2 - x^2)``); there the material softens.

The material follows the hyperbolic law of soil mechanics (Kondner; Duncan and Chang) in plane
strain, written in Mandel components (``m = (1, 1, 0)``, ``tr = eps_11 + eps_22``):

.. math::  \sigma = \kappa\, \mathrm{tr}(\varepsilon)\, m + 2 \mu(\gamma)\, (\varepsilon - \tfrac12 \mathrm{tr}(\varepsilon)\, m),
           \qquad \mu(\gamma) = \frac{\mu_0}{1 + \gamma / \gamma_0},\qquad \gamma = |\varepsilon - \tfrac12 \mathrm{tr}(\varepsilon)\, m| ,

with ``kappa = lambda + mu_0`` and ``mu_0`` the Lame constants of ``E = 50 MPa, nu = 0.3``: linear
in volume, softening in shear, the shear stress saturating at ``2 mu_0 gamma_0``
(``gamma_0 = 5e-3``). At small strain it is the linear plane-strain law, which the classical
variant solves (``E``, ``nu``). The DDCM variant never sees the law: only data sampled from it on a
regular grid of Mandel strains, with the isotropic metric of the initial stiffness.

What it shows: the classical (linear) and DDCM (softening data) punch force against the
indentation, and the pressure under the punch, for every formulation; with finer data the DDCM
force converges (the table printed by ``main``). The DDCM force lies below the linear one once the
edges soften.

Run ``python examples/softening_punch.py`` (about 2.5 minutes on 2 cores, a line per load step on
stderr; ``--quick``: a few seconds, ``-q``: no progress): it prints the tables and writes the VTU
series (open ``*.pvd`` in ParaView), the pressure and deformed-body figures and
``force_indentation.png`` to ``examples/output/softening_punch/``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from ddcm_casadi import MaterialDataset
from ddcm_casadi.models.continuum import Contact, FlatPunch, Material, Support, continuum_model, mesh
from ddcm_casadi.drivers.harness import Comparison, compare
from ddcm_casadi.data.metric import Metric, isotropic_elasticity
from ddcm_casadi.outputs.save import save_outputs

NAME = "softening_punch"
E, NU = 50e6, 0.3            # Pa, initial (small-strain) stiffness
GAMMA0 = 5e-3                # reference shear strain of the hyperbolic law
HALF_WIDTH, EDGE = 5e-3, 1e-3  # punch (m)
BLOCK = (0.02, 0.02)         # half model: width, depth (m)
TRAVEL = 1.2e-4              # final indentation (m)
# Data cover |eps_i| <= this in every Mandel component: quick mode, full mode (its graded mesh
# resolves the punch edge, where the strains reach 0.026: a +-0.02 grid flags those steps as
# beyond the data).
STRAIN_RANGE = {True: 0.02, False: 0.03}


def softening_stress(strain: np.ndarray, *, youngs_modulus: float = E, poisson_ratio: float = NU,
                     gamma0: float = GAMMA0) -> np.ndarray:
    """The hyperbolic plane-strain law (module docstring): Mandel stresses ``(n, 3)`` of
    Mandel strains ``(n, 3)``."""
    C = isotropic_elasticity(youngs_modulus, poisson_ratio, 2)[0]
    mu0 = 0.5 * C[2, 2]
    kappa = C[0, 1] + mu0  # lambda + mu
    eps = np.atleast_2d(np.asarray(strain, dtype=float))
    m = np.array([1.0, 1.0, 0.0])
    tr = eps[:, 0] + eps[:, 1]
    dev = eps - 0.5 * tr[:, None] * m
    gamma = np.linalg.norm(dev, axis=1)
    return kappa * tr[:, None] * m + 2.0 * (mu0 / (1.0 + gamma / gamma0))[:, None] * dev


def dataset(points_per_axis: int, *, law: str = "softening", strain_range: float = STRAIN_RANGE[True]
            ) -> MaterialDataset:
    """Data on a regular grid of ``points_per_axis^3`` Mandel strains in ``[-r, r]^3``
    (``r = strain_range``), stresses from the softening law (or the linear one, ``law="linear"``),
    metric: the isotropic stiffness of ``E, nu``."""
    C = isotropic_elasticity(E, NU, 2)[0]
    if law == "linear":
        return MaterialDataset.hookean_grid(C, -strain_range, strain_range, points_per_axis, c=Metric(C))
    return MaterialDataset.from_law(softening_stress, 3, -strain_range, strain_range, points_per_axis, c=Metric(C))


def travel(quick: bool) -> np.ndarray:
    return np.linspace(0.0, TRAVEL, 4 if quick else 7)


def build_model(*, quick: bool = False, points_per_axis: int | None = None, law: str = "softening"):
    """The half block under the punch (``quick``: a coarse uniform mesh, 4 steps, 13^3 data;
    else graded towards the punch edge, 7 steps, 25^3 data)."""
    width, depth = BLOCK
    body = mesh.rectangle(width, depth, nx=8 if quick else 16, ny=8 if quick else 16, origin=(0.0, -depth))
    if not quick:
        body = mesh.refine_near(body, (HALF_WIDTH, 0.0), 3e-3, levels=2, shrink=1.0, buffer=2)
    punch = FlatPunch(center=(0.0, 0.0), normal=(0.0, -1.0), half_width=HALF_WIDTH, edge_radius=EDGE,
                      direction=(0.0, -1.0), travel=travel(quick), name="punch")
    n = points_per_axis or (13 if quick else 25)
    return continuum_model(body, materials=[Material(youngs_modulus=E, poisson_ratio=NU, data=0)],
                           supports=[Support("xmin", "x"), Support("ymin", "xy")],
                           contacts=[Contact(punch, "ymax")],
                           datasets=[dataset(n, law=law, strain_range=STRAIN_RANGE[quick])],
                           name=f"softening punch ({law} data, {n}^3 points)")


def punch_force(model, cmp: Comparison, variant: str, formulation: str) -> np.ndarray:
    """Total punch force per step (N per metre of thickness, both halves), resolved along the
    punch's travel: the contact forces ``a p n`` of the pairs against ``d``."""
    forces = model.contact_force_vectors(cmp.fields(variant, formulation)["contact_pressure"])
    d = np.asarray(model.obstacles[0].direction, dtype=float)
    return 2.0 * np.sum(forces @ (d / np.linalg.norm(d)), axis=-1)


class PunchResult:
    """The comparison at the example's data size, and the DDCM force at every further data size
    run (``data_sizes``: points per axis -> (force per step, converged), Fischer-Burmeister)."""

    def __init__(self, model, comparison: Comparison, travel: np.ndarray) -> None:
        self.model, self.comparison, self.travel = model, comparison, travel
        self.data_sizes: dict[int, tuple[np.ndarray, bool]] = {}
        self.outputs: list[Path] = []

    def table(self) -> str:
        lines = [self.comparison.table(), "", "punch force at the last step (kN/m):"]
        cmp = self.comparison
        for (variant, name), r in cmp.results.items():
            f = punch_force(self.model, cmp, variant, name)[-1]
            flag = "" if r.converged else "  (NOT CONVERGED)"
            lines.append(f"  {variant:9s} {name:22s} {f / 1e3:9.2f}{flag}")
        if self.data_sizes:
            lines.append("DDCM (fischer_burmeister) against the data size:")
            for n, (force, ok) in sorted(self.data_sizes.items()):
                lines.append(f"  {n:3d}^3 = {n ** 3:6d} points: {force[-1] / 1e3:9.2f} kN/m"
                             + ("" if ok else "  (NOT CONVERGED)"))
        return "\n".join(lines)


def figure_force(result: PunchResult, path: Path) -> Path:
    """Punch force against indentation: classical (linear) and DDCM (softening data)."""
    import matplotlib.pyplot as plt

    from ddcm_casadi.outputs.plots import save_figure

    fig, ax = plt.subplots(figsize=(6.0, 4.2))
    s = result.travel * 1e3
    cmp = result.comparison
    for (variant, name), r in cmp.results.items():
        f = punch_force(result.model, cmp, variant, name) / 1e3
        style = "-" if variant == "classical" else "--"
        ax.plot(s, f, style, marker="o" if variant == "classical" else "s", ms=3,
                label=f"{variant} / {name}" + ("" if r.converged else " (NOT CONVERGED)"))
        bad = [i for i, st in enumerate(r.steps) if not st.converged]
        if bad:
            ax.plot(s[bad], f[bad], "o", mfc="none", mec="red", ms=10)
    for n, (force, ok) in sorted(result.data_sizes.items()):
        ax.plot(s, force / 1e3, ":", lw=2, label=f"ddcm / FB, {n}^3 data" + ("" if ok else " (NOT CONVERGED)"))
    ax.set_xlabel("indentation (mm)")
    ax.set_ylabel("punch force (kN/m)")
    ax.set_title("Flat punch: linear law (classical) vs softening data (DDCM)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
    return path


def _progress(variant: str, formulation: str, step) -> None:
    """One line per load step on stderr (the full run takes minutes): a run that stalls is seen."""
    flag = "" if step.converged else "  NOT CONVERGED: " + step.message
    print(f"  {variant}/{formulation}: step {step.step + 1} done in {step.seconds:.1f} s{flag}", file=sys.stderr)


def main(out_dir: str | Path | None = None, *, quick: bool = False, formulations=None,
         data_sizes: tuple[int, ...] | None = None, progress: bool = False) -> PunchResult:
    """Every formulation (or ``formulations``), classical and DDCM, on the example's data; then
    DDCM with Fischer-Burmeister at further data sizes (``data_sizes``: points per axis; default
    none when ``quick``, else 13, 17, 33). Outputs go to ``out_dir`` if given; ``progress``
    prints a line per load step on stderr."""
    report = _progress if progress else None
    model = build_model(quick=quick)
    cmp = compare(model, formulations, progress=report)
    result = PunchResult(model=model, comparison=cmp, travel=travel(quick))
    for n in (data_sizes if data_sizes is not None else (() if quick else (13, 17, 33))):
        if progress:
            print(f"DDCM with {n}^3 data points", file=sys.stderr)
        m = build_model(quick=quick, points_per_axis=n)
        r = compare(m, ["fischer_burmeister"], variants=("ddcm",), progress=report)
        result.data_sizes[n] = (punch_force(m, r, "ddcm", "fischer_burmeister"), r["ddcm", "fischer_burmeister"].converged)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        result.outputs = list(save_outputs(cmp, out)) + [figure_force(result, out / "force_indentation.png")]
    return result


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description="A rigid flat punch pressed into a softening block (plane strain, DDCM).")
    parser.add_argument("--quick", action="store_true", help="coarse mesh, 4 steps, 13^3 data, no data-size study "
                                                            "(a few seconds; the full run takes a few minutes)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    args = parser.parse_args()
    t0 = time.perf_counter()
    res = main(Path(__file__).resolve().parent / "output" / NAME, quick=args.quick, progress=not args.quiet)
    print(res.table())
    print(f"wall time {time.perf_counter() - t0:.1f} s")
