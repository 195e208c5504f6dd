"""The DDCM driver's one alternation loop: pluggable material-update schemes, the physical
checks run by the loop for every scheme, options from one validated object, and the methods
that need an affine problem skipped (with a note) when it is not."""

import dataclasses

import numpy as np
import pytest

from ddcm_casadi import compare, formulations, paper_bar
from ddcm_casadi.errors import InputError
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.validation.quality_rungs import noisy_dataset
from ddcm_casadi.drivers.ddcm import DDCMSolver
from ddcm_casadi.drivers.ddcm_options import DDCMOptions
from ddcm_casadi.drivers.records import MaterialStates
from ddcm_casadi.drivers.scheme import MaterialScheme, Update
from ddcm_casadi.drivers.schemes import SCHEMES
from ddcm_casadi.models.truss import bar_chain

FB = "fischer_burmeister"


def _solver(model, **options):
    problems = build_problems(model)
    return DDCMSolver(problems, formulations.get(FB).build(problems.projection), options=DDCMOptions(**options))


def _chain():
    return bar_chain(length=1.0, elements=2, youngs_modulus=200e9, tip_positions=np.linspace(1.002, 0.99, 4),
                     dataset=noisy_dataset(0.05, 1, n_data=60), name="noisy chain")


def test_schemes_are_registered_by_variant():
    assert set(SCHEMES) == {"plain", "lcdd", "maxent"}
    assert [SCHEMES[v].assigns_data for v in ("plain", "lcdd", "maxent")] == [True, False, False]
    assert all(issubclass(s, MaterialScheme) for s in SCHEMES.values())


@pytest.mark.parametrize("variant", ["plain", "lcdd", "maxent"])
def test_the_loop_finishes_every_step_of_every_scheme(variant):
    """The physical checks and the data's range run in the loop, without a progress callback:
    every step has its data spacing, its nearest datum and no roundoff pressures."""
    path = _solver(_chain(), variant=variant).solve()
    assert path.converged and path.warnings == []
    for s in path.steps:
        assert np.isfinite(s.data_spacings) and s.data_index.shape == (2,)
        assert np.all((s.p == 0) | (s.p > 1e-9)) and s.notes == ""


def test_a_new_scheme_plugs_into_the_same_loop():
    """A scheme is one small object: this one is the nearest datum without the search backend
    (brute force), so it must reproduce plain DDCM's path exactly."""

    class BruteForce(MaterialScheme):
        name = "brute"
        assigns_data = True

        def begin(self, start):
            self.index = start.index

        def update(self, strain, stress):
            data = self.model.dataset
            d2 = [data.distance2(strain, stress, np.full(strain.size, j)) for j in range(len(data))]
            new = np.argmin(np.array(d2), axis=0).astype(np.intp)
            done = np.array_equal(new, self.index)
            self.index = new
            return Update(self.states(new), done=done, converged=done, message="fixed point" if done else "")

        def distance2(self, strain, stress, star: MaterialStates):
            return self.model.dataset.distance2(strain, stress, star.index)

    model = paper_bar()
    plain = _solver(model, exact_max=0).solve()
    solver = _solver(model)
    solver.scheme = BruteForce(model, solver.options)
    brute = solver.solve()
    for field in ("data_index", "outer_iterations", "u", "p", "distance"):
        np.testing.assert_array_equal(brute.array(field), plain.array(field), err_msg=field)


def test_options_are_one_validated_object():
    model = paper_bar()
    solver = _solver(model, search="warm", max_outer=7)
    assert solver.options.search == "graph" and solver.max_outer == 7
    problems = build_problems(model)
    built = formulations.get(FB).build(problems.projection)
    assert DDCMSolver(problems, built, search="kdtree", options=DDCMOptions(search="graph")).search == "kdtree"
    with pytest.raises(InputError, match="max_outer must be an integer in 2..1000000"):
        DDCMSolver(problems, built, max_outer=1)
    with pytest.raises(InputError, match=r"^unknown data search 'fast'; known: kdtree, graph"):
        compare(model, [FB], variants=["ddcm"], ddcm={"search": "fast"})
    with pytest.raises(InputError, match="write it without a decimal point"):
        DDCMOptions(max_outer=1e3)
    r = compare(model, [FB], variants=["ddcm"], ddcm={"search": "graph", "max_outer": 50})["ddcm", FB]
    assert r.converged


def test_methods_that_need_an_affine_problem_are_skipped_with_a_note(monkeypatch):
    """On a problem that is not affine the exact enumeration (and the global optimum), the greedy
    screen and the elastic start are left out, and every step and the path say so."""
    model = _chain()
    monkeypatch.setattr(ComplementarityProblem, "affine", property(lambda self: False))
    solver = _solver(model, start="elastic", improve="greedy", exact_max=10**6)
    assert solver.exact is None and not solver.global_search
    path = solver.solve()
    assert len(path.warnings) == 3 and all("not affine" in w for w in path.warnings)
    assert path.converged
    for s in path.steps:
        assert s.notes == "; ".join(path.warnings)
        assert s.projection_global is None and s.global_optimum is None
    origin = dataclasses.replace(solver.options, start="origin")
    assert np.array_equal(solver.initial_assignment(0),
                          _solver(model, **{f: getattr(origin, f) for f in ("start", "improve")}).initial_assignment(0))
