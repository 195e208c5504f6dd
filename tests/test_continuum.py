"""Continua: strain operator and patch tests, every formulation and variant on small 2-D and 3-D
bodies, the Hertz check, and bad input (docs/maths.md, sections 7 and 8)."""

import math
from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi import compare
from ddcm_casadi import formulations
from ddcm_casadi.models.continuum import (Ball, Circle, Contact, Material, Plane, Sphere, Support,
                                   continuum_model, mesh)
from ddcm_casadi.models.continuum import fem
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.errors import InputError
from ddcm_casadi.validation.ladder import EXACT_TOL  # solver tolerances 1e-9..1e-11 scaled: results agree to 1e-8
from ddcm_casadi.data.metric import Metric, isotropic_elasticity
from ddcm_casadi.outputs.save import save_outputs
from ddcm_casadi.validation.reference import ContactQP

ALL = formulations.available()
EXACT = [n for n in ALL if formulations.get(n).exact]
E, NU = 200e9, 0.25


def _body(dim: int, n: int = 2):
    if dim == 2:
        return mesh.rectangle(0.01, 0.01, nx=n, ny=n)
    return mesh.box(0.01, 0.01, 0.01, nx=n, ny=n, nz=n)


# ------------------------------------------------------------------ strain operator (patch test)
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("degree", [1, 2])
def test_linear_displacement_gives_its_exact_strain(dim, degree):
    """u = A x reproduces sym(A) in Mandel notation at every quadrature point, and the
    weights add up to the body's volume (both exact for P1 and P2)."""
    disc = fem.Discretisation.create(_body(dim, 3), degree)
    B, w = fem.strain_operator(disc)
    A = np.random.default_rng(0).normal(size=(dim, dim))
    u = np.zeros(disc.n_dofs)
    X, vd = disc.dof_locations(), disc.vector_dofs()
    for c in range(dim):
        u[vd[c]] = X @ A[c]
    S, r2 = 0.5 * (A + A.T), math.sqrt(2)
    pairs = [(0, 0), (1, 1), (0, 1)] if dim == 2 else [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    expected = [S[a, b] * (1 if a == b else r2) for a, b in pairs]
    assert np.max(np.abs((B @ u).reshape(-1, len(pairs)) - expected)) < 1e-12 * np.max(np.abs(A))
    assert abs(w.sum() - 0.01 ** dim) < 1e-14


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("degree", [1, 2])
def test_rigid_body_modes_strain_nothing(dim, degree):
    """Translations and rotations have zero strain at every quadrature point and are linearly
    independent (3 in 2-D, 6 in 3-D). Coordinates are of order 1e-2 and the modes of order 1, so
    roundoff in ``B @ mode`` stays below 1e-12 of the largest strain ``B`` gives a unit field."""
    disc = fem.Discretisation.create(_body(dim, 3), degree)
    B, _ = fem.strain_operator(disc)
    modes = disc.rigid_body_modes()
    assert modes.shape == (disc.n_dofs, 3 if dim == 2 else 6)
    assert np.linalg.matrix_rank(modes) == modes.shape[1]
    unit = float(abs(B).sum(axis=1).max())  # the largest strain of a field bounded by 1
    assert np.max(np.abs(B @ modes)) <= 1e-12 * unit

@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("degree", [1, 2])
def test_tributary_areas_are_positive_and_add_up(dim, degree):
    body = _body(dim, 3)
    disc = fem.Discretisation.create(body, degree)
    dofs, area = fem.tributary_areas(disc, body.boundaries["ymax" if dim == 2 else "zmax"])
    assert np.all(area > 0)
    assert abs(area.sum() - 0.01 ** (dim - 1)) < 1e-14


# ------------------------------------------------------- contact patch test: uniform compression
def _compression(dim: int, degree: int, *, data=None):
    """A block on rollers (symmetry on every lower face) pressed by a rigid plane on its top:
    uniform uniaxial stress, ``p = M delta / H`` with ``M = E/(1 - nu^2)`` in plane strain
    (lateral expansion free, e_zz = 0) and ``M = E`` in 3-D."""
    top, axes = ("ymax", "xy") if dim == 2 else ("zmax", "xyz")
    supports = [Support(f"{c}min", c) for c in axes]
    normal = [0.0] * (dim - 1) + [-1.0]
    point = [0.0] * (dim - 1) + [0.01]
    plane = Plane(point=point, normal=normal, direction=normal, travel=[0.0, 1e-6, 3e-6])
    mat = Material(youngs_modulus=E, poisson_ratio=NU, data=None if data is None else 0)
    return continuum_model(_body(dim), degree=degree, materials=[mat], supports=supports,
                           contacts=[Contact(plane, top)], datasets=[] if data is None else [data])


def _penalty_expected(p_exact, stiffness_per_area, gamma):
    """A penalty spring in series with the block: ``p = p_exact / (1 + k / gamma)``."""
    return p_exact / (1.0 + stiffness_per_area / gamma)


@pytest.mark.parametrize("dim, degree", [(2, 1), (2, 2), (3, 1)])
def test_compression_patch_test_every_formulation(dim, degree):
    model = _compression(dim, degree)
    M = E / (1 - NU ** 2) if dim == 2 else E
    cmp = compare(model, variants=["classical"])
    for name in ALL:
        r = cmp.results[("classical", name)]
        assert r.converged, name
        for s, delta in zip(r.steps, [0.0, 1e-6, 3e-6]):
            exact = M * delta / 0.01
            expected = exact
            gamma = cmp.formulations[ALL.index(name)].penalty_stiffness(cmp.problems.classical)
            if gamma is not None:
                expected = _penalty_expected(exact, M / 0.01, gamma)
            # Every pair carries the same pressure; relative to the largest pressure
            tol = EXACT_TOL * M * 3e-6 / 0.01
            assert np.max(np.abs(s.p - expected)) <= tol, (name, s.step)


@pytest.mark.parametrize("dim", [2, 3])
def test_classical_agrees_with_the_qp_reference(dim):
    """An independent convex QP (qpOASES) on a body pressed by a round indenter."""
    model = _indented(dim)
    ref = ContactQP(model).solve()
    assert ref.success.all()
    cmp = compare(model, EXACT, variants=["classical"])
    scale = float(np.max(np.abs(ref.p)))
    for name in EXACT:
        r = cmp.results[("classical", name)]
        assert r.converged
        assert np.max(np.abs(r.array("p") - ref.p)) <= EXACT_TOL * scale, name


def _indented(dim: int, *, data=None):
    R = 0.05
    if dim == 2:
        body, ob, top = _body(2, 4), Circle((0.005, 0.01 + R), R, travel=[0.0, 2e-6, 4e-6]), "ymax"
        supports = [Support("ymin", "xy")]
    else:
        body, ob, top = _body(3, 2), Sphere((0.005, 0.005, 0.01 + R), R, direction=(0, 0, -1),
                                            travel=[0.0, 2e-6, 4e-6]), "zmax"
        supports = [Support("zmin", "xyz")]
    mat = Material(youngs_modulus=E, poisson_ratio=NU, data=None if data is None else 0)
    return continuum_model(body, materials=[mat], supports=supports, contacts=[Contact(ob, top)],
                           datasets=[] if data is None else [data])


# ----------------------------------------------------------- every formulation, both variants
@pytest.mark.parametrize("dim", [2, 3])
def test_every_formulation_and_variant_on_a_small_body(dim, tmp_path):
    """All formulations converge in both variants and the exact ones agree with each other
    (DDCM accuracy against data size is the ddcm-validate rung)."""
    C = isotropic_elasticity(E, NU, dim)[0]
    points = 9 if dim == 2 else 5
    data = MaterialDataset.hookean_grid(C, -5e-4, 5e-4, points, c=Metric(C))
    model = _indented(dim, data=data)
    cmp = compare(model)
    for key, r in cmp.results.items():
        assert r.converged, (key, [s.message for s in r.steps if not s.converged])
    for variant in ("classical", "ddcm"):
        ref = cmp.results[(variant, "fischer_burmeister")].array("p")
        # relative to the largest pressure, or to the problem's stress unit if none is larger
        scale = max(float(np.max(np.abs(ref))), model.scales_for(variant)["stress"])
        for name in EXACT:
            assert np.max(np.abs(cmp.results[(variant, name)].array("p") - ref)) <= EXACT_TOL * scale, (variant, name)
    # outputs: VTU series and figures, small JSON fields
    written = save_outputs(cmp, tmp_path)
    names = {p.name for p in written}
    assert "classical_fischer_burmeister.pvd" in names and "pressure_profile.png" in names
    # a mesh file and a material-point file per step and run
    assert len([n for n in names if n.endswith(".vtu")]) == 2 * len(cmp.results) * model.n_steps
    assert "ddcm_fischer_burmeister_points.pvd" in names
    kept = model.results_fields(cmp.fields("ddcm", "fischer_burmeister"))
    assert set(kept) == {"contact_coordinates", "contact_obstacle", "contact_pressure", "contact_pressure_recovered",
                         "contact_gap", "total_contact_force", "obstacle_names", "obstacle_travel_directions",
                         "contact_force_vector_as_modelled", "contact_force_along_travel_as_modelled",
                         "symmetry_factor", "contact_force_along_travel_full_body", "converged", "notes"}


# ----------------------------------------------------------------------------------- Hertz
def test_hertz_2d_on_the_example_mesh():
    """The example's default mesh (P2): ``p0`` within 2 % (the issue's target) and ``a`` within
    one element of the contact zone (the accuracy a nodal contact can resolve)."""
    from ddcm_casadi.casefiles.config import load_case

    case = load_case(Path(__file__).resolve().parent.parent / "examples" / "cases" / "hertz2d.toml")
    model = case.model
    cmp = compare(model, ["fischer_burmeister"], variants=["classical"])
    r = cmp.results[("classical", "fischer_burmeister")]
    assert r.converged
    m = model.reference.measure(model, r.steps[-1].p)
    h = mesh.mesh_size(model.mesh)[0]
    assert m["error_p0"] <= 0.02
    assert abs(m["a_fe"] - m["a_hertz"]) <= h


def test_hertz_formulas():
    """The closed forms against each other: p0 = sqrt(P E*/(pi R)) (2-D), delta = a^2/R and
    F = 4/3 E* sqrt(R) delta^(3/2) (3-D)."""
    from ddcm_casadi.models.continuum.hertz import hertz_2d, hertz_3d

    a, p0 = hertz_2d(1e6, 0.05, 2e11)
    assert math.isclose(p0, math.sqrt(1e6 * 2e11 / (math.pi * 0.05)), rel_tol=1e-14)
    a, p0 = hertz_3d(1e3, 0.01, 2e11)
    delta = a ** 2 / 0.01
    assert math.isclose(4 / 3 * 2e11 * math.sqrt(0.01) * delta ** 1.5, 1e3, rel_tol=1e-12)
    assert math.isclose(p0, 3e3 / (2 * math.pi * a ** 2), rel_tol=1e-14)
    assert hertz_2d(0.0, 0.05, 2e11) == (0.0, 0.0)
    with pytest.raises(InputError, match="compressive load"):
        hertz_3d(-1.0, 0.01, 2e11)


def test_hertz_measure_of_a_step_without_contact():
    """Roundoff pressures of either sign (a penalty's -1e-20 Pa) are no load, not a crash (it
    once ended a 22-minute run while writing its results)."""
    from ddcm_casadi.models.continuum.hertz import HertzReference

    model = _indented(2)
    ref = HertzReference(E, NU, obstacle=0)
    p = np.full(model.n_contacts, -1e-20)
    m = ref.measure(model, p)
    assert m["force"] == 0.0 and m["a_hertz"] == 0.0 and m["p0_hertz"] == 0.0
    assert ref.step_summary(model, p)["hertz_force"] == 0.0


# ------------------------------------------------------------------------------- bad input
def test_contact_on_quadratic_tetrahedra_is_refused():
    """A quadratic triangle's vertex functions integrate to zero: nodal contact cannot work."""
    with pytest.raises(InputError, match="quadratic tetrahedra"):
        _compression(3, 2)


def test_obstacle_that_cannot_touch_is_refused():
    with pytest.raises(InputError, match="cannot touch"):
        continuum_model(_body(2), materials=[Material(youngs_modulus=E, poisson_ratio=NU)],
                        supports=[Support("ymin", "xy")], contacts=[Contact(Circle((0, 1.0), 0.05), "ymax")])


def test_unheld_body_and_bad_data_are_refused():
    with pytest.raises(InputError, match="rigid-body motion"):
        continuum_model(_body(2), materials=[Material(youngs_modulus=E, poisson_ratio=NU)],
                        supports=[Support("ymin", "y")])
    one_component = MaterialDataset.hookean(E, -1e-3, 1e-3, 11, c=E)
    with pytest.raises(InputError, match="needs 3"):
        continuum_model(_body(2), materials=[Material(data=0)], supports=[Support("ymin", "xy")],
                        datasets=[one_component])
    with pytest.raises(InputError, match="positive definite"):
        Metric([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    with pytest.raises(InputError, match="Ball|radius"):
        Ball(center=(0.0, 0.0), radius=-1.0)


def _write_case(tmp_path, text):
    path = tmp_path / "case.toml"
    path.write_text(text)
    return path


_CASE = """
[mesh]
shape = "rectangle"
size = [0.01, 0.01]
divisions = [2, 2]
[material]
youngs_modulus = 200e9
poisson_ratio = 0.3
[[supports]]
boundary = "ymin"
fix = "xy"
[[contact]]
boundary = "ymax"
obstacle = "circle"
radius = 0.05
center = [0.005, 0.06]
travel = [0.0, 1e-6]
"""


@pytest.mark.parametrize("change, message", [
    (("radius = 0.05", "radius = -1"), "radius must be finite and positive"),
    (("boundary = \"ymax\"", "boundary = \"top\""), "unknown boundary"),
    (("poisson_ratio = 0.3", "poisson_ratio = 0.7"), "poisson_ratio must be in"),
    (("center = [0.005, 0.06]", "center = [0.005, 5.0]"), "cannot touch"),
    (("obstacle = \"circle\"", "obstacle = \"sphere\""), "needs a 3-D mesh"),
    (("fix = \"xy\"", "fix = \"y\""), "rigid-body motion"),
    (("divisions = [2, 2]", "divisions = [2, 0]"), "divisions"),
])
def test_bad_case_files_give_one_line_and_write_nothing(tmp_path, change, message):
    from ddcm_casadi.commands.compare import main

    path = _write_case(tmp_path, _CASE.replace(*change))
    out = tmp_path / "out"
    import io
    import contextlib

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        status = main(["--config", str(path), "--out", str(out), "-q"])
    assert status == 2
    lines = err.getvalue().strip().splitlines()
    assert len(lines) == 1 and message in lines[0], lines
    assert not out.exists() or not any(out.iterdir())


def test_data_with_the_wrong_number_of_columns(tmp_path):
    from ddcm_casadi.casefiles.config import load_case

    (tmp_path / "d.csv").write_text("strain,stress\n0,0\n1e-3,2e8\n")
    path = _write_case(tmp_path, _CASE + '[data]\npath = "d.csv"\nc = "isotropic"\n')
    with pytest.raises(InputError, match="strain_1,strain_2,strain_3"):
        load_case(path)


def test_the_case_file_runs_every_variant(tmp_path):
    """The small case end to end through the CLI: VTU series, figures, small JSON."""
    import json

    from ddcm_casadi.commands.compare import main

    path = _write_case(tmp_path, _CASE + '[data]\nhookean = { strain_min = -1e-3, strain_max = 1e-3, points = 5 }\n'
                                         'c = "isotropic"\n')
    out = tmp_path / "out"
    assert main(["--config", str(path), "--out", str(out), "-q", "--formulations", "fischer_burmeister"]) == 0
    doc = json.loads((out / "results.json").read_text())
    run = doc["fields"]["classical/fischer_burmeister"]
    assert set(run) >= {"contact_coordinates", "contact_pressure", "total_contact_force"}
    assert len(run["contact_pressure"]) == 2
    assert (out / "vtu" / "ddcm_fischer_burmeister.pvd").exists()
    assert (out / "deformed_ddcm.png").stat().st_size > 0
