"""What every command-line tool shares (``ddcm-compare``, ``ddcm-sweep``, ``ddcm-validate``):
one-line usage errors, exit statuses, and errors and Ctrl-C turned into one line and a status."""

from __future__ import annotations

import argparse
import os
import sys
from typing import Callable, NoReturn

from ddcm_casadi.errors import DDCMError, one_line
from ddcm_casadi.linalg import abandoned_work

#: Exit status of bad input (usage errors included): one line ``prog: error: ...`` on stderr.
EXIT_INPUT = 2
#: Exit status of ``--strict`` when a step did not converge (or a sweep case failed).
EXIT_NOT_CONVERGED = 3
#: Exit status after Ctrl-C (128 + SIGINT, as a shell reports it).
EXIT_INTERRUPTED = 130


class Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, like every other input error."""

    def error(self, message: str) -> NoReturn:
        """Print ``prog: error: message`` on one line and exit with :data:`EXIT_INPUT`.

        Parameters
        ----------
        message : str
            The problem found by :mod:`argparse`.
        """
        self.exit(EXIT_INPUT, f"{self.prog}: error: {one_line(message)} (see --help)\n")


def run_guarded(prog: str, run_command: Callable[[list[str] | None], int], argv: list[str] | None, *,
                interrupted: str = "interrupted") -> int:
    """``run_command(argv)``, with an input error as one line ``prog: error: ...`` and exit status
    :data:`EXIT_INPUT`, running out of memory (``MemoryError``) as one line and :data:`EXIT_INPUT`
    too, and Ctrl-C as ``prog: interrupted`` and status 130 (every command's ``main``). After
    Ctrl-C during a long factorisation (:func:`ddcm_casadi.linalg.abandoned_work`) the process
    leaves at once (``os._exit``): its ``with`` blocks have run, and the interpreter's shutdown
    would free memory under the factorisation still running.

    Parameters
    ----------
    prog : str
        The command's name, the first word of its messages.
    run_command : callable
        The command: parses ``argv`` and returns its exit status.
    argv : list of str, optional
        The arguments (default: ``sys.argv[1:]``, as :mod:`argparse` takes them).
    interrupted : str
        What to say after Ctrl-C.
    """
    try:
        return run_command(argv)
    except DDCMError as exc:
        print(f"{prog}: error: {one_line(exc)}", file=sys.stderr)
        return EXIT_INPUT
    except MemoryError:
        print(f"{prog}: error: out of memory: the case is too big for this machine; use a coarser mesh, "
              "fewer data points or fewer --jobs", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        print(f"{prog}: {interrupted}", file=sys.stderr)
        if abandoned_work():  # a factorisation still runs in its thread: shutting down would free
            sys.stdout.flush()  # its memory under it, so leave at once
            sys.stderr.flush()
            os._exit(EXIT_INTERRUPTED)
        return EXIT_INTERRUPTED
