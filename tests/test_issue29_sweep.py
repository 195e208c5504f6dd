"""Issue 29, item 11: sweeps for real users (the remaining bullets).

- every case is validated before any work, whatever its place in the grid;
- a large grid is not materialised: cases are computed from their index and submitted in batches;
- Ctrl-C reaches the client only (the workers ignore the terminal's SIGINT);
- ``--scheduler`` pointed at a silent peer gives up after a bounded handshake;
- the data-range flag and non-converged steps reach ``sweep.csv``, the warnings and ``--strict``;
- no dashboard (nor any HTTP server) listens on 8787;
- ``[generate]`` makes continuum (Mandel) data, and no message about a deleted temporary file;
- the Hertz metrics of continuum cases reach ``sweep.csv``; an empty figure is not written.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi.errors import InputError

from .test_sweep import read_csv, write_spec

distributed = pytest.importorskip("distributed")

ROOT = Path(__file__).resolve().parent.parent


def sweep_cli(*args: str) -> tuple[int, str]:
    """``ddcm-sweep ARGS`` in a child process (a LocalCluster leaves threads in the process that
    ran it, which makes later forked runs of the test session serial): exit status and stderr."""
    proc = subprocess.run([sys.executable, "-m", "ddcm_casadi.commands.sweep", *args], capture_output=True,
                          text=True, timeout=300)
    return proc.returncode, proc.stderr


# ---------------------------------------------------------------- every case validated up front
def test_a_bad_value_anywhere_in_the_grid_is_refused_before_any_work(tmp_path, capsys):
    """A bad value was refused up front only in the first case; later it failed its case at run time."""
    from ddcm_casadi.commands.sweep import main as sweep_main
    from ddcm_casadi.sweep.spec import load_spec

    path = write_spec(tmp_path / "spec", 'base = "base.toml"\nvariants = ["ddcm"]\nformulations = ["fischer_burmeister"]\n'
                                          '[grid]\n"bar.youngs_modulus" = [200e9, 100e9, -1.0]\n"ddcm.c" = [3e11, 4e11]\n')
    with pytest.raises(InputError, match=r"^case 5 \(bar\.youngs_modulus = -1\.0, ddcm\.c = 300000000000\.0\): "
                                         r"\[bar\] youngs_modulus must be finite and positive, got -1\.0$"):
        load_spec(path)
    out = tmp_path / "out"
    assert sweep_main([str(path), "--out", str(out), "-q", "--scheduler", "tcp://127.0.0.1:1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("ddcm-sweep: error: case 5 ") and not out.exists()
    # a bad generated value in the last seed-free combination, too
    path = write_spec(tmp_path / "gen", 'base = "base.toml"\nseeds = 2\n[generate]\n'
                                        '[grid]\n"generate.strain_max" = [0.002, -0.5]\n')
    with pytest.raises(InputError, match=r"^case 3 \(generate\.strain_max = -0\.5, seed = 0\): .*strain_min"):
        load_spec(path)


def test_seeds_share_one_build_when_validated(tmp_path):
    from ddcm_casadi.sweep.spec import load_spec, validate_cases

    spec = load_spec(write_spec(tmp_path, 'base = "base.toml"\nseeds = 5\n[generate]\n[grid]\n'
                                          '"generate.points" = [30, 60]\n'), check=False)
    assert len(spec.cases) == 10 and validate_cases(spec) == 2


# ------------------------------------------------------------------------------- lazy expansion
def test_a_large_grid_is_not_materialised(tmp_path):
    """A 10^6-case grid spent 89 s and 2.4 GB expanding; the cases are now computed on demand."""
    from ddcm_casadi.sweep.spec import load_spec

    values = ", ".join(f"{3e11 + i:.1f}" for i in range(1000))
    path = write_spec(tmp_path, f'base = "base.toml"\n[grid]\n"ddcm.c" = [{values}]\n'
                                f'"bar.length" = [{", ".join(f"{1 + i / 1e4:.4f}" for i in range(1000))}]\n')
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        spec = load_spec(path, check=False, max_cases=10**6)
        n = len(spec.cases)
        last = spec.cases[-1]
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert n == 10**6 and time.perf_counter() - t0 < 10 and peak < 20 * 2**20
    assert last.index == 10**6 - 1 and last.params == {"ddcm.c": 3e11 + 999, "bar.length": 1.0999}
    assert spec.cases[1].params == {"ddcm.c": 3e11, "bar.length": 1.0001}  # the last key innermost
    assert [c.index for c in spec.cases[2:4]] == [2, 3]


class _FakeFuture:
    def __init__(self, value):
        self.value = value

    def result(self):
        return self.value

    def release(self):
        pass


class _FakeClient:
    """Runs each task at once, counting the futures in flight (submitted, not yet taken)."""

    def __init__(self, runner):
        self.runner, self.in_flight, self.most = runner, 0, 0

    def submit(self, fn, task, pure=False):
        self.in_flight += 1
        self.most = max(self.most, self.in_flight)
        return _FakeFuture(dict(status="ok", error=None, rows=[], results_rows=None, results=None, seconds=0.0,
                                worker=None))

    def cancel(self, futures):
        pass


def test_cases_are_submitted_in_batches(tmp_path, monkeypatch):
    """Every case was submitted at once (all futures and tasks in memory)."""
    import distributed as dist

    from ddcm_casadi.sweep import runner
    from ddcm_casadi.sweep.spec import load_spec

    class _AsCompleted:
        def __init__(self, futures):
            self.queue = list(futures)

        def add(self, future):
            self.queue.append(future)

        def __iter__(self):
            while self.queue:
                client.in_flight -= 1
                yield self.queue.pop(0)

    values = ", ".join(f"{3e11 + i:.1f}" for i in range(100))
    spec = load_spec(write_spec(tmp_path / "spec", f'base = "base.toml"\n[grid]\n"ddcm.c" = [{values}]\n'),
                     check=False)
    client = _FakeClient(runner)
    monkeypatch.setattr(dist, "as_completed", _AsCompleted)
    out = tmp_path / "out"
    out.mkdir()
    report = runner.SweepReport(out=out, total=100, workers=2)
    todo = runner.pending(spec, out)
    runner._run(client, spec, todo, out, report, None)
    assert report.ran == 100 and len(list((out / runner.CASES).iterdir())) == 100
    assert client.most == runner.MIN_BATCH


# ------------------------------------------------------------------------------ quiet Ctrl-C
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="process groups and SIGINT")
def test_ctrl_c_prints_the_one_line_message_only(tmp_path):
    """Ctrl-C (SIGINT to the terminal's process group) printed ~90 lines of worker tracebacks."""
    values = ", ".join(f"{3e11 + i:.1f}" for i in range(40))
    path = write_spec(tmp_path / "spec", f'base = "base.toml"\nformulations = ["fischer_burmeister"]\n'
                                         f'[grid]\n"ddcm.c" = [{values}]\n')
    log = tmp_path / "stderr.txt"
    with open(log, "w") as err:
        proc = subprocess.Popen([sys.executable, "-m", "ddcm_casadi.commands.sweep", str(path), "--out",
                                 str(tmp_path / "out"), "--workers", "2", "--no-plots"],
                                stdout=subprocess.DEVNULL, stderr=err, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while " 2/40 " not in log.read_text():
            assert proc.poll() is None and time.monotonic() < deadline, log.read_text()
            time.sleep(0.05)
        lines_before = len(log.read_text().splitlines())
        os.killpg(proc.pid, signal.SIGINT)  # as the terminal does: the whole foreground group
        code = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    after = log.read_text().splitlines()[lines_before:]
    after = [line for line in after if not line.startswith("ddcm-sweep: ") or "interrupted" in line]
    assert code == 130 and after == ["ddcm-sweep: interrupted; finished cases are kept, rerun the same command "
                                     "to resume"], "\n".join(after)


# ---------------------------------------------------------------------- bounded handshake
def test_a_scheduler_that_never_answers_is_given_up_in_bounded_time(tmp_path):
    """A peer that accepts TCP and never answers made ddcm-sweep --scheduler hang forever."""
    path = write_spec(tmp_path / "spec", 'base = "base.toml"\n[grid]\n"ddcm.c" = [3e11]\n')
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    server.settimeout(0.1)
    accepted, stop = [], threading.Event()

    def accept() -> None:  # and never answer
        while not stop.is_set():
            try:
                accepted.append(server.accept()[0])
            except socket.timeout:
                continue

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    port = server.getsockname()[1]
    code = ("import sys, ddcm_casadi.sweep.runner as r; r.HANDSHAKE_TIMEOUT = 1.0; "
            "from ddcm_casadi.commands.sweep import main; sys.exit(main(sys.argv[1:]))")
    t0 = time.monotonic()
    try:
        proc = subprocess.run([sys.executable, "-c", code, str(path), "--out", str(tmp_path / "out"), "-q",
                               "--scheduler", f"tcp://127.0.0.1:{port}"], capture_output=True, text=True, timeout=90)
    finally:
        stop.set()
        thread.join(timeout=10)  # no thread outlives the test (forked runs need a single-threaded process)
        server.close()
        for conn in accepted:
            conn.close()
    assert accepted, "the client never connected"
    assert proc.returncode == 2 and time.monotonic() - t0 < 60, proc.stderr
    assert proc.stderr.splitlines() == [f"ddcm-sweep: error: the Dask scheduler at tcp://127.0.0.1:{port} did not "
                                        "answer within 1 s (is it a Dask scheduler?)"]


# ---------------------------------------------------------------------------- no dashboard
_PROBE = """
import json, signal, socket
from ddcm_casadi.sweep.runner import dask_client

def listening():
    with socket.socket() as probe:
        probe.settimeout(1.0)
        return probe.connect_ex(("127.0.0.1", 8787)) == 0

if __name__ == "__main__":
    before = listening()  # another program (or a concurrent test run) may hold it
    with dask_client(workers=1) as client:
        during = listening()
        port = client.scheduler_info()["services"].get("dashboard")
        ignored = sorted({int(v) for v in client.run(lambda: signal.getsignal(signal.SIGINT)).values()})
    print(json.dumps(dict(before=before, during=during, port=port, ignored=ignored)))
"""


def test_a_local_cluster_opens_nothing_on_8787(tmp_path):
    """dashboard_address=None turned the dashboard's pages off, but the scheduler still listened on 8787."""
    script = tmp_path / "probe.py"
    script.write_text(_PROBE)
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    seen = json.loads(proc.stdout.strip().splitlines()[-1])
    assert seen["port"] != 8787 and (seen["before"] or not seen["during"])
    assert seen["ignored"] == [int(signal.SIG_IGN)]  # the workers ignore the terminal's Ctrl-C


# ------------------------------------------------------------- data range and --strict
def test_data_range_and_non_converged_steps_reach_sweep_csv_warnings_and_strict(tmp_path):
    """A case beyond its data (DATA RANGE EXCEEDED) or with a non-converged step exited 0 with no word."""
    path = write_spec(tmp_path / "spec", 'base = "base.toml"\nvariants = ["classical", "ddcm"]\n'
                                         'formulations = ["fischer_burmeister"]\n[generate]\n'
                                         '[grid]\n"generate.strain_min" = [-0.01, -0.001]\n')
    out = tmp_path / "out"
    code, err = sweep_cli(str(path), "--out", str(out), "--workers", "1", "-q", "--no-plots")
    assert code == 0, err
    rows = read_csv(out / "sweep.csv")
    ddcm = [r for r in rows if r["variant"] == "ddcm"]
    assert [r["extrapolated_steps"] for r in ddcm][0] == "0" and int(ddcm[1]["extrapolated_steps"]) > 0
    assert int(ddcm[1]["max_extrapolated_states"]) >= 1
    assert "WARNING: DATA RANGE EXCEEDED in 1 cases" in err and ddcm[1]["case"] in err
    assert sweep_cli(str(path), "--out", str(out), "--workers", "1", "-q", "--strict")[0] == 3  # (nothing reruns)
    # a non-converged step: the warning and --strict (two outer iterations of DDCM are not enough
    # for the whole steps; without step bisection, which reaches them in sub-steps)
    path = write_spec(tmp_path / "nc", 'base = "base.toml"\nvariants = ["ddcm"]\nformulations = ["fischer_burmeister"]\n'
                                       '[grid]\n"ddcm.max_outer" = [2]\nmin_substep = [0]\n')
    code, err = sweep_cli(str(path), "--out", str(tmp_path / "nc_out"), "--workers", "1", "-q", "--strict", "--no-plots")
    row = read_csv(tmp_path / "nc_out" / "sweep.csv")[0]
    assert row["converged_steps"] != row["steps"], row
    assert code == 3 and "WARNING: 1 cases have non-converged steps" in err


# ------------------------------------------------------------- continuum cases in sweeps
def _hertz_base() -> str:
    text = (ROOT / "examples" / "cases" / "hertz2d.toml").read_text()
    text = text.replace("divisions = [10, 10]", "divisions = [4, 4]").replace("points = 101", "points = 11")
    return "\n".join(line for line in text.splitlines() if not line.startswith("refine_near"))


def test_generate_makes_mandel_data_for_a_continuum(tmp_path):
    """[generate] on a continuum case failed with a message about a deleted temporary data file;
    it now makes the case's Mandel data (3 components in plane strain), noise on every component."""
    from ddcm_casadi.data.dataset import MaterialDataset
    from ddcm_casadi.data.metric import isotropic_elasticity
    from ddcm_casadi.sweep.generators import DataGenerator
    from ddcm_casadi.sweep.spec import load_spec

    base = _hertz_base()
    spec = ('base = "base.toml"\nvariants = ["ddcm"]\nformulations = ["fischer_burmeister"]\n'
            '[generate]\npoints = 7\n[grid]\n"generate.noise" = [0.0, 0.01]\n')
    path = write_spec(tmp_path, spec, base)
    cases = list(load_spec(path).cases)
    generator = DataGenerator(**cases[0].generate)  # the resolved generator a case carries
    assert generator.components == 3 and generator.poisson_ratio == 0.3 and generator.grading == 2
    strain, stress = generator.sample()
    C = isotropic_elasticity(200e9, 0.3, 2)[0]
    reference = MaterialDataset.hookean_grid(C, -0.012, 0.012, 7, c=C, grading=2)
    np.testing.assert_array_equal(strain, reference.strain)
    np.testing.assert_allclose(stress, reference.stress, rtol=1e-15, atol=0)
    noisy = DataGenerator(**cases[1].generate).sample()[1]
    # multiplicative noise, 1 %: every nonzero component moves, by a few percent at most (5 sigma)
    moved = stress != 0
    assert np.all(noisy[moved] != stress[moved]) and np.max(np.abs(noisy - stress)) <= 0.05 * np.max(np.abs(stress))
    out = tmp_path / "out"
    code, err = sweep_cli(str(path), "--out", str(out), "--workers", "1", "-q")
    assert code == 0, err
    rows = read_csv(out / "sweep.csv")
    assert len(rows) == 2 and all(r["status"] == "ok" and int(r["converged_steps"]) == int(r["steps"]) for r in rows)


def test_generate_refuses_what_mandel_data_cannot_be(tmp_path):
    """One line, before any work: a one-dimensional law, or a mesh file without components."""
    from ddcm_casadi.sweep.spec import load_spec

    for generate, message in (('law = "tanh"\nstress_scale = 1e9', "makes one-component data"),
                              ("components = 4", "components must be 3 (plane strain) or 6 (3-D)")):
        path = write_spec(tmp_path / generate.split()[0], f'base = "base.toml"\n[generate]\npoints = 5\n{generate}\n'
                          '[grid]\n"generate.noise" = [0.0]\n', _hertz_base())
        with pytest.raises(InputError) as exc:
            load_spec(path)
        assert message in str(exc.value) and "\n" not in str(exc.value) and "ddcm-sweep-" not in str(exc.value)


def test_hertz_metrics_reach_sweep_csv_and_an_empty_figure_is_not_written(tmp_path):
    """The Hertz metrics of continuum cases did not reach sweep.csv, and their figure was written empty."""
    spec = ('base = "base.toml"\nvariants = ["classical"]\nformulations = ["fischer_burmeister"]\n'
            '[grid]\n"mesh.divisions" = [[4, 4], [6, 6]]\n'
            '[[figures]]\nkind = "band"\nx = "mesh.divisions"\ny = "hertz_error_p0"\nfile = "p0.png"\n')
    out = tmp_path / "out"
    code, err = sweep_cli(str(write_spec(tmp_path / "hertz", spec, _hertz_base())), "--out", str(out), "--workers", "1",
                          "-q")
    assert code == 0, err
    rows = read_csv(out / "sweep.csv")
    assert len(rows) == 2 and all(float(r["hertz_force"]) > 0 for r in rows)
    # relative errors of coarse meshes: on the 4 x 4 mesh one node touches, so the measured a is 0
    # and its error exactly 1 (or just below, with a grazing neighbour's roundoff pressure)
    assert all(0 <= float(r[k]) <= 1 for r in rows for k in ("hertz_error_p0", "hertz_error_a", "hertz_error_l2"))
    assert any(float(r["hertz_error_p0"]) > 0 for r in rows)
    # a bar has no Hertz reference: its figure of hertz_error_p0 is skipped with a note, not written empty
    bar = ('base = "base.toml"\nformulations = ["fischer_burmeister"]\n[grid]\n"ddcm.c" = [3e11, 4e11]\n'
           '[[figures]]\nkind = "rate"\nx = "ddcm.c"\ny = "hertz_error_p0"\nfile = "p0.png"\n')
    out = tmp_path / "bar_out"
    code, err = sweep_cli(str(write_spec(tmp_path / "bar", bar)), "--out", str(out), "--workers", "1", "-q")
    assert code == 0, err
    assert not (out / "p0.png").exists() and "figure not drawn: p0.png: no finished case has a value" in err
    assert json.loads((out / "sweep.json").read_text())["figures"] == []
