"""The first run: the paper's default ``ddcm-compare --out DIR`` against the import time of its
dependencies, both as fresh processes, measured alternately in one run (the machine is shared).

    python benchmarks/first_run.py [--repeats N]

The floor is a process that imports what the run needs and does nothing else: casadi, numpy,
scipy's sparse LU and KD-tree, and matplotlib with its Agg pyplot (``floor_seconds``); the
narrower ``import casadi, numpy, scipy, matplotlib`` (scipy and matplotlib load their submodules
lazily) is reported as ``bare_import_seconds``. Medians over ``repeats`` alternating rounds.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time

FLOOR = ("import casadi, numpy, scipy.sparse.linalg, scipy.spatial, matplotlib; "
         "matplotlib.use('Agg'); import matplotlib.pyplot")
BARE = "import casadi, numpy, scipy, matplotlib"


def _wall(argv: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def first_run(repeats: int = 5) -> dict:
    """A ``benchmarks.json`` record: ``seconds`` (the default run with its figures and results),
    ``floor_seconds`` (the imports it needs), ``ratio``, ``bare_import_seconds``."""
    run, floor, bare = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeats):
            floor.append(_wall([sys.executable, "-c", FLOOR]))
            bare.append(_wall([sys.executable, "-c", BARE]))
            run.append(_wall([sys.executable, "-m", "ddcm_casadi.cli", "--out", f"{tmp}/r{i}", "-q"]))
    s, f = statistics.median(run), statistics.median(floor)
    return dict(name="first run: ddcm-compare --out DIR (paper example) / imports", unknowns=1, data_points=500,
                seconds=s, floor_seconds=f, ratio=s / f, bare_import_seconds=statistics.median(bare),
                ratio_to_bare_import=s / statistics.median(bare), repeats=repeats)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    rec = first_run(ap.parse_args(argv).repeats)
    print(f"default run {rec['seconds']:.2f} s, imports it needs {rec['floor_seconds']:.2f} s "
          f"(ratio {rec['ratio']:.2f}), bare imports {rec['bare_import_seconds']:.2f} s "
          f"(ratio {rec['ratio_to_bare_import']:.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
