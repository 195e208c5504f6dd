"""Max-ent data-driven solver with annealing (Kirchdoerfer & Ortiz 2017; docs/maths.md, Sec. 9).

References: the enumerated global optimum and the closed-form projection of the paper's bar,
brute-force nearest data, the free energy evaluated directly from its definition, the
noise-free classical closed form, and repeated runs.
"""

import json

import numpy as np
import pytest

from ddcm_casadi import compare, formulations
from ddcm_casadi.commands.compare import main
from ddcm_casadi.casefiles.config import load_case
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.data.metric import Metric, isotropic_elasticity
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.validation.quality_rungs import noisy_dataset, noisy_paper_bar
from ddcm_casadi.drivers.ddcm_options import DDCMOptions
from ddcm_casadi.drivers.noise_robust import TOL, boltzmann_weights, data_spread, neighbourhoods
from ddcm_casadi.drivers.path import DDCMSolver
from ddcm_casadi.models.truss import bar_chain

from .test_continuum import E, NU, _indented
from .test_ddcm import EXACT_PROJECTION_RTOL  # the exact formulations' projections: 1e-9..1e-11 scaled
from .test_ddcm_quality import CASE, ROUNDOFF  # roundoff of an objective in scaled energy units

FB = "fischer_burmeister"
#: Annealing until the weights concentrate: x4 per stage, more stages than it takes (about 6-10).
ANNEALED = dict(variant="maxent", maxent_steps=30, maxent_beta_growth=4.0)


def _run(model, **options):
    return compare(model, [FB], variants=("ddcm",), ddcm=DDCMOptions(**options))["ddcm", FB]


# ------------------------------------------------------------------------------- bad option values
# Bad values of each max-ent option, one by one: tests/test_ddcm_quality.py::test_bad_options_are_one_line_errors.
def test_case_file_options_are_checked_and_recorded(tmp_path, capsys):
    cfg = tmp_path / "case.toml"
    cfg.write_text(CASE + "maxent_beta_growth = 1\n", encoding="utf-8")
    out = tmp_path / "bad"
    assert main(["--config", str(cfg), "--out", str(out), "-q", "--no-plots", "--formulations", FB]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "[ddcm] maxent_beta_growth" in err
    assert not out.exists() or not any(out.iterdir())

    cfg.write_text(CASE + 'variant = "maxent"\nmaxent_neighbours = 8\nmaxent_steps = 3\nmaxent_beta_growth = 3\n',
                   encoding="utf-8")
    case = load_case(cfg)
    assert case.ddcm_options == DDCMOptions(variant="maxent", maxent_neighbours=8, maxent_steps=3,
                                            maxent_beta_growth=3.0)
    out = tmp_path / "out"
    assert main(["--config", str(cfg), "--out", str(out), "-q", "--no-plots", "--formulations", FB]) == 0
    doc = json.loads((out / "results.json").read_text())
    assert doc["parameters"]["ddcm"] == case.ddcm_options.describe()
    assert doc["parameters"]["ddcm"]["maxent_beta_growth"] == 3.0


# ------------------------------------------------------------------------------------------ weights
def test_boltzmann_weights_against_their_formula():
    d2 = np.array([[1.0, 1.0, 2.0, 5.0], [0.0, 3.0, 4.0, 4.0], [7.0, 7.5, 9.0, 30.0]])
    beta = 0.7
    direct = np.exp(-beta * d2 / 2) / np.sum(np.exp(-beta * d2 / 2), axis=1, keepdims=True)
    w, concentrated = boltzmann_weights(d2, beta)
    assert np.allclose(w, direct, rtol=1e-14, atol=0) and not concentrated
    # the farther data below 1e-16 of the nearest: exp(-beta 0.5 / 2) < 1e-16 for beta > 147.4
    assert not boltzmann_weights(d2, 147.0)[1] and boltzmann_weights(d2, 148.0)[1]
    # shifted by the row minimum: no underflow of every weight at once, however large d2 or beta
    w, concentrated = boltzmann_weights(d2 + 1e6, float("inf"))
    assert concentrated and np.array_equal(w, [[0.5, 0.5, 0, 0], [1, 0, 0, 0], [1, 0, 0, 0]])


# ---------------------------------------------------------------------------------- reproducibility
def test_runs_are_reproducible():
    model = noisy_paper_bar(0.05, 2, n_data=300)
    opts = dict(variant="maxent", start="random", seed=7, warm=False, maxent_steps=2)
    a, b = _run(model, **opts), _run(model, **opts)
    for name in ("u", "p", "strain_star", "stress_star", "data_index", "projections", "distance"):
        assert np.array_equal(a.array(name), b.array(name)), name


# ---------------------------------------------------------------------------------------- descent
def test_free_energy_never_increases_at_fixed_beta():
    """docs/maths.md, Sec. 9: with F = sum_i w_i F_i, F_i = -log(sum_j exp(-beta d_ij^2 / 2)) / beta
    over the K nearest data, the weighted-mean update and the Z_E projection give
    F(z') <= G(z', p) <= G(z, p) = F(z). Checked on a noisy 3-element chain in contact, at three
    temperatures, up to the projection's accuracy (ROUNDOFF in scaled energy units)."""
    model = bar_chain(length=1.0, elements=3, youngs_modulus=200e9, tip_positions=np.linspace(1.002, 0.99, 5),
                      dataset=noisy_dataset(0.05, 3, n_data=300), name="noisy chain")
    problems = build_problems(model)
    solver = DDCMSolver(problems, formulations.get(FB).build(problems.projection),
                        options=DDCMOptions(variant="maxent"))
    data, step, K = model.dataset, model.n_steps - 1, 32
    tol = ROUNDOFF * problems.scales("mpcc")["energy"]
    index = solver.initial_assignment(step)
    warm, cost = (np.zeros(problems.projection.n_x), np.zeros(problems.projection.n_pairs), None), dict(inner=0, t_project=0.0)
    star = data.strain[index], data.stress[index]
    beta0 = None
    for factor in (1.0, 4.0, 16.0):
        history = []
        for _ in range(12):
            sol, is_global, _, failed = solver.project_data(step, *star, warm, cost)
            assert not failed and is_global
            warm = (sol.x, sol.p, sol.state)
            f = problems.fields("mpcc", sol.x, sol.p)
            near, d2 = neighbourhoods(model, f["strain"], f["stress"], K)
            beta0 = beta0 or 1.0 / float(np.mean(d2))
            beta = factor * beta0
            lo = d2.min(axis=1)
            F_i = 0.5 * lo - np.log(np.sum(np.exp(-0.5 * beta * (d2 - lo[:, None])), axis=1)) / beta
            history.append(float(np.dot(model.volumes, F_i)))
            w, _ = boltzmann_weights(d2, beta)
            star = np.sum(w * data.strain[near], axis=1), np.sum(w * data.stress[near], axis=1)
        assert np.all(np.diff(history) <= tol), (factor, history)
        assert history[-1] < history[0] - 100 * tol  # it does descend, far beyond roundoff: not vacuous


# --------------------------------------------------------------------------------------- accuracy
@pytest.mark.parametrize("noise", [0.02, 0.05])
def test_maxent_is_closer_to_the_law_than_plain_ddcm_on_noisy_data(noise):
    """Max relative error of p over the steps against the noise-free classical closed form.

    Plain DDCM takes one noisy datum per point. Max-ent's settled state is the weighted mean of
    its K = 32 nearest data with weights exp(-beta0 d^2 / 2), beta0 = 1 / <d^2>: for data spread
    along the law through the state (d_j^2 ~ j^2, <d^2> ~ d_K^2 / 3) the effective number of data
    n_eff = (sum w)^2 / sum w^2 is about 0.87 K = 28, so the noise of the mean is about
    1 / sqrt(28) = 0.19 of one datum's. The test asks for less than half of plain's error on
    average over four data sets (a factor 2.6 of margin for the data sets' spread and for plain's
    selection of the nearest datum), and for a lower error on every data set (the issue's target).
    """
    ratios = []
    for seed in range(4):
        model = noisy_paper_bar(noise, seed)
        errors = {}
        for name, opts in (("plain", {}), ("maxent", dict(variant="maxent"))):
            cmp = compare(model, [FB], variants=("ddcm",), ddcm=DDCMOptions(**opts))
            assert cmp["ddcm", FB].converged, name
            errors[name] = float(np.max(cmp.errors("ddcm", FB)["p"]))
        assert errors["maxent"] < errors["plain"], (seed, errors)
        ratios.append(errors["maxent"] / errors["plain"])
    assert np.mean(ratios) <= 0.5, ratios


# ------------------------------------------------------------------------------ zero temperature
def test_annealed_to_concentration_is_the_plain_ddcm_optimum_on_noiseless_data(paper):
    """Annealed until the weights concentrate, max-ent's material state is the nearest datum to
    roundoff (relative weights < 1e-16), so every step is a fixed point of plain DDCM: the datum
    nearest the state (brute force) whose exact projection (closed form) is the state. On the
    paper's noiseless data it is moreover the enumerated global optimum at every step, including
    h = 0.992 where plain alternation stops at a local minimum (tests/test_ddcm.py).

    Tolerances: the reported state is the projection of the material state of the previous
    update, which the last one moved by at most ``tol = TOL x spread`` in the metric; the bar's
    branches of Z_E are convex, so the projection moves by no more: ``|dp| <= sqrt(c) tol``,
    ``|du| = L |d eps| <= L tol / sqrt(c)``, and the distance ``w d^2 / 2`` by at most
    ``w (d tol + tol^2 / 2)``; plus the solver's accuracy."""
    plain = _run(paper)
    annealed = _run(paper, **ANNEALED)
    assert annealed.converged
    assert all("concentrated" in s.message for s in annealed.steps)
    data, c, w = paper.dataset, paper.dataset.c, float(paper.volumes[0])
    tol = TOL * data_spread(paper)
    rtol = EXACT_PROJECTION_RTOL
    u_tol = rtol * paper.scales["displacement"] + paper.length * tol / np.sqrt(c)
    p_tol = rtol * paper.scales["stress"] + np.sqrt(c) * tol
    energy = build_problems(paper).scales("mpcc")["energy"]
    for s, ref in zip(annealed.steps, plain.steps):
        j = int(s.data_index[0])
        assert s.strain_star[0] == pytest.approx(data.strain[j], rel=1e-12)
        assert s.stress_star[0] == pytest.approx(data.stress[j], rel=1e-12, abs=1e-12 * paper.scales["stress"])
        u_ex, p_ex, _ = paper.projection_closed_form(s.step, data.strain[j], data.stress[j])
        assert abs(s.u[0] - u_ex) <= u_tol and abs(s.p[0] - p_ex) <= p_tol
        d2 = c * (s.strain[0] - data.strain) ** 2 + (s.stress[0] - data.stress) ** 2 / c
        assert d2[j] <= d2.min() * (1 + 1e-12) + 1e-300
        d = np.sqrt(2 * ref.global_distance / w)
        assert abs(s.distance - ref.global_distance) <= w * (d * tol + tol**2 / 2) + ROUNDOFF * energy
        if ref.global_optimum:
            assert j == int(ref.data_index[0])
    assert [s.load_parameter for s in plain.steps if s.global_optimum is False] == [pytest.approx(0.992)]


def test_annealed_on_a_continuum_ends_at_a_plain_ddcm_fixed_point():
    """Plane strain (three components per point, a matrix metric): the concentrated state's data
    are the nearest to it, and projecting them onto Z_E again reproduces it, within what the
    last update moved the material states (each point by at most ``tol = TOL x spread`` in the
    metric, so ``sqrt(sum_i w_i d_i^2) <= sqrt(sum w) tol`` for a projection onto a convex branch)
    and the solver's accuracy (EXACT_PROJECTION_RTOL of the same scale)."""
    C = isotropic_elasticity(E, NU, 2)[0]
    model = _indented(2, data=MaterialDataset.hookean_grid(C, -5e-4, 5e-4, 9, c=Metric(C)))
    r = _run(model, **ANNEALED)
    assert r.converged and all("concentrated" in s.message for s in r.steps)
    problems = build_problems(model)
    solver = DDCMSolver(problems, formulations.get(FB).build(problems.projection))
    data, warm = model.dataset, (np.zeros(problems.projection.n_x), np.zeros(problems.projection.n_pairs), None)
    bound = np.sqrt(np.sum(model.volumes)) * (TOL + EXACT_PROJECTION_RTOL) * data_spread(model)
    for s in r.steps:
        index = data.nearest(s.strain, s.stress)
        assert np.array_equal(index, s.data_index)
        sol, _, _, failed = solver.project_data(s.step, data.strain[index], data.stress[index], warm,
                                                dict(inner=0, t_project=0.0))
        assert not failed
        f = problems.fields("mpcc", sol.x, sol.p)
        d2 = data.metric.distance2(f["strain"] - s.strain, f["stress"] - s.stress)
        assert np.sqrt(np.dot(model.volumes, d2)) <= bound, s.step
