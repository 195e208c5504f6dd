"""Running a sweep on ``dask.distributed``: one task per case, one folder per finished case.

Every case of a :class:`~ddcm_casadi.sweep.spec.SweepSpec` is one task, :func:`run_case`: a plain
function of the case's resolved parameters (a small dict) that builds the case exactly as a case
file (:func:`~ddcm_casadi.sweep.spec.build_case`), runs it with the library's entry point
(:func:`ddcm_casadi.run.run_case`, writing nothing) and returns small records: summary metrics,
and the rows of ``results.csv`` and the document of ``results.json`` (the one builder,
:func:`ddcm_casadi.run.results_document`, with the fields the model keeps there). Workers need
only the installed package; they write nothing.

The client writes each finished case to ``DIR/cases/<id>/`` (``case.json``: parameters, status,
message and metrics; for a case that ran, ``results.csv`` and ``results.json`` as ``ddcm-compare``
writes them, the swept values and the spec's ``[set]`` recorded as ``parameters.overrides``): the files go to a temporary folder that is then renamed, so a case folder is
complete or absent. A rerun skips the cases whose folder exists (resumable after a crash, a
Ctrl-C or a lost worker); ``force`` reruns every case, ``retry_failed`` the failed ones. A case
that raises is recorded as failed with its message and does not stop the sweep; a task lost by
the cluster (a worker killed more often than Dask retries it) is not recorded, so the next run
runs it. ``DIR/sweep.csv`` and ``DIR/sweep.json`` are then written from the case folders, in
the order of the spec, whatever the order in which the cases finished, with the figures, all
together (:class:`~ddcm_casadi.io.OutputFolder`: a rerun removes the previous sweep's figures it
does not draw). ``DIR`` is locked for the whole run: a second sweep (or ``ddcm-compare``) into it
is refused.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
import time
from contextlib import contextmanager, nullcontext
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

from ddcm_casadi.errors import one_line
from ddcm_casadi.errors import DDCMError, InputError
from ddcm_casadi.io import MANIFEST_FORMAT_KEY, OutputFolder, umask, write_csv_atomic, write_json_atomic
from ddcm_casadi.run import RESULTS_CSV, RESULTS_JSON, run_case as run_library_case
from ddcm_casadi.version import versions as package_versions
from ddcm_casadi.sweep.spec import SweepCase, SweepSpec, build_case, flatten
from ddcm_casadi.sweep.table import case_rows, fits, summary_rows

CASES = "cases"
#: The identity of a ``sweep.json`` written by ``ddcm-sweep`` (its ``format``; see OutputFolder).
SWEEP_FORMAT = "ddcm-casadi sweep"
RECORD = "case.json"


def _message(exc: BaseException) -> str:
    text = one_line(exc)
    return text if isinstance(exc, DDCMError) and text else f"{type(exc).__name__}: {text}"


def run_case(task: dict) -> dict:
    """Run one case (on a worker): build it, compare, and return small records.

    Parameters
    ----------
    task : dict
        ``case`` (the fields of a :class:`SweepCase`), ``base`` (the base case file, against
        whose folder relative paths resolve), ``variants`` and ``formulations`` (lists, or
        ``None`` for the defaults of ``ddcm-compare``), and optionally ``overrides`` (what the
        case changes of the base case, recorded in ``results.json``; default: its parameters).

    Returns
    -------
    dict
        ``status`` (``"ok"`` or ``"failed"``), ``error`` (the one-line message of a failed case),
        ``rows`` (:func:`~ddcm_casadi.sweep.table.summary_rows`), ``results_rows`` and ``results``
        (the content of ``results.csv`` and ``results.json``), ``seconds`` and ``worker``.
    """
    t0 = time.perf_counter()
    try:
        sweep_case = SweepCase(**task["case"])
        case = build_case(sweep_case, Path(task["base"]))
        overrides = task.get("overrides", sweep_case.params)
        run = run_library_case(case, formulations=task["formulations"], variants=task["variants"],
                               overrides=overrides)
        out = dict(status="ok", error=None, rows=summary_rows(run.comparison, run.document["summary"], run.rows),
                   results_rows=run.rows, results=run.document)
    except Exception as exc:  # noqa: BLE001 - any failure of a case is recorded and the sweep goes on
        out = dict(status="failed", error=_message(exc), rows=[], results_rows=None, results=None)
    out["seconds"] = time.perf_counter() - t0
    out["worker"] = _worker()
    return out


def _worker() -> str | None:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):  # not on a dask worker (run in process)
        return None


# ---------------------------------------------------------------------------------- case folders
def read_record(out: Path, case_id: str) -> dict | None:
    """The ``case.json`` record of a finished case, or ``None`` (not run, or unreadable)."""
    import json

    path = out / CASES / case_id / RECORD
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def write_case(out: Path, case: SweepCase, spec: SweepSpec, result: dict) -> dict:
    """Write a finished case to ``out/cases/<id>/`` atomically (a temporary folder, renamed);
    returns its record (what ``case.json`` holds)."""
    cases = out / CASES
    cases.mkdir(exist_ok=True)
    record = dict(id=case.id, index=case.index, params=case.params, status=result["status"], error=result["error"],
                  seconds=result["seconds"], worker=result["worker"],
                  variants=list(spec.variants) if spec.variants else None,
                  formulations=list(spec.formulations) if spec.formulations else None,
                  case=case.doc, generate=case.generate, rows=result["rows"])
    tmp = Path(tempfile.mkdtemp(dir=cases, prefix=f".{case.id}."))
    try:
        if result["results"] is not None:
            write_csv_atomic(tmp / RESULTS_CSV, result["results_rows"])
            write_json_atomic(tmp / RESULTS_JSON, result["results"])  # its files: these two
        write_json_atomic(tmp / RECORD, record)
        os.chmod(tmp, 0o777 & ~umask())
        final = cases / case.id
        if final.exists():  # --force: move the old folder away first, so the new one lands whole
            old = Path(tempfile.mkdtemp(dir=cases, prefix=f".{case.id}.old."))
            os.replace(final, old / case.id)
            os.replace(tmp, final)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return record


def _clean_partial(out: Path) -> None:
    """Remove temporary folders left by an interrupted write (never a finished case)."""
    cases = out / CASES
    if cases.is_dir():
        for p in cases.iterdir():
            if p.name.startswith(".") and p.is_dir():
                shutil.rmtree(p, ignore_errors=True)


# ----------------------------------------------------------------------------------------- dask
def default_workers() -> int:
    """The cores this process may use (the LocalCluster's default size)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


#: Seconds to wait for a ``--scheduler`` to answer Dask's handshake (a peer that accepts TCP and
#: never answers made ``distributed.Client`` wait forever: its handshake read has no timeout).
HANDSHAKE_TIMEOUT = 10.0
#: What the worker processes run first: they ignore SIGINT, so Ctrl-C on the terminal (sent to the
#: whole foreground process group) reaches the client only, which cancels the tasks and closes the
#: cluster; the workers then print no tracebacks.
_IGNORE_SIGINT = "import signal\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\n"


def check_scheduler(address: str, timeout: float | None = None) -> None:
    """Connect to the Dask scheduler at ``address`` and complete Dask's handshake within
    ``timeout`` seconds (default :data:`HANDSHAKE_TIMEOUT`), or raise.

    Raises
    ------
    InputError
        Nothing listens there, the address is malformed, or the peer does not answer in time.
    """
    import asyncio

    from distributed.comm import connect

    timeout = HANDSHAKE_TIMEOUT if timeout is None else timeout

    async def handshake() -> None:
        comm = await asyncio.wait_for(connect(address, timeout=timeout), timeout)
        await comm.close()

    try:
        asyncio.run(handshake())
    except asyncio.TimeoutError:
        raise InputError(f"the Dask scheduler at {address} did not answer within {timeout:g} s "
                         "(is it a Dask scheduler?)") from None
    except (OSError, ValueError, TypeError) as exc:
        raise InputError(f"cannot connect to the Dask scheduler at {address}: {_message(exc)}") from None


@contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored while processes start: an ignored signal stays ignored across ``exec``, so
    the spawned worker processes ignore it from their first instruction (their preload keeps it so)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextmanager
def dask_client(*, workers: int | None = None, scheduler: str | None = None) -> Iterator:
    """A ``distributed.Client``: on an existing scheduler (its handshake bounded by
    :data:`HANDSHAKE_TIMEOUT`), or on a LocalCluster of ``workers`` single-threaded worker
    processes on the loopback interface (CasADi, IPOPT and MUMPS run one solve per process).

    The LocalCluster opens no dashboard: ``dashboard_address=None`` only turns the dashboard's
    pages off, the scheduler still starts its HTTP server on the default port 8787, so it is
    given an ephemeral loopback port. Its workers ignore SIGINT (Ctrl-C stops the client only)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError("ddcm-sweep needs dask.distributed: pip install 'ddcm-casadi[sweep]'") from None
    if scheduler is not None:
        check_scheduler(scheduler)
        try:
            client = Client(scheduler, timeout=f"{HANDSHAKE_TIMEOUT}s")
        except (OSError, ValueError) as exc:
            raise InputError(f"cannot connect to the Dask scheduler at {scheduler}: {_message(exc)}") from None
        with client:
            yield client
        return
    n = workers or default_workers()
    with _sigint_ignored():
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, scheduler_kwargs=dict(dashboard_address="127.0.0.1:0"),
                               preload=[_IGNORE_SIGINT], silence_logs=logging.ERROR)
    logger = logging.getLogger("distributed")
    level = logger.level
    try:
        with cluster, Client(cluster) as client:
            try:
                yield client
            except BaseException:
                # Torn down by an error or Ctrl-C: the local scheduler logs the tasks it is told to
                # forget ("Couldn't gather keys") at ERROR, after the one-line message.
                logger.setLevel(logging.CRITICAL)
                raise
    finally:
        logger.setLevel(level)


def n_workers(client) -> int:
    """How many workers the client's scheduler has."""
    return len(client.scheduler_info(n_workers=-1)["workers"])


# ---------------------------------------------------------------------------------------- sweep
@dataclass
class SweepReport:
    """What a call of :func:`run_sweep` did."""

    out: Path
    total: int
    ran: int = 0
    skipped: int = 0
    failed: list[str] = field(default_factory=list)
    lost: list[str] = field(default_factory=list)
    workers: int | None = None
    seconds: float = 0.0
    fits: list[dict] = field(default_factory=list)
    figures: list[str] = field(default_factory=list)
    #: Figures not drawn, with why (no finite value of their ``y``): ``"file: reason"``.
    skipped_figures: list[str] = field(default_factory=list)


#: ``progress(done, total, case, record_or_None, error_or_None)`` after each case of this run.
Progress = Callable[[int, int, SweepCase, dict | None, str | None], None]


def pending(spec: SweepSpec, out: Path, *, force: bool = False, retry_failed: bool = False) -> array:
    """The indices of the cases still to run (all with ``force``; else those without a finished
    folder, and the failed ones with ``retry_failed``), as a compact array of integers: the cases
    themselves are built again when they are submitted."""
    if force:
        return array("q", range(len(spec.cases)))
    todo = array("q")
    for case in spec.cases:
        record = read_record(out, case.id)
        if record is None or (retry_failed and record.get("status") != "ok"):
            todo.append(case.index)
    return todo


#: Tasks in flight per worker: enough to keep every worker busy, few enough that a grid of 10^6
#: cases never has more than a few hundred cases (and their futures) in memory at once.
BATCH_PER_WORKER = 4
MIN_BATCH = 16


def run_sweep(spec: SweepSpec, out: str | Path, *, workers: int | None = None, scheduler: str | None = None,
              force: bool = False, retry_failed: bool = False, figures: bool = True,
              progress: Progress | None = None, versions: dict | None = None) -> SweepReport:
    """Run the missing cases of ``spec`` on Dask and write ``sweep.csv``, ``sweep.json`` and figures.

    Parameters
    ----------
    spec : SweepSpec
        The validated spec (:func:`~ddcm_casadi.sweep.spec.load_spec`).
    out : str or Path
        The output folder (created if needed).
    workers : int, optional
        Worker processes of the LocalCluster (default: the cores this process may use).
    scheduler : str, optional
        Address of an existing Dask scheduler; then ``workers`` is ignored.
    force, retry_failed : bool
        Rerun every case, or the failed ones too (by default a rerun skips finished cases).
    figures : bool
        Draw the spec's figures (matplotlib is imported only then).
    progress : callable, optional
        Called after every case of this run (see :data:`Progress`); an exception it raises
        (e.g. ``KeyboardInterrupt``) cancels the remaining tasks, keeps the finished cases and
        propagates.
    versions : dict, optional
        Extra entries of ``sweep.json``'s ``versions``.

    Returns
    -------
    SweepReport
    """
    t0 = time.perf_counter()
    out = Path(out)
    if figures and spec.figures:
        from ddcm_casadi.sweep import figures as _figures  # noqa: F401 - a missing matplotlib fails before any work
    # Locked before the cluster starts, to the end: one sweep (or ddcm-compare) per folder, and a
    # refused second sweep starts no workers.
    folder = OutputFolder(out, tool="ddcm-sweep", manifest="sweep.json", identity=SWEEP_FORMAT)
    try:
        todo = pending(spec, out, force=force, retry_failed=retry_failed)
        report = SweepReport(out=out, total=len(spec.cases), skipped=len(spec.cases) - len(todo))
        if len(todo):
            _clean_partial(folder.path)
            with dask_client(workers=workers, scheduler=scheduler) as client:
                report.workers = n_workers(client)
                _run(client, spec, todo, folder.path, report, progress)
        report.seconds = time.perf_counter() - t0
        finish(spec, folder.path, report, figures=figures, versions=versions, folder=folder)
    finally:
        folder.close()
    return report


def _run(client, spec: SweepSpec, todo: array, out: Path, report: SweepReport,
         progress: Progress | None, batch: int | None = None) -> None:
    """Submit the cases of ``todo`` (indices) in batches: at most ``batch`` tasks in flight
    (default :data:`BATCH_PER_WORKER` per worker, at least :data:`MIN_BATCH`), the next submitted
    as one finishes, so memory stays bounded whatever the size of the grid."""
    from distributed import as_completed

    variants = list(spec.variants) if spec.variants else None
    formulations = list(spec.formulations) if spec.formulations else None
    fixed = dict(flatten(spec.document.get("set", {})))  # the spec's [set], applied to every case
    batch = batch or max(MIN_BATCH, BATCH_PER_WORKER * (report.workers or 1))
    indices = iter(todo)
    futures: dict = {}

    def submit() -> object | None:
        index = next(indices, None)
        if index is None:
            return None
        case = spec.cases[index]
        task = dict(case=dict(id=case.id, index=case.index, params=case.params, doc=case.doc, generate=case.generate),
                    base=str(spec.base.resolve()), variants=variants, formulations=formulations,
                    overrides={**fixed, **case.params})
        future = client.submit(run_case, task, pure=False)
        futures[future] = case
        return future

    first = [f for f in (submit() for _ in range(batch)) if f is not None]
    queue = as_completed(first)
    done = 0
    try:
        for future in queue:
            case = futures.pop(future)
            record, error = None, None
            try:
                result = future.result()
            except Exception as exc:  # noqa: BLE001 - a task lost by the cluster: rerun next time
                error = _message(exc)
                report.lost.append(case.id)
            else:
                record = write_case(out, case, spec, result)
                report.ran += 1
                if result["status"] != "ok":
                    report.failed.append(case.id)
            future.release()
            done += 1
            if progress is not None:
                progress(done, len(todo), case, record, error)
            following = submit()
            if following is not None:
                queue.add(following)
    except BaseException:
        client.cancel(list(futures))
        raise


def finish(spec: SweepSpec, out: Path, report: SweepReport, *, figures: bool = True,
           versions: dict | None = None, folder: OutputFolder | None = None) -> None:
    """Write ``sweep.csv``, ``sweep.json`` and the figures from the finished case folders (with
    ``folder``, through its staging folder: all of them or none, and the previous sweep's figures
    that this one does not draw are removed)."""
    with folder.staging() if folder is not None else nullcontext(out) as into:
        _write_summary(spec, out, into, report, figures=figures, versions=versions)


def _write_summary(spec: SweepSpec, out: Path, into: Path, report: SweepReport, *, figures: bool,
                   versions: dict | None) -> None:
    rows, status, index = [], {}, []  # one pass over the cases, none kept (only ids and values)
    for case in spec.cases:
        rec = read_record(out, case.id)
        if rec is not None:
            rows.extend(case_rows(rec, spec.columns))
        status[case.id] = (rec or {}).get("status", "missing")
        index.append(dict(id=case.id, params=case.params, status=status[case.id]))
    report.fits = fits(rows, spec.figures, spec.columns)
    if figures and spec.figures and rows:
        from ddcm_casadi.sweep.figures import save_figures

        report.figures = [p.name for p in save_figures(spec, rows, into, skipped=report.skipped_figures)]
    doc = dict(spec=spec.document, spec_path=str(spec.path), base=str(spec.base), columns=spec.columns,
               cases=len(spec.cases), finished=sum(s != "missing" for s in status.values()),
               failed=sum(s == "failed" for s in status.values()), missing=sum(s == "missing" for s in status.values()),
               ran=report.ran, skipped=report.skipped, lost=len(report.lost), workers=report.workers,
               seconds=report.seconds, fits=report.fits, figures=report.figures,
               versions={**package_versions(), **_dask_versions(), **(versions or {})},
               case_index=index,
               files=["sweep.csv", *report.figures, "sweep.json"],  # the manifest (see OutputFolder)
               **{MANIFEST_FORMAT_KEY: SWEEP_FORMAT})
    write_csv_atomic(into / "sweep.csv", rows)
    write_json_atomic(into / "sweep.json", doc)


def _dask_versions() -> dict:
    try:
        import dask
        import distributed
    except ImportError:
        return {}
    return {"dask": dask.__version__, "distributed": distributed.__version__}
