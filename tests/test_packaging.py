"""Installing the project adds one top-level import name, ``ddcm_casadi``: the formulations in
the folder ``formulations/`` are installed as ``ddcm_casadi.formulations``."""

import importlib.metadata
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_installed_distribution_has_only_the_projects_import_name():
    # setuptools writes the installed top-level names from the package configuration
    # (an install that still shipped `formulations` would list it here).
    top = importlib.metadata.distribution("ddcm-casadi").read_text("top_level.txt")
    assert top is not None and top.split() == ["ddcm_casadi"]


def test_formulations_import_under_the_project():
    from ddcm_casadi import formulations

    assert Path(formulations.__file__).parent == ROOT / "formulations"
    assert set(formulations.available()) == {"penalty", "augmented_lagrangian", "fischer_burmeister", "mpcc"}
    assert importlib.util.find_spec("ddcm_casadi.formulations.ncp") is not None
