"""DDCM search options: starts, restarts, greedy improvement, certificates and LCDD.

Reference values come from independent routes: the classical closed form of the paper's bar,
brute-force enumeration of every data assignment through the per-column exact projection
(:meth:`ExactEnumerator.solve`, one parameter column per assignment), and repeated runs.
"""

import itertools
import json

import numpy as np
import pytest

from ddcm_casadi import compare, formulations, paper_bar
from ddcm_casadi.commands.compare import main
from ddcm_casadi.casefiles.config import load_case
from ddcm_casadi.errors import InputError
from ddcm_casadi.problems.exact import ExactEnumerator
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.validation.quality_rungs import noisy_dataset, noisy_paper_bar
from ddcm_casadi.drivers.ddcm_options import DDCMOptions
from ddcm_casadi.drivers import ddcm as ddcm_driver
from ddcm_casadi.drivers.ddcm_search import (
    descent_threshold, elastic_state, random_assignment, single_moves, tolerant_argsort,
)
from ddcm_casadi.drivers.ddcm_projection import Projection
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.validation import ladder
from ddcm_casadi.drivers.path import DDCMSolver
from ddcm_casadi.models import truss
from ddcm_casadi.models.truss import bar_chain

FB = "fischer_burmeister"
#: Roundoff of a distance: the enumerator expands quadratics whose terms are O(1) in scaled units.
ROUNDOFF = 1e-9


def _run(model, **options):
    return compare(model, [FB], variants=("ddcm",), ddcm=DDCMOptions(**options))["ddcm", FB]


def _chain(noise: float, seed: int, *, elements: int = 2, n_data: int = 30):
    """An N-element bar pushed 1 % into contact, on noisy data (few elements: enumerable)."""
    data = noisy_dataset(noise, seed, n_data=n_data)
    return bar_chain(length=1.0, elements=elements, youngs_modulus=200e9,
                     tip_positions=np.linspace(1.002, 0.99, 5), dataset=data, name="noisy chain")


# ------------------------------------------------------------------------------- bad option values
@pytest.mark.parametrize("bad, key", [
    (dict(start="elastc"), "start"), (dict(improve="best"), "improve"), (dict(restarts=-1), "restarts"),
    (dict(restarts=1.5), "restarts"), (dict(seed=True), "seed"), (dict(warm="yes"), "warm"),
    (dict(initial=[0, -1]), "initial"), (dict(initial="0"), "initial"), (dict(variant="maxent2"), "variant"),
    (dict(lcdd_neighbours=1), "lcdd_neighbours"), (dict(greedy_budget=0), "greedy_budget"),
    # max-ent (tests/test_maxent.py)
    (dict(maxent_neighbours=1), "maxent_neighbours"), (dict(maxent_neighbours=5000), "maxent_neighbours"),
    (dict(maxent_neighbours=2.5), "maxent_neighbours"), (dict(maxent_steps=0), "maxent_steps"),
    (dict(maxent_steps=201), "maxent_steps"), (dict(maxent_steps=True), "maxent_steps"),
    (dict(maxent_beta_growth=1), "maxent_beta_growth"), (dict(maxent_beta_growth=0.5), "maxent_beta_growth"),
    (dict(maxent_beta_growth="2"), "maxent_beta_growth"), (dict(maxent_beta_growth=float("nan")), "maxent_beta_growth"),
    (dict(maxent_beta_growth=float("inf")), "maxent_beta_growth"), (dict(maxent_beta_growth=True), "maxent_beta_growth"),
    (dict(variant="maxent", restarts=1), "does not combine"), (dict(variant="maxent", improve="greedy"), "does not combine"),
])
def test_bad_options_are_one_line_errors(bad, key):
    with pytest.raises(InputError) as exc:
        DDCMOptions(**bad)
    assert key in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(InputError):  # and through compare, as a mapping, before any work
        compare(paper_bar(n_data=20), [FB], variants=("ddcm",), ddcm=bad)


def test_unknown_option_and_bad_initial_assignment():
    with pytest.raises(InputError, match="unknown ddcm option 'restart'"):
        compare(paper_bar(n_data=20), [FB], variants=("ddcm",), ddcm={"restart": 2})
    with pytest.raises(InputError, match="initial has 2 indices"):
        _run(paper_bar(n_data=20), initial=(1, 2))
    with pytest.raises(InputError, match="outside"):
        _run(paper_bar(n_data=20), initial=(20,))


CASE = """[bar]
length = 1.0
youngs_modulus = 200e9

[obstacle]
positions = [1.01, 1.0, 0.995, 0.99]

[data]
hookean = { strain_min = -0.05, strain_max = 0.01, points = 200 }

[ddcm]
c = 300e9
"""


@pytest.mark.parametrize("extra, key", [('start = "warm"', "start"), ("restarts = -2", "restarts"),
                                        ('improve = "greedy "', "improve"), ("seed = 1.0", "seed"),
                                        ("initial = [1.5]", "initial")])
def test_bad_case_file_values(tmp_path, capsys, extra, key):
    cfg = tmp_path / "case.toml"
    cfg.write_text(CASE + extra + "\n", encoding="utf-8")
    with pytest.raises(InputError, match=rf"^\[ddcm\] {key}"):
        load_case(cfg)
    out = tmp_path / "out"
    assert main(["--config", str(cfg), "--out", str(out), "-q", "--no-plots", "--formulations", FB]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"[ddcm] {key}" in err
    assert not out.exists() or not any(out.iterdir())


def test_options_recorded_in_results_json(tmp_path, capsys):
    cfg = tmp_path / "case.toml"
    cfg.write_text(CASE + 'start = "elastic"\nrestarts = 1\nseed = 3\nimprove = "greedy"\n', encoding="utf-8")
    case = load_case(cfg)
    assert case.ddcm_options == DDCMOptions(start="elastic", restarts=1, seed=3, improve="greedy")
    out = tmp_path / "out"
    assert main(["--config", str(cfg), "--out", str(out), "-q", "--no-plots", "--formulations", FB]) == 0
    doc = json.loads((out / "results.json").read_text())
    assert doc["parameters"]["ddcm"] == case.ddcm_options.describe()
    ddcm = next(s for s in doc["summary"] if s["variant"] == "ddcm")
    # every step ran its own run and one restart, at least one projection each
    assert ddcm["projections"] >= 2 * case.model.n_steps


# ------------------------------------------------------------------------------------------ starts
def test_elastic_state_is_the_classical_solution_when_the_metric_is_the_modulus():
    """With c = E the linear problem of the elastic start is the classical one (closed form)."""
    model = paper_bar(c=200e9)
    for k in range(model.n_steps):
        u, strain, stress = elastic_state(model, k)
        u_ex, p_ex = model.closed_form(k)
        assert u[0] == pytest.approx(u_ex[0], rel=1e-9, abs=1e-12 * model.length)
        assert stress[0] == pytest.approx(-p_ex[0], rel=1e-9, abs=1e-9 * model.scales["stress"])


def test_starts_and_explicit_initial_assignment():
    model = paper_bar()
    data = model.dataset
    _, strain, stress = elastic_state(model, 0)
    j_el = int(data.nearest(strain, stress)[0])
    built = formulations.get(FB).build(build_problems(model).projection)
    problems = build_problems(model)
    r = DDCMSolver(problems, built, options=DDCMOptions(start="elastic")).solve()
    # h = 1.01: the bar is free, the elastic state is the origin's and both start there.
    assert int(r.steps[0].data_index[0]) == j_el == int(data.nearest([0.0], [0.0])[0])
    default = DDCMSolver(problems, built).solve()
    same = DDCMSolver(problems, built, options=DDCMOptions(initial=(j_el,))).solve()
    assert np.array_equal(same.array("data_index"), default.array("data_index"))
    j = 123
    r = DDCMSolver(problems, built, options=DDCMOptions(initial=(j,))).solve()
    # A free bar keeps eps* and drops its stress: the walk leaves datum j (strain -0.035) and
    # ends at a fixed point between it and the origin.
    s0 = r.steps[0]
    assert s0.outer_iterations > 1 and data.strain[j] < s0.strain_star[0] <= 0.0
    assert int(data.nearest(s0.strain, s0.stress)[0]) == int(s0.data_index[0])


# ------------------------------------------------------------------------- reproducibility, descent
def test_seeded_runs_are_reproducible():
    model = noisy_paper_bar(0.02, 4, n_data=200)
    opts = dict(start="random", restarts=2, seed=11, improve="greedy", greedy_screen=False)
    a, b = _run(model, **opts), _run(model, **opts)
    assert np.array_equal(a.array("data_index"), b.array("data_index"))
    assert np.array_equal(a.array("distance"), b.array("distance"))
    assert np.array_equal(a.array("projections"), b.array("projections"))
    c = _run(model, **{**opts, "seed": 12})
    assert not np.array_equal(a.array("projections"), c.array("projections"))  # the seed matters


@pytest.mark.parametrize("screen", [True, False])
@pytest.mark.parametrize("model", [noisy_paper_bar(0.05, 1, n_data=300), _chain(0.05, 2, elements=3, n_data=60)],
                         ids=["bar", "chain"])
def test_greedy_is_a_descent_method(model, screen):
    """Every step starts from the same assignment (warm=False), so the greedy search starts from
    plain alternating's fixed point and may only lower its objective."""
    plain = _run(model, warm=False)
    greedy = _run(model, warm=False, improve="greedy", greedy_screen=screen)
    assert greedy.converged and plain.converged
    d0, d1 = plain.array("distance"), greedy.array("distance")
    scale = model.scales_for("ddcm")["energy"]
    assert np.all(d1 <= d0 + ROUNDOFF * scale)
    improved = greedy.array("improvements") > 0
    assert np.all(d1[improved] < d0[improved])
    assert np.array_equal(d1[~improved], d0[~improved])
    assert improved.any()  # noisy data: some step had a better fixed point


def test_restarts_keep_the_lowest_objective():
    model = noisy_paper_bar(0.05, 3, n_data=300)
    plain = _run(model, warm=False)
    more = _run(model, warm=False, restarts=3, seed=5)
    assert np.all(more.array("distance") <= plain.array("distance"))
    assert np.all(more.array("runs") == 4)


# ----------------------------------------------------------------------------------- certificates
def _brute_force(problems, step, m, n):
    """Every data assignment's exact projection, one parameter column each: the global minimum."""
    data = problems.model.dataset
    combos = np.array(list(itertools.product(range(n), repeat=m))).T  # (m, n^m)
    P = problems.projection_params(step, data.strain[combos], data.stress[combos])
    ex = ExactEnumerator(problems.projection).solve(P, bordered=False)  # branch by branch: independent
    return float(np.min(ex.objective)) * problems.scales("mpcc")["energy"]


def test_single_moves_are_the_exact_projections_of_the_moved_assignments():
    """The screen's closed forms (only the moving points' directions) against the exact projection
    of each moved assignment solved directly; both are the same branch QPs, so they agree to roundoff."""
    from ddcm_casadi.drivers.ddcm_search import single_moves

    model = _chain(0.02, 3, elements=3, n_data=12)
    problems = build_problems(model)
    exact = ExactEnumerator(problems.projection)
    data, step = model.dataset, 4
    index = np.array([2, 5, 7])
    points, cand = np.array([0, 2]), np.array([[0, 4, 11], [1, 6, 9]])
    obj, mine = single_moves(problems, exact, step, index, points, cand)
    moved = np.repeat(index[:, None], cand.size, axis=1)
    for a, i in enumerate(points):
        moved[i, a * cand.shape[1]:(a + 1) * cand.shape[1]] = cand[a]
    direct = exact.solve(problems.projection_params(step, data.strain[moved], data.stress[moved]),
                         bordered=False).objective
    scale = max(1.0, float(np.max(np.abs(direct))))
    assert np.max(np.abs(obj.ravel() - direct)) <= ROUNDOFF * scale
    own = exact.solve(problems.projection_params(step, data.strain[index], data.stress[index]),
                      bordered=False).objective[0]
    assert abs(mine - own) <= ROUNDOFF * max(1.0, abs(own))


@pytest.mark.parametrize("given", ["assignment", "parameters"])
def test_closed_form_projection_is_the_exact_projection(given):
    """The closed-form projection from the step's solved directions, of an assignment
    (:func:`assignment_projection`: a greedy trial's first projection) or of a parameter vector
    (:func:`params_projection`: the check of a search's projection), against the exact projection
    solved directly for its parameters; a parameter vector outside the directions' family
    (another step's load) gets no closed form."""
    from ddcm_casadi.drivers.ddcm_search import assignment_projection, params_projection

    model = ladder.warren_truss(n_data=200)
    problems = build_problems(model)
    exact = ExactEnumerator(problems.projection)
    data, rng = model.dataset, np.random.default_rng(7)
    for step in (0, model.n_steps - 1):
        for _ in range(5):
            index = random_assignment(model, rng)
            params = problems.projection_params(step, data.strain[index], data.stress[index])
            x, p, obj = (assignment_projection(problems, exact, step, index) if given == "assignment"
                         else params_projection(problems, exact, step, params))
            ex = exact.solve(params)
            z, z_ref = np.concatenate([x, p]), np.concatenate([ex.x[:, 0], ex.p[:, 0]])
            assert np.max(np.abs(z - z_ref)) <= ROUNDOFF * max(1.0, float(np.max(np.abs(z_ref))))
            assert abs(obj - ex.objective[0]) <= ROUNDOFF * max(1.0, abs(ex.objective[0]))
        other = problems.projection_params((step + 1) % model.n_steps, data.strain[index], data.stress[index])
        assert params_projection(problems, exact, step, other) is None


def _random_params(model, problems, rng, count):
    """Projection parameters of ``count`` random data assignments over the load steps."""
    cols = []
    for j in range(count):
        index = random_assignment(model, rng)
        cols.append(problems.projection_params(j % model.n_steps, model.dataset.strain[index],
                                               model.dataset.stress[index]))
    return np.column_stack(cols)


@pytest.mark.parametrize("build", [ladder.stops_bar, ladder.warren_truss], ids=["stops bar", "truss"])
def test_bordered_form_is_the_branch_by_branch_enumeration(build):
    """One factorisation with every constraint imposed and 2 nc x 2 nc blocks per branch give the
    exact projections that factorising each branch's own KKT matrix gives (4 and 3 pairs)."""
    model = build()
    problems = build_problems(model)
    exact = ExactEnumerator(problems.projection)
    assert exact.bordered
    P = _random_params(model, problems, np.random.default_rng(3), 40)
    fast, reference = exact.solve(P), exact.solve(P, bordered=False)
    assert np.array_equal(fast.found, reference.found) and fast.found.all()
    z, z_ref = np.vstack([fast.x, fast.p]), np.vstack([reference.x, reference.p])
    assert np.max(np.abs(z - z_ref)) <= ROUNDOFF * max(1.0, float(np.max(np.abs(z_ref))))
    assert np.max(np.abs(fast.objective - reference.objective)) <= ROUNDOFF * max(1.0, float(np.max(reference.objective)))


@pytest.mark.parametrize("build", [ladder.stops_bar, ladder.warren_truss], ids=["stops bar", "truss"])
def test_pruned_screen_keeps_every_descending_move(build):
    """The screen's bound (the projection without contact constraints) leaves out only moves that
    cannot descend: the descending moves and their objectives are those of the full screen, which
    equal the branch-by-branch family's."""
    model = build(n_data=300)
    problems = build_problems(model)
    exact = ExactEnumerator(problems.projection)
    rng = np.random.default_rng(5)
    step = model.n_steps - 1
    points = np.arange(min(8, model.n_points))
    cand = np.repeat(np.arange(len(model.dataset))[None, :], points.size, axis=0)
    near = model.dataset.nearest(*_elastic_fields(model, problems, step))  # near a fixed point: few descend
    for index in (near, random_assignment(model, rng)):
        full, mine = single_moves(problems, exact, step, index, points, cand)
        pruned, mine_pruned = single_moves(problems, exact, step, index, points, cand, prune=True)
        assert mine_pruned == mine
        one_row, _ = single_moves(problems, exact, step, index, points, cand[:1], prune=True)  # shared, as one row
        assert np.array_equal(one_row, pruned)
        limit = descent_threshold(mine)
        assert np.array_equal(pruned < limit, full < limit)
        kept = np.isfinite(pruned)
        assert np.max(np.abs(pruned[kept] - full[kept]), initial=0.0) <= ROUNDOFF * max(1.0, abs(mine))
    assert (full < limit).any()  # a random assignment has descending moves
    # The bordered family against the branch-by-branch one: 40 random single moves from near, as
    # directions (c = the identity: one move each).
    data = model.dataset
    P0 = problems.projection_params(step, data.strain[near], data.stress[near])
    moved = np.repeat(near[:, None], 40, axis=1)
    moved[rng.integers(0, model.n_points, 40), np.arange(40)] = rng.integers(0, len(data), 40)
    D = problems.projection_params(step, data.strain[moved], data.stress[moved]) - P0[:, None]
    a, b = exact.affine_family(P0, D).best(np.eye(40)), exact.affine_family(P0, D, bordered=False).best(np.eye(40))
    assert np.all(np.isfinite(a)) and np.all(np.isfinite(b))
    assert np.max(np.abs(a - b)) <= ROUNDOFF * max(1.0, float(np.max(b)))


def _elastic_fields(model, problems, step):
    """The classical solution's strain and stress at ``step`` (an assignment near a fixed point)."""
    from ddcm_casadi.drivers.path import solve_classical

    r = solve_classical(problems, formulations.get(FB).build(problems.classical), FB)
    return r.steps[step].strain, r.steps[step].stress


def test_no_enumeration_for_problems_without_pairs(monkeypatch):
    """A projection without contact pairs is one linear solve: nothing to enumerate, reported
    global (convex) when it converges; with pairs the enumeration is built on first use only."""
    built_count = []
    original = ddcm_driver.ExactEnumerator

    def counting(*args, **kwargs):
        built_count.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(ddcm_driver, "ExactEnumerator", counting)
    device = bar_chain(length=1.0, elements=3, youngs_modulus=200e9, tip_displacements=[-0.001, -0.002],
                       dataset=noisy_dataset(0.0, 0, n_data=50))
    assert device.n_contacts == 0
    problems = build_problems(device)
    path = DDCMSolver(problems, formulations.get(FB).build(problems.projection)).solve()
    assert path.converged and not built_count
    assert all(s.projection_global is True and np.isnan(s.projection_error) for s in path.steps)
    problems = build_problems(paper_bar())
    solver = DDCMSolver(problems, formulations.get(FB).build(problems.projection))
    assert not built_count  # not at set-up
    path = solver.solve()
    assert built_count == [1] and all(s.projection_global for s in path.steps)


@pytest.mark.parametrize("elements, n_data", [(1, 200), (2, 30), (3, 10)])
def test_certificate_against_brute_force(elements, n_data):
    model = _chain(0.02, 7, elements=elements, n_data=n_data)
    r = _run(model, exact_max=n_data ** elements)
    problems = build_problems(model)
    tol = ROUNDOFF * problems.scales("mpcc")["energy"]
    for s in r.steps:
        best = _brute_force(problems, s.step, elements, n_data)
        assert s.global_distance == pytest.approx(best, rel=1e-9, abs=tol)
        assert s.global_gap == pytest.approx(s.distance - best, abs=2 * tol)
        assert s.global_optimum == bool(s.distance <= best + tol)


def test_no_certificate_beyond_exact_max():
    r = _run(_chain(0.02, 7, elements=2, n_data=30), exact_max=899)
    assert all(s.global_optimum is None for s in r.steps)


def test_tolerant_argsort_breaks_near_ties_by_position():
    """Values within the tolerance of their sorted neighbour keep their positions' order, whatever
    their last bits; values farther apart are sorted."""
    values = np.array([3.0, 1.0 + 1e-15, 2.0, 1.0, 1.0 - 1e-15, 0.5])
    assert tolerant_argsort(values, 1e-12).tolist() == [5, 1, 3, 4, 2, 0]
    assert tolerant_argsort(values, 0.0).tolist() == [5, 4, 3, 1, 2, 0]
    assert tolerant_argsort(np.array([]), 1.0).size == 0


def _noisy_warren_truss(noise: float, seed: int, n_data: int = 2001):
    """The quality benchmark's noisy Warren truss (3 contacts, mirror-symmetric members) on fewer data."""
    data = noisy_dataset(noise, seed, n_data=n_data, c=200e9)
    scale = 0.004 / 0.05  # the paper's strains onto the truss's range
    return truss.warren_truss(panels=4, gap=0.002, contact_nodes=range(1, 4), load_factors=np.linspace(0.5, 3.0, 7),
                              dataset=MaterialDataset(data.strain * scale, data.stress * scale, 200e9),
                              name="noisy Warren truss")


@pytest.mark.parametrize("noise, seed", [(0.01, 2), (0.05, 0)])
def test_greedy_trials_reuse_the_screened_exact_projection(monkeypatch, noise, seed):
    """A greedy trial's first projection is the exact one the screen evaluated (no formulation
    solve): the same data assignments and objectives, to roundoff, as solving it with the
    formulation and checking it by enumeration, with fewer Newton iterations."""
    model = _noisy_warren_truss(noise, seed)
    opts = dict(restarts=1, restart_neighbours=10, improve="greedy")
    reused = _run(model, **opts)
    monkeypatch.setattr(Projection, "exact_solution", lambda self, params, state, known=None: None)  # the formulation's solve
    solved = _run(model, **opts)
    _assert_same_states(model, reused, solved)
    assert reused.array("improvements").sum() > 0  # trials ran
    assert reused.array("iterations").sum() < solved.array("iterations").sum()


def _assert_same_states(model, fast, reference):
    """Two paths of one search through the same states: the same data assignments and projection
    counts, objectives equal to roundoff."""
    assert fast.converged and reference.converged
    assert np.array_equal(fast.array("data_index"), reference.array("data_index"))
    assert np.array_equal(fast.array("projections"), reference.array("projections"))
    d0, d1 = reference.array("distance"), fast.array("distance")
    assert np.max(np.abs(d1 - d0)) <= ROUNDOFF * model.scales_for("ddcm")["energy"]


@pytest.mark.parametrize("noise, seed", [(0.01, 2), (0.05, 0)])
def test_search_checks_from_closed_forms_give_the_same_states(monkeypatch, noise, seed):
    """Restarts and greedy trials check their formulation solves against the step's closed forms
    (``Projection.closed_form``) instead of a solve with the bordered matrix: the same data
    assignments, projections and objectives (to roundoff) as checking with the enumerator's solve."""
    model = _noisy_warren_truss(noise, seed)
    opts = dict(restarts=1, restart_neighbours=10, improve="greedy")
    calls = []
    closed = DDCMSolver._closed_form

    def counted(self, k):
        form = closed(self, k)

        def answer(params):
            calls.append(form(params))
            return calls[-1]
        return answer

    monkeypatch.setattr(DDCMSolver, "_closed_form", counted)
    fast = _run(model, **opts)
    assert sum(c is not None for c in calls) > 20  # the closed forms answered the search's checks
    monkeypatch.setattr(DDCMSolver, "_closed_form", lambda self, k: None)  # the enumerator's solve
    _assert_same_states(model, fast, _run(model, **opts))


def test_greedy_reaches_the_enumerated_optimum_on_one_element():
    """On one element the screened moves cover the whole data set: every step is certified."""
    for seed in range(3):
        r = _run(noisy_paper_bar(0.05, seed, n_data=300), improve="greedy")
        assert all(s.global_optimum for s in r.steps)


# ------------------------------------------------------------------------------------------- LCDD
@pytest.mark.parametrize("noise", [0.02, 0.05])
def test_lcdd_is_closer_to_the_law_than_plain_ddcm_on_noisy_data(noise):
    """Mean over seeded data sets of the max relative error of p against the noise-free classical
    closed form: LCDD averages its neighbours' noise, plain DDCM takes one noisy datum."""
    errs = {"plain": [], "lcdd": []}
    for seed in range(4):
        model = noisy_paper_bar(noise, seed)
        for name, opts in (("plain", {}), ("lcdd", dict(variant="lcdd"))):
            cmp = compare(model, [FB], variants=("ddcm",), ddcm=DDCMOptions(**opts))
            r = cmp["ddcm", FB]
            # Plain DDCM and LCDD at 2 % settle at every step; at 5 % LCDD may leave a step unsettled
            # (reported as not converged, measured: one step in three of four seeds). Errors are
            # compared on the steps that converged.
            assert r.converged or (name == "lcdd" and noise > 0.02)
            ok = np.array([s.converged for s in r.steps])
            assert ok.sum() >= len(ok) - 1
            errs[name].append(float(np.max(cmp.errors("ddcm", FB)["p"][ok])))
    mean = {k: np.mean(v) for k, v in errs.items()}
    assert mean["lcdd"] < mean["plain"], mean


def test_lcdd_refuses_what_it_cannot_do():
    with pytest.raises(InputError, match="does not combine"):
        _run(paper_bar(n_data=20), variant="lcdd", restarts=1)
