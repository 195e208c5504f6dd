"""``ddcm-compare --config CASE --set KEY=VALUE``: overrides of the case document.

An override is applied to the parsed document before validation, so it gives the same case (and
the same results) as the value written in the file, is refused with the file's own one-line
messages, and is recorded in ``results.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ddcm_casadi.errors import InputError
from ddcm_casadi.casefiles.config import load_case_with_overrides
from ddcm_casadi.casefiles.overrides import apply_overrides, parse_item, parse_value

from .test_bad_input import assert_input_error, case_toml, run_cli

CASES = Path(__file__).resolve().parent.parent / "examples" / "cases"
SMALL = case_toml(positions="[1.002, 1.0, 0.998, 0.996]",
                  data="hookean = { strain_min = -0.01, strain_max = 0.002, points = 60 }")


@pytest.mark.parametrize("text, value", [
    ("2e11", 2e11), ("100", 100), ("-0.5", -0.5), ("true", True), ("[1.0, 0.99]", [1.0, 0.99]),
    ('"isotropic"', "isotropic"), ("isotropic", "isotropic"), ("{ points = 5, strain_min = 0.0 }",
                                                              {"points": 5, "strain_min": 0.0}),
    ("inf", float("inf")),
])
def test_values_are_toml_values(text, value):
    assert parse_value(text) == value
    assert type(parse_value(text)) is type(value)


@pytest.mark.parametrize("item, message", [
    ("ddcm.c", "needs KEY=VALUE"), ("=1", "needs KEY=VALUE"), ("ddcm.c=1e11 2", "not a TOML value"),
    ("ddcm.c=[1,", "not a TOML value"), ("ddcm.c=1e11\nmax_outer = 2", "more than one TOML value"),
])
def test_bad_items(item, message):
    with pytest.raises(InputError, match=message):
        parse_item(item)


def test_dotted_keys_reach_tables_and_arrays_without_touching_the_input():
    doc = {"data": [{"c": 1.0}, {"c": 2.0}], "obstacle": {"positions": [1.0, 0.9]}}
    out = apply_overrides(doc, [("data.1.c", 7e10), ("obstacle.positions.0", 1.1),
                                ("formulations.penalty.gamma", 1e14)])
    assert out == {"data": [{"c": 1.0}, {"c": 7e10}], "obstacle": {"positions": [1.1, 0.9]},
                   "formulations": {"penalty": {"gamma": 1e14}}}
    assert doc == {"data": [{"c": 1.0}, {"c": 2.0}], "obstacle": {"positions": [1.0, 0.9]}}
    for key, message in [("data.2.c", "index 2 out of range"), ("data.x.c", "index it with a number"),
                         ("obstacle.positions.0.x", "is a value"), ("a..b", "not a dotted key")]:
        with pytest.raises(InputError, match=message):
            apply_overrides(doc, [(key, 1.0)])


def test_an_override_is_the_value_written_in_the_file(tmp_path):
    (tmp_path / "a.toml").write_text(SMALL)
    (tmp_path / "b.toml").write_text(SMALL.replace("c = 300e9", "c = 2e11").replace("points = 60", "points = 90"))
    case, overrides = load_case_with_overrides(tmp_path / "a.toml", ["ddcm.c=2e11", "data.hookean.points=90"])
    direct, _ = load_case_with_overrides(tmp_path / "b.toml", [])
    assert overrides == {"ddcm.c": 2e11, "data.hookean.points": 90}
    assert case.model.describe() == direct.model.describe()
    assert case.model.dataset.describe() == direct.model.dataset.describe()


def test_overrides_run_and_are_recorded(tmp_path, capsys):
    out = tmp_path / "out"
    code, _, err = run_cli(["--config", str(CASES / "truss3d.json"), "--set", "data.1.c=7e10", "--set",
                            "formulations.penalty.gamma=1e14", "--set", "ddcm.max_outer=50",
                            "--formulations", "penalty", "--variants", "ddcm", "--no-plots", "-q", "--out", str(out)],
                           capsys)
    assert code == 0, err
    results = json.loads((out / "results.json").read_text())
    params = results["parameters"]
    assert params["overrides"] == {"data.1.c": 7e10, "formulations.penalty.gamma": 1e14, "ddcm.max_outer": 50}
    assert params["ddcm_max_outer"] == 50 and params["formulations"]["penalty"]["gamma"] == 1e14
    assert params["data"]["sets"][1]["c"] == 7e10
    # without --set, results.json has no overrides record
    code, _, _ = run_cli(["--config", str(CASES / "bar_stops.toml"), "--formulations", "fischer_burmeister",
                          "--no-plots", "-q", "--out", str(tmp_path / "plain")], capsys)
    assert code == 0 and "overrides" not in json.loads((tmp_path / "plain" / "results.json").read_text())["parameters"]


@pytest.mark.parametrize("item, expected", [
    ("ddcm.cc=1e11", "unknown key 'cc' in [ddcm]"),
    ("bar.youngs_modulus=-1", "[bar] youngs_modulus must be finite and positive"),
    ("bar.youngs_modulus=nan", "[bar] youngs_modulus must be finite"),
    ("bar.length=\"long\"", "[bar] length must be a number"),
    ("formulations.penalty.gama=1e14", "unknown option 'gama'"),
    ("formulations.nope.x=1", "unknown formulation"),
    ("obstacle.positions.99=1.0", "index 99 out of range"),
    ("bar.length.x=1", "is a value, not a table"),
    ("nosection.x=1", "unknown section [nosection]"),
    ("ddcm.c=1e11 x", "not a TOML value"),
    ("ddcm.c", "needs KEY=VALUE"),
])
def test_bad_overrides_are_one_line_exit_2_nothing_written(tmp_path, capsys, item, expected):
    out = tmp_path / "out"
    code, _, err = run_cli(["--config", str(CASES / "bar_stops.toml"), "--set", item, "--out", str(out)], capsys)
    assert_input_error(code, err, expected)
    assert not out.exists()


def test_set_needs_a_case_file(tmp_path, capsys):
    code, _, err = run_cli(["--set", "ddcm.c=1e11", "--out", str(tmp_path / "o")], capsys)
    assert_input_error(code, err, "--set needs --config")
