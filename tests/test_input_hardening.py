"""Inputs that used to give tracebacks, nonsense or unclear messages (the hardening issue).

Each case gives one line ``ddcm-compare: error: ...``, exit 2 and no results, or (physically odd
but meaningful input) a warning line and a normal run. The helpers are those of the bad-input
contract (:mod:`tests.test_bad_input`).
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi import PhysicsWarning, compare
from ddcm_casadi.casefiles.config import load_case
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.data.limits import METRIC_RATIO_LIMIT
from ddcm_casadi.errors import InputError
from ddcm_casadi.loops.ipopt_options import FAILED_TO_START, check_ipopt_options, iteration_count

from .test_bad_input import FAST, assert_input_error, assert_no_results, case_toml, run_cli

TRUSS = Path(__file__).resolve().parents[1] / "examples" / "cases" / "truss2d.toml"


def _run_case(tmp_path: Path, capsys, text: str, *args: str, files: dict[str, bytes] | None = None):
    cfg = tmp_path / "case.toml"
    cfg.write_text(text)
    for name, content in (files or {}).items():
        (tmp_path / name).write_bytes(content)
    out = tmp_path / "out"
    code, stdout, err = run_cli(["--config", str(cfg), "--out", str(out), *FAST, *args], capsys)
    return code, stdout, err, out


# ------------------------------------------------------------------------------------ IPOPT options
IPOPT_CASES = [
    pytest.param("{ bogus_option = 1 }", "no such IPOPT option 'bogus_option'", id="unknown"),
    pytest.param("{ max_iter = -5 }", "'max_iter' must be at least 1", id="negative"),
    pytest.param("{ max_iter = 0 }", "'max_iter' must be at least 1", id="zero-cannot-converge"),
    pytest.param('{ max_iter = "abc" }', "'max_iter' has a value of the wrong type", id="wrong-type"),
    pytest.param("{ tol = -1.0 }", "tol = '-1' is not a valid setting (valid: 0 <", id="out-of-range"),
    pytest.param('{ mu_strategy = "foo" }', "valid: monotone, adaptive", id="bad-setting"),
    pytest.param('{ linear_solver = "ma27" }', "IPOPT cannot start", id="solver-not-installed"),
    pytest.param('{ print_level = 0, max_iter = "abc" }', "'max_iter'", id="culprit-named"),
    pytest.param("{ max_iter = true }", "must be a number or a string", id="boolean"),
    pytest.param("5", "must be a table", id="not-a-table"),
]


@pytest.mark.parametrize("ipopt, expected", IPOPT_CASES)
def test_ipopt_options_from_a_case_file(tmp_path: Path, capsys, ipopt: str, expected: str) -> None:
    """Were RuntimeError tracebacks from inside ``casadi.nlpsol``, or (max_iter = 0, a solver that
    is not installed) runs with every step failed and ``its/step 3728794826``."""
    text = case_toml(extra=f"[formulations.mpcc]\nipopt = {ipopt}\n")
    code, _, err, out = _run_case(tmp_path, capsys, text, "--formulations", "mpcc")
    assert_input_error(code, err, expected)
    assert_no_results(out)


def test_valid_ipopt_options_pass() -> None:
    check_ipopt_options("test", {"print_level": 0, "max_iter": 20, "mu_strategy": "monotone"})


def test_iteration_count_of_a_failed_start() -> None:
    """IPOPT leaves ``iter_count`` uninitialised when it stops before its first iteration."""
    for status in FAILED_TO_START:
        assert iteration_count({"return_status": status, "iter_count": 3728794826}) == 0
    assert iteration_count({"return_status": "Solve_Succeeded", "iter_count": 7}) == 7


# ------------------------------------------------------------------------------ ranges of settings
@pytest.mark.parametrize("extra, expected", [
    pytest.param("[ddcm]\nmax_outer = 1\n", "max_outer must be an integer in 2..1000000, got 1", id="max_outer-1"),
    pytest.param("[ddcm]\nmax_outer = 1e7\n", "got the float 10000000.0 (write it without a decimal point",
                 id="max_outer-float"),
    pytest.param("[ddcm]\nmax_outer = 10000001\n", "in 2..1000000", id="max_outer-huge"),
    pytest.param("[formulations.penalty]\nmax_iter = 0\n", "'max_iter' of 'penalty' must be an integer in 1..",
                 id="newton-max_iter-0"),
    pytest.param("[formulations.mpcc]\nmax_homotopy = 0\n", "'max_homotopy' of 'mpcc' must be an integer in 1..",
                 id="max_homotopy-0"),
    pytest.param("[formulations.augmented_lagrangian]\nmax_updates = 0\n", "'max_updates'", id="max_updates-0"),
    pytest.param("[formulations.fischer_burmeister]\ntol = 1e-20\n", "'tol' of 'fischer_burmeister' must be in",
                 id="tol-below-roundoff"),
    pytest.param("[formulations.penalty]\nresidual_tol = 2.0\n", "'residual_tol'", id="tol-above-one"),
])
def test_settings_that_cannot_converge(tmp_path: Path, capsys, extra: str, expected: str) -> None:
    text = case_toml(c="200e9").replace("[ddcm]\nc = 200e9\n", "[ddcm]\nc = 200e9\n" + extra.split("\n", 1)[1]) \
        if extra.startswith("[ddcm]") else case_toml(extra=extra)
    code, _, err, out = _run_case(tmp_path, capsys, text)
    assert_input_error(code, err, expected)
    assert_no_results(out)


def test_max_outer_through_the_api() -> None:
    case = load_case(TRUSS)
    with pytest.raises(InputError, match="max_outer must be an integer in 2"):
        compare(case.model, ["fischer_burmeister"], variants=["ddcm"], ddcm_max_outer=1)


# -------------------------------------------------------------------------- extreme finite values
@pytest.mark.parametrize("kw, expected", [
    pytest.param(dict(youngs_modulus="1e300"), "out of range", id="E-1e300"),
    pytest.param(dict(c="1e300"), "the metric c = 1e+300 Pa is about 1e+289 times", id="c-1e300"),
    pytest.param(dict(c="1e-300"), "out of range for the metric c = 1e-300", id="c-1e-300"),
    pytest.param(dict(c="1e20"), "within 1.5e-08 to 6.7e+07 times", id="c-beyond-roundoff-balance"),
])
def test_extreme_values(tmp_path: Path, capsys, kw: dict, expected: str) -> None:
    """``c = 1e300`` ran 605 Newton iterations per step to a 100 % error, ``c = 1e-300`` and
    ``E = 1e300`` printed numpy overflow warnings before their message."""
    code, _, err, out = _run_case(tmp_path, capsys, case_toml(**kw))
    assert_input_error(code, err, expected)  # one line: a numpy RuntimeWarning would be a second
    assert_no_results(out)


def test_tiny_modulus_is_refused_not_solved_into_nonsense(tmp_path: Path, capsys) -> None:
    """``youngs_modulus = 1e-300`` on a loaded truss: the classical run failed with a NaN residual
    and the DDCM run (data of that modulus, metric 2e11) was reported converged."""
    code, _, err = run_cli(["--config", str(TRUSS), "--set", "structure.youngs_modulus=1e-300", *FAST], capsys)
    assert_input_error(code, err, "times the data's own modulus")
    code, _, err = run_cli(["--config", str(TRUSS), "--set", "structure.youngs_modulus=1e-300",
                            "--variants", "classical", *FAST], capsys)
    assert code == 2 and "error:" in err


def test_metric_limit_is_the_roundoff_balance() -> None:
    """The two terms of ``d^2 = c de^2 + ds^2 / c`` keep both contributions while ``(E/c)^2 >= eps``."""
    eps = np.finfo(float).eps
    assert METRIC_RATIO_LIMIT == pytest.approx(1 / np.sqrt(eps))
    strain = np.linspace(-1e-3, 1e-3, 11)
    MaterialDataset(strain, 2e11 * strain, c=2e11 * METRIC_RATIO_LIMIT / 2)  # inside: accepted
    with pytest.raises(InputError, match="times the data's own modulus"):
        MaterialDataset(strain, 2e11 * strain, c=2e11 * METRIC_RATIO_LIMIT * 2)


def test_data_file_with_huge_values(tmp_path: Path, capsys) -> None:
    """Was the KD-tree's own message about infinite coordinates."""
    text = case_toml(data='path = "data.csv"')
    code, _, err, out = _run_case(tmp_path, capsys, text,
                                  files={"data.csv": b"strain,stress\n0,0\n0.001,1e300\n-0.001,-2e8\n"})
    assert_input_error(code, err, "stress 1e+300 of data point 1 is out of range")
    assert_no_results(out)


# ------------------------------------------------------------------------------------ file messages
@pytest.mark.skipif(os.name != "posix", reason="symbolic links")
@pytest.mark.parametrize("make, expected", [
    pytest.param(lambda p: p.mkdir(), "data file is a directory", id="directory"),
    pytest.param(lambda p: (p.symlink_to(p.with_name("loop2.csv")), p.with_name("loop2.csv").symlink_to(p)),
                 "symbolic link loop", id="symlink-loop"),
    pytest.param(lambda p: p.symlink_to(p.with_name("nowhere.csv")), "dangling symbolic link", id="dangling"),
])
def test_data_path_that_is_not_a_file(tmp_path: Path, capsys, make, expected: str) -> None:
    """Each was reported as ``data file not found``."""
    make(tmp_path / "data.csv")
    code, _, err, out = _run_case(tmp_path, capsys, case_toml(data='path = "data.csv"'))
    assert_input_error(code, err, expected)
    assert_no_results(out)


def test_config_that_is_a_directory(tmp_path: Path, capsys) -> None:
    code, _, err = run_cli(["--config", str(tmp_path), *FAST], capsys)
    assert_input_error(code, err, "config file is a directory")


@pytest.mark.parametrize("content, expected", [
    pytest.param(b"strain,stress\n0,0\n0.001,abc\n", "'abc' to float64 on line 3, column 2 ('stress')",
                 id="stress"),
    pytest.param(b"label,strain,stress\n1,0,0\n2,x,1\n", "'x' to float64 on line 3, column 2 ('strain')",
                 id="extra-column"),
])
def test_csv_parse_error_position(tmp_path: Path, capsys, content: bytes, expected: str) -> None:
    """Was ``at row 1, column 2``: data rows counted from 0 after the header, columns from 1."""
    code, _, err, out = _run_case(tmp_path, capsys, case_toml(data='path = "data.csv"'),
                                  files={"data.csv": content})
    assert_input_error(code, err, expected)


# ------------------------------------------------------------------------- physically odd load paths
def test_obstacle_starting_inside_the_body(tmp_path: Path, capsys) -> None:
    """Ran silently with contact forces before any load; now a warning with the amount."""
    code, _, err, out = _run_case(tmp_path, capsys, case_toml(positions="[0.95, 0.94]"))
    assert code == 0, err
    lines = [ln for ln in err.splitlines() if ln.startswith("ddcm-compare: warning:")]
    assert any("start inside the body: 1 contact pair(s) penetrate by up to 0.05 m" in ln for ln in lines), err
    assert (out / "results.csv").is_file()
    doc = json.loads((out / "results.json").read_text())
    assert len(doc["warnings"]) == 1 and "start inside the body" in doc["warnings"][0]


def test_truss_floor_above_the_chord_warns_through_the_api() -> None:
    case = load_case(TRUSS, overrides=[("obstacles.0.offset", 0.01)])
    with pytest.warns(PhysicsWarning, match="3 contact pair"):
        cmp = compare(case.model, ["fischer_burmeister"], variants=["classical"])
    assert any("start inside the body" in w for w in cmp.warnings)


def test_examples_have_no_path_warnings() -> None:
    for name in ("truss2d.toml", "bar_stops.toml", "truss3d.json"):
        assert load_case(TRUSS.with_name(name)).model.path_warnings() == []


@pytest.mark.parametrize("positions, expected", [
    pytest.param("[1.0, 0.5, -5.0]", "impose a strain of about 6 at h=-5", id="past-the-fixed-end"),
    pytest.param("[1.0, 0.0]", "impose a strain of about 1 at h=0", id="to-the-fixed-end"),
])
def test_obstacle_pushed_past_the_fixed_end(tmp_path: Path, capsys, positions: str, expected: str) -> None:
    """Was a run to strain -6 reported converged."""
    code, _, err, out = _run_case(tmp_path, capsys, case_toml(positions=positions))
    assert_input_error(code, err, expected)
    assert_no_results(out)


def test_large_imposed_strain_warns(tmp_path: Path) -> None:
    case = load_case(TRUSS.with_name("bar_stops.toml"),
                     overrides=[("obstacle.positions", [1.0, 0.85])])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        messages = case.model.path_warnings()
    # The stop behind node 8 (clearance 0.01 m) leaves the last 0.2 m of the bar to take the
    # remaining 0.14 m of the 0.15 m travel: a strain of about 0.7, not 0.15.
    assert len(messages) == 1 and "strain of about 0.7" in messages[0]


def test_validate_refuses_an_empty_out(capsys) -> None:
    """``ddcm-validate --out ""`` ran the whole ladder and wrote nothing, silently."""
    from ddcm_casadi.commands.validate import main as validate

    assert validate(["--out", "", "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ddcm-validate: error:") and len(err.strip().splitlines()) == 1


def test_case_file_reads_npy_data(tmp_path: Path, capsys) -> None:
    """``[data] path = "data.npy"``: the memory-mapped reader, same results as the CSV."""
    strain = np.linspace(-0.05, 0.01, 50)
    np.save(tmp_path / "data.npy", np.column_stack([strain, 200e9 * strain]))
    (tmp_path / "data.csv").write_text("strain,stress\n" + "".join(f"{float(e)!r},{float(200e9 * e)!r}\n" for e in strain))
    rows = {}
    for name in ("data.npy", "data.csv"):
        case = tmp_path / f"{name}.toml"
        case.write_text(case_toml(data=f'path = "{name}"'))
        cmp = compare(load_case(case).model, ["fischer_burmeister"], variants=["ddcm"])
        rows[name] = cmp["ddcm", "fischer_burmeister"].array("p")
    np.testing.assert_array_equal(rows["data.npy"], rows["data.csv"])
