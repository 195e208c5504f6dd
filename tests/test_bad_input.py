"""The bad-input contract of ``ddcm-compare``, end to end.

Every bad input gets one line ``ddcm-compare: error: ...`` on stderr naming the problem, exit status 2,
no traceback and no partial results (the ``--out`` folder is not even created).
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from ddcm_casadi.commands.compare import EXIT_INPUT, main

PREFIX = "ddcm-compare: error: "
HOOKEAN = "hookean = { strain_min = -0.05, strain_max = 0.01, points = 50 }"
FAST = ["-q", "--no-plots", "--formulations", "fischer_burmeister"]
RESULTS = ("results.csv", "results.json")


def case_toml(*, length: str = "1.0", area: str = "1.0", youngs_modulus: str = "200e9",
              positions: str = "[1.01, 1.0, 0.99]", data: str | None = HOOKEAN, c: str = "300e9",
              extra: str = "") -> str:
    """A case file with the given TOML values (written verbatim, so they may be bad)."""
    text = (f"[bar]\nlength = {length}\narea = {area}\nyoungs_modulus = {youngs_modulus}\n\n"
            f"[obstacle]\npositions = {positions}\n\n")
    if data is not None:
        text += f"[data]\n{data}\n\n[ddcm]\nc = {c}\n\n"
    return text + extra


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """Run ``main(argv)`` in-process: exit status, stdout, stderr.

    argparse exits through ``SystemExit``; that counts as the exit status. Warnings a real process
    would print on stderr (``UserWarning``, ``RuntimeWarning``) are reported as stderr lines.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    shown = [w for w in caught if issubclass(w.category, (UserWarning, RuntimeWarning))
             and not issubclass(w.category, DeprecationWarning)]
    err += "".join(f"warning: {w.message}\n" for w in shown)
    return code, out, err


def assert_input_error(code: int, err: str, expected: str) -> None:
    """Exit 2, one line ``ddcm-compare: error: ...`` mentioning ``expected``, no traceback."""
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(PREFIX), err
    assert expected.lower() in lines[0].lower(), err
    assert code == EXIT_INPUT, err


def assert_no_results(folder: Path) -> None:
    if folder.is_dir():
        left = sorted(p.name for p in folder.iterdir()
                      if p.name in RESULTS or p.suffix in (".png", ".tmp") or p.name.startswith(".write-test-"))
        assert not left, left


# --------------------------------------------------------------------------------------- config values
BAD_NUMBERS = {"nan": "nan", "zero": "0.0", "negative": "-1.0", "string": '"abc"', "inf": "inf"}

CONFIG_CASES = [
    *[pytest.param(case_toml(youngs_modulus=v), "youngs_modulus", id=f"youngs_modulus-{k}")
      for k, v in BAD_NUMBERS.items()],
    *[pytest.param(case_toml(length=v), "length", id=f"length-{k}") for k, v in BAD_NUMBERS.items()],
    *[pytest.param(case_toml(area=v), "area", id=f"area-{k}") for k, v in BAD_NUMBERS.items()],
    *[pytest.param(case_toml(c=v), "[ddcm] c", id=f"c-{k}") for k, v in BAD_NUMBERS.items()],
    pytest.param(case_toml(data=None, extra="[ddcm]\nc = nan\n"), "[ddcm] c", id="c-nan-without-data"),
    pytest.param(case_toml(positions="[]"), "positions", id="positions-empty"),
    pytest.param(case_toml(positions="[1.0, nan]"), "positions", id="positions-nan"),
    pytest.param(case_toml(positions="[1.0, inf]"), "positions", id="positions-inf"),
    pytest.param(case_toml(positions="[1.0, -inf]"), "positions", id="positions-minus-inf"),
    pytest.param(case_toml(positions='[1.0, "x"]'), "positions", id="positions-string"),
    pytest.param(case_toml(positions="1.0"), "positions", id="positions-not-a-list"),
    pytest.param(case_toml(positions="[[1.0]]"), "positions", id="positions-nested"),
    pytest.param(case_toml(data="hookean = { strain_min = -0.05, strain_max = 0.01, points = 1e13 }"),
                 "data points", id="hookean-points-too-many"),
    pytest.param(case_toml(data="hookean = { strain_min = -0.05, strain_max = 0.01, points = 2.5 }"),
                 "points", id="hookean-points-fraction"),
    # formulations
    pytest.param(case_toml(extra="[formulations.foo]\n"), "unknown formulation", id="formulation-table-unknown"),
    pytest.param(case_toml(extra="[formulations.penalty]\ngama = 1\n"), "unknown option 'gama'",
                 id="option-unknown"),
    pytest.param(case_toml(extra='[formulations.penalty]\ngamma = "big"\n'), "gamma", id="option-wrong-type"),
    pytest.param(case_toml(extra="[formulations.penalty]\ngamma = -1\n"), "gamma", id="option-negative"),
    pytest.param(case_toml(extra="[formulations.penalty]\ngamma = 0\n"), "gamma", id="option-zero"),
    pytest.param(case_toml(extra="[formulations.penalty]\ngamma = nan\n"), "gamma", id="option-nan"),
    pytest.param(case_toml(extra="[formulations]\npenalty = 1\n"), "formulations.penalty",
                 id="formulation-not-a-table"),
    # structure
    pytest.param(case_toml(extra="[foo]\nbar = 1\n"), "unknown section", id="unknown-section"),
    pytest.param(case_toml(extra="[ddcm]\nmax_outer = 10\n", data=None).replace("area = 1.0", "aera = 1.0"),
                 "unknown key 'aera'", id="unknown-key"),
    pytest.param("[bar]\nlength = 1.0\n", "missing section [obstacle]", id="missing-section"),
    pytest.param(case_toml().replace("youngs_modulus = 200e9\n", ""), "youngs_modulus", id="missing-key"),
    pytest.param("[bar\nlength = 1.0\n", "malformed TOML", id="malformed-toml"),
    pytest.param("[bar]\nlength = = 1.0\n", "malformed TOML", id="malformed-toml-value"),
    pytest.param(case_toml(extra="[ddcm]\nmax_outer = 0\n", data=None), "max_outer", id="max_outer-zero"),
]


@pytest.mark.parametrize("text, expected", CONFIG_CASES)
def test_bad_config(tmp_path: Path, capsys, text: str, expected: str) -> None:
    cfg = tmp_path / "case.toml"
    cfg.write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    code, stdout, err = run_cli(["--config", str(cfg), "--out", str(out), *FAST], capsys)
    assert_input_error(code, err, expected)
    assert stdout == ""
    assert not out.exists(), "the output folder is created only for valid input"


def test_config_not_utf8(tmp_path: Path, capsys) -> None:
    cfg = tmp_path / "case.toml"
    cfg.write_bytes(case_toml().encode("utf-8").replace(b"[bar]", b"[bar] # \xff\xfe"))
    code, _, err = run_cli(["--config", str(cfg), "--out", str(tmp_path / "out"), *FAST], capsys)
    assert_input_error(code, err, "UTF-8")
    assert not (tmp_path / "out").exists()


def test_config_missing(tmp_path: Path, capsys) -> None:
    code, _, err = run_cli(["--config", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "out"), *FAST], capsys)
    assert_input_error(code, err, "config file not found")
    assert not (tmp_path / "out").exists()


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root can read any file")
def test_config_unreadable(tmp_path: Path, capsys) -> None:
    cfg = tmp_path / "case.toml"
    cfg.write_text(case_toml(), encoding="utf-8")
    cfg.chmod(0)
    try:
        code, _, err = run_cli(["--config", str(cfg), *FAST], capsys)
    finally:
        cfg.chmod(0o644)
    assert_input_error(code, err, "cannot read config file")


# ----------------------------------------------------------------------------------------- data files
DATA_CASES = [
    pytest.param(None, "data file not found", id="missing"),
    pytest.param(b"", "data file is empty", id="empty"),
    pytest.param(b"\n\n", "data file is empty", id="blank-lines"),
    pytest.param(b"strain,stress\n", "no data rows", id="header-only"),
    pytest.param(b"strain\n0.0\n0.01\n", "data file", id="one-column"),
    pytest.param(b"strain,stress\n0.0,0.0\n0.01,abc\n", "not numeric", id="non-numeric"),
    pytest.param(b"strain,stress\n0.0,0.0\n0.01\n", "data file", id="ragged-row"),
    pytest.param(b"a,b\n0.0,0.0\n0.01,2e9\n", "header with columns 'strain' and 'stress'", id="wrong-header"),
    pytest.param(b"0.0,0.0\n0.01,2e9\n", "header with columns 'strain' and 'stress'", id="no-header"),
    pytest.param(b"strain,stress\n0.0,0.0\n0.01,nan\n", "NaN", id="nan-value"),
    pytest.param(b"strain,stress\n0.0,0.0\n\xff\xfe,1\n", "UTF-8", id="not-utf8-body"),
    pytest.param(b"str\xffain,stress\n0.0,0.0\n", "UTF-8", id="not-utf8-header"),
]


@pytest.mark.parametrize("content, expected", DATA_CASES)
def test_bad_data_file(tmp_path: Path, capsys, content: bytes | None, expected: str) -> None:
    if content is not None:
        (tmp_path / "data.csv").write_bytes(content)
    cfg = tmp_path / "case.toml"
    cfg.write_text(case_toml(data='path = "data.csv"'), encoding="utf-8")
    out = tmp_path / "out"
    code, _, err = run_cli(["--config", str(cfg), "--out", str(out), *FAST], capsys)
    assert_input_error(code, err, expected)
    assert "data" in err
    assert not out.exists()


# ------------------------------------------------------------------------------------- command line
def _valid_config(tmp_path: Path, **kw) -> Path:
    cfg = tmp_path / "case.toml"
    cfg.write_text(case_toml(**kw), encoding="utf-8")
    return cfg


@pytest.mark.parametrize("args, expected", [
    pytest.param(["--formulations", "foo"], "unknown formulation 'foo'", id="formulation-unknown"),
    pytest.param(["--formulations", "fischer_burmeister,foo"], "unknown formulation 'foo'", id="formulation-mixed"),
    pytest.param(["--formulations", ","], "--formulations", id="formulation-empty"),
    pytest.param(["--variants", "foo"], "unknown variant 'foo'", id="variant-unknown"),
    pytest.param(["--variants", ""], "--variants", id="variant-empty"),
    pytest.param(["--bogus"], "unrecognized arguments", id="argparse-unknown-option"),
    pytest.param(["--config"], "--config", id="argparse-missing-value"),
])
def test_bad_command_line(tmp_path: Path, capsys, args: list[str], expected: str) -> None:
    cfg = _valid_config(tmp_path)
    out = tmp_path / "out"
    argv = ["-q", "--no-plots", "--out", str(out), "--config", str(cfg)]
    if "--formulations" not in args:
        argv += ["--formulations", "fischer_burmeister"]
    code, stdout, err = run_cli(argv + args, capsys)
    assert_input_error(code, err, expected)
    assert stdout == ""
    assert not out.exists()


def test_ddcm_variant_without_data(tmp_path: Path, capsys) -> None:
    cfg = _valid_config(tmp_path, data=None)
    out = tmp_path / "out"
    code, _, err = run_cli(["--config", str(cfg), "--out", str(out), "--variants", "ddcm", *FAST], capsys)
    assert_input_error(code, err, "material data set")
    assert not out.exists()


def test_out_is_a_file(tmp_path: Path, capsys) -> None:
    cfg = _valid_config(tmp_path)
    out = tmp_path / "out.txt"
    out.write_text("keep me\n")
    code, _, err = run_cli(["--config", str(cfg), "--out", str(out), *FAST], capsys)
    assert_input_error(code, err, "not a directory")
    assert out.read_text() == "keep me\n"
    assert_no_results(tmp_path)


def test_out_below_a_file(tmp_path: Path, capsys) -> None:
    cfg = _valid_config(tmp_path)
    (tmp_path / "file").write_text("")
    code, _, err = run_cli(["--config", str(cfg), "--out", str(tmp_path / "file" / "sub"), *FAST], capsys)
    assert_input_error(code, err, "output directory")


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root can write anywhere")
@pytest.mark.parametrize("sub, expected", [("", "not writable"), ("new", "cannot create output directory")])
def test_out_not_writable(tmp_path: Path, capsys, sub: str, expected: str) -> None:
    cfg = _valid_config(tmp_path)
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        code, _, err = run_cli(["--config", str(cfg), "--out", str(ro / sub), *FAST], capsys)
        assert_input_error(code, err, expected)
        assert sorted(ro.iterdir()) == []
    finally:
        ro.chmod(0o755)


# ------------------------------------------------------------------------------------- real process
def _subprocess(argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ddcm_casadi.commands.compare", *argv], cwd=cwd, capture_output=True,
                          text=True, timeout=120)


@pytest.mark.parametrize("text, data, args, expected", [
    pytest.param(case_toml(youngs_modulus="nan"), None, [], "youngs_modulus", id="youngs_modulus-nan"),
    pytest.param("[bar\n", None, [], "malformed TOML", id="malformed-toml"),
    pytest.param(case_toml(data='path = "data.csv"'), b"strain,stress\n", [], "no data rows", id="header-only"),
    pytest.param(case_toml(), None, ["--bogus"], "unrecognized arguments", id="argparse"),
])
def test_real_process(tmp_path: Path, text: str, data: bytes | None, args: list[str], expected: str) -> None:
    (tmp_path / "case.toml").write_text(text, encoding="utf-8")
    if data is not None:
        (tmp_path / "data.csv").write_bytes(data)
    proc = _subprocess(["--config", "case.toml", "--out", "out", *FAST, *args], tmp_path)
    assert proc.returncode == EXIT_INPUT, proc.stderr
    assert_input_error(proc.returncode, proc.stderr, expected)
    assert proc.stdout == ""
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------------------- good input
def test_valid_small_case(tmp_path: Path) -> None:
    (tmp_path / "case.toml").write_text(case_toml(), encoding="utf-8")
    proc = _subprocess(["--config", "case.toml", "--out", "out", *FAST], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    out = tmp_path / "out"
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(RESULTS), names  # no figures with --no-plots, no temporary files left
    with (out / "results.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2 * 3  # classical and ddcm, 3 steps each
    assert {r["formulation"] for r in rows} == {"fischer_burmeister"}
    doc = json.loads((out / "results.json").read_text())
    assert doc["parameters"]["positions"] == [1.01, 1.0, 0.99]
    assert doc["parameters"]["data"]["points"] == 50


def test_default_variants_follow_the_case(tmp_path: Path, capsys) -> None:
    """Without [data] the default is the classical variant only (not an error, not an empty run)."""
    cfg = _valid_config(tmp_path, data=None)
    out = tmp_path / "out"
    code, stdout, err = run_cli(["--config", str(cfg), "--out", str(out), *FAST], capsys)
    assert code == 0, err
    with (out / "results.csv").open(newline="") as fh:
        assert {r["variant"] for r in csv.DictReader(fh)} == {"classical"}


@pytest.mark.parametrize("content", [
    pytest.param("strain,stress\n0.01,2e9\n-0.05,-1e10\n0.0,0.0\n0.01,2e9\n-0.02,-4e9\n0.0,0.0\n",
                 id="duplicate-unsorted"),
    pytest.param("\ufeffstrain,stress\n-0.05,-1e10\n0.0,0.0\n0.01,2e9\n", id="utf8-bom"),
    pytest.param("stress,strain,temperature\n-1e10,-0.05,300\n0.0,0.0,300\n2e9,0.01,300\n", id="column-order"),
])
def test_data_file_accepted(tmp_path: Path, capsys, content: str) -> None:
    (tmp_path / "data.csv").write_text(content, encoding="utf-8")
    cfg = _valid_config(tmp_path, data='path = "data.csv"')
    out = tmp_path / "out"
    code, _, err = run_cli(["--config", str(cfg), "--out", str(out), *FAST], capsys)
    assert code == 0, err
    doc = json.loads((out / "results.json").read_text())
    n_rows = len(content.strip().splitlines()) - 1
    assert doc["parameters"]["data"]["points"] == n_rows
    assert doc["parameters"]["data"]["strain_min"] == -0.05


def test_huge_data_file_is_rejected_before_reading(tmp_path, capsys, monkeypatch):
    """A file over the size cap is refused with one line, without reading it."""
    import ddcm_casadi.data.limits as limits

    data = tmp_path / "big.csv"
    data.write_text("strain,stress\n" + "0.0,0.0\n" * 1000)
    monkeypatch.setattr(limits, "MAX_DATA_FILE_BYTES", 100)
    case = tmp_path / "case.toml"
    case.write_text('[bar]\nlength = 1.0\nyoungs_modulus = 2e11\n[obstacle]\npositions = [1.0]\n'
                    '[data]\npath = "big.csv"\n[ddcm]\nc = 3e11\n')
    out = tmp_path / "out"
    assert main(["-q", "--config", str(case), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "too large" in err[0]
    assert not out.exists()


def test_unwritable_output_directory_simulated(tmp_path, capsys, monkeypatch):
    """Running as root, simulate the permission error the write test would raise."""
    import tempfile

    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "NamedTemporaryFile", refuse)
    out = tmp_path / "out"
    assert main(["-q", "--formulations", "fischer_burmeister", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not writable" in err[0]
    assert not any(out.iterdir())
