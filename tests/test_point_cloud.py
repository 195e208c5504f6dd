"""The material-point cloud of a continuum run, read back from its VTU files and checked point by
point against the data sets and the driver's records (:mod:`ddcm_casadi.outputs.point_cloud`); the
mesh series' P2 element means, its P1 cells and its contact fields
(:mod:`ddcm_casadi.outputs.continuum_results`)."""

from __future__ import annotations

import json
import warnings

import meshio
import numpy as np
import pytest

from ddcm_casadi.casefiles.base import Case
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.data.metric import Metric, isotropic_elasticity
from ddcm_casadi.models.continuum import Circle, Contact, Material, Support, continuum_model, mesh
from ddcm_casadi.run import run_case

E, NU, R = 200e9, 0.25, 0.05
FORMULATION = "fischer_burmeister"
R2 = np.sqrt(2.0)


def _model(degree: int, *, two_sets: bool = True):
    """A block (10 mm, 3 x 3 squares) indented by a cylinder in two steps. With ``two_sets`` its
    lower half is a second material with its own data set (another modulus, another metric, a
    range its states leave): global and local data indices differ there, and the data-range flag
    is raised."""
    body = mesh.rectangle(0.01, 0.01, nx=3, ny=3)
    C = isotropic_elasticity(E, NU, 2)[0]
    sets = [MaterialDataset.hookean_grid(C, -5e-4, 5e-4, 9, c=Metric(C))]
    materials = [Material(youngs_modulus=E, poisson_ratio=NU, data=0)]
    if two_sets:
        body = body.with_subdomains({"bottom": lambda x: x[1] < 0.005})
        C2 = isotropic_elasticity(2 * E, NU, 2)[0]
        sets.append(MaterialDataset.hookean_grid(C2, -2e-5, 2e-5, 5, c=Metric(C2)))
        materials.append(Material(region="bottom", youngs_modulus=2 * E, poisson_ratio=NU, data=1))
    indenter = Circle((0.005, 0.01 + R), R, travel=[0.0, 2e-6, 4e-6])
    return continuum_model(body, degree=degree, materials=materials, supports=[Support("ymin", "xy")],
                           contacts=[Contact(indenter, "ymax")], datasets=sets)


def _run(model, out):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the coarse data warn; that is not what is tested here
        return run_case(Case(model=model), out, formulations=[FORMULATION], figures=False)


@pytest.fixture(scope="module")
def p2_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("p2")
    model = _model(2)
    assert model.discretisation.points_per_element == 3  # P2 triangles: three material points each
    return model, _run(model, out), out


def _cloud(out, variant: str, step: int) -> meshio.Mesh:
    return meshio.read(out / "vtu" / f"{variant}_{FORMULATION}_points_{step:04d}.vtu")


# ---------------------------------------------------------------- the checks, as measurements
def datum_mismatch(model, cloud: meshio.Mesh) -> float:
    """The largest difference between a point's written datum (strain, stress) and row
    ``data_index`` of data set ``data_set``: 0 when every datum is a datum."""
    pd = cloud.point_data
    worst = 0.0
    for s, data in enumerate(model.dataset.datasets):
        pts = np.flatnonzero(pd["data_set"] == s)
        rows = pd["data_index"][pts]
        if pts.size and (rows.min() < 0 or rows.max() >= len(data)):
            return float("inf")
        for written, stored in (("data_strain_mandel", data.strain), ("data_stress_mandel", data.stress)):
            worst = max(worst, float(np.max(np.abs(pd[written][pts] - stored[rows]), initial=0.0)))
    return worst


def distance_mismatch(model, cloud: meshio.Mesh, step) -> float:
    """The largest relative difference between ``ddcm_distance`` and the metric distance of the
    step's recorded state to the written datum, under its data set's metric (absolute where every
    distance is zero)."""
    pd, k = cloud.point_data, model.strain_components
    strain, stress = np.reshape(step.strain, (-1, k)), np.reshape(step.stress, (-1, k))
    expected = np.empty(model.n_points)
    for s, data in enumerate(model.dataset.datasets):
        pts = np.flatnonzero(pd["data_set"] == s)
        rows = pd["data_index"][pts]
        expected[pts] = np.sqrt(data.metric.distance2(strain[pts] - data.strain[rows], stress[pts] - data.stress[rows]))
    error, scale = float(np.max(np.abs(pd["ddcm_distance"] - expected))), float(np.max(expected))
    return error / scale if scale > 0 else error  # at rest every state is on its datum


# ------------------------------------------------------------------------------- the P2 run
def test_results_json_lists_both_series(p2_run):
    model, run, out = p2_run
    files = json.loads((out / "results.json").read_text())["files"]
    assert files == run.files
    for variant in ("classical", "ddcm"):
        stem = f"vtu/{variant}_{FORMULATION}"
        expected = [f"{stem}_{k:04d}.vtu" for k in range(model.n_steps)] + [f"{stem}.pvd"]
        expected += [f"{stem}_points_{k:04d}.vtu" for k in range(model.n_steps)] + [f"{stem}_points.pvd"]
        assert set(expected) <= set(files), variant
        assert all((out / f).is_file() for f in expected)
    pvd = (out / "vtu" / f"ddcm_{FORMULATION}_points.pvd").read_text()
    assert pvd.count("<DataSet") == model.n_steps and f"ddcm_{FORMULATION}_points_0001.vtu" in pvd


@pytest.mark.parametrize("variant", ["classical", "ddcm"])
def test_one_point_per_material_point_at_its_position(p2_run, variant):
    """As many vertices as material points, at the quadrature points; each element's points
    average to its centroid (the symmetric three-point rule) and carry its material region."""
    model, run, out = p2_run
    disc = model.discretisation
    for k in range(model.n_steps):
        cloud = _cloud(out, variant, k)
        assert len(cloud.points) == model.n_points == disc.mesh.t.shape[1] * 3
        assert [(c.type, len(c.data)) for c in cloud.cells] == [("vertex", model.n_points)]
        np.testing.assert_array_equal(cloud.points[:, :2], disc.quadrature_points())
        pd = cloud.point_data
        element = pd["element"]
        centroids = disc.mesh.p[:, disc.mesh.t].mean(axis=1).T
        mean = np.stack([np.bincount(element, weights=cloud.points[:, a]) / 3 for a in range(2)], axis=1)
        np.testing.assert_allclose(mean, centroids, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(pd["region"], model.point_region)
        steps = run.comparison.results[(variant, FORMULATION)].steps
        np.testing.assert_array_equal(pd["strain_mandel"], np.reshape(steps[k].strain, (-1, 3)))
        np.testing.assert_array_equal(pd["stress_mandel"], np.reshape(steps[k].stress, (-1, 3)))
        # the tensors are the Mandel components
        t = pd["stress"].reshape(-1, 3, 3)
        np.testing.assert_allclose(t[:, 0, 1] * R2, pd["stress_mandel"][:, 2], rtol=1e-15)
        np.testing.assert_array_equal(t[:, 1, 1], pd["stress_mandel"][:, 1])


def test_every_ddcm_point_carries_a_datum_of_its_set(p2_run):
    """Each point's datum strain and stress are row ``data_index`` of data set ``data_set``,
    exactly; the row is the one the driver assigned (its global index, its material states)."""
    model, run, out = p2_run
    steps = run.comparison.results[("ddcm", FORMULATION)].steps
    offsets = model.dataset.offsets
    _, material = model.dataset.point_materials(model.n_points)
    used = set()
    for k, step in enumerate(steps):
        cloud = _cloud(out, "ddcm", k)
        pd = cloud.point_data
        assert datum_mismatch(model, cloud) == 0.0
        np.testing.assert_array_equal(pd["data_set"], material)
        np.testing.assert_array_equal(pd["data_index"] + offsets[pd["data_set"]], step.data_index)
        np.testing.assert_array_equal(pd["data_strain_mandel"], np.reshape(step.strain_star, (-1, 3)))
        np.testing.assert_array_equal(pd["data_stress_mandel"], np.reshape(step.stress_star, (-1, 3)))
        assert "material_stress_mandel" not in pd  # the nearest-datum scheme's states are data
        # 2-D data carry no sigma_zz: unknown in the datum's tensor
        assert np.isnan(pd["data_stress"].reshape(-1, 3, 3)[:, 2, 2]).all()
        used |= {(int(s), int(i)) for s, i in zip(pd["data_set"], pd["data_index"])}
    # the checks can tell data apart: many data, from both sets
    assert len(used) > 10 and {s for s, _ in used} == {0, 1}


def test_distance_is_the_metric_distance_to_the_datum(p2_run):
    """``ddcm_distance`` is ``sqrt(d^2)`` of the recorded state to its datum in its set's metric,
    to round-off, and the step's objective ``1/2 sum w d^2`` follows from it."""
    model, run, out = p2_run
    for k, step in enumerate(run.comparison.results[("ddcm", FORMULATION)].steps):
        cloud = _cloud(out, "ddcm", k)
        assert distance_mismatch(model, cloud, step) <= 1e-13
        d = cloud.point_data["ddcm_distance"]
        w = cloud.point_data["volume"]
        np.testing.assert_array_equal(w, model.volumes)
        assert 0.5 * np.dot(w, d ** 2) == pytest.approx(step.distance, rel=1e-12, abs=0.0)


def test_data_range_flag_is_the_steps_count(p2_run):
    """``beyond_data`` flags exactly the step's ``extrapolated`` points, and some are flagged (the
    lower material's data stop at a strain of 2e-5)."""
    model, run, out = p2_run
    flagged = 0
    for k, step in enumerate(run.comparison.results[("ddcm", FORMULATION)].steps):
        pd = _cloud(out, "ddcm", k).point_data
        assert int(np.sum(pd["beyond_data"])) == step.extrapolated
        assert np.nanmax(pd["data_spacings"]) == pytest.approx(step.data_spacings, rel=1e-12)
        flagged += step.extrapolated
    assert flagged > 0


def test_the_checks_fail_on_a_wrong_datum(p2_run):
    """The measurements above see a datum one row off, or a global index read as a local one."""
    model, run, out = p2_run
    step = run.comparison.results[("ddcm", FORMULATION)].steps[-1]
    cloud = _cloud(out, "ddcm", model.n_steps - 1)
    pd = cloud.point_data
    one_off = dict(pd, data_index=np.where(pd["data_index"] > 0, pd["data_index"] - 1, 1))
    assert datum_mismatch(model, meshio.Mesh(cloud.points, cloud.cells, point_data=one_off)) > 0
    as_global = dict(pd, data_index=pd["data_index"] + model.dataset.offsets[pd["data_set"]])
    assert datum_mismatch(model, meshio.Mesh(cloud.points, cloud.cells, point_data=as_global)) > 0
    swapped = dict(pd, ddcm_distance=pd["ddcm_distance"][::-1])
    assert distance_mismatch(model, meshio.Mesh(cloud.points, cloud.cells, point_data=swapped), step) > 1e-3


def test_p2_mesh_has_no_averaged_data(p2_run):
    """The P2 mesh file holds element means of the states, named as means, and no data field; the
    means are those of the points."""
    model, run, out = p2_run
    for variant in ("classical", "ddcm"):
        mesh_file = meshio.read(out / "vtu" / f"{variant}_{FORMULATION}_0002.vtu")
        names = set(mesh_file.cell_data)
        assert "data_stress" not in names and "ddcm_distance" not in names
        assert names and all(n.endswith("_element_mean") for n in names), names
        stress = _cloud(out, variant, 2).point_data["stress"]
        np.testing.assert_allclose(mesh_file.cell_data["stress_element_mean"][0], stress.reshape(-1, 3, 9).mean(axis=1),
                                   rtol=1e-15, atol=1e-15 * np.nanmax(np.abs(stress)))


def test_contact_gap_and_pressure_on_the_contact_nodes(p2_run):
    """Gap and pressure of every contact pair at its node (P2 midpoints included); the gap is NaN
    off the contact nodes, the pressure zero."""
    model, run, out = p2_run
    for variant in ("classical", "ddcm"):
        step = run.comparison.results[(variant, FORMULATION)].steps[-1]
        pd = meshio.read(out / "vtu" / f"{variant}_{FORMULATION}_0002.vtu").point_data
        on = np.zeros(len(pd["contact_node"]), dtype=bool)
        on[model.contact_dofs] = True
        np.testing.assert_array_equal(pd["contact_node"], on.astype(np.uint8))
        assert np.isnan(pd["contact_gap"][~on]).all() and np.all(pd["contact_pressure"][~on] == 0)
        np.testing.assert_array_equal(pd["contact_gap"][model.contact_dofs], model.gap(step.u, step.step))
        np.testing.assert_array_equal(pd["contact_pressure"][model.contact_dofs], step.p)
        assert np.max(step.p) > 0  # the indenter touches


# ---------------------------------------------------------------------------------- P1 mesh
def test_p1_mesh_cells_are_the_points(tmp_path):
    """On P1 every element is one material point: the mesh keeps its cell names (``stress``,
    ``data_stress``, ``ddcm_distance``, ...) and they equal the point cloud's, value for value."""
    model = _model(1, two_sets=False)
    _run(model, tmp_path)
    for k in range(model.n_steps):
        cells = meshio.read(tmp_path / "vtu" / f"ddcm_{FORMULATION}_{k:04d}.vtu").cell_data
        points = _cloud(tmp_path, "ddcm", k).point_data
        assert len(points["stress"]) == model.mesh.t.shape[1]
        assert {"strain", "stress", "von_mises", "von_mises_in_plane", "data_stress", "ddcm_distance"} <= set(cells)
        for name in ("stress", "data_stress", "ddcm_distance", "von_mises_in_plane"):
            np.testing.assert_array_equal(cells[name][0], points[name])


# ------------------------------------------------- small kinematics: every element kind writes its points
@pytest.mark.parametrize("dim,degree", [(2, 1), (2, 2), (3, 1), (3, 2)])
def test_small_strain_point_cloud_of_every_element(tmp_path, dim, degree):
    """Small kinematics, P1 and P2 in 2-D and 3-D (a block under a traction; quadratic tetrahedra
    take no contact): one vertex per material point, and for DDCM its datum (set, row, strain,
    stress), its distance and the data-range flag."""
    from ddcm_casadi.models.continuum import Traction

    C = isotropic_elasticity(E, NU, dim)[0]
    data = MaterialDataset.hookean_grid(C, -1e-4, 1e-4, 3, c=Metric(C))
    body = mesh.rectangle(0.01, 0.01, nx=2, ny=2) if dim == 2 else mesh.box(0.01, 0.01, 0.01, nx=1, ny=1, nz=1)
    top = "ymax" if dim == 2 else "zmax"
    traction = (0.0, -1e6) if dim == 2 else (0.0, 0.0, -1e6)
    model = continuum_model(body, degree=degree, materials=[Material(youngs_modulus=E, poisson_ratio=NU, data=0)],
                            supports=[Support("ymin" if dim == 2 else "zmin", "xyz"[:dim])],
                            tractions=[Traction(top, traction)], load_factors=[0.5, 1.0], datasets=[data])
    assert model.kinematics == "small"
    _run(model, tmp_path)
    for variant in ("classical", "ddcm"):
        cloud = _cloud(tmp_path, variant, 1)
        assert cloud.points.shape[0] == model.n_points
        np.testing.assert_allclose(cloud.points[:, :dim], model.discretisation.quadrature_points(), atol=1e-15)
        assert {"strain", "stress", "strain_mandel", "stress_mandel"} <= set(cloud.point_data)
        if variant == "ddcm":
            assert {"data_set", "data_index", "data_strain_mandel", "data_stress_mandel", "ddcm_distance",
                    "beyond_data"} <= set(cloud.point_data)
            assert datum_mismatch(model, cloud) == 0.0
