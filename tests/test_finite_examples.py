"""The finite-strain example cases run end to end (shortened: a coarser mesh and the first steps
of their load paths), classical and data-driven (every step converged, no inverted element), and
the exact classical formulations agree within their stopping tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi.casefiles.config import load_case_with_overrides
from ddcm_casadi.drivers.harness import compare
from ddcm_casadi.validation.finite_strain_rungs import exact_bounds_at

CASES = Path(__file__).resolve().parents[1] / "examples" / "cases"
SHORT = {
    "seal2d_finite.toml": ["mesh.refine=2", "contact.0.travel=[0.0, 0.00002, 0.00004, 0.00006]"],
    "indentation3d_finite.toml": ["mesh.divisions=[2, 2, 2]", "contact.0.travel=[0.0, 0.0003]",
                                  "data.samples.count=2000"],
}
@pytest.mark.parametrize("name", sorted(SHORT))
def test_finite_example_runs_and_exact_formulations_agree(name):
    case, _ = load_case_with_overrides(CASES / name, SHORT[name])
    model = case.model
    assert model.kinematics == "finite"
    cmp = compare(model, ["fischer_burmeister", "augmented_lagrangian"], variants=["classical", "ddcm"])
    for (variant, formulation), run in cmp.results.items():
        assert all(s.converged for s in run.steps), (variant, formulation, [s.message for s in run.steps])
        assert all(model.inadmissible(s.u) is None for s in run.steps)
    def force(variant, formulation, step=-1):
        return float(np.sum(model.contact_area * cmp[variant, formulation].steps[step].p))

    assert force("classical", "fischer_burmeister") > 0
    # the exact formulations solve one discrete problem: at the last step their forces differ by no
    # more than their stopping tests allow, s_p sum(a) |dz| each (|dz| from the system's inverse
    # on the active set, exact_bounds_at)
    last = model.n_steps - 1
    s_p = cmp.problems.scales("mcp")["stress"]
    bound = sum(s_p * float(np.sum(model.contact_area)) * exact_bounds_at(cmp, name, last)
                for name in ("fischer_burmeister", "augmented_lagrangian"))
    assert abs(force("classical", "fischer_burmeister") - force("classical", "augmented_lagrangian")) <= bound
