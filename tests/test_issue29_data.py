"""Issue 29, items 3, 4 and 7: DDCM on coarse data says so, data files of the wrong dimension are
refused, and ``c = "estimated"`` works from a case file for a real material."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi.casefiles.config import load_case
from ddcm_casadi.data.metric import isotropic_elasticity
from ddcm_casadi.errors import InputError

HERTZ = Path(__file__).resolve().parents[1] / "examples" / "cases" / "hertz2d.toml"


def _hertz_with_data(tmp_path: Path, data: str) -> Path:
    """hertz2d.toml with its ``[data]`` table replaced by ``data``."""
    text = HERTZ.read_text()
    case = tmp_path / "case.toml"
    case.write_text(text[:text.index("[data]")] + data)
    return case


def _mandel_csv(path: Path, k: int, youngs_modulus: float = 200e9, points: int = 3) -> Path:
    """Hookean data on a grid of ``points^k`` Mandel strains (``k`` 3 or 6), written as CSV."""
    D = isotropic_elasticity(youngs_modulus, 0.3, {3: 2, 6: 3}[k])[0]
    axis = np.linspace(-0.01, 0.01, points)
    strain = np.stack(np.meshgrid(*([axis] * k), indexing="ij"), axis=-1).reshape(-1, k)
    header = ",".join([f"strain_{i}" for i in range(1, k + 1)] + [f"stress_{i}" for i in range(1, k + 1)])
    np.savetxt(path, np.column_stack([strain, strain @ D.T]), delimiter=",", header=header, comments="")
    return path


# --------------------------------------------------------------- item 4: columns of another dimension
def test_item4_a_3d_data_file_is_refused_by_a_2d_case(tmp_path: Path) -> None:
    """A 6-component (3-D) file was read as 3 components: e33 taken for sqrt(2) e12."""
    _mandel_csv(tmp_path / "data3d.csv", 6, points=2)
    case = _hertz_with_data(tmp_path, '[data]\npath = "data3d.csv"\nc = "isotropic"\n')
    with pytest.raises(InputError) as info:
        load_case(case)
    message = str(info.value)
    assert "\n" not in message
    assert "6 strain and 6 stress" in message and "3 of each" in message, message


def test_item4_a_2d_data_file_is_refused_by_a_3d_metric(tmp_path: Path) -> None:
    from ddcm_casadi.data.dataset import MaterialDataset
    path = _mandel_csv(tmp_path / "data2d.csv", 3)
    with pytest.raises(InputError, match="3 strain and 3 stress .*6 of each"):
        MaterialDataset.from_csv(path, c=np.eye(6))


def test_item4_other_columns_are_still_ignored(tmp_path: Path) -> None:
    from ddcm_casadi.data.dataset import MaterialDataset
    path = _mandel_csv(tmp_path / "data2d.csv", 3)
    lines = path.read_text().splitlines()
    path.write_text("\n".join([lines[0] + ",temperature"] + [ln + ",293" for ln in lines[1:]]) + "\n")
    assert MaterialDataset.from_csv(path, c=isotropic_elasticity(200e9, 0.3, 2)[0]).k == 3


# --------------------------------------------------- item 7: c = "estimated" for a real material
def test_item7_estimated_metric_from_a_case_file_for_steel(tmp_path: Path) -> None:
    """Steel-like data (E = 200 GPa): the data were first checked against a unit metric and refused."""
    _mandel_csv(tmp_path / "steel.csv", 3)
    case = load_case(_hertz_with_data(tmp_path, '[data]\npath = "steel.csv"\nc = "estimated"\n'))
    metric = case.model.dataset.metric
    D = isotropic_elasticity(200e9, 0.3, 2)[0]
    assert np.allclose(metric.matrix, D, rtol=1e-9, atol=1e-9 * np.abs(D).max())


def test_item7_estimated_metric_for_generated_steel_data(tmp_path: Path) -> None:
    case = load_case(_hertz_with_data(
        tmp_path, '[data]\nhookean = { strain_min = -0.01, strain_max = 0.01, points = 5 }\nc = "estimated"\n'))
    D = isotropic_elasticity(200e9, 0.3, 2)[0]
    assert np.allclose(case.model.dataset.metric.matrix, D, rtol=1e-9, atol=1e-9 * np.abs(D).max())


# ------------------------------------------------------------------ item 3: DDCM on coarse data says so
def _hertz_forces(case_path: Path, overrides=(), formulation: str = "fischer_burmeister"):
    """The comparison of one formulation on a Hertz case, and its last classical and DDCM forces."""
    import warnings

    from ddcm_casadi import compare
    case = load_case(case_path, overrides=overrides)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cmp = compare(case.model, [formulation], ddcm_max_outer=case.ddcm_max_outer)
    force = lambda variant: case.model.step_summary(cmp[variant, formulation].steps[-1].u,  # noqa: E731
                                                    cmp[variant, formulation].steps[-1].p)["total_contact_force"]
    return cmp, force("classical"), force("ddcm"), caught


def test_item3_three_points_per_axis_is_flagged_everywhere(tmp_path: Path) -> None:
    """Zero contact force where the classical one is 1.9 MN/m, reported converged and nothing else."""
    import json

    from ddcm_casadi.errors import PhysicsWarning
    from ddcm_casadi.run import run_case
    cmp, classical, ddcm, caught = _hertz_forces(HERTZ, [("data.hookean.points", 3)])
    assert classical > 1e6 and ddcm < 1e-3 * classical  # the silent nonsense, still computed
    steps = cmp["ddcm", "fischer_burmeister"].steps
    assert steps[-1].datum_share == 1.0 and steps[-1].state_spacings < 1.0  # within a spacing of zero
    assert steps[-1].coarse_data and not steps[0].coarse_data  # the unloaded step is not judged
    assert any(issubclass(w.category, PhysicsWarning) and "too coarse" in str(w.message) for w in caught)
    assert "DATA TOO COARSE" in cmp.table()
    row = [r for r in cmp.rows() if r["variant"] == "ddcm"][-1]
    assert row["datum_share"] == 1.0 and row["coarse_data"]
    case = load_case(HERTZ, overrides=[("data.hookean.points", 3)])
    with pytest.warns(PhysicsWarning, match="too coarse"):
        done = run_case(case, tmp_path / "out", formulations=["fischer_burmeister"], figures=False)
    doc = json.loads((done.out_dir / "results.json").read_text())
    ddcm_run = next(r for r in doc["summary"] if r["variant"] == "ddcm")
    assert ddcm_run["coarse_data_steps"] == [1, 2, 3, 4] and ddcm_run["max_datum_share"] == 1.0
    assert any("too coarse" in w for w in doc["warnings"])


def test_item3_a_uniform_state_on_one_datum_is_not_coarse() -> None:
    from ddcm_casadi.data.extrapolation import coarse_data
    assert coarse_data(1.0, 0.0, 5.0, 100) == ""      # every point on one datum, alike: a uniform strain
    assert coarse_data(1.0, 0.5, 5.0, 1) == ""        # one material point (a bar)
    assert coarse_data(0.67, 1.2, 12.0, 1308) != ""   # hertz2d on 21^3 data
    assert coarse_data(0.01, 1.0, 120.0, 1308) == ""  # hertz2d on its graded 101^3 data


def test_item3_the_hertz_example_data_are_adequate() -> None:
    """hertz2d.toml's DDCM force was 48 % of the classical one (21^3 regular data)."""
    cmp, classical, ddcm, caught = _hertz_forces(HERTZ)
    assert abs(ddcm / classical - 1) < 0.08, ddcm / classical
    assert not any("too coarse" in str(w.message) for w in caught)
    assert not cmp["ddcm", "fischer_burmeister"].steps[-1].coarse_data


def test_item3_graded_data_keep_their_ends() -> None:
    from ddcm_casadi.data.dataset import graded_axis
    axis = graded_axis(-0.012, 0.012, 7, 2.0)
    assert axis[0] == -0.012 and axis[-1] == 0.012 and axis[3] == 0.0
    assert np.allclose(np.diff(axis)[2:4], 0.012 / 9)  # (1/3)^2 of the range's half
    with pytest.raises(InputError, match="grading"):
        graded_axis(-1, 1, 5, 0.5)
