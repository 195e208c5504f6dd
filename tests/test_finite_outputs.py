"""The outputs of a finite-strain continuum, read back and checked against quantities computed here
independently (:mod:`ddcm_casadi.outputs.continuum_results`, :mod:`ddcm_casadi.outputs.point_cloud`,
``ContinuumModel.results_fields``, the ``force_indentation`` figure, ``ddcm-compare``'s ``wrote`` line).

The case: a 1 x 1 neo-Hookean block (plane strain, 2 x 2 squares), held by rollers on its left and
bottom edges and pressed 30 % by a frictionless plane from above, classical and DDCM (an (E, S) grid
of the same law). On P1 the classical solution is homogeneous, which gives closed forms: the
Cauchy stress is uniaxial, ``-sigma_yy`` the true contact pressure and ``sigma_xx = 0``.

Every check is a measurement (a function returning the largest mismatch) and
``test_the_checks_fail_on_wrong_outputs`` shows that each sees a wrong output.
"""

from __future__ import annotations

import json

import meshio
import numpy as np
import pytest

from ddcm_casadi.casefiles.config import load_case_with_overrides
from ddcm_casadi.commands.compare import written_summary
from ddcm_casadi.data.hyperelastic import lame, neo_hookean_stress
from ddcm_casadi.data.metric import tensor_to_mandel as mandel_vector
from ddcm_casadi.outputs.drawings import drawing
from ddcm_casadi.run import run_case

FORMULATION = "fischer_burmeister"
YOUNG, NU = 1.0, 0.3
NORMAL = np.array([0.0, -1.0])  # the plane's normal (into the body) and direction of travel
TRAVEL = np.array([0.0, 0.1, 0.2, 0.3])
CASE = """\
kinematics = "finite"
[mesh]
shape = "rectangle"
size = [1.0, 1.0]
divisions = [2, 2]
degree = 2
[material]
youngs_modulus = 1.0
poisson_ratio = 0.3
law = "neo_hookean"
[[supports]]
boundary = "ymin"
fix = "y"
[[supports]]
boundary = "xmin"
fix = "x"
[[contact]]
boundary = "ymax"
obstacle = "plane"
point = [0.0, 1.0]
normal = [0.0, -1.0]
direction = [0.0, -1.0]
travel = [0.0, 0.1, 0.2, 0.3]
[data]
law = "neo_hookean"
grid = { strain_min = -0.3, strain_max = 0.3, points = 21 }
c = "isotropic"
"""


def _run(tmp_path_factory, degree: int):
    folder = tmp_path_factory.mktemp(f"finite_p{degree}")
    path = folder / "comp.toml"
    path.write_text(CASE)
    case, overrides = load_case_with_overrides(path, [f"mesh.degree={degree}"])
    out = folder / "out"
    run = run_case(case, out, formulations=[FORMULATION], overrides=overrides)
    return case.model, run, out


@pytest.fixture(scope="module")
def p1(tmp_path_factory):
    return _run(tmp_path_factory, 1)


@pytest.fixture(scope="module")
def p2(tmp_path_factory):
    return _run(tmp_path_factory, 2)


def _mesh(out, variant: str, step: int) -> meshio.Mesh:
    return meshio.read(out / "vtu" / f"{variant}_{FORMULATION}_{step:04d}.vtu")


def _cloud(out, variant: str, step: int) -> meshio.Mesh:
    return meshio.read(out / "vtu" / f"{variant}_{FORMULATION}_points_{step:04d}.vtu")


def _tensors(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=float).reshape(-1, 3, 3)


# ------------------------------------------------------------------ independent computations
def own_deformation_gradient(points: np.ndarray, triangles: np.ndarray, displacement: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` ``F = I + du/dX`` of linear triangles from nodal displacements (``F_33 = 1``):
    ``H = [u1 - u0, u2 - u0] [X1 - X0, X2 - X0]^-1``."""
    X, u = points[:, :2][triangles], displacement[:, :2][triangles]  # (n, 3, 2)
    dX = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]], axis=2)  # columns: edge vectors
    du = np.stack([u[:, 1] - u[:, 0], u[:, 2] - u[:, 0]], axis=2)
    F = np.tile(np.eye(3), (len(triangles), 1, 1))
    F[:, :2, :2] += du @ np.linalg.inv(dX)
    return F


def own_contact_areas(points: np.ndarray, triangles: np.ndarray, on_contact: np.ndarray) -> np.ndarray:
    """Per node (zero off contact): half the length of each boundary edge between two contact nodes
    (the lumped area of linear facets), at the coordinates ``points``."""
    edges = np.sort(triangles[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    boundary = unique[count == 1]
    contact = boundary[on_contact[boundary[:, 0]] & on_contact[boundary[:, 1]]]
    length = np.linalg.norm(points[contact[:, 0]] - points[contact[:, 1]], axis=1)
    area = np.zeros(len(points))
    np.add.at(area, contact[:, 0], length / 2)
    np.add.at(area, contact[:, 1], length / 2)
    return area


def _max_mismatch(a: np.ndarray, b: np.ndarray) -> float:
    """The largest ``|a - b|`` relative to ``max |b|``; infinite where one is NaN and the other not."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if not np.array_equal(np.isnan(a), np.isnan(b)):
        return float("inf")
    ok = ~np.isnan(b)
    scale = float(np.max(np.abs(b[ok]), initial=0.0)) or 1.0
    return float(np.max(np.abs(a[ok] - b[ok]), initial=0.0)) / scale


# ---------------------------------------------------------------------- the checks, as numbers
def jacobian_mismatch(data: dict) -> float:
    """``max |J - det F|`` of written ``J`` and ``deformation_gradient``."""
    return float(np.max(np.abs(data["J"] - np.linalg.det(_tensors(data["deformation_gradient"])))))


def cauchy_asymmetry(data: dict) -> float:
    """``max |sigma - sigma^T| / max |sigma|`` of the written Cauchy stress."""
    s = _tensors(data["cauchy_stress"])
    return float(np.nanmax(np.abs(s - s.transpose(0, 2, 1)))) / (float(np.nanmax(np.abs(s))) or 1.0)


def cauchy_mismatch(data: dict) -> float:
    """The written Cauchy stress against ``F S F^T / J`` of the written ``S`` and ``F``. In plane
    strain (``F e_3 = e_3``) an unknown ``S_33`` (NaN, DDCM) makes ``sigma_33`` alone unknown."""
    F, S = _tensors(data["deformation_gradient"]), _tensors(data["second_piola_kirchhoff_stress"])
    unknown = np.isnan(S[:, 2, 2])
    assert not np.isnan(S[:, :2, :2]).any()
    assert not unknown.any() or np.array_equal(F[unknown][:, 2], np.tile([0.0, 0.0, 1.0], (int(unknown.sum()), 1)))
    expected = np.einsum("nij,njk,nlk->nil", F, np.nan_to_num(S), F) / np.linalg.det(F)[:, None, None]
    expected[unknown, 2, 2] = np.nan
    return _max_mismatch(_tensors(data["cauchy_stress"]), expected)


def strain_mismatch(data: dict, F: np.ndarray) -> float:
    """The written Green-Lagrange strain against ``(F^T F - I) / 2`` of ``F``."""
    expected = 0.5 * (np.einsum("nki,nkj->nij", F, F) - np.eye(3))
    return float(np.max(np.abs(_tensors(data["green_lagrange_strain"]) - expected)))


def law_mismatch(data: dict) -> float:
    """A classical point's written ``S`` against the neo-Hookean law of its written ``E``, in plane
    (the textbook form) and ``S_33 = lambda ln J`` (``C_33 = 1``)."""
    E = mandel_vector(_tensors(data["green_lagrange_strain"]), 2)
    S = _tensors(data["second_piola_kirchhoff_stress"])
    lam, _ = lame(YOUNG, NU)
    in_plane = _max_mismatch(mandel_vector(S, 2), neo_hookean_stress(E, YOUNG, NU, 2))
    log_j = 0.5 * np.log(np.linalg.det(np.eye(2) + 2 * _tensors(data["green_lagrange_strain"])[:, :2, :2]))
    return max(in_plane, _max_mismatch(S[:, 2, 2], lam * log_j))


def pressure_area_mismatch(mesh_file: meshio.Mesh, reference: meshio.Mesh) -> float:
    """On a P1 mesh file: ``true x current area`` against ``nominal x reference area`` at the
    contact nodes, both areas computed here (the current one on the mesh moved by the written
    ``displacement``)."""
    pd = mesh_file.point_data
    tri = mesh_file.cells_dict["triangle"]
    on = pd["contact_node"].astype(bool)
    a0 = own_contact_areas(reference.points, tri, on)
    a = own_contact_areas(mesh_file.points + pd["displacement"], tri, on)
    return _max_mismatch((pd["contact_pressure_true"] * a)[on], (pd["contact_pressure_nominal"] * a0)[on])


def force_mismatch(run_json: dict, step: int, mesh_file: meshio.Mesh) -> float:
    """``results.json``'s force vector and its component along the travel against ``sum a p n``
    over the contact nodes of the mesh file, ``a p`` = current area (computed here) times true
    pressure, ``n`` the plane's normal."""
    pd = mesh_file.point_data
    on = pd["contact_node"].astype(bool)
    a = own_contact_areas(mesh_file.points + pd["displacement"], mesh_file.cells_dict["triangle"], on)
    expected = np.sum(a * pd["contact_pressure_true"]) * NORMAL
    vector = np.asarray(run_json["contact_force_vector_as_modelled"][step][0], dtype=float)
    along = float(run_json["contact_force_along_travel_as_modelled"][step][0])
    scale = max(float(np.linalg.norm(expected)), 1e-300)
    return max(float(np.linalg.norm(vector - expected)), abs(along - expected @ NORMAL)) / scale


def homogeneous_mismatch(data: dict, true_pressure: np.ndarray) -> float:
    """A homogeneous uniaxial compression: ``sigma_yy = -p_true`` at every point and ``sigma_xx =
    sigma_xy = 0`` (free lateral faces), relative to ``p_true``."""
    s = _tensors(data["cauchy_stress"])
    p = float(np.mean(true_pressure))
    return float(max(np.max(np.abs(s[:, 1, 1] + p)), np.max(np.abs(s[:, 0, 0])), np.max(np.abs(s[:, 0, 1])),
                     np.ptp(true_pressure))) / p


# ------------------------------------------------------------------------------------ the P1 run
def test_deformed_configuration_is_the_displacement(p1):
    """Both series carry ``displacement`` (3 components, for *Warp By Vector*): the mesh's equals the
    run's nodal displacement, and moved by it the contact nodes lie on the plane (``y = 1 - s``)."""
    model, run, out = p1
    for variant in ("classical", "ddcm"):
        steps = run.comparison.results[(variant, FORMULATION)].steps
        for k, step in enumerate(steps):
            mesh_file, cloud = _mesh(out, variant, k), _cloud(out, variant, k)
            u = mesh_file.point_data["displacement"]
            assert u.shape == (len(mesh_file.points), 3) and cloud.point_data["displacement"].shape[1] == 3
            np.testing.assert_array_equal(u[:, :2], model.dof_displacement(step.u))
            on = mesh_file.point_data["contact_node"].astype(bool)
            touching = on & (mesh_file.point_data["contact_pressure_nominal"] > 0)
            y = (mesh_file.points + u)[touching, 1]
            if step.converged:
                assert np.max(np.abs(y - (1.0 - TRAVEL[k])), initial=0.0) <= 1e-8, (variant, k)
            if variant == "classical" and k == model.n_steps - 1:
                assert on.any() and touching[on].all()  # the last step presses on every contact node


def test_p1_cells_J_F_and_E_from_our_own_element_gradient(p1):
    """On P1, ``F`` from the written nodal displacement with our own element gradient: the written
    ``deformation_gradient``, ``J = det F`` and ``E = (F^T F - I) / 2`` (cells and points alike)."""
    model, run, out = p1
    worst = dict(F=0.0, J=0.0, E=0.0, cloud=0.0)
    for variant in ("classical", "ddcm"):
        for k in range(model.n_steps):
            mesh_file = _mesh(out, variant, k)
            cells = {name: values[0] for name, values in mesh_file.cell_data.items()}
            F = own_deformation_gradient(mesh_file.points, mesh_file.cells_dict["triangle"],
                                         mesh_file.point_data["displacement"])
            worst["F"] = max(worst["F"], float(np.max(np.abs(_tensors(cells["deformation_gradient"]) - F))))
            worst["J"] = max(worst["J"], float(np.max(np.abs(cells["J"] - np.linalg.det(F)))))
            worst["E"] = max(worst["E"], strain_mismatch(cells, F))
            cloud = _cloud(out, variant, k).point_data
            for name in ("J", "cauchy_stress", "green_lagrange_strain", "second_piola_kirchhoff_stress"):
                worst["cloud"] = max(worst["cloud"], _max_mismatch(cells[name], cloud[name]))
    print(f"P1: max |F - F_own| {worst['F']:.2e}, max |J - det F_own| {worst['J']:.2e}, "
          f"max |E - E(F_own)| {worst['E']:.2e}, cells vs points {worst['cloud']:.2e}")
    assert worst["F"] <= 1e-12 and worst["J"] <= 1e-12 and worst["E"] <= 1e-12 and worst["cloud"] == 0.0
    J = _mesh(out, "classical", model.n_steps - 1).cell_data["J"][0]
    assert np.all(J < 0.9)  # the block is compressed, visibly: the checks see a deformation


def test_p1_classical_is_the_homogeneous_compression(p1):
    """The classical P1 solution is homogeneous: the written Cauchy stress is uniaxial with
    ``-sigma_yy`` the written true pressure (and not the nominal one, nor ``S_yy``), ``S`` the
    neo-Hookean law of ``E`` (``S_33 = lambda ln J``)."""
    model, run, out = p1
    for k in range(1, model.n_steps):
        mesh_file = _mesh(out, "classical", k)
        cells = {name: values[0] for name, values in mesh_file.cell_data.items()}
        on = mesh_file.point_data["contact_node"].astype(bool)
        true = mesh_file.point_data["contact_pressure_true"][on]
        nominal = mesh_file.point_data["contact_pressure_nominal"][on]
        mismatch = homogeneous_mismatch(cells, true)
        print(f"step {k}: homogeneous mismatch {mismatch:.2e}, law mismatch {law_mismatch(cells):.2e}, "
              f"true/nominal {np.mean(true / nominal):.4f}")
        assert mismatch <= 1e-7
        assert law_mismatch(cells) <= 1e-10
        assert abs(np.mean(true / nominal) - 1.0) > 0.02  # the two pressures differ: a real check


def test_p1_true_pressure_times_current_area(p1):
    """``true x current area = nominal x reference area`` at the contact nodes, both areas ours; and
    ``results.json``'s true pressures and areas are the mesh file's."""
    model, run, out = p1
    doc = json.loads((out / "results.json").read_text())
    reference = meshio.read(out / "vtu" / f"classical_{FORMULATION}_0000.vtu")
    worst = 0.0
    for variant in ("classical", "ddcm"):
        rec = doc["fields"][f"{variant}/{FORMULATION}"]
        for k in range(model.n_steps):
            mesh_file = _mesh(out, variant, k)
            worst = max(worst, pressure_area_mismatch(mesh_file, reference))
            true = np.asarray(rec["contact_pressure_true"][k], dtype=float)
            np.testing.assert_allclose(mesh_file.point_data["contact_pressure_true"][model.contact_dofs], true,
                                       rtol=1e-14, atol=0.0)
            area = own_contact_areas(mesh_file.points + mesh_file.point_data["displacement"],
                                     mesh_file.cells_dict["triangle"], mesh_file.point_data["contact_node"] > 0)
            np.testing.assert_allclose(rec["contact_area_current"][k], area[model.contact_dofs], rtol=1e-12)
    print(f"P1: max |true a - nominal a0| / max |nominal a0| = {worst:.2e}")
    assert worst <= 1e-12


def test_results_json_force_is_the_sum_of_a_p_n(p1):
    """Per step, ``results.json``'s force vector is ``sum a p n`` over the contact nodes (our
    current areas, the written true pressures, the plane's normal), and its value along the travel
    that vector's component; the fields are named by what they are."""
    model, run, out = p1
    doc = json.loads((out / "results.json").read_text())
    worst = 0.0
    for variant in ("classical", "ddcm"):
        rec = doc["fields"][f"{variant}/{FORMULATION}"]
        assert {"contact_pressure_nominal", "contact_pressure_true", "contact_force_vector_as_modelled",
                "contact_force_along_travel_as_modelled", "notes"} <= set(rec)
        assert "contact_pressure" not in rec  # which pressure, a reader could not tell
        assert rec["obstacle_travel_directions"] == [NORMAL.tolist()]
        for k in range(1, model.n_steps):
            worst = max(worst, force_mismatch(rec, k, _mesh(out, variant, k)))
    print(f"P1: results.json force vs sum a p n: {worst:.2e}")
    assert worst <= 1e-12
    assert len(json.dumps(doc)) < 20_000  # small: no full fields


def test_force_indentation_figure(p1):
    """``force_indentation.png`` is written and listed; the figure's curves are ``results.json``'s
    force along the travel against the plane's travel, one per run."""
    model, run, out = p1
    doc = json.loads((out / "results.json").read_text())
    assert "force_indentation.png" in doc["files"] and "pressure_profile.png" in doc["files"]
    assert (out / "force_indentation.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    fig = drawing("force_indentation")(run.comparison)
    curves = [line for line in fig.axes[0].get_lines() if len(line.get_xdata()) == model.n_steps]
    assert len(curves) >= 2
    expected = [np.asarray(doc["fields"][f"{v}/{FORMULATION}"]["contact_force_along_travel_as_modelled"])[:, 0]
                for v in ("classical", "ddcm")]
    for line, y in zip(curves[:2], expected):
        np.testing.assert_array_equal(line.get_xdata(), TRAVEL)
        np.testing.assert_allclose(line.get_ydata(), y, rtol=1e-12)
    assert expected[0][-1] > expected[0][1] > 0  # the classical force grows with the travel


# ------------------------------------------------------------------------------------ the P2 run
def test_p2_point_cloud_measures(p2):
    """The P2 material points (three per triangle): ``J = det F``, a symmetric Cauchy stress equal to
    ``F S F^T / J`` of the written ``S`` and ``F``, and (classical) ``S`` the law of ``E``; DDCM's
    unknown ``S_33`` leaves ``sigma_33`` NaN and the in-plane von Mises stress finite."""
    model, run, out = p2
    worst = dict(J=0.0, asym=0.0, cauchy=0.0, law=0.0, E=0.0)
    for variant in ("classical", "ddcm"):
        for k in range(model.n_steps):
            pd = _cloud(out, variant, k).point_data
            assert len(pd["J"]) == model.n_points == 3 * model.mesh.t.shape[1]
            worst["J"] = max(worst["J"], jacobian_mismatch(pd))
            worst["asym"] = max(worst["asym"], cauchy_asymmetry(pd))
            worst["cauchy"] = max(worst["cauchy"], cauchy_mismatch(pd))
            worst["E"] = max(worst["E"], strain_mismatch(pd, _tensors(pd["deformation_gradient"])))
            if variant == "classical":
                worst["law"] = max(worst["law"], law_mismatch(pd))
            else:
                assert np.isnan(_tensors(pd["cauchy_stress"])[:, 2, 2]).all()
                assert np.isfinite(pd["von_mises_cauchy_in_plane"]).all()
    print("P2: max |J - det F| {J:.2e}, max Cauchy asymmetry {asym:.2e}, max |sigma - F S F^T / J| {cauchy:.2e}, "
          "law {law:.2e}, max |E - E(F)| {E:.2e}".format(**worst))
    assert worst["J"] <= 1e-14 and worst["asym"] <= 1e-14 and worst["cauchy"] <= 1e-14
    assert worst["law"] <= 1e-10 and worst["E"] <= 1e-12


def test_p2_ddcm_data_are_E_S_pairs(p2):
    """The DDCM datum fields stay: each point's ``data_strain_mandel``, ``data_stress_mandel`` is an
    ``(E, S)`` pair of the neo-Hookean data (S the law of E)."""
    model, run, out = p2
    pd = _cloud(out, "ddcm", model.n_steps - 1).point_data
    assert {"data_set", "data_index", "data_strain", "data_stress", "ddcm_distance"} <= set(pd)
    E, S = pd["data_strain_mandel"], pd["data_stress_mandel"]
    assert _max_mismatch(S, neo_hookean_stress(E, YOUNG, NU, 2)) <= 1e-10
    # the data moved off the zero state (the compression is homogeneous: one datum may serve all)
    assert np.max(np.abs(E[:, 1])) > 0.1


def test_p2_mesh_fields_and_json(p2):
    """The P2 mesh file: both pressures on the contact nodes (zero elsewhere), element means named
    so; in ``results.json`` ``true x current area = nominal x reference area`` per pair."""
    model, run, out = p2
    doc = json.loads((out / "results.json").read_text())
    for variant in ("classical", "ddcm"):
        mesh_file = _mesh(out, variant, model.n_steps - 1)
        pd = mesh_file.point_data
        assert {"displacement", "contact_pressure_nominal", "contact_pressure_true", "contact_gap"} <= set(pd)
        assert "contact_pressure" not in pd
        off = pd["contact_node"] == 0
        assert np.all(pd["contact_pressure_true"][off] == 0) and np.all(pd["contact_pressure_nominal"][off] == 0)
        assert set(mesh_file.cell_data) >= {"J_element_mean", "cauchy_stress_element_mean",
                                            "second_piola_kirchhoff_stress_element_mean",
                                            "green_lagrange_strain_element_mean"}
        rec = doc["fields"][f"{variant}/{FORMULATION}"]
        true, nominal = np.asarray(rec["contact_pressure_true"]), np.asarray(rec["contact_pressure_nominal"])
        a, a0 = np.asarray(rec["contact_area_current"]), np.asarray(rec["contact_area_reference"])
        assert _max_mismatch(true * a, nominal * a0[None, :]) <= 1e-14
        assert np.max(np.abs(a - a0[None, :])) > 0.05 * np.max(a0)  # the areas differ: a real check


# ------------------------------------------------------------------ curved obstacle, no solve
def test_force_vector_uses_the_current_normals():
    """Against a circle, ``results.json``'s force is ``sum a_0 p n`` with ``n`` the circle's normal
    at the *current* contact points (the obstacle moved, the body sheared and stretched; computed
    here), its true pressure ``a_0 p / a`` with our own current areas; the figure's forces are the
    same numbers; the reference normals would be off."""
    from ddcm_casadi.models.continuum import Circle, Contact, Material, Support, continuum_model, mesh
    from ddcm_casadi.outputs.continuum_results import obstacle_forces

    radius, centre, travel = 2.0, np.array([0.5, 3.0]), 0.2
    model = continuum_model(mesh.rectangle(1.0, 1.0, nx=4, ny=2), kinematics="finite",
                            materials=[Material(youngs_modulus=YOUNG, poisson_ratio=NU, law="neo_hookean")],
                            supports=[Support("ymin", "xy")],
                            contacts=[Contact(Circle(tuple(centre), radius, travel=[0.0, travel]), "ymax")])

    def motion(X):  # zero on the support y = 0; shears and stretches the top
        return np.stack([0.3 * X[:, 0] * X[:, 1], -0.2 * X[:, 1] + 0.1 * X[:, 0] * X[:, 1]], axis=1)

    disc = model.discretisation
    full = np.zeros(disc.n_dofs)
    full[disc.vector_dofs().T] = motion(disc.dof_locations())
    u = full[model.free_dofs]
    p = np.linspace(1.0, 2.0, model.n_contacts)
    rec = model.results_fields(dict(u=np.stack([0 * u, u]), contact_pressure=np.stack([0 * p, p]),
                                    converged=np.array([True, True])))
    X = model.contact_points
    x = X + motion(X)
    order = np.argsort(X[:, 0])  # the top edge, left to right: lumped areas are half the segments

    def areas(points):
        seg = np.linalg.norm(np.diff(points[order], axis=0), axis=1)
        a = np.zeros(len(points))
        a[order[:-1]] += seg / 2
        a[order[1:]] += seg / 2
        return a

    a0, a = areas(X), areas(x)
    c = centre + travel * np.array([0.0, -1.0])
    n = (x - c) / np.linalg.norm(x - c, axis=1, keepdims=True)
    expected = np.sum((a0 * p)[:, None] * n, axis=0)
    vector = np.asarray(rec["contact_force_vector_as_modelled"])[1, 0]
    mismatch = float(np.linalg.norm(vector - expected) / np.linalg.norm(expected))
    n_reference = (X - centre) / np.linalg.norm(X - centre, axis=1, keepdims=True)
    with_reference_normals = np.sum((a0 * p)[:, None] * n_reference, axis=0)
    reference_error = float(np.linalg.norm(with_reference_normals - expected) / np.linalg.norm(expected))
    print(f"circle: force vs sum a0 p n(current) {mismatch:.2e}; with the reference normals it would be off by "
          f"{reference_error:.2e}; true pressure {_max_mismatch(rec['contact_pressure_true'][1], a0 * p / a):.2e}")
    assert mismatch <= 1e-13 and reference_error > 1e-2
    assert np.asarray(rec["contact_force_along_travel_as_modelled"])[1, 0] == pytest.approx(-expected[1], rel=1e-13)
    assert _max_mismatch(rec["contact_pressure_true"][1], a0 * p / a) <= 1e-13
    assert np.max(np.abs(a / a0 - 1)) > 0.1  # the top is stretched: true and nominal differ
    vectors, along = obstacle_forces(model, np.stack([0 * u, u]), np.stack([0 * p, p]))
    np.testing.assert_array_equal(vectors, rec["contact_force_vector_as_modelled"])
    np.testing.assert_array_equal(along, rec["contact_force_along_travel_as_modelled"])


# ------------------------------------------------------------------- the checks can fail
def test_the_checks_fail_on_wrong_outputs(p1, p2):
    """Each measurement above sees a wrong output: ``J`` of another point, a sheared ``F``, ``S`` written
    as the Cauchy stress (or the Cauchy stress as ``S``), an asymmetric stress, the undeformed ``F``,
    the nominal pressure for the true one, a tilted force vector, half the force along the travel."""
    model, run, out = p2
    pd = dict(_cloud(out, "classical", model.n_steps - 1).point_data)
    assert jacobian_mismatch(dict(pd, J=pd["J"][::-1] * 1.01)) > 1e-3
    sheared = _tensors(pd["deformation_gradient"]).copy()
    sheared[:, 0, 1] += 0.01
    assert cauchy_mismatch(dict(pd, deformation_gradient=sheared.reshape(-1, 9))) > 1e-3
    assert cauchy_mismatch(dict(pd, cauchy_stress=pd["second_piola_kirchhoff_stress"])) > 1e-3
    skew = _tensors(pd["cauchy_stress"]).copy()
    skew[:, 0, 1] += 0.01 * np.max(np.abs(skew))
    assert cauchy_asymmetry(dict(pd, cauchy_stress=skew.reshape(-1, 9))) > 1e-4
    assert law_mismatch(dict(pd, second_piola_kirchhoff_stress=pd["second_piola_kirchhoff_stress"] * 1.01)) > 1e-3
    assert law_mismatch(dict(pd, second_piola_kirchhoff_stress=pd["cauchy_stress"])) > 1e-3

    model, run, out = p1
    k = model.n_steps - 1
    mesh_file = _mesh(out, "classical", k)
    cells = {name: values[0] for name, values in mesh_file.cell_data.items()}
    on = mesh_file.point_data["contact_node"].astype(bool)
    nominal = mesh_file.point_data["contact_pressure_nominal"][on]
    assert homogeneous_mismatch(cells, nominal) > 1e-2
    S_as_cauchy = dict(cells, cauchy_stress=cells["second_piola_kirchhoff_stress"])
    assert homogeneous_mismatch(S_as_cauchy, mesh_file.point_data["contact_pressure_true"][on]) > 1e-2
    F = own_deformation_gradient(mesh_file.points, mesh_file.cells_dict["triangle"], np.zeros_like(mesh_file.points))
    assert strain_mismatch(cells, F) > 1e-2  # the undeformed F does not give the written E
    reference = _mesh(out, "classical", 0)
    as_nominal = meshio.Mesh(mesh_file.points, mesh_file.cells, point_data=dict(
        mesh_file.point_data, contact_pressure_true=mesh_file.point_data["contact_pressure_nominal"]))
    assert pressure_area_mismatch(as_nominal, reference) > 1e-2
    rec = json.loads((out / "results.json").read_text())["fields"][f"classical/{FORMULATION}"]
    tilted = dict(rec, contact_force_vector_as_modelled=[[list(np.array(v[0]) + [1e-2 * v[0][1], 0.0])]
                                                         for v in rec["contact_force_vector_as_modelled"]])
    assert force_mismatch(tilted, k, mesh_file) > 1e-3
    halved = dict(rec, contact_force_along_travel_as_modelled=[[0.5 * v[0]] for v in rec["contact_force_along_travel_as_modelled"]])
    assert force_mismatch(halved, k, mesh_file) > 0.1


# --------------------------------------------------------------------------- the "wrote" line
def test_wrote_line_summarises_the_vtu_series():
    """``ddcm-compare``'s ``wrote`` line names the files but the VTU series, which it counts."""
    files = ["results.csv"]
    for run in ("classical_penalty", "ddcm_penalty"):
        for stem in (run, f"{run}_points"):
            files += [f"vtu/{stem}_{k:04d}.vtu" for k in range(4)] + [f"vtu/{stem}.pvd"]
    files += ["pressure_profile.png", "force_indentation.png", "results.json"]
    assert written_summary(files) == ("results.csv, vtu/: 2 mesh series and 2 point-cloud series, 20 files "
                                      "(16 .vtu, 4 .pvd), pressure_profile.png, force_indentation.png, results.json")
    assert written_summary(["results.csv", "results.json"]) == "results.csv, results.json"
