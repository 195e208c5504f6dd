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


def test_example_cases_are_installed_as_package_data():
    """``examples/cases`` is the package ``ddcm_casadi.cases`` with every case file as package data,
    so a regular (not editable) install has the Hertz example that ``ddcm-validate`` reads."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    from fnmatch import fnmatch

    from ddcm_casadi import cases
    from ddcm_casadi.validation.continuum import EXAMPLE

    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert "ddcm_casadi.cases" in config["packages"]
    assert config["package-dir"]["ddcm_casadi.cases"] == "examples/cases"
    globs = config["package-data"]["ddcm_casadi.cases"]
    files = [p for p in (ROOT / "examples" / "cases").iterdir() if p.is_file() and p.suffix != ".py"]
    assert files and all(any(fnmatch(p.name, g) for g in globs) for p in files), files
    assert Path(cases.__file__).parent == ROOT / "examples" / "cases"
    assert EXAMPLE.is_file() and EXAMPLE.parent == Path(cases.__file__).parent
