"""Models that describe themselves: a new model kind needs no change to any front end.

A tiny kind defined here (two springs in series against a moving obstacle) runs through the
harness (:func:`compare`, rows, fields, summary) and the CLI's records (parameters, fields, JSON);
and the front ends carry no type checks on model classes and no formulation internals.
"""

from __future__ import annotations

import ast
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from ddcm_casadi import MaterialDataset, compare
from ddcm_casadi import run
from ddcm_casadi.casefiles.config import Case
from ddcm_casadi.io import write_json_atomic
from ddcm_casadi.models.base import ContactModel

E, A, L = 200e9, 1e-4, 1.0
POSITIONS = np.array([1.004, 1.0, 0.998, 0.995, 0.99])  # tip obstacle x = h, one per step


@dataclass(frozen=True, eq=False)
class SpringPair(ContactModel):
    """Two equal springs in series (each ``L / 2``), fixed at ``x = 0``; the tip meets a rigid
    obstacle at ``x = h``: gap ``g = (h - L) - u_tip``. Unknowns ``(u_mid, u_tip)``."""

    def closed_form(self, step: int):
        """``u_tip = min(0, w)`` with ``w = h - L``, the middle node halfway, ``p = -E u_tip / L``."""
        w = self.gap_offsets[step, 0]
        tip = min(0.0, w)
        return np.array([0.5 * tip, tip]), np.array([-E * tip / L])

    def describe(self) -> dict:
        return dict(name=self.name, kind="two springs in series", springs=self.n_points,
                    positions=self.load_parameter.tolist())

    def extra_fields(self, u: np.ndarray, stress: np.ndarray) -> dict:
        return dict(spring_force=A * np.asarray(stress))


def spring_pair(*, dataset: MaterialDataset | None = None) -> SpringPair:
    """The kind's builder: sparse ``B`` (strains from nodal displacements) and ``G`` (the gap)."""
    half = 0.5 * L
    B = sp.csr_matrix(np.array([[1.0, 0.0], [-1.0, 1.0]]) / half)
    G = sp.csr_matrix(np.array([[0.0, -1.0]]))
    n = POSITIONS.size
    return SpringPair(strain_operator=B, volumes=np.full(2, A * half), gap_operator=G, contact_area=np.array([A]),
                      gap_offsets=(POSITIONS - L)[:, None], loads=np.zeros((n, 2)), load_parameter=POSITIONS,
                      youngs_modulus=np.full(2, E), dataset=dataset, length_scale=L, name="spring pair",
                      load_parameter_name="h")


@pytest.fixture(scope="module")
def cmp():
    data = MaterialDataset.hookean(E, -0.02, 0.01, 301, c=1.5 * E)
    return compare(spring_pair(dataset=data), ["fischer_burmeister", "penalty"])


def test_new_kind_runs_through_the_harness(cmp):
    assert set(cmp.results) == {(v, f) for v in ("classical", "ddcm") for f in ("fischer_burmeister", "penalty")}
    assert all(r.converged for r in cmp.results.values())
    fb = cmp.errors("classical", "fischer_burmeister")
    assert max(fb["u"].max(), fb["p"].max()) < 1e-8
    # No penalty closed form on this kind: the penalty run is compared with the exact solution,
    # and its error is the penalty's (E/l) / (E/l + gamma), about 1e-4 with the default gamma.
    pen = cmp.errors("classical", "penalty")
    assert 1e-6 < pen["u"].max() < 1e-3

    rows = cmp.rows()
    assert len(rows) == 4 * POSITIONS.size
    # Two unknowns: the rows summarise each step (ContactModel.step_summary) under the model's
    # load parameter name.
    assert {"h", "max_abs_u", "total_contact_force", "active_contacts", "error_u", "error_p"} <= set(rows[0])
    assert "u" not in rows[0] and "p" not in rows[0]
    last = [r for r in rows if r["variant"] == "classical" and r["formulation"] == "fischer_burmeister"][-1]
    assert last["active_contacts"] == 1
    assert last["max_abs_u"] == pytest.approx(L - POSITIONS[-1], rel=1e-9)
    assert last["total_contact_force"] == pytest.approx(A * E * (L - POSITIONS[-1]) / L, rel=1e-9)

    f = cmp.fields("ddcm", "fischer_burmeister")
    assert f["u"].shape == (POSITIONS.size, 2) and f["strain"].shape == (POSITIONS.size, 2)
    assert "nodal_displacement" not in f
    np.testing.assert_allclose(f["spring_force"], A * f["stress"])  # the kind's own field
    assert {"strain_star", "stress_star", "data_index"} <= set(f)

    summary = {(s["variant"], s["formulation"]): s for s in cmp.summary()}
    assert summary["classical", "fischer_burmeister"]["max_error_u"] < 1e-8
    assert "max_error_u_vs_exact" not in summary["classical", "penalty"]  # compared with the exact one already
    assert summary["ddcm", "penalty"]["converged_steps"] == POSITIONS.size
    assert "errors: max over steps" in cmp.table()


def test_new_kind_runs_through_the_cli_records(cmp, tmp_path):
    case = Case(model=cmp.model, source="test kind")
    params = run.parameters(case, cmp)
    assert params["case"] == "test kind"
    assert params["kind"] == "two springs in series" and params["springs"] == 2  # its own describe()
    assert params["positions"] == POSITIONS.tolist()
    assert params["data"]["points"] == 301 and params["data"]["c"] == 1.5 * E
    assert params["formulations"]["penalty"]["gamma_used"] > 0  # resolved options
    assert "gamma_used" not in params["formulations"]["fischer_burmeister"]
    per_step = run.fields(cmp)
    assert set(per_step) == {f"{v}/{f}" for v, f in cmp.results}

    doc = run.results_document(case, cmp, files=["results.csv", "results.json"])
    assert doc["parameters"] == params and doc["fields"].keys() == per_step.keys()
    write_json_atomic(tmp_path / "results.json", doc)
    back = json.loads((tmp_path / "results.json").read_text())
    assert back["parameters"] == json.loads(json.dumps(params))  # tuples of options become lists
    fields = back["fields"]["ddcm/fischer_burmeister"]
    assert np.asarray(fields["spring_force"]).shape == (POSITIONS.size, 2)
    assert np.asarray(fields["u"]).shape == (POSITIONS.size, 2)


def test_new_kind_without_figures_of_its_own(cmp, tmp_path):
    """The figures are the kind's choice: the base draws the contact-force history (it works for
    any kind), and outputs.save_figures draws what the model declares."""
    from ddcm_casadi.outputs.save import save_figures
    from ddcm_casadi.outputs.plots import figure_contact_history

    assert [p.name for p in save_figures(cmp, tmp_path)] == ["contact_history.png"]
    assert (tmp_path / "contact_history.png").stat().st_size > 0
    fig = figure_contact_history(cmp)  # the generic figure works for any kind
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert "pair 0" in labels and "closed form" in labels


# --------------------------------------------------------------------- front ends carry no type checks
FRONT_ENDS = ("drivers/harness.py", "commands/compare.py", "outputs/plots.py", "outputs/bar_figures.py",
              "outputs/truss_figures.py", "outputs/contact_history.py", "outputs/marks.py", "casefiles/config.py",
              "run.py", "outputs/save.py")
MODEL_CLASSES = {"BarModel", "TrussModel", "StoppedBarModel"}
PACKAGE = Path(__file__).resolve().parent.parent / "ddcm_casadi"


def _names(node: ast.AST) -> set[str]:
    """Every name and attribute mentioned in ``node``."""
    out = set()
    for n in ast.walk(node):
        if isinstance(n, ast.Name):
            out.add(n.id)
        elif isinstance(n, ast.Attribute):
            out.add(n.attr)
    return out


@pytest.mark.parametrize("module", FRONT_ENDS)
def test_front_ends_have_no_model_type_checks(module):
    tree = ast.parse((PACKAGE / module).read_text(encoding="utf-8"))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            if node.func.id in ("isinstance", "issubclass") and _names(node) & MODEL_CLASSES:
                found.append(f"line {node.lineno}: {node.func.id} on a model class")
            if node.func.id == "hasattr":
                found.append(f"line {node.lineno}: hasattr")
            if node.func.id == "type" and _names(node) & {"model", "m"}:
                found.append(f"line {node.lineno}: type() of a model")
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "gamma":
            found.append(f"line {node.lineno}: .gamma(...)")
        if isinstance(node, ast.ImportFrom) and {a.name for a in node.names} & MODEL_CLASSES:
            found.append(f"line {node.lineno}: imports a model class")
        if isinstance(node, ast.Compare) and any(isinstance(c, ast.Constant) and c.value == "penalty"
                                                 for c in [node.left, *node.comparators]):
            found.append(f"line {node.lineno}: compares with the name 'penalty'")
    assert not found, f"{module}: " + "; ".join(found)
