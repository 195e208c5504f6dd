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
from .errors import ConvergenceError, DDCMError, InputError
from .harness import Comparison, compare
from .model import BarModel, ContactModel, bar_model, paper_bar
from .problem import build_problems

try:
    __version__ = _version("ddcm-casadi")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0+unknown"

__all__ = ["BarModel", "Comparison", "ConvergenceError", "ContactModel", "DDCMError", "InputError",
           "MaterialDataset", "bar_model", "build_problems", "compare", "paper_bar", "__version__"]
