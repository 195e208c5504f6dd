"""Approximate nearest-neighbour libraries on DDCM data: faiss, hnswlib, pynndescent.

    python benchmarks/ann_libraries.py N COMPONENTS [--libraries faiss-ivf,hnswlib,...] [--out DIR]

One library per fresh process (its peak memory is its own). Data: ``N`` points of a noisy linear
law in the metric's scaled coordinates (:func:`ann_search.law_data`), 1 component (2 coordinates)
or 6 (12); queries: 1e5 states near the data (:func:`ann_search.states`). Measured: build
seconds, seconds for the 1e5 queries (k = 1, both cores), peak memory above the data, and
recall@1 against the exact KD-tree. Writes ``DIR/ann_libraries_N_k.json``.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ddcm_casadi.io import write_json_atomic

from ann_search import law_data, states  # the script's own folder (run as a script)

LIBRARIES = ("faiss-ivf", "faiss-hnsw", "hnswlib", "pynndescent")
QUERIES = 100_000


def _rss_peak() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def one(library: str, n: int, k: int) -> dict:
    X = law_data(n, k).astype(np.float32)
    Q = states(X, QUERIES).astype(np.float32)
    from scipy.spatial import cKDTree
    truth = cKDTree(X.astype(np.float64), balanced_tree=False, compact_nodes=False).query(Q.astype(np.float64))[1]
    base = _rss_peak()
    d = X.shape[1]
    t0 = time.perf_counter()
    if library.startswith("faiss"):
        import faiss
        faiss.omp_set_num_threads(2)
        if library == "faiss-ivf":
            nlist = int(4 * np.sqrt(n))
            index = faiss.IndexIVFFlat(faiss.IndexFlatL2(d), d, nlist)
            index.train(X[np.random.default_rng(0).choice(n, min(n, 64 * nlist), replace=False)])
            index.add(X)
            index.nprobe = 8
        else:
            index = faiss.IndexHNSWFlat(d, 32)
            index.hnsw.efConstruction = 40
            index.add(X)
            index.hnsw.efSearch = 64
        build = time.perf_counter() - t0
        t0 = time.perf_counter()
        _, idx = index.search(Q, 1)
    elif library == "hnswlib":
        import hnswlib
        index = hnswlib.Index(space="l2", dim=d)
        index.init_index(max_elements=n, ef_construction=100, M=16)
        index.set_num_threads(2)
        index.add_items(X)
        index.set_ef(50)
        build = time.perf_counter() - t0
        t0 = time.perf_counter()
        idx, _ = index.knn_query(Q, k=1)
    else:
        import pynndescent
        index = pynndescent.NNDescent(X, n_neighbors=15, n_jobs=2, low_memory=True)
        index.prepare()
        build = time.perf_counter() - t0
        t0 = time.perf_counter()
        idx, _ = index.query(Q, k=1)
    query = time.perf_counter() - t0
    recall = float(np.mean(np.asarray(idx).reshape(-1) == truth))
    return dict(library=library, points=n, components=k, dims=d, build_seconds=build,
                query_seconds=query, queries=QUERIES, memory_bytes=_rss_peak() - base, recall_at_1=recall)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("n", type=float)
    ap.add_argument("components", type=int, choices=(1, 6))
    ap.add_argument("--libraries", default=",".join(LIBRARIES))
    ap.add_argument("--out", default="results")
    ap.add_argument("--one", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    n = int(args.n)
    if args.one:
        print(json.dumps(one(args.one, n, args.components)))
        return 0
    rows = []
    for lib in args.libraries.split(","):
        r = subprocess.run([sys.executable, __file__, str(n), str(args.components), "--one", lib],
                           capture_output=True, text=True)
        row = json.loads(r.stdout.strip().splitlines()[-1]) if r.returncode == 0 else \
            dict(library=lib, points=n, components=args.components, error=r.stderr.strip().splitlines()[-1:])
        rows.append(row)
        print(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()), flush=True)
    write_json_atomic(Path(args.out) / f"ann_libraries_{n:.0e}_{args.components}.json", rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
