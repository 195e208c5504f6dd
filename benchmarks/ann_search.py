"""Certified nearest-datum search at scale: the strip search (one-component data), faiss's IVF
(the extra ``ann``) and the exact KD-tree, on one machine in one run.

    python benchmarks/ann_search.py N [--components 1|6] [--backends strips,dataset,kdtree,ann]
                                      [--queries 100000] [--out DIR] [--data-dir DIR]

Each backend runs in a fresh process (its peak memory is its own): ``N`` points of a noisy linear
law in the search's coordinates (:func:`law_data`; float32 for ``strips`` and ``ann``, float64
for the KD-tree, which is float64 only), then ``--queries`` states near the data
(:func:`states`). The strip search reads its data from a float32 ``.npy`` file written beforehand
in a temporary folder (``--tmp``, default ``/tmp``) by another process (:func:`law_file`), as a
set larger than memory would be: the file's pages stay in the page cache, outside the measured
process (``--data-dir`` keeps the file, and reuses one of ``N`` points written there before).
Its answers on a sample of 200 states are checked against an exact search that shares nothing
with it (:func:`slab_check`). ``dataset`` is the same file reached as a DDCM user reaches it:
:meth:`MaterialDataset.from_npy <ddcm_casadi.MaterialDataset.from_npy>` (the file's columns as
strain and stress, ``c = 1``, so its scaled coordinates are the file's values) and its
``strips`` search (``[ddcm] search = "strips"``), built from blocks of the file (one more pass
for the data set's frame; the keys are the file's float32 values, the frame applied to the
queries only, so nothing is read from the file to re-rank or certify), without the KD-tree or a
float64 copy; its build seconds include the data set's.
Measured (wall and CPU seconds: on a shared machine the process may get a fraction of a core,
and CPU seconds are what it needed): build seconds; seconds to answer every state exactly (the
certified search widened until every answer is certified); the share certified by the first
search and its seconds; the memory of the structure (bytes a point beside the data) and the
process's peak resident memory above the imports (Linux ``VmHWM``), data included; the load
average of the machine before and after (``os.getloadavg``, 1 minute). Prints a table and writes
``DIR/ann_search_N_k.json`` (atomically).
"""

from __future__ import annotations

import argparse
import json
import mmap
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ddcm_casadi.data.ann import Certificate, IVFSearch, StripSearch
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.data.metric import Metric
from ddcm_casadi.data.search import KDTreeSearch
from ddcm_casadi.io import write_json_atomic

BACKENDS = {"strips": StripSearch, "dataset": StripSearch, "ann": IVFSearch, "kdtree": KDTreeSearch}
#: The backends that search the float32 data file of :func:`law_file` (one component).
FROM_FILE = ("strips", "dataset")


def law_blocks(n: int, components: int, *, seed: int = 0, noise: float = 0.01):
    """``n`` points of a noisy linear law in the search's coordinates, as float64 blocks of up to
    ``2^22`` rows: strain uniform in a box, stress ``C strain`` plus Gaussian noise of ``noise``
    times the stress range (``C``: ``E = 1``, 1 component; isotropic 3-D, ``nu = 0.3``, 6
    components), scaled by the metric ``C``, centred and rotated to the principal axes (as
    :class:`~ddcm_casadi.MaterialDataset` does; the frame of the first block)."""
    rng = np.random.default_rng(seed)
    metric = Metric(1.0) if components == 1 else Metric.isotropic(1.0, 0.3, 3)
    C = metric.matrix
    lo, hi = (-0.05, 0.01) if components == 1 else (-0.01, 0.01)
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
        x -= frame[0]
        if x.shape[1] > 2:
            yield x @ frame[1]
        else:  # by columns: numpy's (m, 2) @ (2, 2) took 360 ns a row here, this 10
            yield np.column_stack([x[:, 0] * frame[1][0, j] + x[:, 1] * frame[1][1, j] for j in range(2)])


def law_data(n: int, components: int, *, dtype=np.float64) -> np.ndarray:
    """The points of :func:`law_blocks` in one ``(n, 2 components)`` array of ``dtype``."""
    X = np.empty((n, 2 * components), dtype=dtype)
    a = 0
    for block in law_blocks(n, components):
        X[a:a + block.shape[0]] = block
        a += block.shape[0]
    return X


def law_file(folder: Path, n: int, queries: int) -> tuple[Path, Path]:
    """:func:`law_data` (one component) written in float32 to ``folder/law.npy`` by plain writes
    (no mapping: the pages go to the page cache, not to this process), and :func:`states` near
    them to ``folder/states.npy``."""
    path = folder / "law.npy"
    header = np.lib.format.open_memmap(path, mode="w+", dtype=np.float32, shape=(n, 2))
    offset = header.offset
    del header
    with open(path, "r+b") as fh:
        fh.seek(offset)
        for block in law_blocks(n, 1):
            block.astype(np.float32).tofile(fh)
    np.save(folder / "states.npy", states(np.load(path, mmap_mode="r"), queries))
    return path, folder / "states.npy"


def slab_check(path: Path, Q: np.ndarray, distance: np.ndarray) -> np.ndarray:
    """The exact nearest distance of each state by a pass over the file in blocks, sharing
    nothing with the search: a datum nearer than ``distance`` lies in the slab
    ``|y_0 - q_0| <= distance`` (enlarged by a relative 1e-9), and only those are measured (the
    states' slabs dealt into layers of disjoint intervals, one ``searchsorted`` a layer)."""
    r = distance * (1 + 1e-9)
    lo, hi = Q[:, 0] - r, Q[:, 0] + r
    layers, ends = [], []
    for i in np.argsort(lo):
        k = next((k for k, e in enumerate(ends) if e < lo[i]), len(ends))
        if k == len(ends):
            layers.append([]), ends.append(-np.inf)
        layers[k].append(i)
        ends[k] = hi[i]
    layers = [np.array(layer) for layer in layers]
    best = np.full(Q.shape[0], np.inf)
    X = np.load(path, mmap_mode="r")
    n, offset = X.shape[0], X.offset
    with open(path, "rb") as fh:
        fh.seek(offset)
        for a in range(0, n, 1 << 18):  # small blocks: their temporaries stay in malloc's heap
            y = np.fromfile(fh, dtype=np.float32, count=2 * min(1 << 18, n - a)).reshape(-1, 2)
            y0 = y[:, 0].astype(np.float64)
            for layer in layers:
                k = np.searchsorted(lo[layer], y0, side="right") - 1
                inside = np.flatnonzero((k >= 0) & (y0 <= hi[layer][np.maximum(k, 0)]))
                owner = layer[k[inside]]
                diff = y[inside].astype(np.float64) - Q[owner]
                np.minimum.at(best, owner, np.sqrt(np.einsum("ij,ij->i", diff, diff)))
    return best


def gathered(X: np.memmap, index: np.ndarray) -> np.ndarray:
    """``X[index]`` (float64) of a memory-mapped file by chunks, each chunk's pages then left to
    the page cache (``MADV_DONTNEED``): each fault maps the 64 KB around it, so 1e5 random rows
    of an 8 GB file would map 6 GB into the process."""
    out = np.empty((index.size, X.shape[1]))
    for a in range(0, index.size, 4096):
        out[a:a + 4096] = X[index[a:a + 4096]]
        X._mmap.madvise(mmap.MADV_DONTNEED)
    return out


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


def measure(backend: str, n: int, components: int, queries: int, data: Path | None = None) -> dict:
    """One backend at one size (run in a fresh process by :func:`main`); ``data``: the folder of
    :func:`law_file` (the strip search over the file)."""
    load = os.getloadavg()[0]
    base = _status("VmRSS:")
    _reset_peak()
    if data is not None:
        X, Q = np.load(data / "law.npy", mmap_mode="r"), np.load(data / "states.npy")
    else:
        X = law_data(n, components, dtype=np.float64 if backend == "kdtree" else np.float32)
        Q = states(X, queries)
    t0, c0 = time.perf_counter(), time.process_time()
    if backend == "dataset":  # the DDCM user's path: the data set's frame, then its strip search
        dataset = MaterialDataset.from_npy(data / "law.npy", c=1.0)
        search = dataset.search("strips")
        Q = dataset.coordinates(Q[:, 0], Q[:, 1])
    else:
        search = StripSearch.from_npy(data / "law.npy") if data is not None else BACKENDS[backend].build(X)
    build, build_cpu = time.perf_counter() - t0, time.process_time() - c0
    row = dict(backend=backend, points=n, components=components, coordinates=X.shape[1], queries=queries,
               load_before=load,
               build_seconds=build, build_cpu_seconds=build_cpu, data_bytes=int(X.nbytes),
               structure_bytes=_structure_bytes(search), peak_build_bytes=_status("VmHWM:") - base)
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
    row["load_after"] = os.getloadavg()[0]
    if data is not None:  # agreement with an exact search on a sample, first search and widened
        pick = np.random.default_rng(2).choice(queries, min(queries, 200), replace=False)
        if backend == "dataset":  # the answers' distances in the file's own coordinates
            Q = np.load(data / "states.npy")
            cert, first = (Certificate(c.index, np.sqrt(np.einsum("ij,ij->i", *(2 * [gathered(X, c.index) - Q]))),
                                       c.bound, c.certified) for c in (cert, first))
        t0 = time.perf_counter()
        truth = slab_check(data / "law.npy", Q[pick], cert.distance[pick])
        tol = 10 * 2.0 ** -53  # the two float64 distances' roundoff (2 coordinates)
        sure = first.certified[pick]
        row.update(check_states=int(pick.size), check_seconds=time.perf_counter() - t0,
                   agreement=float(np.mean(cert.distance[pick] <= truth * (1 + tol))),
                   first_certified_agreement=float(np.mean(first.distance[pick][sure] <= truth[sure] * (1 + tol))),
                   first_sample_certified=float(sure.mean()))
    return row


COLUMNS = ("backend", "points", "coordinates", "load_before", "build_seconds", "build_cpu_seconds", "query_seconds",
           "query_cpu_seconds", "first_seconds", "first_cpu_seconds",
           "first_certified", "certified", "agreement", "structure_bytes_per_point", "peak_build_bytes",
           "peak_bytes")


def table(rows: list[dict]) -> str:
    def cell(v):
        return f"{v:.4g}" if isinstance(v, float) else str(v)
    lines = [" | ".join(COLUMNS), " | ".join("---" for _ in COLUMNS)]
    lines += [" | ".join(cell(r.get(c, "")) for c in COLUMNS) for r in rows]
    return "\n".join(lines)


def _written(folder: Path, n: int, queries: int) -> bool:
    """Whether ``folder`` holds the data file of ``n`` points and ``queries`` states (:func:`law_file`)."""
    try:
        return (np.load(folder / "law.npy", mmap_mode="r").shape == (n, 2)
                and np.load(folder / "states.npy", mmap_mode="r").shape == (queries, 2))
    except (OSError, ValueError):
        return False


def run(n: int, components: int, backends, queries: int, tmp: str = "/tmp", data_dir: str | None = None) -> list[dict]:
    """Each backend in a fresh process; a failure (e.g. faiss missing) is a row with ``error``.
    The one-component strip search reads a float32 file written by another process (in
    ``data_dir``, kept and reused, if given)."""
    rows = []
    for backend in backends:
        with tempfile.TemporaryDirectory(dir=tmp) as scratch:
            folder = Path(data_dir or scratch)
            extra, made = [], None
            if backend in FROM_FILE and components == 1:
                if not _written(folder, n, queries):
                    folder.mkdir(parents=True, exist_ok=True)
                    t0 = time.perf_counter()
                    subprocess.run([sys.executable, __file__, str(n), "--write", str(folder), "--queries",
                                    str(queries)], check=True)
                    made = time.perf_counter() - t0
                extra = ["--data", str(folder)]
            r = subprocess.run([sys.executable, __file__, str(n), "--components", str(components), "--one", backend,
                                "--queries", str(queries), *extra], capture_output=True, text=True)
        if r.returncode == 0:
            rows.append(json.loads(r.stdout.strip().splitlines()[-1]))
            if made is not None:
                rows[-1]["data_file_seconds"] = made
        else:
            rows.append(dict(backend=backend, points=n, components=components,
                             error=(r.stderr.strip().splitlines() or ["killed"])[-1]))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("n", type=float, help="data points (1e8 is accepted)")
    ap.add_argument("--components", type=int, choices=(1, 6), default=1)
    ap.add_argument("--backends", default=None, help="default: strips,dataset,kdtree (1 component), ann,kdtree (6)")
    ap.add_argument("--queries", type=int, default=100_000)
    ap.add_argument("--out", default="results")
    ap.add_argument("--tmp", default="/tmp", help="folder of the strip search's temporary data file")
    ap.add_argument("--data-dir", default=None, help="keep the data file here (and reuse one written before)")
    ap.add_argument("--one", choices=tuple(BACKENDS), help=argparse.SUPPRESS)
    ap.add_argument("--data", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--write", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    n = int(args.n)
    if args.write:
        law_file(args.write, n, args.queries)
        return 0
    if args.one:
        print(json.dumps(measure(args.one, n, args.components, args.queries, args.data)))
        return 0
    backends = (args.backends or ("strips,dataset,kdtree" if args.components == 1 else "ann,kdtree")).split(",")
    rows = run(n, args.components, backends, args.queries, args.tmp, args.data_dir)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    print(table(rows))
    write_json_atomic(Path(args.out) / f"ann_search_{n:.0e}_{args.components}.json", rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
