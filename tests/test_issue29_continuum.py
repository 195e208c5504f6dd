"""Issue 29, the continuum items: nothing silent on bad bodies, obstacles, materials and files
(1: unsupported bodies, 2: obstacles through the body, 5: P1 locking, 6: plane-strain von Mises,
13: messages, 14: meshes from files). Each test failed on the code before its fix."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest
import skfem

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from ddcm_casadi import compare
from ddcm_casadi.errors import InputError, PhysicsWarning
from ddcm_casadi.models.continuum import Circle, Contact, Material, Plane, Support, continuum_model, mesh
from ddcm_casadi.models.continuum import model as continuum_module
from ddcm_casadi.models.continuum.model import BodyForce
from tests.test_continuum import _CASE  # a 10 mm square pressed by a circle

E, NU = 200e9, 0.3


def _two_bodies() -> skfem.MeshTri1:
    """Two copies of a 20 x 10 mm rectangle, 30 mm apart, sharing no node."""
    one = mesh.rectangle(0.02, 0.01, nx=4, ny=2)
    shifted = one.p.copy()
    shifted[0] += 0.05
    return skfem.MeshTri1(np.hstack([one.p, shifted]), np.hstack([one.t, one.t + one.p.shape[1]]))


def _left_edge(x: np.ndarray) -> np.ndarray:
    return np.abs(x[0]) < 1e-9


def _gravity_model(body: skfem.MeshTri1):
    return continuum_model(body, materials=[Material(youngs_modulus=E, poisson_ratio=NU)],
                           supports=[Support(_left_edge, "xy")], body_forces=[BodyForce((0.0, -8e4))],
                           load_factors=[0.5, 1.0, 1.5])


# ------------------------------------------------------------------------ 1: unsupported bodies
def test_item1_an_unsupported_second_body_is_refused():
    """The supports hold only the first of two disconnected rectangles: refused, naming the body."""
    with pytest.raises(InputError, match=r"rigid-body motion of body 2 of 2"):
        _gravity_model(_two_bodies())


def test_item1_the_true_equilibrium_check_catches_a_singular_solve(monkeypatch):
    """Without the build-time refusal, the penalty solve of the singular system meets its own
    scaled test (residual ~1e-17) while the true |K u - f - G^T a p| is 3 times the load (0.4 to
    0.7 of the larger element forces): every step must end not converged, saying so."""
    monkeypatch.setattr(continuum_module, "_check_held", lambda model: None)
    result = compare(_gravity_model(_two_bodies()), ["penalty"], variants=("classical",))
    steps = result["classical", "penalty"].steps
    assert steps and not any(s.converged for s in steps)
    assert all("true equilibrium error" in s.message for s in steps)


def test_item1_a_held_body_passes_the_equilibrium_check():
    """The same load on one held rectangle converges: the check is no false alarm."""
    result = compare(_gravity_model(mesh.rectangle(0.02, 0.01, nx=4, ny=2)), ["penalty"], variants=("classical",))
    assert all(s.converged for s in result["classical", "penalty"].steps)


# ------------------------------------------------------------- 2: an obstacle through the body
def _indented_block(travel, radius: float = 0.05):
    """A 20 x 10 mm block held at its bottom, a circle of radius 50 mm above it moving down."""
    block = mesh.rectangle(0.02, 0.01, nx=4, ny=2)
    circle = Contact(Circle((0.01, 0.01 + radius), radius, direction=(0.0, -1.0), travel=travel), "ymax")
    return continuum_model(block, materials=[Material(youngs_modulus=E, poisson_ratio=NU)],
                           supports=[Support("ymin", "xy")], contacts=[circle])


def test_item2_an_obstacle_through_the_body_is_refused():
    """Travel 0.5 m into a 10 mm block: the circle is out the other side, every gap positive
    again; refused in one line rather than converged with zero force."""
    with pytest.raises(InputError, match=r"passes through the body") as err:
        _indented_block([0.0, 0.5])
    assert "\n" not in str(err.value)


def test_item2_an_ordinary_indentation_passes():
    """Travel of 20 um into the same block (a usual indentation) builds."""
    assert _indented_block([0.0, 1e-5, 2e-5]).n_contacts > 0


# ----------------------------------------------------------------- 5: near-incompressible P1
def _pressed_block(nu: float, degree: int):
    """A 10 x 10 mm block on its bottom, pressed by a plane 1 um into its top."""
    plane = Plane(point=(0.0, 0.01), normal=(0.0, -1.0), direction=(0.0, -1.0), travel=[0.0, 1e-6])
    return continuum_model(mesh.rectangle(0.01, 0.01, nx=2, ny=2), degree=degree,
                           materials=[Material(youngs_modulus=E, poisson_ratio=nu)],
                           supports=[Support("ymin", "xy")], contacts=[Contact(plane, "ymax")])


def test_item5_near_incompressible_p1_warns_and_points_to_p2(tmp_path):
    """nu = 0.4999 on P1: a PhysicsWarning naming P2, also in results.json's warnings."""
    import json

    from ddcm_casadi.casefiles.config import load_case
    from ddcm_casadi.run import run_case

    with pytest.warns(PhysicsWarning, match=r"P1.*degree = 2"):
        result = compare(_pressed_block(0.4999, 1), ["penalty"], variants=("classical",))
    assert any("locks" in w for w in result.warnings)
    case = tmp_path / "case.toml"
    case.write_text(_CASE.replace("poisson_ratio = 0.3", "poisson_ratio = 0.4999"))
    with pytest.warns(PhysicsWarning):
        run_case(load_case(case), tmp_path / "out", formulations=["penalty"], variants=["classical"], figures=False)
    warnings = json.loads((tmp_path / "out" / "results.json").read_text())["warnings"]
    assert any("degree = 2 (P2)" in w for w in warnings)


@pytest.mark.parametrize("nu, degree", [(0.3, 1), (0.4999, 2)])
def test_item5_no_locking_warning_where_there_is_none(nu, degree):
    """Ordinary nu on P1, and any nu on P2: no locking warning."""
    assert not any("locks" in w for w in _pressed_block(nu, degree).path_warnings())


# ------------------------------------------------------------- 6: plane-strain von Mises stress
def test_item6_plane_strain_sigma_zz_in_the_vtu_and_von_mises(tmp_path):
    """Classical: sigma_zz = nu (s11 + s22) in the stress tensor and in von Mises, element by
    element (the block pressed by a plane). DDCM: sigma_zz unknown (its 2-D data carry none), NaN
    in the tensor and von Mises, with an in-plane von Mises beside them."""
    import meshio

    from ddcm_casadi.data.dataset import MaterialDataset
    from ddcm_casadi.data.metric import Metric, isotropic_elasticity
    from ddcm_casadi.outputs.continuum_results import write_vtu

    D = isotropic_elasticity(E, NU, 2)[0]
    data = MaterialDataset.hookean_grid(D, -2e-4, 2e-4, 7, c=Metric(D))
    plane = Plane(point=(0.0, 0.01), normal=(0.0, -1.0), direction=(0.0, -1.0), travel=[0.0, 1e-6])
    model = continuum_model(mesh.rectangle(0.01, 0.01, nx=2, ny=2),
                            materials=[Material(youngs_modulus=E, poisson_ratio=NU, data=0)],
                            supports=[Support("ymin", "xy")], contacts=[Contact(plane, "ymax")], datasets=[data])
    cmp = compare(model, ["penalty"])
    write_vtu(cmp, tmp_path)
    classical = meshio.read(tmp_path / "vtu" / "classical_penalty_0001.vtu")
    stress = classical.cell_data["stress"][0].reshape(-1, 3, 3)
    s11, s22, s12, s33 = stress[:, 0, 0], stress[:, 1, 1], stress[:, 0, 1], stress[:, 2, 2]
    assert np.max(np.abs(s22)) > 0  # the block is loaded
    # exact arithmetic up to roundoff of the per-element mean: 1e-12 of the stress
    scale = np.max(np.abs(stress))
    np.testing.assert_allclose(s33, NU * (s11 + s22), atol=1e-12 * scale)
    mean = (s11 + s22 + s33) / 3
    expected = np.sqrt(1.5 * ((s11 - mean) ** 2 + (s22 - mean) ** 2 + (s33 - mean) ** 2 + 2 * s12 ** 2))
    np.testing.assert_allclose(classical.cell_data["von_mises"][0], expected, rtol=1e-12, atol=1e-12 * scale)
    ddcm = meshio.read(tmp_path / "vtu" / "ddcm_penalty_0001.vtu")
    assert np.isnan(ddcm.cell_data["stress"][0].reshape(-1, 3, 3)[:, 2, 2]).all()
    assert np.isnan(ddcm.cell_data["von_mises"][0]).all()
    assert np.isfinite(ddcm.cell_data["von_mises_in_plane"][0]).all()


# ------------------------------------------------------------------------------ 13: messages


def _cli(tmp_path, text: str, *sets: str, capsys=None) -> tuple[int, str]:
    """``ddcm-compare --config case.toml --set ...``: its exit status and its stderr."""
    from ddcm_casadi.commands.compare import main

    case = tmp_path / "case.toml"
    case.write_text(text)
    args = ["--config", str(case), "--formulations", "penalty", "--variants", "classical", "-q"]
    for s in sets:
        args += ["--set", s]
    try:
        code = main(args)
    except SystemExit as stop:  # argparse's errors exit
        code = stop.code
    return code, capsys.readouterr().err


def _path_case(path: str) -> str:
    return _CASE.replace('shape = "rectangle"\nsize = [0.01, 0.01]\ndivisions = [2, 2]', f'path = "{path}"')


@pytest.mark.parametrize("setup, sets, expected", [
    ("folder", (), r"mesh path .*mesh is a folder, not a mesh file"),
    ("garbage", (), r"cannot read Gmsh file .*garbage\.msh: not a Gmsh mesh \(undecodable bytes\)"),
    (None, ("mesh.degree=3",), r"\[mesh\] degree must be 1 \(P1\) or 2 \(P2\), got 3$"),
    (None, ("mesh.refine_near={point=[0.5, 0.5], radius=0.004, levels=2}",),
     r"\[mesh\] refine_near: no mesh node lies within radius 0\.004 of point \(0\.5, 0\.5\)$"),
    (None, ("contact.0.radius=1e300",), r"out of range: the classical problem's displacement scale is 1e\+300"),
])
def test_item13_case_file_messages(tmp_path, capsys, setup, sets, expected):
    """Each a single line naming what is wrong, exit status 2, no 'array(' and no traceback."""
    text = _CASE
    if setup == "folder":
        (tmp_path / "mesh").mkdir()
        text = _path_case("mesh")
    elif setup == "garbage":
        (tmp_path / "garbage.msh").write_bytes(bytes(range(128, 256)) * 20)
        text = _path_case("garbage.msh")
    code, err = _cli(tmp_path, text, *sets, capsys=capsys)
    lines = [line for line in err.splitlines() if "error" in line]
    assert code == 2 and len(lines) == 1, err
    assert re.search(expected, lines[0]), lines[0]
    assert "array(" not in err and "Traceback" not in err


def test_item13_a_contact_boundary_matching_no_facet():
    """From the API: a facet test no facet passes is named, not a numpy ValueError."""
    contact = Contact(Circle((0.01, 0.06), 0.05, travel=[0.0, 1e-6]), lambda x: x[1] > 1.0)
    with pytest.raises(InputError, match=r"contact 0 \(obstacle .*\): boundary its facet test matches no boundary facet"):
        continuum_model(mesh.rectangle(0.02, 0.01, nx=4, ny=2), materials=[Material(youngs_modulus=E, poisson_ratio=NU)],
                        supports=[Support("ymin", "xy")], contacts=[contact])


def test_item13_an_obstacle_pressing_on_fully_fixed_nodes():
    """A plane pressed into the top, which the supports fix in x and y: refused before solving
    (it ended NOT CONVERGED), naming the obstacle, the nodes and the penetration."""
    plane = Plane(point=(0.0, 0.01), normal=(0.0, -1.0), direction=(0.0, -1.0), travel=[0.0, 1e-6], name="press")
    with pytest.raises(InputError, match=r"obstacle 'press' presses on 5 contact node\(s\) the supports fix in every "
                                         r"direction .*penetration 1e-06 m at step 1"):
        continuum_model(mesh.rectangle(0.02, 0.01, nx=4, ny=2), materials=[Material(youngs_modulus=E, poisson_ratio=NU)],
                        supports=[Support("ymin", "xy"), Support("ymax", "xy")], contacts=[Contact(plane, "ymax")])


# ------------------------------------------------------------------------ 14: meshes from files
EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "cases"


def test_item14_the_example_mesh_file_with_physical_groups_runs():
    """examples/cases/block_groups.toml on its .msh (boundaries from Gmsh physical names)."""
    from ddcm_casadi.casefiles.config import load_case

    model = load_case(EXAMPLES / "block_groups.toml").model
    assert {"bottom", "top", "left", "4"} <= set(model.mesh.boundaries)
    run = compare(model, ["fischer_burmeister"], variants=("classical",))["classical", "fischer_burmeister"]
    assert run.converged and np.sum(model.contact_area * run.steps[-1].p) > 0


def _facets(case_text: str, tmp_path, section: str = "supports") -> tuple[set, skfem.MeshTri1]:
    """The facets the first ``section`` table of a case selects, and the case's mesh."""
    from ddcm_casadi.casefiles import continuum as parser
    from ddcm_casadi.casefiles.config import load_case
    from ddcm_casadi.models.continuum.mesh import select_facets

    case = tmp_path / "case.toml"
    case.write_text(case_text)
    load_case(case)  # the whole case builds
    # the parser's boundary of the first table of the section, on the case's mesh
    doc = tomllib.loads(case_text)
    body = parser._shape_mesh(doc, tmp_path)[0]
    return set(select_facets(body, parser._boundary(section, doc[section][0], 2)).tolist()), body


def test_item14_boundaries_by_tag_box_and_plane_on_a_file_without_names(tmp_path):
    """A VTU of the example's block has no boundaries: a box and a plane choose them, and pick
    the same facets as the names of the .msh; the unnamed tag 4 of the .msh is its right side."""
    import meshio

    from ddcm_casadi.models.continuum.mesh import read_mesh

    named = read_mesh(EXAMPLES / "block_groups.msh")
    meshio.write(tmp_path / "block.vtu", meshio.Mesh(np.column_stack([named.p.T, np.zeros(named.p.shape[1])]),
                                                     [("triangle", named.t.T)]))
    assert not read_mesh(tmp_path / "block.vtu").boundaries
    text = (EXAMPLES / "block_groups.toml").read_text().replace('path = "block_groups.msh"', 'path = "block.vtu"')
    text = text.replace('boundary = "bottom" ', 'boundary = { point = [0.0, 0.0], normal = [0.0, 1.0] } ')
    text = text.replace('boundary = "top" ', 'boundary = { min = [0.0, 0.01], max = [0.02, 0.01] } ')
    bottom, body = _facets(text, tmp_path, "supports")
    top, _ = _facets(text, tmp_path, "contact")
    # read_mesh keeps the node and element order, so facet numbers agree between the two files
    assert np.array_equal(body.facets, named.facets)
    assert bottom == set(named.boundaries["bottom"].tolist()) and top == set(named.boundaries["top"].tolist())
    on_msh = (EXAMPLES / "block_groups.toml").read_text().replace(
        'path = "block_groups.msh"', f'path = "{EXAMPLES / "block_groups.msh"}"').replace(
        'boundary = "bottom" ', 'boundary = 4 ')
    right, msh = _facets(on_msh, tmp_path, "supports")
    assert right == set(np.flatnonzero(np.isclose(msh.p[0, msh.facets].mean(axis=0), 0.02)).tolist())


def test_item14_a_bad_boundary_table_is_one_line(tmp_path, capsys):
    """A table that is neither a box nor a plane: named in one line, exit 2."""
    text = _CASE.replace('boundary = "ymin"', 'boundary = { centre = [0.0, 0.0] }')
    code, err = _cli(tmp_path, text, capsys=capsys)
    assert code == 2 and "is a box {min, max} or a plane {point, normal[, tolerance]}, got keys centre" in err


def test_item2_an_approach_from_afar_in_one_step_passes():
    """A circle 1 m above the block that comes down 1 m + 10 um in one step only indents it: its
    travel is 1 m, but it touches only after 1 m."""
    block = mesh.rectangle(0.02, 0.01, nx=4, ny=2)
    far = Contact(Circle((0.01, 1.06), 0.05, direction=(0.0, -1.0), travel=[0.0, 1.0 + 1e-5]), "ymax")
    model = continuum_model(block, materials=[Material(youngs_modulus=E, poisson_ratio=NU)],
                            supports=[Support("ymin", "xy")], contacts=[far])
    assert np.min(model.gap_offsets[-1]) < 0
