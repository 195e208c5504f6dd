"""The four things the core is built to be extended with, each added in one place and used by the
unchanged drivers: a search backend, a formulation, a model kind, a contact law. (The model kind:
``tests/test_model_kinds.py``; the contact law and a formulation's declared support:
``tests/test_seams.py``.)"""

from __future__ import annotations

import numpy as np
import pytest

from ddcm_casadi import compare, paper_bar
from ddcm_casadi.data.search import SEARCHES, NeighbourSearch
from ddcm_casadi.drivers.ddcm_options import DDCMOptions
from ddcm_casadi.formulations.fischer_burmeister import FischerBurmeister


class BruteForceSearch(NeighbourSearch):
    """Exact nearest data by computing every distance: the simplest backend there is."""

    name = "brute_force_test"

    def __init__(self, points: np.ndarray) -> None:
        self._points = points

    @classmethod
    def build(cls, points, *, base=None):
        return cls(points)

    @property
    def points(self) -> np.ndarray:
        return self._points

    def k_nearest(self, queries, k: int) -> np.ndarray:
        d2 = ((np.asarray(queries)[:, None, :] - self._points[None, :, :]) ** 2).sum(axis=2)
        return np.argsort(d2, axis=1, kind="stable")[:, :k]

    def nearest(self, queries, *, previous=None, stats=None) -> np.ndarray:
        return self.k_nearest(queries, 1)[:, 0]


def test_a_search_backend_is_one_class(monkeypatch):
    monkeypatch.setitem(SEARCHES, BruteForceSearch.name, BruteForceSearch)
    model = paper_bar(n_data=200)
    plain = compare(model, ["fischer_burmeister"], variants=("ddcm",))["ddcm", "fischer_burmeister"]
    brute = compare(model, ["fischer_burmeister"], variants=("ddcm",),
                    ddcm=DDCMOptions(search=BruteForceSearch.name))["ddcm", "fischer_burmeister"]
    np.testing.assert_array_equal(brute.array("data_index"), plain.array("data_index"))
    np.testing.assert_array_equal(brute.array("u"), plain.array("u"))
    assert BruteForceSearch.build(np.zeros((3, 2))).exact


def test_a_formulation_is_one_class():
    """A formulation with its own options runs through the harness unchanged (a registered one,
    ``formulations.register``, is then also reachable by name from case files)."""

    class LooseFB(FischerBurmeister):
        name = "loose_fb_test"

    cmp = compare(paper_bar(n_data=200), [LooseFB(tol=1e-6, residual_tol=1e-6)])
    assert {name for _, name in cmp.results} == {"loose_fb_test"}
    assert all(r.converged for r in cmp.results.values())


@pytest.mark.parametrize("name", ["kdtree", "graph"])
def test_builtin_backends_are_registered(name):
    assert SEARCHES[name].name == name
