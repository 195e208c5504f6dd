"""ddcm-casadi: unilateral contact in classical and model-free data-driven computational mechanics.

Three layers:

- the model description (:mod:`ddcm_casadi.model`) says what the problem is;
- a formulation (:mod:`formulations`) says how the contact pairs are enforced and builds the
  CasADi problem;
- a solver (:mod:`ddcm_casadi.solvers`) drives it: Newton, Uzawa, IPOPT homotopy, or the DDCM
  alternating projections.

:func:`compare` runs a model; :func:`run_case` runs a case and writes its results (the entry point
of ``ddcm-compare`` and ``ddcm-sweep``).
"""

from .data import MaterialDataset
from .errors import ConvergenceError, DDCMError, InputError, PhysicsWarning
from .bar import BarModel, bar_model, paper_bar
from .model import ContactModel
from .problem import build_problems
from .harness import Comparison, compare
from .run import CaseRun, run_case
from .version import __version__

__all__ = ["BarModel", "CaseRun", "Comparison", "ConvergenceError", "ContactModel", "DDCMError", "InputError",
           "PhysicsWarning", "MaterialDataset", "bar_model", "build_problems", "compare", "paper_bar", "run_case",
           "__version__"]
