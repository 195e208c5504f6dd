"""What the peer scripts measure of their own process (they run in the peers' interpreters,
which do not have ddcm-casadi; ``ddcm_casadi.heap.peak_resident_bytes`` is the package's copy)."""


def peak_resident_bytes() -> int:
    """The peak resident set of this process (Linux ``VmHWM``; not ``ru_maxrss``, which a process
    started by a large parent inherits from it), in bytes."""
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmHWM:"))
