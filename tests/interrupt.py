"""Send a real Ctrl-C (SIGINT) to a command once a line of its stderr shows it is at work."""

from __future__ import annotations

import os
import queue
import re
import signal
import subprocess
import threading
from pathlib import Path


def interrupt_at(argv: list[str], cwd: Path, pattern: str, *, delay: float = 0.5) -> tuple[int, str]:
    """Run ``argv`` in ``cwd``, send SIGINT ``delay`` seconds after a stderr line matches
    ``pattern``; returns the exit status and all of stderr.

    Reading stderr to its end also checks that no process of the command outlives it: one still
    holding stderr open would make the last read time out (``queue.Empty``).
    """
    # SIGINT as at a terminal even if the tests run where it is ignored (a background job)
    proc = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    lines: queue.Queue = queue.Queue()
    err: list[str] = []

    def read():
        for line in proc.stderr:
            err.append(line)
            lines.put(line)
        lines.put(None)

    threading.Thread(target=read, daemon=True).start()
    try:
        while True:
            line = lines.get(timeout=300)
            assert line is not None, "".join(err)
            if re.search(pattern, line):
                break
        threading.Event().wait(delay)
        os.kill(proc.pid, signal.SIGINT)
        proc.wait(timeout=120)
    finally:
        proc.kill()
        proc.wait()
    while lines.get(timeout=10) is not None:
        pass
    return proc.returncode, "".join(err)
