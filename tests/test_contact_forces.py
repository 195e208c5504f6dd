"""The resultant contact forces of a continuum (:func:`~ddcm_casadi.models.continuum.pressure.surface_forces`,
``results.json``, ``results.csv``) and the one symmetry factor a case has.

Closed form: a block on rollers pressed by a plane carries ``F = sigma_nn A`` with
``sigma_nn = E' delta / H`` (``tests/test_contact_pressure_field.py``); the exact formulations give
it to their stopping accuracy (1e-8 relative, as there).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from ddcm_casadi.casefiles.base import read_document
from ddcm_casadi.casefiles.config import case_from_dict
from ddcm_casadi.drivers.harness import compare
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.continuum.hertz import HertzReference
from ddcm_casadi.models.continuum.model import with_reference
from ddcm_casadi.models.continuum.pressure import surface_forces
from ddcm_casadi.outputs.continuum_results import obstacle_forces
from tests.test_contact_pressure_field import DELTA, E, EXACT, EXACT_TOL, H, NU, _exact_pressure, pressed_block

FB = "fischer_burmeister"


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("formulation", EXACT)
def test_resultant_equals_the_applied_load(dim, formulation):
    model = pressed_block(dim)
    cmp = compare(model, [formulation], variants=("classical",))
    r = cmp["classical", formulation]
    last = r.steps[-1]
    load = _exact_pressure(dim) * H ** (dim - 1)  # per unit thickness in 2-D
    vector = surface_forces(model, last.u, last.p)[0, 0]
    expected = np.zeros(dim)
    expected[-1] = -load  # the platen pushes the body down, along its travel
    assert np.max(np.abs(vector - expected)) <= EXACT_TOL * load
    row = cmp.rows()[-1]
    assert row["contact_force_along_travel_as_modelled"] == pytest.approx(load, rel=EXACT_TOL)
    assert row["contact_force_along_travel_full_body"] == row["contact_force_along_travel_as_modelled"]
    # every normal is the platen's: the magnitudes' sum is the resultant here
    assert row["total_contact_force"] == pytest.approx(load, rel=EXACT_TOL)
    kept = model.results_fields(cmp.fields("classical", formulation))
    np.testing.assert_allclose(kept["contact_force_vector_as_modelled"][-1, 0], vector, rtol=0, atol=1e-12 * load)
    assert set(kept["notes"]) >= {"total_contact_force", "contact_force_vector_as_modelled",
                                  "contact_force_along_travel_full_body", "contact_gap"}
    # the gap closes to the solver's accuracy where the platen presses
    assert np.max(np.abs(kept["contact_gap"][-1])) <= EXACT_TOL * DELTA


def test_obstacle_force_of_a_pressed_block():
    """The force-indentation figure's force along the travel is the uniform pressure's resultant."""
    model = pressed_block(3)
    r = compare(model, [FB], variants=("classical",))["classical", FB]
    vectors, along = obstacle_forces(model, r.array("u"), r.array("p"))
    np.testing.assert_allclose(along[-1, 0], _exact_pressure(3) * H ** 2, rtol=EXACT_TOL)


def _hertz3d(**mesh):
    from ddcm_casadi.validation.continuum import EXAMPLE_3D

    doc = read_document(EXAMPLE_3D)
    doc.pop("data", None)
    doc["mesh"].update(mesh)
    return doc


def test_symmetry_factor_is_the_hertz_force_factor():
    """The quarter model's full-body force along the travel is Hertz's force (one factor, 4)."""
    from ddcm_casadi.validation.continuum import EXAMPLE_3D

    model = case_from_dict(_hertz3d(), base_dir=EXAMPLE_3D.parent, source="h.toml").model
    assert model.symmetry_factor == 4.0 == model.reference.force_factor
    cmp = compare(model, [FB], variants=("classical",))
    for row in cmp.rows()[1:]:
        assert row["contact_force_along_travel_full_body"] == pytest.approx(row["hertz_force"], rel=1e-12)


def test_one_symmetry_setting():
    from ddcm_casadi.validation.continuum import EXAMPLE_3D

    base = dict(base_dir=EXAMPLE_3D.parent, source="h.toml")
    assert case_from_dict(_hertz3d(symmetry_factor=2), **base).model.reference.force_factor == 2.0
    doc = _hertz3d()
    doc["mesh"].pop("symmetry_factor")
    doc["hertz"]["force_factor"] = 4  # the older place, alone: taken
    assert case_from_dict(doc, **base).model.symmetry_factor == 4.0
    doc["mesh"]["symmetry_factor"] = 2
    with pytest.raises(InputError, match="differ"):
        case_from_dict(doc, **base)
    doc = _hertz3d(symmetry_factor=0.5)
    with pytest.raises(InputError, match=">= 1"):
        case_from_dict(doc, **base)
    model = case_from_dict(_hertz3d(), **base).model
    with pytest.raises(InputError, match="force_factor"):
        with_reference(model, HertzReference(E, NU))  # force_factor 1 against the model's 4


def test_results_files_name_each_force(tmp_path):
    from ddcm_casadi.commands.compare import main
    from ddcm_casadi.validation.continuum import EXAMPLE_3D

    out = tmp_path / "out"
    assert main(["--config", str(EXAMPLE_3D), "--out", str(out), "-q", "--formulations", FB, "--variants", "classical",
                 "--set", "mesh.refine_near.levels=1", "--no-plots"]) == 0
    doc = json.loads((out / "results.json").read_text())
    run = doc["fields"][f"classical/{FB}"]
    assert run["symmetry_factor"] == 4.0
    assert len(run["contact_gap"][-1]) == len(run["contact_pressure_recovered"][-1]) == len(run["contact_obstacle"])
    header = (out / "results.csv").read_text().splitlines()[0].split(",")
    assert {"contact_force_along_travel_as_modelled", "contact_force_along_travel_full_body", "hertz_force",
            "hertz_pressure_scatter"} <= set(header)


def test_force_columns_see_the_obstacle_where_each_step_puts_it():
    """At finite strain the normals depend on where the obstacle is: each step's row in
    ``results.csv`` must resolve that step's forces with that step's obstacle (the whole-run
    ``obstacle_forces`` is the reference), not the first step's."""
    from ddcm_casadi.models.continuum import mesh as meshes
    from ddcm_casadi.models.continuum.model import Contact, Material, Support, continuum_model
    from ddcm_casadi.models.continuum.obstacles import Circle

    R = 0.01
    model = continuum_model(
        meshes.rectangle(0.02, 0.01, nx=8, ny=4, origin=(0.0, -0.01)), kinematics="finite",
        materials=[Material(None, 1e6, 0.3, law="neo_hookean")],
        supports=[Support("ymin", "xy")],
        contacts=[Contact(Circle((0.012, R), R, direction=(0.3, -1.0), travel=[2e-4, 6e-4, 1e-3]), "ymax")])
    cmp = compare(model, ["fischer_burmeister"], variants=["classical"])
    f = cmp.fields("classical", "fischer_burmeister")
    along = obstacle_forces(model, f["u"], f["contact_pressure"])[1][:, 0]
    rows = [r["contact_force_along_travel_as_modelled"] for r in cmp.rows()]
    assert along[-1] > 0
    np.testing.assert_allclose(rows, along, rtol=1e-12)
