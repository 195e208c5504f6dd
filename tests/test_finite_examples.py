"""The finite-strain example cases run end to end (shortened: a coarser mesh and the first steps
of their load paths), classical and data-driven, and the exact formulations agree."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi.casefiles.config import load_case_with_overrides
from ddcm_casadi.drivers.harness import compare

CASES = Path(__file__).resolve().parents[1] / "examples" / "cases"
SHORT = {
    "seal2d_finite.toml": ["mesh.refine=2", "contact.0.travel=[0.0, 0.00002, 0.00004, 0.00006]"],
    "indentation3d_finite.toml": ["mesh.divisions=[2, 2, 2]", "contact.0.travel=[0.0, 0.0003]",
                                  "data.samples.count=2000"],
}
# Newton's residual tolerance on the scaled equations, with the forces' relative roundoff: the
# exact formulations solve the same discrete problem, so their forces agree to far below it.
AGREEMENT = 1e-7


@pytest.mark.parametrize("name", sorted(SHORT))
def test_finite_example_runs_and_exact_formulations_agree(name):
    case, _ = load_case_with_overrides(CASES / name, SHORT[name])
    model = case.model
    assert model.kinematics == "finite"
    cmp = compare(model, ["fischer_burmeister", "augmented_lagrangian"], variants=["classical", "ddcm"])
    for (variant, formulation), run in cmp.results.items():
        assert all(s.converged for s in run.steps), (variant, formulation, [s.message for s in run.steps])
        assert all(model.inadmissible(s.u) is None for s in run.steps)
    def forces(variant, formulation):
        return np.array([np.sum(model.contact_area * s.p) for s in cmp[variant, formulation].steps])

    scale = np.max(forces("classical", "fischer_burmeister"))
    assert scale > 0
    # (the shortened 3-D case's coarse data may leave every DDCM point on the zero datum: no force)
    for variant in ("classical", "ddcm"):
        a, b = forces(variant, "fischer_burmeister"), forces(variant, "augmented_lagrangian")
        assert np.max(np.abs(a - b)) <= AGREEMENT * scale, variant
