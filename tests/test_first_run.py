"""The paper's first run made cheaper without changing it (issue 15, item 4).

- Work shared by the DDCM runs of the formulations of one model (the exact enumeration, its
  projections, the data's neighbourhoods) gives every run exactly what it computes alone.
- The remembered exact projections are copies and stay within their budget.
- Fig. 2's fixed layout keeps every text inside the figure and off the axis labels (it replaced
  constrained layout), also with longer tick labels than the paper's.
- The default run does not import what it does not use (scipy.optimize).
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from ddcm_casadi import bar_model, compare, formulations
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.data.extrapolation import DataCoverage
from ddcm_casadi.data import extrapolation
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.drivers.path import DDCMSolver

FIELDS = ("u", "p", "data_index", "distance", "projection_error", "projection_global", "global_optimum",
          "global_distance", "extrapolated", "data_spacings", "iterations", "outer_iterations", "converged")


@pytest.mark.parametrize("name", formulations.available())
def test_shared_work_gives_each_formulation_its_own_answer(paper, paper_comparison, name):
    """Each DDCM run of the all-formulation comparison (which reuses the exact projections and
    data neighbourhoods of the formulations before it) equals the run of that formulation alone."""
    alone = compare(paper, [name], variants=["ddcm"])
    shared, own = paper_comparison[("ddcm", name)], alone[("ddcm", name)]
    for field in FIELDS:
        np.testing.assert_array_equal(shared.array(field), own.array(field), err_msg=field)


def test_exact_projections_are_copies_within_budget(paper, monkeypatch):
    problems = build_problems(paper)
    built = formulations.get("fischer_burmeister").build(problems.projection)
    solver = DDCMSolver(problems, built)
    data = paper.dataset
    params = problems.projection_params(3, data.strain[[10]], data.stress[[10]])
    x, p, obj = solver.projection.exact_projection(params)
    x[:], p[:] = np.nan, np.nan  # a caller that writes into its answer cannot spoil the next one
    x2, p2, obj2 = solver.projection.exact_projection(params)
    ex = solver.exact.solve(params)
    np.testing.assert_array_equal(x2, ex.x[:, 0])
    np.testing.assert_array_equal(p2, ex.p[:, 0])
    assert obj2 == obj == float(ex.objective[0])
    # A second solver of the same problem shares the enumeration and its remembered answers.
    other = DDCMSolver(problems, formulations.get("mpcc").build(problems.projection))
    assert other.exact is solver.exact and other.coverage is solver.coverage

    budget = 3 * params.size  # room for two answers of (params, x, p)
    monkeypatch.setattr(DDCMSolver, "EXACT_CACHE_VALUES", budget)
    fresh = build_problems(paper)
    small = DDCMSolver(fresh, built)
    for j in range(10, 20):
        small.projection.exact_projection(fresh.projection_params(3, data.strain[[j]], data.stress[[j]]))
    cache = fresh.projection.shared(("exact_projections",), dict)
    assert 0 < cache["values"] <= budget
    assert len(cache["items"]) < 10


def test_remembered_neighbourhoods_give_the_same_check(monkeypatch):
    data = MaterialDataset.hookean(200e9, -0.005, 0.005, 200, c=200e9)
    rng = np.random.default_rng(4)
    strain = rng.uniform(-0.006, 0.006, 5)
    stress = 200e9 * strain + rng.normal(0.0, 1e6, 5)
    cov = DataCoverage(data, 5)
    first = cov.check(strain, stress)
    second = cov.check(strain, stress)  # from the remembered neighbourhoods
    monkeypatch.setattr(extrapolation, "_FEW", 0)
    direct = DataCoverage(data, 5).check(strain, stress)
    for a, b, c in zip(first, second, direct):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)


def _texts_inside(fig) -> None:
    """Everything drawn of ``fig``'s axes (ticks, labels, title, legend) is inside the figure, and
    the y tick labels clear the y label."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    W, H = canvas.get_width_height()
    ax = fig.axes[0]
    box = ax.get_tightbbox(renderer)  # what is drawn: ticks in view, labels, title, legend
    assert box.x0 >= -0.5 and box.y0 >= -0.5 and box.x1 <= W + 0.5 and box.y1 <= H + 0.5, box
    lo, hi = sorted(ax.get_ylim())
    labels = [t.label1.get_window_extent(renderer) for t in ax.yaxis.get_major_ticks()
              if lo <= t.get_loc() <= hi and t.label1.get_text()]
    assert labels
    assert ax.yaxis.label.get_window_extent(renderer).x1 <= min(b.x0 for b in labels)


def test_fig2_layout_keeps_texts_inside(paper_comparison):
    from ddcm_casadi.outputs import plots

    for draw in (plots.figure_displacement, plots.figure_pressure):
        _texts_inside(draw(paper_comparison))


def test_fig2_layout_widens_for_long_tick_labels():
    """A path of micrometres: tick labels of several digits (and a minus sign) still fit."""
    from ddcm_casadi.outputs import plots

    model = bar_model(length=1.0, youngs_modulus=200e9, positions=np.linspace(1.0 + 3e-7, 1.0 - 1.23e-6, 6))
    cmp = compare(model, ["fischer_burmeister"], variants=["classical"])
    for draw in (plots.figure_displacement, plots.figure_pressure):
        fig = draw(cmp)
        _texts_inside(fig)


def test_default_run_does_not_import_scipy_optimize(tmp_path):
    code = ("import sys; from ddcm_casadi.commands.compare import main; main(['--out', sys.argv[1], '-q']); "
            "print(sorted(m for m in sys.modules if m.startswith('scipy.optimize')))")
    proc = subprocess.run([sys.executable, "-c", code, str(tmp_path / "out")], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "[]"
