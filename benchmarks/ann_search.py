"""Certified nearest-datum search at scale: the strip search (one-component data), faiss's IVF
(the extra ``ann``) and the exact KD-tree, on one machine in one run.

    python benchmarks/ann_search.py N [--components 1|6] [--backends strips,kdtree,ann]
                                      [--queries 100000] [--out DIR]

Each backend runs in a fresh process (its peak memory is its own): ``N`` points of a noisy linear
law in the search's coordinates (:func:`law_data`; float32 for ``strips`` and ``ann``, float64
for the KD-tree, which is float64 only), then ``--queries`` states near the data
(:func:`states`). Measured (wall and CPU seconds: on a shared machine the process may get a fraction of a core,
and CPU seconds are what it needed): build seconds; seconds to answer every state exactly (the certified
search widened until every answer is certified); the share certified by the first search and
its seconds; the memory of the structure (bytes a point beside the data) and the process's peak
resident memory above the imports (Linux ``VmHWM``), data included. Prints a table and writes
``DIR/ann_search_N_k.json`` (atomically).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ddcm_casadi.data.ann import IVFSearch, StripSearch
from ddcm_casadi.data.metric import Metric
from ddcm_casadi.data.search import KDTreeSearch
from ddcm_casadi.io import write_json_atomic

BACKENDS = {"strips": StripSearch, "ann": IVFSearch, "kdtree": KDTreeSearch}


def law_data(n: int, components: int, *, seed: int = 0, noise: float = 0.01, dtype=np.float64) -> np.ndarray:
    """``n`` points of a noisy linear law in the search's coordinates: strain uniform in a box,
    stress ``C strain`` plus Gaussian noise of ``noise`` times the stress range (``C``: ``E = 1``,
    1 component; isotropic 3-D, ``nu = 0.3``, 6 components), scaled by the metric ``C``, centred
    and rotated to the principal axes (as :class:`~ddcm_casadi.MaterialDataset` does)."""
    rng = np.random.default_rng(seed)
    metric = Metric(1.0) if components == 1 else Metric.isotropic(1.0, 0.3, 3)
    C = metric.matrix
    lo, hi = (-0.05, 0.01) if components == 1 else (-0.01, 0.01)
    X = np.empty((n, 2 * components), dtype=dtype)
    chunk = 1 << 22
    frame = None
    for a in range(0, n, chunk):
        m = min(chunk, n - a)
        e = rng.uniform(lo, hi, (m, components))
        s = e @ C.T + rng.normal(0.0, noise * (hi - lo) * np.linalg.norm(C, 2), (m, components))
        x = metric.coordinates(e, s)
        if frame is None:
            mean = x.mean(axis=0)
            _, axes = np.linalg.eigh((x - mean).T @ (x - mean))
            frame = (mean, axes[:, ::-1])
        X[a:a + m] = (x - frame[0]) @ frame[1]
    return X


def states(X: np.ndarray, n: int, *, seed: int = 1, spread: float = 0.05) -> np.ndarray:
    """``n`` query states near the data: random data points moved by Gaussian steps of
    ``spread`` times the data's standard deviation along each axis (float64)."""
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, X.shape[0], n)
    sd = X[rng.integers(0, X.shape[0], min(X.shape[0], 100_000))].astype(np.float64).std(axis=0)
    return X[pick].astype(np.float64) + rng.normal(0.0, 1.0, (n, X.shape[1])) * spread * sd


def _status(key: str) -> int:
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith(key)) * 1024


def _reset_peak() -> None:
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")  # the peak (VmHWM) back to the current resident set


def _structure_bytes(search) -> int:
    """Bytes of the arrays a backend holds beside the data it was given (faiss: its lists)."""
    if isinstance(search, IVFSearch):
        return int(search.index.ntotal * (4 * search.index.d + 8) + search.centroids.nbytes)
    if isinstance(search, KDTreeSearch):
        return 16 * search.tree.n  # about 16 bytes a point beside the coordinates (search.kd_tree)
    return int(sum(getattr(search, a).nbytes for a in ("keys", "perm", "offsets", "lo_t", "hi_t", "right_lo",
                                                       "left_hi")))


def measure(backend: str, n: int, components: int, queries: int) -> dict:
    """One backend at one size (run in a fresh process by :func:`main`)."""
    base = _status("VmRSS:")
    _reset_peak()
    X = law_data(n, components, dtype=np.float64 if backend == "kdtree" else np.float32)
    Q = states(X, queries)
    t0, c0 = time.perf_counter(), time.process_time()
    search = BACKENDS[backend].build(X)
    build, build_cpu = time.perf_counter() - t0, time.process_time() - c0
    row = dict(backend=backend, points=n, components=components, coordinates=X.shape[1], queries=queries,
               build_seconds=build, build_cpu_seconds=build_cpu, data_bytes=int(X.nbytes), structure_bytes=_structure_bytes(search))
    if backend == "kdtree":
        t0, c0 = time.perf_counter(), time.process_time()
        search.nearest(Q)
        row.update(query_seconds=time.perf_counter() - t0, query_cpu_seconds=time.process_time() - c0,
                   first_certified=1.0)
    else:
        search.certified(Q[:1000])  # first touches of the structure out of the timings
        t0, c0 = time.perf_counter(), time.process_time()
        cert = search.certified(Q)
        row["query_seconds"], row["query_cpu_seconds"] = time.perf_counter() - t0, time.process_time() - c0
        t0, c0 = time.perf_counter(), time.process_time()
        first = search.certified(Q, rounds=0)
        row["first_seconds"], row["first_cpu_seconds"] = time.perf_counter() - t0, time.process_time() - c0
        row.update(first_certified=float(first.certified.mean()),
                   certified=float(cert.certified.mean()), first_max_gap=float(first.gap.max()),
                   median_distance=float(np.median(cert.distance)))
    row["peak_bytes"] = _status("VmHWM:") - base
    row["structure_bytes_per_point"] = row["structure_bytes"] / n
    return row


COLUMNS = ("backend", "points", "coordinates", "build_seconds", "build_cpu_seconds", "query_seconds",
           "query_cpu_seconds", "first_seconds", "first_cpu_seconds",
           "first_certified", "certified", "structure_bytes_per_point", "peak_bytes")


def table(rows: list[dict]) -> str:
    def cell(v):
        return f"{v:.4g}" if isinstance(v, float) else str(v)
    lines = [" | ".join(COLUMNS), " | ".join("---" for _ in COLUMNS)]
    lines += [" | ".join(cell(r.get(c, "")) for c in COLUMNS) for r in rows]
    return "\n".join(lines)


def run(n: int, components: int, backends, queries: int) -> list[dict]:
    """Each backend in a fresh process; a failure (e.g. faiss missing) is a row with ``error``."""
    rows = []
    for backend in backends:
        r = subprocess.run([sys.executable, __file__, str(n), "--components", str(components), "--one", backend,
                            "--queries", str(queries)], capture_output=True, text=True)
        if r.returncode == 0:
            rows.append(json.loads(r.stdout.strip().splitlines()[-1]))
        else:
            rows.append(dict(backend=backend, points=n, components=components,
                             error=(r.stderr.strip().splitlines() or ["killed"])[-1]))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("n", type=float, help="data points (1e8 is accepted)")
    ap.add_argument("--components", type=int, choices=(1, 6), default=1)
    ap.add_argument("--backends", default=None, help="default: strips,kdtree (1 component), ann,kdtree (6)")
    ap.add_argument("--queries", type=int, default=100_000)
    ap.add_argument("--out", default="results")
    ap.add_argument("--one", choices=tuple(BACKENDS), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    n = int(args.n)
    if args.one:
        print(json.dumps(measure(args.one, n, args.components, args.queries)))
        return 0
    backends = (args.backends or ("strips,kdtree" if args.components == 1 else "ann,kdtree")).split(",")
    rows = run(n, args.components, backends, args.queries)
    print(table(rows))
    write_json_atomic(Path(args.out) / f"ann_search_{n:.0e}_{args.components}.json", rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
