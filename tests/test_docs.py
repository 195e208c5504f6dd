"""The architecture document names every module of the package (so it cannot go stale)."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_architecture_lists_every_module():
    text = (ROOT / "docs" / "architecture.md").read_text()
    modules = [p for base in ("ddcm_casadi", "formulations") for p in (ROOT / base).rglob("*.py")
               if p.name != "__init__.py" or p.parent == ROOT / "ddcm_casadi"]
    missing = sorted(str(p.relative_to(ROOT)) for p in modules if f"`{p.relative_to(ROOT)}`" not in text)
    assert not missing, f"docs/architecture.md does not name: {missing}"


def _readme_figures():
    import importlib.util

    spec = importlib.util.spec_from_file_location("readme_figures", ROOT / "benchmarks" / "readme_figures.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("readme_figures", module)  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return sys.modules["readme_figures"]


def test_every_readme_figure_has_the_command_that_makes_it():
    module = _readme_figures()
    made = {f.name for f in module.FIGURES}
    missing = module.readme_figures() - made
    assert not missing, f"README figures with no command in benchmarks/readme_figures.py: {sorted(missing)}"


def test_readme_figures_are_remade_by_their_commands(tmp_path):
    """Two of the quick figures, made into a scratch docs folder by their commands."""
    module = _readme_figures()
    docs = tmp_path / "docs"
    docs.mkdir()
    for figure in module.FIGURES:
        if figure.name in ("fig2a_tip_displacement.png", "von_mises_contact_history.png"):
            assert module.make(figure, tmp_path, docs).stat().st_size > 10_000
