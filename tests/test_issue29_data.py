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
