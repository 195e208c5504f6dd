"""Outputs a real user can trust: an owned, locked ``--out`` folder, clean failures while writing,
Ctrl-C inside IPOPT, and progress lines in a log.

- ``--out ""`` is an input error; a folder in use by another run is refused (a lock that a killed
  holder does not keep); a rerun removes the files of the previous run that it did not write
  (stale figures, a VTU series) and never a file the tool did not write.
- A failure while writing (a full disk, simulated) or Ctrl-C is one line (exit 2, resp. 130) and
  leaves the folder's previous results byte for byte; a fresh folder is not left behind.
- Ctrl-C during an IPOPT solve stops the run (CasADi and IPOPT turn it into a solver status).
- Without a terminal, progress prints a line per run's first and last step and at most one every
  ``_Progress.interval`` seconds in between.
"""

from __future__ import annotations

import errno
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from ddcm_casadi.commands import compare as cli
from ddcm_casadi.commands.compare import EXIT_INPUT, main
from ddcm_casadi.errors import InputError
from ddcm_casadi.io import LOCK_FILE, PREVIOUS_PREFIX, STAGING_PREFIX, FolderLock, OutputFolder

from .interrupt import interrupt_at
from .test_bad_input import FAST, PREFIX, assert_input_error, case_toml, run_cli
from .test_continuum import _CASE as TINY_CONTINUUM  # a 2 x 2 block under a cylinder, two steps

ROOT = Path(__file__).resolve().parent.parent
CASES = ROOT / "examples" / "cases"
FB = ["--formulations", "fischer_burmeister"]


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (hidden ones too) with its content."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def bar_case(tmp_path: Path) -> Path:
    cfg = tmp_path / "case.toml"
    cfg.write_text(case_toml(), encoding="utf-8")
    return cfg


def one_error_line(err: str, expected: str) -> None:
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(PREFIX) and expected in lines[0], err


# ------------------------------------------------------------------------------- --out and the lock
@pytest.mark.parametrize("value", ["", "   "])
def test_empty_out_is_an_input_error(tmp_path, capsys, monkeypatch, value):
    monkeypatch.chdir(tmp_path)
    cfg = bar_case(tmp_path)
    code, stdout, err = run_cli(["--config", str(cfg), "--out", value, *FAST], capsys)
    assert_input_error(code, err, "output folder")
    assert stdout == "" and sorted(p.name for p in tmp_path.iterdir()) == ["case.toml"]


def _holder(folder: Path) -> subprocess.Popen:
    """Another process that holds the folder's lock until its stdin closes."""
    code = ("import sys; from ddcm_casadi.io import FolderLock; lock = FolderLock(sys.argv[1], 'ddcm-compare'); "
            "print('locked', flush=True); sys.stdin.read()")
    proc = subprocess.Popen([sys.executable, "-c", code, str(folder)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout.readline().strip() == "locked"
    return proc


@pytest.mark.parametrize("ending", ["exits", "killed"])
def test_a_folder_in_use_is_refused_until_its_holder_ends(tmp_path, capsys, ending):
    cfg, out = bar_case(tmp_path), tmp_path / "out"
    assert run_cli(["--config", str(cfg), "--out", str(out), *FAST], capsys)[0] == 0
    before = snapshot(out)
    holder = _holder(out)
    try:
        code, stdout, err = run_cli(["--config", str(cfg), "--out", str(out), *FAST], capsys)
        assert_input_error(code, err, f"output folder {out} is in use by ddcm-compare (pid {holder.pid})")
        assert stdout == ""  # refused before any work
        assert {k: v for k, v in snapshot(out).items() if k != LOCK_FILE} == before
    finally:
        if ending == "exits":
            holder.communicate("")
        else:  # a crash: the kernel drops the lock, the file stays and is reused
            holder.kill()
            holder.wait()
    assert run_cli(["--config", str(cfg), "--out", str(out), *FAST], capsys)[0] == 0
    assert sorted(snapshot(out)) == ["results.csv", "results.json"]  # the lock file is gone too


def test_a_second_lock_in_the_same_process_is_refused_and_released_on_exit(tmp_path):
    with FolderLock(tmp_path, "ddcm-sweep"):
        assert (tmp_path / LOCK_FILE).read_text() == f"{os.getpid()} ddcm-sweep\n"
        with pytest.raises(InputError, match=f"in use by ddcm-sweep \\(pid {os.getpid()}\\)"):
            FolderLock(tmp_path, "ddcm-compare")
    with FolderLock(tmp_path, "ddcm-compare"):
        pass
    assert not any(tmp_path.iterdir())


def test_ddcm_sweep_refuses_a_folder_in_use(tmp_path, capsys):
    pytest.importorskip("distributed")
    from ddcm_casadi.commands.sweep import main as sweep_main

    from .test_sweep import write_spec

    spec = write_spec(tmp_path / "spec", 'base = "base.toml"\nvariants = ["classical"]\n'
                                         'formulations = ["fischer_burmeister"]\n[grid]\n"ddcm.c" = [3e11]\n')
    out = tmp_path / "out"
    out.mkdir()
    with FolderLock(out, "ddcm-compare"):
        assert sweep_main([str(spec), "--out", str(out), "--workers", "1", "-q"]) == EXIT_INPUT
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"ddcm-sweep: error: output folder {out} is in use by ddcm-compare (pid {os.getpid()}); "
                   "wait for it to finish or choose another folder"]
    assert not any(out.iterdir())


# ------------------------------------------------------------------------------- owning the folder
def test_a_rerun_removes_the_previous_runs_files_and_keeps_the_users(tmp_path, capsys):
    out = tmp_path / "out"
    (out / "vtu").mkdir(parents=True)
    (out / "notes.txt").write_text("mine")
    (out / "vtu" / "mine.vtu").write_text("mine too")
    # 1. a truss-like bar with figures
    code, _, err = run_cli(["-q", "--config", str(CASES / "bar_stops.toml"), "--out", str(out), *FB], capsys)
    assert code == 0, err
    first = {"results.csv", "results.json", "structure_classical.png", "structure_ddcm.png", "contact_history.png"}
    assert set(json.loads((out / "results.json").read_text())["files"]) == first
    # 2. a continuum case: a VTU series, no figures
    (tmp_path / "c.toml").write_text(TINY_CONTINUUM)
    code, _, err = run_cli(["-q", "--no-plots", "--config", str(tmp_path / "c.toml"), "--out", str(out), *FB], capsys)
    assert code == 0, err
    files = set(json.loads((out / "results.json").read_text())["files"])
    assert {"results.csv", "results.json", "vtu/classical_fischer_burmeister.pvd"} <= files
    assert set(snapshot(out)) == files | {"notes.txt", "vtu/mine.vtu"}  # the stale figures are gone
    # 3. the paper's bar without figures: the VTU series goes, the user's files stay (and their folder)
    code, _, err = run_cli(["-q", "--no-plots", "--out", str(out), *FB], capsys)
    assert code == 0, err
    assert set(snapshot(out)) == {"results.csv", "results.json", "notes.txt", "vtu/mine.vtu"}
    assert json.loads((out / "results.json").read_text())["files"] == ["results.csv", "results.json"]
    # 4. without the user's file the emptied vtu/ folder is removed as well
    (out / "vtu" / "mine.vtu").unlink()
    assert run_cli(["-q", "--config", str(tmp_path / "c.toml"), "--no-plots", "--out", str(out), *FB], capsys)[0] == 0
    assert run_cli(["-q", "--no-plots", "--out", str(out), *FB], capsys)[0] == 0
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "results.csv", "results.json"]


def test_a_manifest_never_reaches_outside_the_folder(tmp_path):
    """Names in a (tampered) manifest that are not plain relative paths inside the folder are ignored."""
    out = tmp_path / "out"
    out.mkdir()
    (tmp_path / "outside.txt").write_text("keep")
    (out / ".hidden").write_text("keep")
    (out / "a.txt").write_text("old")
    (out / "m.json").write_text(json.dumps({"files": ["../outside.txt", str(tmp_path / "outside.txt"), ".hidden",
                                                      "a.txt", 7, "missing.txt"]}))
    with OutputFolder(out, tool="test", manifest="m.json") as folder:
        assert folder.previous_files() == ["a.txt"]
        with folder.staging() as stage:
            (stage / "m.json").write_text(json.dumps({"files": ["m.json"]}))
    assert (tmp_path / "outside.txt").read_text() == "keep"
    assert sorted(p.name for p in out.iterdir()) == [".hidden", "m.json"]


# ------------------------------------------------------------------------ failures while writing
def _enospc(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("where", ["results.csv", "figure", "results.json", "moving into place"])
@pytest.mark.parametrize("fresh", [False, True], ids=["previous-results", "fresh-folder"])
def test_a_full_disk_is_one_line_and_keeps_the_previous_results(tmp_path, capsys, monkeypatch, where, fresh):
    import ddcm_casadi.io as io_module
    import ddcm_casadi.outputs.plots as plots

    out = tmp_path / "out"
    if not fresh:
        code, _, err = run_cli(["-q", "--out", str(out), *FB], capsys)  # the paper's bar with its figures
        assert code == 0, err
    before = snapshot(out) if out.exists() else None
    if where == "figure":
        monkeypatch.setattr(plots, "write_bytes_atomic", _enospc)
    elif where == "moving into place":
        real = os.replace  # the new results.json out of its staging folder (not the restore after it)
        monkeypatch.setattr(os, "replace", lambda a, b: _enospc() if Path(b) == out / "results.json"
                            and Path(a).parent.name.startswith(STAGING_PREFIX) else real(a, b))
    else:
        real_write = io_module.write_bytes_atomic
        monkeypatch.setattr(io_module, "write_bytes_atomic",
                            lambda path, data: _enospc() if Path(path).name == where else real_write(path, data))
    code, stdout, err = run_cli(["-q", "--out", str(out), *FB], capsys)
    one_error_line(err, f"cannot write the outputs to {out}: No space left on device")
    assert code == EXIT_INPUT and "variant" in stdout  # the table was printed, then the write failed
    if fresh:
        assert not out.exists()
    else:
        assert snapshot(out) == before  # byte for byte, no temporary folder or lock left


def test_ctrl_c_while_writing_keeps_the_previous_results(tmp_path, capsys, monkeypatch):
    import ddcm_casadi.outputs.plots as plots

    out = tmp_path / "out"
    assert run_cli(["-q", "--out", str(out), *FB], capsys)[0] == 0
    before = snapshot(out)

    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(plots, "write_bytes_atomic", interrupt)
    code, _, err = run_cli(["-q", "--out", str(out), *FB], capsys)
    assert code == 130 and err.strip() == "ddcm-compare: interrupted"
    assert snapshot(out) == before


def test_a_run_killed_while_moving_its_files_is_undone_by_the_next(tmp_path):
    """Left by a killed run: its staging folder (new outputs) and the previous files it had moved
    away; the next run drops the first and puts the second back before anything else."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "r.json").write_text(json.dumps({"files": ["r.json", "fig.png"]}))  # the killed run's, half moved
    (out / f"{STAGING_PREFIX}x").mkdir()
    (out / f"{STAGING_PREFIX}x" / "other.png").write_text("new")
    (out / f"{PREVIOUS_PREFIX}y").mkdir()
    (out / f"{PREVIOUS_PREFIX}y" / "r.json").write_text(json.dumps({"files": ["r.json", "old.png"]}))
    (out / f"{PREVIOUS_PREFIX}y" / "old.png").write_text("old")
    with OutputFolder(out, tool="test", manifest="r.json") as folder:
        assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE, "old.png", "r.json"]
        assert folder.previous_files() == ["r.json", "old.png"]


# ------------------------------------------------------------------------------ Ctrl-C inside IPOPT
def test_ipopt_reporting_a_user_stop_is_an_interrupt():
    from ddcm_casadi.loops.ipopt_options import ipopt_stats

    class Stopped:
        def __init__(self, status):
            self.status = status

        def stats(self):
            return {"return_status": self.status, "iter_count": 3}

    for status in ("User_Requested_Stop", "NonIpopt_Exception_Thrown"):
        with pytest.raises(KeyboardInterrupt):
            ipopt_stats(Stopped(status))
    assert ipopt_stats(Stopped("Infeasible_Problem_Detected"))["iter_count"] == 3


def test_ctrl_c_during_an_ipopt_solve_stops_the_run(tmp_path):
    """A real SIGINT while IPOPT solves the second step of a refined Hertz case (steps 2-5 take
    about 4 s of IPOPT iterations, measured): ``interrupted``, exit 130, nothing in ``--out``."""
    argv = [sys.executable, "-m", "ddcm_casadi.commands.compare", "--config", str(CASES / "hertz2d.toml"),
            "--set", "mesh.divisions=[16,16]",
            # the homotopy on the full problem: the active-set branch NLPs, or the problem condensed
            # on its pairs, end the whole run in a fraction of a second
            "--set", "formulations.mpcc.active_set=false", "--set", "condense=false",
            "--formulations", "mpcc", "--variants", "classical", "--no-plots", "--out", "out"]
    # the progress line of the first step (stderr is a pipe): IPOPT is at work
    returncode, text = interrupt_at(argv, tmp_path, r"classical/mpcc\s+step\s+1/5")
    assert returncode == 130, text
    assert text.strip().splitlines()[-1] == "ddcm-compare: interrupted", text
    assert "Traceback" not in text and "step   5/5" not in text
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------------- progress in logs
def _progress_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if re.search(r"step\s+\d+/11\s", line)]


def test_progress_without_a_terminal_prints_periodic_lines(capsys, monkeypatch):
    argv = ["--config", str(CASES / "bar_stops.toml"), "--variants", "classical", *FB]
    monkeypatch.setattr(cli._Progress, "interval", 0.0)
    assert main(argv) == 0
    lines = _progress_lines(capsys.readouterr().err)
    assert [int(re.search(r"step\s+(\d+)/", line).group(1)) for line in lines] == list(range(1, 12))
    assert all(re.search(r"\d+\.\d\d s$", line) for line in lines)  # elapsed time
    monkeypatch.setattr(cli._Progress, "interval", 1e9)  # a quick run: its first and its last step
    assert main(argv) == 0
    lines = _progress_lines(capsys.readouterr().err)
    assert [re.search(r"step\s+(\d+/\d+)", line).group(1) for line in lines] == ["1/11", "11/11"]
