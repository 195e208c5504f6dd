"""The first run: the paper's default ``ddcm-compare --out DIR`` against the import time of its
dependencies, both as fresh processes, measured alternately in one run (the machine is shared).

    python benchmarks/first_run.py [--repeats N]

The floor is a process that imports what the run needs and does nothing else: casadi, numpy,
scipy's sparse LU and KD-tree, and matplotlib with its Agg pyplot (``floor_seconds``); the
narrower ``import casadi, numpy, scipy, matplotlib`` (scipy and matplotlib load their submodules
lazily) is reported as ``bare_import_seconds``. Medians over ``repeats`` alternating rounds.

Bytecode: every process runs with Python's bytecode cache on, in a temporary folder
(``PYTHONPYCACHEPREFIX``), filled by one untimed warm-up of each command, so the project's modules
load from bytecode as the dependencies' do (as after ``pip install``, which compiles them). Where
the environment turns the cache off (``PYTHONDONTWRITEBYTECODE=1``), Python compiles the
project's ~50 modules from source in every process: that run is also timed, as
``seconds_without_bytecode_cache``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

from ddcm_casadi.parallel import resolve_jobs

FLOOR = ("import casadi, numpy, scipy.sparse.linalg, scipy.spatial, matplotlib; "
         "matplotlib.use('Agg'); import matplotlib.pyplot")
BARE = "import casadi, numpy, scipy, matplotlib"


def _wall(argv: list[str], env: dict, cwd: str) -> float:
    t0 = time.perf_counter()
    # ``cwd``: a scratch folder, since ``python -m`` / ``-c`` put the working directory first on
    # sys.path (from the repository's root the source tree would shadow the installed package).
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, cwd=cwd)
    return time.perf_counter() - t0


def _environments(tmp: str) -> tuple[dict, dict]:
    """The child processes' environments: bytecode cached in ``tmp`` / never written."""
    cached = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    cached["PYTHONPYCACHEPREFIX"] = os.path.join(tmp, "pycache")
    uncached = {k: v for k, v in os.environ.items() if k != "PYTHONPYCACHEPREFIX"}
    uncached["PYTHONDONTWRITEBYTECODE"] = "1"
    return cached, uncached


def first_run(repeats: int = 5) -> dict:
    """A ``benchmarks.json`` record: ``seconds`` (the default run with its figures and results),
    ``floor_seconds`` (the imports it needs), ``ratio``, ``bare_import_seconds``,
    ``seconds_without_bytecode_cache`` (the run compiling the project's sources) and
    ``seconds_in_one_process`` (``--jobs 1``; by default the 8 runs and the 2 figures go side by
    side in ``jobs`` processes, one per available core)."""
    run, serial, floor, bare, uncompiled = [], [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        cached, uncached = _environments(tmp)
        floor_cmd, bare_cmd = [sys.executable, "-c", FLOOR], [sys.executable, "-c", BARE]

        def run_cmd(out: str) -> list[str]:
            return [sys.executable, "-m", "ddcm_casadi.commands.compare", "--out", os.path.join(tmp, out), "-q"]

        for argv in (floor_cmd, bare_cmd, run_cmd("warm-up")):  # untimed: fills the bytecode cache
            _wall(argv, cached, tmp)
        for i in range(repeats):
            floor.append(_wall(floor_cmd, cached, tmp))
            bare.append(_wall(bare_cmd, cached, tmp))
            run.append(_wall(run_cmd(f"r{i}"), cached, tmp))
            serial.append(_wall(run_cmd(f"s{i}") + ["--jobs", "1"], cached, tmp))
            uncompiled.append(_wall(run_cmd(f"u{i}"), uncached, tmp))
    s, f = statistics.median(run), statistics.median(floor)
    return dict(name="first run: ddcm-compare --out DIR (paper example) / imports", unknowns=1, data_points=500,
                seconds=s, floor_seconds=f, ratio=s / f, bare_import_seconds=statistics.median(bare),
                ratio_to_bare_import=s / statistics.median(bare),
                seconds_without_bytecode_cache=statistics.median(uncompiled),
                seconds_in_one_process=statistics.median(serial), jobs=resolve_jobs(None, 8), repeats=repeats)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    rec = first_run(ap.parse_args(argv).repeats)
    print(f"default run {rec['seconds']:.2f} s, imports it needs {rec['floor_seconds']:.2f} s "
          f"(ratio {rec['ratio']:.2f}), bare imports {rec['bare_import_seconds']:.2f} s "
          f"(ratio {rec['ratio_to_bare_import']:.2f}); without a bytecode cache the run takes "
          f"{rec['seconds_without_bytecode_cache']:.2f} s; in one process (--jobs 1) "
          f"{rec['seconds_in_one_process']:.2f} s (ratio {rec['seconds_in_one_process'] / rec['floor_seconds']:.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
