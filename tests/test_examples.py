"""The examples are modules the tests run."""

import importlib.util
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _load(name):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_compare_formulations_example(tmp_path, capsys):
    result = _load("compare_formulations").main(str(tmp_path), n_data=500)
    assert all(r.converged for r in result.results.values())
    assert (tmp_path / "fig2a_tip_displacement.png").stat().st_size > 0
    assert (tmp_path / "fig2b_contact_pressure.png").stat().st_size > 0
    assert "fischer_burmeister" in capsys.readouterr().out
