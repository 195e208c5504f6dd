"""ddcm-casadi: unilateral contact in classical and model-free data-driven computational mechanics.

Three layers:

- the model description (:mod:`ddcm_casadi.models.base`) says what the problem is;
- a formulation (:mod:`formulations`) says how the contact pairs are enforced and builds the
  CasADi problem;
- a solver (:mod:`ddcm_casadi.loops`) drives it: Newton, Uzawa, IPOPT homotopy, or the DDCM
  alternating projections.

:func:`compare` runs a model; :func:`run_case` runs a case and writes its results (the entry point
of ``ddcm-compare`` and ``ddcm-sweep``).
"""

from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.errors import ConvergenceError, DDCMError, InputError, PhysicsWarning
from ddcm_casadi.models.bar import BarModel, bar_model, paper_bar
from ddcm_casadi.models.base import ContactModel
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.drivers.harness import Comparison, compare
from ddcm_casadi.run import CaseRun, run_case
from ddcm_casadi.version import __version__

__all__ = ["BarModel", "CaseRun", "Comparison", "ConvergenceError", "ContactModel", "DDCMError", "InputError",
           "PhysicsWarning", "MaterialDataset", "bar_model", "build_problems", "compare", "paper_bar", "run_case",
           "__version__"]
