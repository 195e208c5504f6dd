"""The architecture document names every module of the package (so it cannot go stale)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_architecture_lists_every_module():
    text = (ROOT / "docs" / "architecture.md").read_text()
    modules = [p for base in ("ddcm_casadi", "formulations") for p in (ROOT / base).rglob("*.py")
               if p.name != "__init__.py" or p.parent == ROOT / "ddcm_casadi"]
    missing = sorted(str(p.relative_to(ROOT)) for p in modules if f"`{p.relative_to(ROOT)}`" not in text)
    assert not missing, f"docs/architecture.md does not name: {missing}"
