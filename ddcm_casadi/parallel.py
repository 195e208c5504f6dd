"""Independent runs in processes forked from this one (``compare(..., jobs=N)``, ``ddcm-compare --jobs``).

A comparison is a handful of independent runs (formulation x variant) on one model. Forked workers
inherit the model, its built problems and every loaded library, so nothing is pickled on the way
in, and only each run's result (small: per-step records) on the way back. Runs are handed out one
at a time from a shared counter, so a long run does not hold up the others; each result is the
same as in a serial run (the runs share no state).

Ctrl-C reaches the whole process group: workers ignore it and the parent, which gets the
``KeyboardInterrupt``, kills them. Workers die with their parent however it ends (SIGTERM from
``timeout``, CI or a batch scheduler, SIGKILL): on Linux the kernel sends them SIGKILL when it
dies (``PR_SET_PDEATHSIG``); elsewhere a thread of each worker watches its parent and ends the
worker once the parent is gone. An exception in a run is re-raised in the parent (the one of the
first run in order, as a serial loop would have raised it); warnings issued in a worker are
re-issued in the parent. Where ``os.fork`` does not exist (Windows), runs are serial.
"""

from __future__ import annotations

import contextlib
import functools
import os
import pickle
import signal
import sys
import threading
import warnings
from typing import Callable, Iterator, Sequence, TypeVar

from ddcm_casadi.errors import InputError

T = TypeVar("T")
R = TypeVar("R")


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity where the platform reports it)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def physical_memory() -> int | None:
    """The machine's physical memory in bytes (``os.sysconf``), or ``None`` where it is unknown."""
    try:
        pages, size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None
    return int(pages) * int(size) if pages > 0 and size > 0 else None


#: The environment variable that sets the BLAS threads of the package's solves (default 1; ``0``
#: leaves the BLAS library's own setting).
BLAS_THREADS_VARIABLE = "DDCM_BLAS_THREADS"


def blas_thread_limit() -> int:
    """The BLAS threads the package's solves use: ``$DDCM_BLAS_THREADS`` (an integer >= 0), 1 if
    unset. ``0`` means no limit."""
    value = os.environ.get(BLAS_THREADS_VARIABLE, "1").strip()
    if not value.isdigit():
        raise InputError(f"{BLAS_THREADS_VARIABLE} must be an integer >= 0 (0: the BLAS library's own), not {value!r}")
    return int(value)


@contextlib.contextmanager
def blas_threads() -> Iterator[None]:
    """Run the enclosed code with the process's BLAS libraries limited to :func:`blas_thread_limit`
    threads (threadpoolctl), restored on the way out.

    The solves' dense work is many small products (vectors of 1e4-1e6 entries, 6 x 6 rotations,
    condensed systems of a few hundred rows), where waking BLAS threads costs more than the
    product: a DDCM iteration of a 5 050-dof block took 20.5 ms with OpenBLAS's default threads on
    a 2-core machine and 8.5 ms with one, and forked workers (``compare(..., jobs=2)``) would
    otherwise each start their own.
    """
    limit = blas_thread_limit()
    if limit == 0:
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=limit, user_api="blas"):
        yield


def limited_blas(function: Callable[..., R]) -> Callable[..., R]:
    """Decorator: ``function`` runs inside :func:`blas_threads`."""
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        with blas_threads():
            return function(*args, **kwargs)
    return wrapper


def resolve_jobs(jobs: int | None, tasks: int) -> int:
    """Worker processes for ``tasks`` runs: ``jobs`` (``None``: :func:`available_cores`), at most one
    per run."""
    n = available_cores() if jobs is None else int(jobs)
    return max(1, min(n, tasks))


def _other_threads() -> bool:
    """Whether threads other than this one run that a fork must not leave behind (the idle
    factorising thread of :mod:`ddcm_casadi.linalg` may be: :func:`~ddcm_casadi.linalg.fork_safe`)."""
    from ddcm_casadi.linalg import fork_safe

    me = threading.current_thread()
    return any(t is not me and not fork_safe(t) for t in threading.enumerate())


def map_forked(function: Callable[[T], R], items: Sequence[T], *, jobs: int) -> list[R]:
    """``[function(item) for item in items]``, in up to ``jobs`` processes (this one included).

    Parameters
    ----------
    function : callable
        Run in forked workers: it may be a closure over anything (nothing is pickled); its
        result must pickle.
    items : sequence
    jobs : int
        Processes, this one included. Runs are serial here with 1, on a platform without
        ``fork``, and in a process with other Python threads (a dask worker, say): a fork copies
        only the calling thread, so a lock another thread holds would never be released (the
        idle factorising thread excepted, :func:`~ddcm_casadi.linalg.fork_safe`).

    Returns
    -------
    list
        The results in the order of ``items``.
    """
    items = list(items)
    jobs = max(1, min(int(jobs), len(items)))
    if jobs == 1 or not hasattr(os, "fork") or _other_threads():
        return [function(x) for x in items]
    take, stop = _counter(len(items))
    sys.stdout.flush()  # else a worker inherits, and would repeat, what is still buffered
    sys.stderr.flush()
    workers: list[tuple[int, int | None]] = []  # (pid, read end of its pipe while open)
    try:
        for _ in range(jobs - 1):
            workers.append(_fork_worker(function, items, take, stop))
        done: dict[int, tuple[bool, object]] = {}
        _run_items(function, items, take, stop, done)
        caught = _collect(workers, done)
    finally:
        _kill(workers)
    for message, category, filename, lineno in caught:
        warnings.warn_explicit(message, category, filename, lineno)
    out = []
    for i in range(len(items)):
        # An item nobody took lies after a failed one (every process stops at its failure): the
        # first failure in order is raised before any gap is reached.
        ok, value = done.get(i, (False, RuntimeError(f"run {i} was lost between the worker processes")))
        if not ok:
            raise value
        out.append(value)
    return out


def _counter(n: int) -> tuple[Callable[[], int], Callable[[], None]]:
    """``take()``, the next item's index, and ``stop()``, which ends the handing out of ``n`` items:
    a counter shared by this process and the workers it forks."""
    import multiprocessing

    counter = multiprocessing.get_context("fork").Value("q", 0)

    def take() -> int:
        with counter.get_lock():
            i = counter.value
            counter.value += 1
        return i

    def stop() -> None:
        # After a failure no process starts another item (a serial loop would have stopped there);
        # items already taken finish, so every item before the failure has its outcome.
        with counter.get_lock():
            counter.value = max(counter.value, n)

    return take, stop


def _run_items(function, items, take, stop, results: dict[int, tuple[bool, object]]) -> None:
    """Run the items handed out by ``take`` into ``results`` (``(True, result)`` or ``(False,
    exception)``) until none is left; the first exception stops the handing out and this loop."""
    while (i := take()) < len(items):
        try:
            results[i] = (True, function(items[i]))
        except Exception as exc:  # re-raised by map_forked, after the workers are collected
            results[i] = (False, exc)
            stop()
            break


def _fork_worker(function, items, take, stop) -> tuple[int, int]:
    """Fork one worker (:func:`_worker`); its pid and the read end of its pipe."""
    read, write = os.pipe()
    parent = os.getpid()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the worker (coverage does not follow forks)
        os.close(read)
        die_with_parent(parent)
        _worker(function, items, take, stop, write)
    os.close(write)
    return pid, read


def _collect(workers: list[tuple[int, int | None]], done: dict[int, tuple[bool, object]]) -> list:
    """Read each worker's results into ``done`` and reap it, removing it from ``workers`` (which then
    holds only those not yet reaped); the warnings they caught."""
    caught: list = []
    while workers:
        pid, read = workers[0]
        with os.fdopen(read, "rb") as pipe:  # until the worker's end: it writes once, then exits
            workers[0] = (pid, None)
            payload = pipe.read()
        os.waitpid(pid, 0)
        workers.pop(0)
        if not payload:
            raise RuntimeError(f"a worker process (pid {pid}) ended without a result")
        results, worker_warnings = pickle.loads(payload)
        done.update(results)
        caught += worker_warnings
    return caught


def _kill(workers: list[tuple[int, int | None]]) -> None:
    """Interrupted or failed: stop and reap the workers not yet reaped, and close their pipes."""
    for pid, read in workers:
        try:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        except OSError:
            pass
        if read is not None:  # else closed by its reader
            os.close(read)


def die_with_parent(parent: int) -> None:
    """Make this (forked) process end when its parent ``parent`` does, however the parent ends.

    On Linux the kernel sends SIGKILL at the parent's death (``prctl(PR_SET_PDEATHSIG)``); elsewhere,
    or if ``prctl`` is not available, a daemon thread polls the parent's pid twice a second and
    ends the process with ``os._exit`` once it has changed (the worker was re-parented). A parent
    that died before the request took effect is caught by the same pid check.

    Parameters
    ----------
    parent : int
        The pid of the parent, read before the fork.
    """
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            pr_set_pdeathsig = 1
            if libc.prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0) == 0:
                if os.getppid() != parent:  # the parent died before the request
                    os._exit(1)
                return
        except (OSError, AttributeError):  # no libc prctl: watch instead
            pass

    def watch() -> None:
        while os.getppid() == parent:
            threading.Event().wait(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="ddcm-parent-watch", daemon=True).start()


def _worker(function, items, take, stop, write: int) -> None:  # pragma: no cover - runs in a fork
    """A forked worker's life: runs until the counter passes the end, then its results and warnings
    through the pipe ``write``, and ``os._exit`` (no cleanup of the parent's state)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and kills the workers
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # whatever the parent installed: end at once
    results: dict[int, tuple[bool, object]] = {}
    status = 0
    with warnings.catch_warnings(record=True) as caught:
        try:
            _run_items(function, items, take, stop, results)
        except BaseException:  # noqa: BLE001 - the worker must always reach os._exit
            status = 1
    try:
        ws = [(w.message, w.category, w.filename, w.lineno) for w in caught]
        for i, (ok, value) in results.items():
            try:
                pickle.loads(pickle.dumps(value))  # an exception may pickle but not unpickle
            except Exception as exc:  # say what could not be sent, rather than lose the run
                what = "result" if ok else f"exception {type(value).__name__}: {value}"
                results[i] = (False, RuntimeError(f"the run's {what} cannot be sent between processes: {exc}"))
        try:
            payload = pickle.dumps((results, ws))
        except Exception:  # the warnings: send them as text
            payload = pickle.dumps((results, [(str(m), UserWarning, f, n) for m, _, f, n in ws]))
        with os.fdopen(write, "wb") as pipe:
            pipe.write(payload)
        sys.stdout.flush()
        sys.stderr.flush()
    except BaseException:  # noqa: BLE001
        status = 1
    os._exit(status)
