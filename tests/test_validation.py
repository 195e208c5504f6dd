"""The verification ladder (``ddcm-validate``) passes every check, and its outputs are complete."""

import json

import numpy as np
import pytest

from ddcm_casadi.validation import ladder
from ddcm_casadi import paper_bar
from ddcm_casadi.problems.exact import CONTACT, ExactEnumerator
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.commands.validate import main

FIELDS = {"name", "quantity", "value", "reference", "tolerance", "passed", "note"}


@pytest.fixture(scope="module")
def validation(tmp_path_factory):
    out = tmp_path_factory.mktemp("validation")
    status = main(["--out", str(out), "-q"])
    return status, out, json.loads((out / "validation.json").read_text())


def test_every_check_passes(validation):
    status, out, checks = validation
    failed = [c for c in checks if not c["passed"]]
    assert not failed, failed
    assert status == 0
    assert (out / "validation.md").read_text().startswith(f"# Validation: {len(checks)}/{len(checks)}")


def test_records_are_complete(validation):
    _, _, checks = validation
    assert checks
    for c in checks:
        assert FIELDS <= set(c), c
        assert c["passed"] == (abs(c["value"] - c["reference"]) <= c["tolerance"])


@pytest.mark.parametrize("model", ["paper", "stops", "warren", "tower"])
def test_every_rung_model_is_covered(validation, model):
    names = {c["name"].split(" / ")[0] for c in validation[2]}
    label = {"paper": "paper bar", "stops": "bar with 3 stops", "warren": "2-D Warren truss",
             "tower": "3-D tower on a plane"}[model]
    assert label in names


def test_fitted_rate_is_reported(validation):
    rate = next(c for c in validation[2] if "fitted rate" in c["quantity"])
    assert rate["reference"] == -1.0 and "N=16000" in rate["note"]


def test_closed_form_of_stops_bar_solves_the_lcp():
    """The concave-envelope closed form is a solution of the classical problem (checked by the
    exact enumerator, which shares no code with it)."""
    m = ladder.stops_bar()
    problems = build_problems(m)
    ex = ExactEnumerator(problems.classical)
    s = m.scales
    for k in range(m.n_steps):
        sol = ex.solutions(problems.step_params(k))
        assert len(sol) == 1
        u, p = m.closed_form(k)
        assert np.allclose(sol[0].z[:m.n_dofs] * s["displacement"], u, rtol=0, atol=1e-12 * max(1e-3, abs(u).max()))
        assert np.allclose(sol[0].z[m.n_dofs:] * s["stress"], p, rtol=0, atol=1e-9 * max(1.0, abs(p).max()))


def test_bad_option_is_one_line(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--nope"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ddcm-validate: error:")


def test_a_biactive_point_found_on_one_branch_is_judged_on_both():
    """Paper bar at its last step with the datum (w / L, -1e9): the free branch gives u = w, p = 0,
    a biactive point from which raising p lowers the distance (pressure multiplier +1/3 on the
    grazing partition). It is not a local minimum; the contact branch is the only one."""
    m = paper_bar()
    problems = build_problems(m)
    k = m.n_steps - 1
    w = m.load_parameter[k] - m.length
    minima = ExactEnumerator(problems.projection).local_minima(problems.projection_params(k, [w / m.length], [-1e9]))
    assert [b.partition for b in minima] == [(CONTACT,)]
