"""ddcm-casadi: unilateral contact in classical and model-free data-driven computational mechanics.

Three layers:

- the model description (:mod:`ddcm_casadi.model`) says what the problem is;
- a formulation (:mod:`formulations`) says how the contact pairs are enforced and builds the
  CasADi problem;
- a solver (:mod:`ddcm_casadi.solvers`) drives it: Newton, Uzawa, IPOPT homotopy, or the DDCM
  alternating projections.
"""

from importlib.metadata import PackageNotFoundError, version as _version

from .data import MaterialDataset
from .errors import ConvergenceError, DDCMError, InputError, PhysicsWarning
from .bar import BarModel, bar_model, paper_bar
from .model import ContactModel
from .problem import build_problems

try:
    __version__ = _version("ddcm-casadi")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0+unknown"


def __getattr__(name: str):
    # The harness imports the `formulations` package, which imports this package's core modules:
    # load it on first use to keep the import graph acyclic.
    if name in ("compare", "Comparison"):
        from . import harness

        return getattr(harness, name)
    raise AttributeError(f"module 'ddcm_casadi' has no attribute {name!r}")


__all__ = ["BarModel", "Comparison", "ConvergenceError", "ContactModel", "DDCMError", "InputError", "PhysicsWarning",
           "MaterialDataset", "bar_model", "build_problems", "compare", "paper_bar", "__version__"]
