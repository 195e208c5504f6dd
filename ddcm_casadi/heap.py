"""The C heap of the process (glibc): what the large builds give back, and what they keep.

numpy's temporaries live in the C library's heap. After a large factor or a build's temporaries
are freed, glibc keeps their pages in holes later arrays may not fill (:func:`release_heap` gives
them back); while a build allocates and frees the same MB-sized blocks a hundred thousand times,
trimming and re-faulting them costs more than keeping them (:func:`kept_heap`). Both do nothing
where the C library is not glibc.
"""

from __future__ import annotations

import ctypes
import functools
from contextlib import contextmanager
from typing import Callable, Iterator


@functools.cache
def _glibc(name: str) -> Callable | None:
    """glibc's function ``name``, or ``None`` (another C library)."""
    try:
        return getattr(ctypes.CDLL(None), name)
    except (OSError, AttributeError):
        return None


def release_heap() -> None:
    """Give the free pages of the C heap back to the system (glibc's ``malloc_trim(0)``; nothing
    where the C library has none). A freed factor and a build's freed temporaries stay in the
    process's heap otherwise, in holes that later arrays of other sizes do not fill: at 1e5
    points, releasing after the reference scales' factor and the reduction's temporaries took the
    DDCM run's peak from 0.63 to 0.56 GB (``docs/performance.md``). A few milliseconds; called
    after a large factor is dropped and after a reduction is built, not in a loop."""
    trim = _glibc("malloc_trim")
    if trim is not None:
        trim(0)


#: glibc's ``mallopt`` parameters: the heap's trim threshold and the size above which a block is
#: mapped on its own.
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
#: The largest mapping threshold glibc accepts on 64 bits (32 MB), and the trim threshold its own
#: adaptive rule ends at (twice it).
MMAP_MAX, TRIM_AFTER = 32 << 20, 64 << 20


@contextmanager
def kept_heap() -> Iterator[None]:
    """Within it, glibc's heap keeps what numpy frees: blocks up to 32 MB come from the heap and
    the heap is not trimmed, so the build's temporaries (MBs, allocated and freed a hundred
    thousand times at 1e9 data) reuse pages instead of faulting in fresh ones. Measured at 1e8:
    560 000 -> 4 800 minor faults, 1.9-4.9 -> 1.1-2.2 s of system time. Process-wide (glibc's
    settings have no getter): afterwards the trim threshold is left at 64 MB, where glibc's
    adaptive rule ends once a block of 32 MB was freed; not glibc (``mallopt`` missing):
    nothing changes."""
    mallopt = _glibc("mallopt")
    if mallopt is None:
        yield
        return
    mallopt(M_MMAP_THRESHOLD, MMAP_MAX)
    mallopt(M_TRIM_THRESHOLD, (1 << 31) - 1)  # the largest C int: never
    try:
        yield
    finally:
        mallopt(M_TRIM_THRESHOLD, TRIM_AFTER)


def peak_resident_bytes() -> int:
    """The peak resident set of this process since it started its program (Linux ``VmHWM``), in
    bytes; 0 where ``/proc`` has none. Unlike ``getrusage``'s ``ru_maxrss``, which a process
    started by ``fork`` and ``exec`` inherits from its parent (a benchmark's child of a 1.3 GB
    parent reported 1.3 GB), the high-water mark of the new program's own memory."""
    try:
        with open("/proc/self/status") as fh:
            return next((int(line.split()[1]) * 1024 for line in fh if line.startswith("VmHWM:")), 0)
    except OSError:
        return 0
