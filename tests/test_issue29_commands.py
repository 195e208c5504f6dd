"""Issue 29, items 8-12: the commands and sweeps for real users.

- 8: a manifest (``results.json``, ``sweep.json``) that another program wrote never makes a run
  remove the files it lists.
- 9: forked workers die with their parent (SIGTERM or SIGKILL to it).
- 10: out of memory is one line (exit 2); sizes are estimated before building.
- 11: sweeps: a cap on size, quiet Ctrl-C, a bounded handshake, the data-range flag and
  ``--strict`` carried over, ``--out ""`` refused, every case validated before starting.
- 12: load-path warnings and refusals based on the computed state or worded as estimates.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ddcm_casadi.io import OutputFolder

from .test_bad_input import FAST, case_toml, run_cli

ROOT = Path(__file__).resolve().parent.parent


# ------------------------------------------------------------------------ 8: foreign manifests
def test_compare_keeps_the_files_a_foreign_results_json_lists(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "results.json").write_text(json.dumps({"files": ["notes.txt", "results.json"]}))  # another tool's
    cfg = tmp_path / "case.toml"
    cfg.write_text(case_toml())
    code, _, err = run_cli([*FAST, "--config", str(cfg), "--out", str(out)], capsys)
    assert code == 0, err
    assert (out / "notes.txt").read_text() == "mine"
    doc = json.loads((out / "results.json").read_text())
    assert doc["format"] == "ddcm-casadi results"
    # our own manifest is trusted: a rerun removes what it listed and does not write again
    (out / "stale.png").write_text("ours")
    doc["files"].append("stale.png")
    (out / "results.json").write_text(json.dumps(doc))
    assert run_cli([*FAST, "--config", str(cfg), "--out", str(out)], capsys)[0] == 0
    assert not (out / "stale.png").exists() and (out / "notes.txt").exists()


def test_sweep_does_not_trust_a_foreign_sweep_json(tmp_path):
    from ddcm_casadi.sweep.runner import SWEEP_FORMAT

    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.png").write_text("mine")
    (out / "sweep.json").write_text(json.dumps({"files": ["mine.png", "sweep.json"]}))
    with OutputFolder(out, tool="ddcm-sweep", manifest="sweep.json", identity=SWEEP_FORMAT) as folder:
        assert folder.previous_files() == []
    (out / "sweep.json").write_text(json.dumps({"files": ["mine.png", "sweep.json"], "format": SWEEP_FORMAT}))
    with OutputFolder(out, tool="ddcm-sweep", manifest="sweep.json", identity=SWEEP_FORMAT) as folder:
        assert folder.previous_files() == ["mine.png", "sweep.json"]


# ------------------------------------------------------------------------ 9: orphaned workers
_FORKER = """
import os, sys, time
from pathlib import Path
from ddcm_casadi.parallel import map_forked

folder = Path(sys.argv[1])

def work(i):
    (folder / f"{os.getpid()}.pid").write_text("")
    t0 = time.monotonic()
    while time.monotonic() - t0 < 120:  # busy, as a solve is
        sum(range(10000))
    return i

map_forked(work, range(3), jobs=3)
"""


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_forked_workers_die_with_their_parent(tmp_path, sig):
    script = tmp_path / "forker.py"
    script.write_text(_FORKER)
    proc = subprocess.Popen([sys.executable, str(script), str(tmp_path)])
    try:
        deadline = time.monotonic() + 120
        while len(list(tmp_path.glob("*.pid"))) < 3:
            assert time.monotonic() < deadline and proc.poll() is None, "the workers did not start"
            time.sleep(0.1)
        workers = [int(p.stem) for p in tmp_path.glob("*.pid") if int(p.stem) != proc.pid]
        assert len(workers) == 2
        proc.send_signal(sig)
        proc.wait(timeout=60)
        deadline = time.monotonic() + 30  # generous: they die at once
        while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        left = [pid for pid in workers if _alive(pid)]
    finally:
        proc.kill()
        proc.wait()
        for pid in workers if "workers" in locals() else []:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
    assert not left, f"workers {left} outlived their parent"


# --------------------------------------------------------- 12: refusals and warnings from the state
_STRETCHED = """
[structure]
nodes = [[0.0, 0.0], [1.0, 0.0]]
members = [[0, 1]]
area = 1.0
youngs_modulus = 1.0
supports = [[0, "xy"], [1, "y"]]

[[obstacles]]
normal = [1.0, 0.0]
offsets = [1.0, 1.5, 2.0]
nodes = [1]
"""


def test_a_bar_stretched_to_strain_one_runs_with_a_warning(tmp_path, capsys):
    """A hard device pulling the bar to strain 1 (E = 1) was refused as 'pushed through the body'."""
    cfg = tmp_path / "stretch.toml"
    cfg.write_text(_STRETCHED)
    code, _, err = run_cli([*FAST, "--config", str(cfg), "--out", str(tmp_path / "out")], capsys)
    assert code == 0, err
    assert "pushed past" not in err and "strain of about 1 " in err
    # pushed the other way, through the fixed end, it is still refused
    cfg.write_text(_STRETCHED.replace("normal = [1.0, 0.0]", "normal = [-1.0, 0.0]")
                   .replace("offsets = [1.0, 1.5, 2.0]", "offsets = [-1.0, -0.5, 0.0]"))
    code, _, err = run_cli([*FAST, "--config", str(cfg), "--out", str(tmp_path / "out2")], capsys)
    assert code == 2 and "pushed past a fixed end" in err


def test_bar_on_stops_has_no_false_strain_warning():
    """It warned 'strain of about 0.12' where the strain is 0.064 (the stops close only part way)."""
    sys.path.insert(0, str(ROOT / "examples"))
    try:
        import bar_on_stops
    finally:
        sys.path.remove(str(ROOT / "examples"))
    from ddcm_casadi.models.scales import computed_strain

    model = bar_on_stops.build_model(quick=True)
    assert model.path_warnings() == []
    low, _ = computed_strain(model, "classical", len(model.load_parameter) - 1)
    assert low == pytest.approx(-0.064, rel=1e-3)


def test_a_continuum_travel_starting_above_zero_is_the_load_not_a_warning():
    from ddcm_casadi.casefiles.config import load_case

    from .test_continuum import _CASE

    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "c.toml"
        path.write_text(_CASE.replace("travel = [0.0, 1e-6]", "travel = [1e-6, 2e-6, 3e-6]"))
        model = load_case(path).model
    assert not any("start inside the body" in w for w in model.path_warnings())


# ------------------------------------------------------------------------------ 10: out of memory
def test_memory_error_is_one_line_exit_2(tmp_path, capsys, monkeypatch):
    """Was a 40-line traceback and exit 1."""
    from ddcm_casadi.commands import compare as cli

    def exhausted(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(cli, "run_case", exhausted)
    code, _, err = run_cli([*FAST, "--out", str(tmp_path / "out")], capsys)
    assert code == 2 and "Traceback" not in err, err
    assert err.strip().splitlines() == ["ddcm-compare: error: out of memory: the case is too big for this machine; "
                                        "use a coarser mesh, fewer data points or fewer --jobs"]


def test_a_case_bigger_than_the_machine_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    import ddcm_casadi.run as run

    assert run.physical_memory() and run.physical_memory() > 2**20
    monkeypatch.setattr(run, "physical_memory", lambda: 1000)
    out = tmp_path / "out"
    code, _, err = run_cli([*FAST, "--out", str(out)], capsys)
    assert code == 2 and "needs about" in err and "GiB of memory" in err, err
    assert not out.exists()


# ---------------------------------------------------------------------------------- 11: sweeps
_BASE = case_toml()


def _spec(folder: Path, grid: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "base.toml").write_text(_BASE)
    path = folder / "spec.toml"
    path.write_text(f'base = "base.toml"\nformulations = ["fischer_burmeister"]\n[grid]\n{grid}\n')
    return path


def test_sweep_refuses_an_empty_out(tmp_path, capsys, monkeypatch):
    from ddcm_casadi.commands.sweep import main as sweep_main

    path = _spec(tmp_path / "spec", '"ddcm.c" = [3e11]')
    monkeypatch.chdir(tmp_path / "spec")
    before = sorted(p.name for p in (tmp_path / "spec").iterdir())
    assert sweep_main([str(path), "--out", "", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ddcm-sweep: error: --out must be a folder")
    assert sorted(p.name for p in (tmp_path / "spec").iterdir()) == before


def test_a_grid_above_the_limit_needs_max_cases(tmp_path, capsys):
    from ddcm_casadi.commands.sweep import main as sweep_main
    from ddcm_casadi.errors import InputError
    from ddcm_casadi.sweep.spec import MAX_CASES, load_spec

    values = ", ".join(f"{3e11 + i:.1f}" for i in range(MAX_CASES + 1))
    path = _spec(tmp_path / "spec", f'"ddcm.c" = [{values}]')
    with pytest.raises(InputError, match=f"has {MAX_CASES + 1} cases, more than {MAX_CASES}; pass --max-cases"):
        load_spec(path, check=False)
    assert len(load_spec(path, check=False, max_cases=MAX_CASES + 1).cases) == MAX_CASES + 1
    assert sweep_main([str(path), "--out", str(tmp_path / "out"), "-q"]) == 2
    assert "--max-cases" in capsys.readouterr().err and not (tmp_path / "out").exists()


def test_sweep_takes_the_lock_before_starting_a_cluster(tmp_path):
    """The lock was taken after a cluster had started: a second sweep into a busy folder first
    connected to (or started) a cluster."""
    from ddcm_casadi.errors import InputError
    from ddcm_casadi.io import FolderLock
    from ddcm_casadi.sweep.runner import run_sweep
    from ddcm_casadi.sweep.spec import load_spec

    spec = load_spec(_spec(tmp_path / "spec", '"ddcm.c" = [3e11]'), check=False)
    out = tmp_path / "out"
    out.mkdir()
    with FolderLock(out, "ddcm-compare"):
        with pytest.raises(InputError, match="is in use by ddcm-compare"):
            run_sweep(spec, out, scheduler="tcp://127.0.0.1:1", figures=False)


_FACTORISING = """
import sys
import numpy as np, scipy.sparse as sp
from ddcm_casadi.commands.base import run_guarded
from ddcm_casadi.linalg import factorize

def command(argv):
    n = 40  # a 3-D Laplacian of 64 000 unknowns: about 8 s to factorise on one core
    I, T = sp.identity(n), sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    A = sp.kron(sp.kron(T, I), I) + sp.kron(sp.kron(I, T), I) + sp.kron(sp.kron(I, I), T)
    print("factorising", flush=True)
    factorize(A)
    print("factorised", flush=True)
    return 0

sys.exit(run_guarded("factorise", command, []))
"""


@pytest.mark.skipif(sys.platform.startswith("win"), reason="SIGINT to a child process")
def test_ctrl_c_interrupts_a_long_factorisation_at_once(tmp_path):
    """Ctrl-C inside a SuperLU factorisation acted only when it ended (263 s on a 3-D mesh of
    1e5 dofs; 8 s here): the main thread now waits for a helper thread and is interrupted."""
    script = tmp_path / "factorise.py"
    script.write_text(_FACTORISING)
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == "factorising"
        time.sleep(0.5)
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
        took = time.monotonic() - sent
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 130, (out, err)
    assert "factorised" not in out and err.strip() == "factorise: interrupted", err
    assert took < 3.0, f"Ctrl-C took {took:.1f} s"


# ------------------------------------------------------------- 10: sizes estimated before building
_BIG_BOX = """
[mesh]
shape = "box"
size = [0.02, 0.02, 0.01]
divisions = [60, 60, 30]
[material]
youngs_modulus = 200e9
poisson_ratio = 0.3
[[supports]]
boundary = "zmin"
fix = "xyz"
[[contact]]
boundary = "zmax"
obstacle = "sphere"
center = [0.01, 0.01, 0.06]
radius = 0.05
travel = [0.0, 1e-6]
[data]
hookean = { strain_min = -0.01, strain_max = 0.01, points = 11 }
c = "isotropic"
"""


def test_a_continuum_that_cannot_fit_is_refused_before_it_is_built(tmp_path, capsys, monkeypatch):
    """The estimate came after the model (and its 1.8 M data points) had been built, minutes in."""
    import ddcm_casadi.parallel as parallel
    from ddcm_casadi.models.continuum import model as continuum

    def never(*args, **kwargs):
        raise AssertionError("the model was built")

    monkeypatch.setattr(parallel, "physical_memory", lambda: 2**30)
    monkeypatch.setattr(continuum, "continuum_model", never)
    cfg = tmp_path / "big.toml"
    cfg.write_text(_BIG_BOX)
    code, _, err = run_cli([*FAST, "--config", str(cfg), "--out", str(tmp_path / "out")], capsys)
    assert code == 2, err
    line, = err.strip().splitlines()
    assert "needs about" in line and "3-D continuum (P1): 648 000 elements" in line and "1.8 M data points" in line
    assert not (tmp_path / "out").exists()


def test_a_large_continuum_build_is_announced_and_warned_about(tmp_path, capsys, monkeypatch):
    """A 3-D mesh of 1e5 dofs printed nothing for minutes, and nothing warned of its memory."""
    import ddcm_casadi.casefiles.continuum as casefile
    import ddcm_casadi.parallel as parallel
    from ddcm_casadi.models.continuum import mesh
    from ddcm_casadi.models.continuum.fem import estimate_size

    from .test_continuum import _CASE

    size = estimate_size(mesh.rectangle(0.01, 0.01, nx=2, ny=2), 1)
    assert (size.elements, size.dofs, size.points, size.stress_unknowns) == (8, 18, 8, 24)
    monkeypatch.setattr(parallel, "physical_memory", lambda: int(1.5 * size.bytes))  # above half of it
    monkeypatch.setattr(casefile, "ANNOUNCE_UNKNOWNS", 10)  # so that this small case counts as large
    cfg = tmp_path / "c.toml"
    cfg.write_text(_CASE)
    loud = [a for a in FAST if a != "-q"]
    code, _, err = run_cli([*loud, "--config", str(cfg)], capsys)
    assert code == 0, err
    assert ("ddcm-compare: building 2-D continuum (P1): 8 elements, 18 unknowns, 24 stress unknowns, about "
            in err), err
    assert "ddcm-compare: warning: " in err and "more than half of the machine's" in err
    code, _, err = run_cli([*FAST, "--config", str(cfg)], capsys)  # -q: no notice, the warning stays
    assert code == 0 and "building" not in err and "more than half" in err


# ------------------------------------------------------------------------- 15: --help tells the truth
def test_compare_help_is_plain_and_names_every_case_kind(capsys):
    """--help never mentioned continua and showed raw RST (``...``)."""
    from ddcm_casadi.commands.compare import main

    with pytest.raises(SystemExit) as exit_:
        main(["--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    for needed in ("[bar]", "[structure]", 'kinematics = "finite"', "[mesh]", "continuum", "docs/meshes.md",
                   "ddcm_casadi.casefiles.config", "examples/cases/", "Case files"):
        assert needed in text, needed
    for markup in ("``", ":func:", ":mod:", ":class:"):
        assert markup not in text, markup
