"""DDCM search quality on noisy data: the measurements of ``benchmarks/ddcm_quality.py`` and the
``ddcm-validate`` rung built on them.

Noisy data: the paper's Hookean data (``E = 200 GPa``, strains equally spaced in
``[-0.05, 0.01]``) with independent Gaussian noise of standard deviation ``noise x std`` added to
the strains and to the stresses (``std`` the spread of the noise-free strains, resp. stresses):
at 1 % about 1.5 data spacings. The paper's bar on such data is a one-element problem, so the
global DDCM optimum of every step is known exactly (enumeration, :mod:`ddcm_casadi.drivers.ddcm_search`).

Measured per configuration (:data:`CONFIGURATIONS`), over several data sets (seeds) x 21 load
steps: the share of steps whose fixed point is the global optimum, the error against the
noise-free classical solution (max over steps of ``|p - p_exact| / max |p_exact|``, and the same
for ``u``), and the cost relative to plain alternating projections as the ratio of ``Z_E``
projections (iteration counts, not wall time).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ddcm_casadi.models.bar import bar_model
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.drivers.harness import compare
from ddcm_casadi.drivers.ddcm_options import DDCMOptions
from ddcm_casadi.validation.verification import Check

#: Noise levels of the measurements (fractions of the data's spread).
NOISE_LEVELS = (0.01, 0.02, 0.05)

#: The searches compared (name -> options).
CONFIGURATIONS: dict[str, DDCMOptions] = {
    "plain": DDCMOptions(),
    "elastic start": DDCMOptions(start="elastic"),
    "elastic, every step": DDCMOptions(start="elastic", warm=False),
    "restarts 2 (uniform)": DDCMOptions(restarts=2),
    "restarts 2 (kick, K=10)": DDCMOptions(restarts=2, restart_neighbours=10),
    "greedy (next-nearest)": DDCMOptions(improve="greedy", greedy_screen=False),
    "greedy (screened)": DDCMOptions(improve="greedy"),
    "restarts 1 (kick) + greedy": DDCMOptions(restarts=1, restart_neighbours=10, improve="greedy"),
    "LCDD (k=5)": DDCMOptions(variant="lcdd"),
}

#: The target of the issue: this share of steps at the global optimum ...
TARGET_SHARE = 0.95
#: ... at no more than this many times the projections of plain alternating.
TARGET_COST = 5.0
#: The configuration the rung checks against the target.
TARGET_CONFIGURATION = "restarts 1 (kick) + greedy"

#: The noise-robust variant the rung checks: max-ent (Kirchdoerfer & Ortiz 2017) at its defaults
#: (K = 32 neighbours, one temperature).
MAXENT_CONFIGURATION = "max-ent (K=32, 1 stage)"
MAXENT_OPTIONS = DDCMOptions(variant="maxent")
#: The rung's bound on max-ent's error of ``p`` over plain alternating's (both against the noise-free
#: closed form). Measured ratios: 0.10-0.12 on the rung's four data sets at 1, 2 and 5 % noise, and
#: 0.14-0.16 on eight others (seeds 4-11): the bound, "at least halves the error", keeps a factor
#: of three over the largest. The error of ``u`` is not claimed: small for both (below 5 %), it was
#: measured at 0.9-2.3 times plain alternating's.
MAXENT_ERROR_RATIO = 0.5


def noisy_dataset(noise: float, seed: int, *, n_data: int = 500, c: float = 300e9,
                  youngs_modulus: float = 200e9) -> MaterialDataset:
    """The paper's Hookean data with Gaussian noise of ``noise x std`` on strains and stresses."""
    strain = np.linspace(-0.05, 0.01, n_data)
    stress = youngs_modulus * strain
    rng = np.random.default_rng(seed)
    noisy_strain = strain + noise * np.std(strain) * rng.standard_normal(n_data)
    noisy_stress = stress + noise * np.std(stress) * rng.standard_normal(n_data)
    return MaterialDataset(noisy_strain, noisy_stress, c)


def noisy_paper_bar(noise: float, seed: int, *, n_data: int = 500):
    """The paper's bar (21 steps, ``h`` from 1.01 to 0.99 m) on noisy data."""
    return bar_model(length=1.0, area=1.0, youngs_modulus=200e9, positions=np.linspace(1.01, 0.99, 21),
                     dataset=noisy_dataset(noise, seed, n_data=n_data), name=f"paper bar, {noise:.0%} noise")


@dataclass
class Quality:
    """One configuration at one noise level, over all seeds."""

    name: str
    noise: float
    steps: int
    at_global: int
    error_p: float
    error_u: float
    projections: int
    seconds: float
    converged: int

    @property
    def checked(self) -> bool:
        """Whether the global optimum was known (not for LCDD, which has no data assignment)."""
        return self.at_global >= 0

    @property
    def share(self) -> float:
        return self.at_global / self.steps


def measure(options: DDCMOptions, noise: float, seeds, *, name: str = "", formulation: str = "fischer_burmeister",
            n_data: int = 500) -> Quality:
    """Run one configuration on the noisy paper bar for every seed (see the module's docstring)."""
    at_global = steps = projections = converged = 0
    err_p, err_u, seconds = [], [], 0.0
    for seed in seeds:
        cmp = compare(noisy_paper_bar(noise, seed, n_data=n_data), [formulation], variants=("ddcm",), ddcm=options)
        r = cmp["ddcm", formulation]
        steps += len(r.steps)
        at_global += sum(bool(s.global_optimum) for s in r.steps)
        converged += sum(s.converged for s in r.steps)
        projections += sum(s.projections for s in r.steps)
        e = cmp.errors("ddcm", formulation)
        err_p.append(float(np.max(e["p"])))
        err_u.append(float(np.max(e["u"])))
        seconds += r.solve_seconds
    if options.variant != "plain":
        at_global = -1
    return Quality(name, noise, steps, at_global, float(np.mean(err_p)), float(np.mean(err_u)), projections, seconds,
                   converged)


def rung_search_quality(*, seeds=range(4)) -> list[Check]:
    """``ddcm-validate`` rung: on the noisy paper bar at 1, 2 and 5 % noise, the target
    configuration reaches the enumerated global optimum at >= 95 % of the steps, at no more than
    5x the ``Z_E`` projections of plain alternating (an iteration-count ratio, not wall time);
    max-ent's error of ``p`` against the noise-free closed form is at most
    :data:`MAXENT_ERROR_RATIO` times plain alternating's."""
    out = []
    for noise in NOISE_LEVELS:
        plain = measure(CONFIGURATIONS["plain"], noise, seeds, name="plain")
        best = measure(CONFIGURATIONS[TARGET_CONFIGURATION], noise, seeds, name=TARGET_CONFIGURATION)
        name = f"noisy paper bar, {noise:.0%} noise / ddcm / {TARGET_CONFIGURATION}"
        out.append(Check.make(name, f"share of steps at the global optimum (>= {TARGET_SHARE:.0%})",
                              best.share, 1.0, 1.0 - TARGET_SHARE,
                              note=f"{best.at_global}/{best.steps} steps, {len(list(seeds))} data sets; plain "
                                   f"alternating {plain.share:.0%}; the optimum by enumeration of the data"))
        ratio = best.projections / plain.projections
        out.append(Check.make(name, f"Z_E projections relative to plain alternating (<= {TARGET_COST:g})",
                              ratio, 0.0, TARGET_COST, note=f"{best.projections} vs {plain.projections} projections"))
        maxent = measure(MAXENT_OPTIONS, noise, seeds, name=MAXENT_CONFIGURATION)
        out.append(Check.make(f"noisy paper bar, {noise:.0%} noise / ddcm / {MAXENT_CONFIGURATION}",
                              f"error of p relative to plain alternating's (<= {MAXENT_ERROR_RATIO:g})",
                              maxent.error_p / plain.error_p, 0.0, MAXENT_ERROR_RATIO,
                              note=f"max relative error of p against the noise-free closed form, mean over "
                                   f"{len(list(seeds))} data sets: {maxent.error_p:.3g} vs plain {plain.error_p:.3g}; "
                                   f"{maxent.converged}/{maxent.steps} steps settled"))
    return out
