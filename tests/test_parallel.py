"""Runs and figures side by side in forked processes (``compare(jobs=N)``, ``ddcm-compare --jobs``).

Every result must equal the serial one (the runs share no state), failures and warnings of a worker
must reach the caller as they would serially, and Ctrl-C must stop every process.
"""

from __future__ import annotations

import os
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi import ConvergenceError, InputError, compare
from ddcm_casadi.commands.compare import main
from ddcm_casadi.outputs.save import save_figures
from ddcm_casadi.drivers.ddcm_reduced import build_projection
from ddcm_casadi.drivers.path import DDCMSolver, solve_classical
from ddcm_casadi.parallel import blas_thread_limit, blas_threads, map_forked, resolve_jobs

from .interrupt import interrupt_at
from .test_first_run import FIELDS

CASES = Path(__file__).resolve().parent.parent / "examples" / "cases"
fork_only = pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this platform")


@fork_only
@pytest.mark.parametrize("jobs", [2, 3, 8])
def test_map_forked_returns_every_result_in_order(jobs):
    def run(i):
        time.sleep(0.05)  # long enough for every worker to start and take a share
        return i * i, os.getpid()

    pids = map_forked(run, range(7), jobs=jobs)
    assert [r for r, _ in pids] == [i * i for i in range(7)]
    assert len({pid for _, pid in pids}) > 1  # the work was shared
    assert map_forked(lambda i: i, [], jobs=jobs) == []


@fork_only
def test_map_forked_raises_the_first_failure_in_order():
    def run(i):
        if i in (3, 5):
            raise ValueError(f"run {i} failed")
        return i

    for jobs in (1, 2, 4):
        with pytest.raises(ValueError, match="run 3 failed"):
            map_forked(run, range(8), jobs=jobs)


@fork_only
def test_no_item_starts_after_a_failure(tmp_path):
    """As a serial loop stops at its failure: items already taken finish, no new one starts."""
    def run(i):
        (tmp_path / str(i)).touch()
        if i == 1:
            raise ValueError("run 1 failed")
        time.sleep(0.5)  # the worker's failure comes while this one runs
        return i

    with pytest.raises(ValueError, match="run 1 failed"):
        map_forked(run, range(8), jobs=2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["0", "1"]


@fork_only
def test_compare_side_by_side_raises_as_one_after_the_other(paper):
    selection = {"penalty": {"max_iter": 1}, "fischer_burmeister": {}}
    errors = []
    for jobs in (1, 2):
        with pytest.raises(ConvergenceError) as exc:
            compare(paper, selection, raise_on_failure=True, jobs=jobs)
        errors.append(exc.value)
    assert str(errors[0]) == str(errors[1]) and "step 11 did not converge" in str(errors[0])
    assert errors[0].diagnostics.keys() == errors[1].diagnostics.keys()


@fork_only
def test_map_forked_reissues_the_workers_warnings():
    def run(i):
        warnings.warn(f"warning of run {i}", UserWarning)
        return i

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert map_forked(run, range(4), jobs=2) == [0, 1, 2, 3]
    assert sorted(str(w.message) for w in caught) == [f"warning of run {i}" for i in range(4)]


@fork_only
def test_map_forked_says_what_cannot_be_sent_back():
    with pytest.raises(RuntimeError, match="cannot be sent between processes"):
        map_forked(_closure, range(4), jobs=2)


def _closure(i):
    time.sleep(0.05)  # every worker takes a share
    return lambda: i  # a closure does not pickle


def test_resolve_jobs():
    assert resolve_jobs(1, 8) == 1
    assert resolve_jobs(16, 3) == 3
    assert 1 <= resolve_jobs(None, 8) <= 8
    assert resolve_jobs(4, 0) == 1


@fork_only
def test_compare_side_by_side_equals_one_after_the_other(paper, paper_comparison):
    side = compare(paper, jobs=3)
    assert list(side.results) == list(paper_comparison.results)
    for key, run in paper_comparison.results.items():
        for field in FIELDS:
            np.testing.assert_array_equal(side[key].array(field), run.array(field), err_msg=f"{key} {field}")


@pytest.mark.parametrize("jobs", [0, -1, 1.5, "2", True])
def test_compare_refuses_bad_jobs(paper, jobs):
    with pytest.raises(InputError, match="jobs must be a positive integer"):
        compare(paper, jobs=jobs)


@pytest.mark.parametrize("value", ["0", "-2", "two", "1.5"])
def test_cli_refuses_bad_jobs(value, capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        main(["--jobs", value, "--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    assert f"--jobs: must be a positive integer, got '{value}'" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@fork_only
def test_figures_side_by_side_are_the_serial_figures(paper_comparison, tmp_path):
    model = paper_comparison.model
    one = save_figures(paper_comparison, tmp_path / "one", jobs=1)
    two = save_figures(paper_comparison, tmp_path / "two", jobs=2)
    assert [p.name for p in one] == [p.name for p in two] == list(model.figures(paper_comparison.results))
    for a, b in zip(one, two):
        assert a.read_bytes() == b.read_bytes(), a.name


@fork_only
def test_ctrl_c_stops_every_process(tmp_path):
    """A real SIGINT to ``ddcm-compare --jobs 2`` while two Hertz runs go on side by side:
    ``interrupted``, exit 130, nothing in ``--out``, and no worker left (:func:`interrupt_at`
    reads stderr to its end, which a live worker would hold open)."""
    argv = [sys.executable, "-m", "ddcm_casadi.commands.compare", "--config", str(CASES / "hertz2d.toml"),
            "--set", "mesh.divisions=[16,16]",  # MPCC's steps 2-5 take about 4 s (measured)
            # by the homotopy (not the active set) on the full problem (not condensed on the pairs)
            "--set", "formulations.mpcc.active_set=false", "--set", "condense=false",
            "--formulations", "mpcc,fischer_burmeister", "--variants", "classical", "--jobs", "2",
            "--no-plots", "--out", "out"]
    # the first step of the (slow) MPCC run: both processes are at work
    returncode, text = interrupt_at(argv, tmp_path, r"classical/mpcc\s+step\s+1/5")
    assert returncode == 130, text
    assert text.strip().splitlines()[-1] == "ddcm-compare: interrupted", text
    assert "Traceback" not in text and "mpcc                  step   5/5" not in text
    assert not (tmp_path / "out").exists()


@fork_only
def test_map_forked_is_serial_where_other_threads_run():
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        pids = map_forked(lambda i: os.getpid(), range(4), jobs=4)
    finally:
        stop.set()
        other.join()
    assert set(pids) == {os.getpid()}


@fork_only
def test_map_forked_forks_beside_the_factorising_thread():
    """A large factorisation leaves the factorising thread running (it frees its factors,
    ``ddcm_casadi.linalg``); forks still share the work, and a child factorises large matrices in
    a thread of its own."""
    import scipy.sparse as sp

    from ddcm_casadi.linalg import INTERRUPTIBLE_MIN_SIZE, factorize

    n = INTERRUPTIBLE_MIN_SIZE
    A = sp.diags([np.full(n - 1, -1.0), np.full(n, 2.0), np.full(n - 1, -1.0)], [-1, 0, 1], format="csc")
    factorize(A).solve(np.ones(n))  # starts the factorising thread in this process
    assert threading.active_count() > 1

    def run(i):
        time.sleep(0.05)
        x = factorize(A).solve(np.full(n, float(i)))
        return float(x[0]), os.getpid()

    out = map_forked(run, range(4), jobs=2)
    reference = factorize(A).solve(np.ones(n))[0]
    assert [v for v, _ in out] == pytest.approx([i * reference for i in range(4)])
    assert len({pid for _, pid in out}) > 1


def _blas_threads() -> list[int]:
    from threadpoolctl import threadpool_info

    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_the_solves_run_with_the_blas_threads_of_ddcm_blas_threads(monkeypatch):
    """One BLAS thread by default inside the solves (their dense products are too small to share),
    the library's own setting with 0, and a one-line error for anything else."""
    monkeypatch.delenv("DDCM_BLAS_THREADS", raising=False)
    assert blas_thread_limit() == 1
    np.ones(3) @ np.ones(3)  # BLAS loaded
    outside = _blas_threads()
    assert outside
    with blas_threads():
        assert set(_blas_threads()) == {1}
    assert _blas_threads() == outside
    monkeypatch.setenv("DDCM_BLAS_THREADS", "0")
    with blas_threads():
        assert _blas_threads() == outside
    monkeypatch.setenv("DDCM_BLAS_THREADS", "two")
    with pytest.raises(InputError, match="DDCM_BLAS_THREADS must be an integer"):
        blas_thread_limit()
    for entry in (DDCMSolver.solve, solve_classical, build_projection):
        assert hasattr(entry, "__wrapped__"), entry
