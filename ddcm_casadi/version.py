"""The package's version and the versions of what it runs on (``results.json``'s ``versions``)."""

from __future__ import annotations

import platform
from importlib.metadata import PackageNotFoundError, version as _version

import casadi
import numpy as np
import scipy

try:
    __version__ = _version("ddcm-casadi")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0+unknown"


def versions() -> dict[str, str]:
    """The versions of this package, CasADi, NumPy, SciPy and Python."""
    return {"ddcm_casadi": __version__, "casadi": casadi.__version__, "numpy": np.__version__,
            "scipy": scipy.__version__, "python": platform.python_version()}
