"""Case files for trusses and N-element bars (TOML and JSON), end to end through ``ddcm-compare``.

The example case files load and run, ``results.json`` carries the per-step nodal displacements and
contact forces, TOML and JSON of the same case give the same model, and bad input of the new
sections is refused with one line, exit status 2 and no output.
"""

from __future__ import annotations

import copy
import json
import math
import sys
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
import scipy.sparse as sp

from ddcm_casadi import formulations
from ddcm_casadi.models.bar import BarModel
from ddcm_casadi.commands.compare import EXIT_INPUT
from ddcm_casadi.casefiles.config import load_case
from ddcm_casadi.data.dataset import MaterialDataset, PointData
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.base import ContactModel
from ddcm_casadi.models.truss import StoppedBarModel, TrussModel

from .test_bad_input import assert_input_error, case_toml, run_cli

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

CASES = Path(__file__).resolve().parent.parent / "examples" / "cases"
EXAMPLES = ["bar_stops.toml", "truss2d.toml", "truss3d.json"]
FAST = ["-q", "--no-plots", "--formulations", "fischer_burmeister"]


# ------------------------------------------------------------------------------------------ helpers
def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(type(v).__name__)


def to_toml(doc: dict) -> str:
    """A TOML document for ``doc``: tables as sections, lists of tables as arrays of tables."""
    lines: list[str] = []
    for section, value in doc.items():
        if isinstance(value, list) and all(isinstance(t, dict) for t in value):
            for table in value:
                lines.append(f"[[{section}]]")
                lines += [f"{k} = {_toml_value(v)}" for k, v in table.items()]
        else:
            lines.append(f"[{section}]")
            lines += [f"{k} = {_toml_value(v)}" for k, v in value.items()]
        lines.append("")
    return "\n".join(lines)


def write_case(folder: Path, doc: dict, fmt: str, stem: str = "case") -> Path:
    path = folder / f"{stem}.{fmt}"
    path.write_text(json.dumps(doc) if fmt == "json" else to_toml(doc), encoding="utf-8")
    return path


def _same(a: Any, b: Any) -> bool:
    if sp.issparse(a) or sp.issparse(b):
        return sp.issparse(a) and sp.issparse(b) and a.shape == b.shape and np.array_equal(a.toarray(), b.toarray())
    if isinstance(a, (MaterialDataset, PointData)) or isinstance(b, (MaterialDataset, PointData)):
        if type(a) is not type(b) or not (_same(a.strain, b.strain) and _same(a.stress, b.stress)):
            return False
        if isinstance(a, PointData):
            return _same(a.material, b.material) and [d.c for d in a.datasets] == [d.c for d in b.datasets]
        return a.c == b.c
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b))
    return a == b


def assert_same_model(a: ContactModel, b: ContactModel) -> None:
    assert type(a) is type(b)
    for name in a.__dataclass_fields__:
        assert _same(getattr(a, name), getattr(b, name)), name


def triangle() -> dict:
    """A small valid 2-D truss case (the base of the bad-input cases)."""
    return {
        "structure": {
            "nodes": [[0.0, 0.0], [1.0, 0.0], [0.5, 0.8]],
            "members": [[0, 1], [1, 2], [0, 2]],
            "area": 1e-3,
            "youngs_modulus": 200e9,
            "supports": [[0, "xy"], [1, "y"]],
            "loads": [[2, [0.0, -1e5]]],
        },
        "path": {"load_factors": [0.0, 1.0, 2.0]},
        "obstacles": [{"normal": [0.0, 1.0], "offset": 0.7995, "nodes": [2]}],
        "data": {"hookean": {"strain_min": -0.01, "strain_max": 0.01, "points": 51}},
        "ddcm": {"c": 200e9},
    }


# --------------------------------------------------------------------------------- example files
@pytest.mark.parametrize("name", EXAMPLES)
def test_example_case_runs_and_writes_fields(tmp_path: Path, capsys, name: str) -> None:
    path = CASES / name
    model = load_case(path).model
    assert isinstance(model, TrussModel)
    out = tmp_path / "out"
    code, stdout, err = run_cli(["--config", str(path), "--out", str(out), *FAST], capsys)
    assert code == 0, err
    assert "NOT CONVERGED" not in stdout
    assert sorted(p.name for p in out.iterdir()) == ["results.csv", "results.json"]
    doc = json.loads((out / "results.json").read_text())
    params = doc["parameters"]
    assert params["n_dofs"] == model.n_dofs and params["n_contacts"] == model.n_contacts
    assert params["n_steps"] == model.n_steps and params["name"] == path.stem
    assert params["data"]["points"] == len(model.dataset)
    assert sorted(doc["fields"]) == ["classical/fischer_burmeister", "ddcm/fischer_burmeister"]
    n_nodes, dim = model.nodes.shape
    for run, fields in doc["fields"].items():
        disp = np.array(fields["nodal_displacement"], dtype=float)
        force = np.array(fields["contact_force"], dtype=float)
        assert disp.shape == (model.n_steps, n_nodes, dim), run
        assert force.shape == (model.n_steps, model.n_contacts), run
        assert np.all(np.isfinite(disp)) and np.all(np.isfinite(force)), run
        # Compressive contact only, to the formulation's complementarity tolerance (scaled pressure).
        comp_tol = formulations.get("fischer_burmeister").options.comp_tol
        assert np.all(force >= -comp_tol * model.scales["stress"] * model.contact_area), run
        assert np.any(force > 0), f"{run}: the example should make contact"
        assert np.array(fields["member_force"]).shape == (model.n_steps, model.n_points)
        assert all(fields["converged"])
    assert "strain_star" in doc["fields"]["ddcm/fischer_burmeister"]


def test_example_models() -> None:
    bar = load_case(CASES / "bar_stops.toml").model
    assert isinstance(bar, StoppedBarModel)
    assert (bar.n_dofs, bar.n_contacts, bar.n_steps) == (10, 4, 11)
    assert bar.contact_nodes.tolist() == [10, 3, 6, 8]
    assert np.allclose(bar.load_parameter, np.linspace(1.0, 0.98, 11))
    assert bar.dataset.c == 300e9 and len(bar.dataset) == 2000
    t2 = load_case(CASES / "truss2d.toml").model
    assert t2.nodes.shape == (9, 2) and t2.n_contacts == 3 and t2.n_steps == 7
    assert t2.contact_nodes.tolist() == [1, 2, 3]
    t3 = load_case(CASES / "truss3d.json").model
    assert t3.nodes.shape[1] == 3 and isinstance(t3.dataset, PointData)
    assert [d.c for d in t3.dataset.datasets] == [200e9, 70e9]
    # each Hookean set takes the modulus of the members using it
    assert np.allclose(t3.dataset.datasets[1].stress, 70e9 * t3.dataset.datasets[1].strain)


def test_paper_bar_has_no_fields(tmp_path: Path, capsys) -> None:
    """The one-unknown bar keeps results.json small and its parameters as before."""
    cfg = tmp_path / "case.toml"
    cfg.write_text(case_toml(), encoding="utf-8")
    out = tmp_path / "out"
    code, _, err = run_cli(["--config", str(cfg), "--out", str(out), *FAST], capsys)
    assert code == 0, err
    doc = json.loads((out / "results.json").read_text())
    assert "fields" not in doc
    assert {"length", "area", "youngs_modulus", "positions", "data"} <= set(doc["parameters"])
    assert isinstance(load_case(cfg).model, BarModel)


# ------------------------------------------------------------------------------- TOML == JSON
@pytest.mark.parametrize("name", EXAMPLES)
def test_toml_and_json_give_the_same_model(tmp_path: Path, name: str) -> None:
    src = CASES / name
    if src.suffix == ".toml":
        doc = tomllib.loads(src.read_text(encoding="utf-8"))
        other = write_case(tmp_path, doc, "json", stem=src.stem)
    else:
        doc = json.loads(src.read_text(encoding="utf-8"))
        other = write_case(tmp_path, doc, "toml", stem=src.stem)
    a, b = load_case(src), load_case(other)
    assert_same_model(a.model, b.model)
    assert a.formulation_options == b.formulation_options and a.ddcm_max_outer == b.ddcm_max_outer


def test_structure_options(tmp_path: Path) -> None:
    """1-D bare coordinates, per-member sections, distributed loads, per-step offsets."""
    doc = {
        "structure": {"nodes": [0.0, 1.0, 3.0], "members": [[0, 1], [1, 2]], "area": [1.0, 2.0],
                      "youngs_modulus": [100.0, 300.0], "supports": [[0, "x"]],
                      "loads": [[2, 5.0]], "distributed_loads": [["all", [1.0]], [1, [2.0]]]},
        "obstacles": [{"normal": [-1.0], "offsets": [-3.5, -3.0, -2.9], "nodes": [2]}],
    }
    for fmt in ("toml", "json"):
        m = load_case(write_case(tmp_path, doc, fmt)).model
        assert m.n_steps == 3 and m.load_parameter_name == "load step"
        assert m.youngs_modulus.tolist() == [100.0, 300.0] and m.dataset is None
        # q = 1 on both, +2 on member 1 (length 2): nodal 0.5, 0.5 + 3, 3 + load 5 (fixed node 0 dropped)
        assert np.allclose(m.loads, [[3.5, 8.0]] * 3)
        assert np.allclose(m.gap_offsets[:, 0], [0.5, 0.0, -0.1])  # g = -(3 + u) + 3.5, ...


def test_ddcm_only_structure(tmp_path: Path, capsys) -> None:
    """No youngs_modulus: the Hookean data give their own, and only the DDCM variant runs."""
    doc = triangle()
    del doc["structure"]["youngs_modulus"]
    doc["data"]["hookean"]["youngs_modulus"] = 200e9
    cfg = write_case(tmp_path, doc, "json")
    out = tmp_path / "out"
    code, _, err = run_cli(["--config", str(cfg), "--out", str(out), *FAST], capsys)
    assert code == 0, err
    fields = json.loads((out / "results.json").read_text())["fields"]
    assert list(fields) == ["ddcm/fischer_burmeister"]
    assert np.array(fields["ddcm/fischer_burmeister"]["nodal_displacement"]).shape == (3, 3, 2)


# ----------------------------------------------------------------------------------- bad input
def _set(path: str, value: Any) -> Callable[[dict], None]:
    """A mutation setting ``doc[a][b]...`` (integers index lists) to ``value``."""
    keys = [int(k) if k.isdigit() else k for k in path.split("/")]

    def apply(doc: dict) -> None:
        target = doc
        for k in keys[:-1]:
            target = target[k]
        target[keys[-1]] = value
    return apply


def _delete(path: str) -> Callable[[dict], None]:
    keys = path.split("/")

    def apply(doc: dict) -> None:
        target = doc
        for k in keys[:-1]:
            target = target[k]
        del target[keys[-1]]
    return apply


def _add_bar(doc: dict) -> None:
    doc["bar"] = {"length": 1.0, "youngs_modulus": 200e9}


def _two_data_sets(doc: dict) -> None:
    doc["data"] = [doc["data"], copy.deepcopy(doc["data"])]


def _coincident_node(doc: dict) -> None:
    doc["structure"]["nodes"].append([1.0, 0.0])
    doc["structure"]["members"].append([1, 3])


def _loose_contact_node(doc: dict) -> None:
    doc["structure"]["nodes"].append([2.0, 0.0])
    doc["structure"]["supports"].append([3, "xy"])
    doc["obstacles"][0]["nodes"] = [2, 3]


BAD = [
    pytest.param(_set("structure/nodez", 1), "unknown key 'nodez' in [structure]", id="unknown-key-structure"),
    pytest.param(_set("obstacles/0/ofset", 0.0), "unknown key 'ofset' in [obstacles 0]", id="unknown-key-obstacle"),
    pytest.param(_set("path/steps", 3), "unknown key 'steps' in [path]", id="unknown-key-path"),
    pytest.param(_set("structure/members/0", [0, 7]), "members[0]", id="member-node-out-of-range"),
    pytest.param(_set("structure/members/0", [0, 1.0]), "node index", id="member-node-not-integer"),
    pytest.param(_set("structure/members/0", [1, 1]), "zero length", id="member-same-node"),
    pytest.param(_coincident_node, "zero length", id="member-coincident-nodes"),
    pytest.param(_set("structure/nodes/1/0", float("nan")), "nodes[1]", id="coordinate-nan"),
    pytest.param(_set("structure/nodes/2/1", float("inf")), "nodes[2]", id="coordinate-inf"),
    pytest.param(_set("structure/nodes/1", [1.0, 0.0, 0.0]), "nodes[1] has 3 coordinates", id="coordinate-count"),
    pytest.param(_set("obstacles/0", {"normal": [0.0, 1.0], "offsets": [0.0, 0.1], "nodes": [2]}),
                 "offsets has 2 values but [path] load_factors has 3", id="offsets-length"),
    pytest.param(_set("obstacles/0/offsets", [0.0, 0.1, 0.2]), "exactly one of 'offset' or 'offsets'",
                 id="offset-and-offsets"),
    pytest.param(_set("structure/material", [0, 0, 1]), "material[2]", id="material-out-of-range"),
    pytest.param(_set("structure/material", [0, 0]), "one data-set index per member", id="material-length"),
    pytest.param(_two_data_sets, "material is required", id="two-data-sets-no-material"),
    pytest.param(_add_bar, "[bar] and [structure] cannot be combined", id="bar-and-structure"),
    pytest.param(_set("obstacle", {"positions": [1.0]}), "[obstacle] belongs to [bar]", id="obstacle-in-structure"),
    pytest.param(_set("structure/supports/0", [0, "xz"]), "axes", id="support-axis-z-in-2d"),
    pytest.param(_set("structure/supports/0", [3, "x"]), "supports[0]", id="support-node-out-of-range"),
    pytest.param(_set("structure/supports", [[0, "x"], [1, "y"]]), "mechanism", id="mechanism"),
    pytest.param(_set("structure/loads/0", [2, [0.0, -1e5, 0.0]]), "loads[0]", id="load-vector-length"),
    pytest.param(_set("structure/distributed_loads", [[3, [0.0, -1.0]]]), "member index",
                 id="distributed-load-member-out-of-range"),
    pytest.param(_set("structure/area", [1e-3, -1e-3, 1e-3]), "area[1]", id="area-negative"),
    pytest.param(_set("structure/area", [1e-3, 1e-3]), "one per member", id="area-length"),
    pytest.param(_set("obstacles/0/normal", [0.0, 0.0]), "normal must be non-zero", id="normal-zero"),
    pytest.param(_set("obstacles/0/nodes", [2, 2]), "twice", id="obstacle-node-twice"),
    pytest.param(_loose_contact_node, "belongs to no member", id="obstacle-node-without-member"),
    pytest.param(_set("path/load_factors", [0.0, float("nan")]), "load_factors", id="load-factor-nan"),
    pytest.param(_delete("structure/youngs_modulus"), "hookean needs youngs_modulus", id="hookean-without-modulus"),
    pytest.param(_delete("structure/supports"), "missing key 'supports'", id="missing-supports"),
    pytest.param(_set("data/c", -1.0), "[data] c", id="data-c-negative"),
]


@pytest.mark.parametrize("fmt", ["toml", "json"])
@pytest.mark.parametrize("mutate, expected", BAD)
def test_bad_structure(tmp_path: Path, capsys, mutate: Callable[[dict], None], expected: str, fmt: str) -> None:
    doc = triangle()
    mutate(doc)
    cfg = write_case(tmp_path, doc, fmt)
    out = tmp_path / "out"
    code, stdout, err = run_cli(["--config", str(cfg), "--out", str(out), *FAST], capsys)
    assert_input_error(code, err, expected)
    assert stdout == ""
    assert not out.exists(), "nothing is written for bad input"


BAD_TEXT = [
    pytest.param("json", '{"structure": {"nodes": [[0.0, 0.0],]}}', "malformed JSON", id="malformed-json"),
    pytest.param("json", "[1, 2]", "JSON object", id="json-not-an-object"),
    pytest.param("json", '{"ddcm": {"c": 1e9}, "ddcm": {"c": 2e9}}', "duplicate key 'ddcm'", id="json-duplicate-key"),
    pytest.param("json", '{"structure": {"area": ' + "9" * 5000 + "}}", "malformed JSON", id="json-huge-integer"),
    pytest.param("json", json.dumps({**triangle(), "stops": [{"node": 1, "clearance": 0.0}]}),
                 "[stops] belongs to [bar]", id="stops-in-structure"),
    pytest.param("yaml", "structure: {}\n", "must be .toml or .json", id="unknown-suffix"),
    pytest.param("toml", case_toml(extra="[[stops]]\nnode = 3\nclearance = 0.01\n"), "elements >= 2",
                 id="stops-without-elements"),
    pytest.param("toml", case_toml().replace("[bar]\n", "[bar]\nelements = 10\n")
                 + "[[stops]]\nnode = 10\nclearance = 0.01\n", "interior node", id="stop-at-the-tip"),
    pytest.param("toml", case_toml().replace("[bar]\n", "[bar]\nelements = 10\n")
                 + "[[stops]]\nnode = 3\nclearance = -0.01\n", "clearance", id="stop-negative-clearance"),
    pytest.param("toml", case_toml().replace("[bar]\n", "[bar]\nelements = 2.5\n"), "elements",
                 id="elements-fraction"),
    pytest.param("toml", case_toml().replace("[bar]\n", "[bar]\nelements = 0\n"), "elements", id="elements-zero"),
    pytest.param("toml", case_toml(extra="[path]\nload_factors = [1.0]\n"), "[path] belongs to [structure]",
                 id="path-in-bar"),
]


@pytest.mark.parametrize("suffix, text, expected", BAD_TEXT)
def test_bad_case_text(tmp_path: Path, capsys, suffix: str, text: str, expected: str) -> None:
    cfg = tmp_path / f"case.{suffix}"
    cfg.write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    code, stdout, err = run_cli(["--config", str(cfg), "--out", str(out), *FAST], capsys)
    assert_input_error(code, err, expected)
    assert code == EXIT_INPUT and stdout == ""
    assert not out.exists(), "nothing is written for bad input"


@pytest.mark.parametrize("fmt", ["toml", "json"])
def test_triangle_is_valid(tmp_path: Path, fmt: str) -> None:
    """The base of the bad-input cases is itself valid (so each case fails for its own reason)."""
    case = load_case(write_case(tmp_path, triangle(), fmt))
    assert case.model.n_dofs == 3 and case.model.n_contacts == 1 and case.model.n_steps == 3


def test_case_kinds_register_their_own_sections():
    """Each model kind declares its section and the sections only it accepts; the paper's bar is
    the default, listed first (the order of the 'known:' list in messages)."""
    from ddcm_casadi.casefiles.config import case_from_dict, case_kinds

    kinds = {k.section: k for k in case_kinds()}
    assert [k.section for k in case_kinds()] == ["bar", "structure", "mesh"]
    assert kinds["bar"].default and kinds["bar"].own_sections == ["obstacle", "stops"]
    assert kinds["structure"].own_sections == ["path", "obstacles"]
    assert kinds["mesh"].own_sections == ["material", "supports", "loads", "contact", "loading", "hertz"]
    with pytest.raises(InputError) as exc:
        case_from_dict({"foo": {}}, source="x.toml")
    assert str(exc.value) == ("unknown section [foo] in x.toml; known: bar, obstacle, stops, structure, path, "
                              "obstacles, mesh, material, supports, loads, contact, loading, hertz, data, ddcm, "
                              "formulations")
    with pytest.raises(InputError) as exc:
        case_from_dict({"obstacle": {}, "path": {}}, source="x.toml")
    assert str(exc.value) == "missing section [structure] in x.toml"  # a kind's own section names it
