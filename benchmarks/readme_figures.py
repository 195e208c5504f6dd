"""Regenerate every figure the README shows, each from the command that makes it.

    python benchmarks/readme_figures.py            # every figure into docs/ (about 4 minutes)
    python benchmarks/readme_figures.py --quick    # the fast ones only (seconds; the tests run this)
    python benchmarks/readme_figures.py --list     # which command makes which figure

Each figure is made by the command a user would run (``ddcm-compare``, ``ddcm-sweep`` or an
example's ``main``) into a scratch folder, then copied into ``docs/`` (atomically). The README may
show only figures listed here (``tests/test_docs.py`` checks it), so none can go stale unnoticed.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


@dataclass(frozen=True)
class Figure:
    """A README figure (``docs/<name>``): the command that makes it and the file it writes."""

    name: str
    command: tuple[str, ...]  # run in the scratch folder; "{out}" is the output folder
    output: str  # the figure's path inside the output folder
    quick: bool  # made in seconds (the tests run these)


def _example(name: str) -> tuple[str, ...]:
    """The command that runs ``examples/<name>.py``'s ``main`` into ``{out}``."""
    code = (f"import importlib.util, sys; spec = importlib.util.spec_from_file_location('ex', {str(ROOT / 'examples' / (name + '.py'))!r}); "
            "m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m); m.main(sys.argv[1])")
    return (sys.executable, "-c", code, "{out}")


def _case(name: str, formulations: str) -> tuple:
    """``ddcm-compare`` on ``examples/cases/<name>.toml`` with ``formulations``, quietly."""
    return ("ddcm-compare", "--config", str(ROOT / "examples" / "cases" / f"{name}.toml"),
            "--formulations", formulations, "--out", "{out}", "-q")


FIGURES = (
    Figure("fig2a_tip_displacement.png", ("ddcm-compare", "--out", "{out}", "-q"), "fig2a_tip_displacement.png", True),
    Figure("fig2b_contact_pressure.png", ("ddcm-compare", "--out", "{out}", "-q"), "fig2b_contact_pressure.png", True),
    Figure("bar_on_stops_contact_history.png", _example("bar_on_stops"), "contact_history.png", True),
    Figure("truss_bridge_structure_ddcm.png", _example("truss_bridge"), "structure_ddcm.png", True),
    Figure("truss_bridge_contact_history.png", _example("truss_bridge"), "contact_history.png", True),
    Figure("truss_3d_plane_structure_ddcm.png", _example("truss_3d_plane"), "structure_ddcm.png", True),
    Figure("von_mises_contact_history.png", _example("von_mises_snap"), "contact_history.png", True),
    Figure("sweep_data_size.png", ("ddcm-sweep", str(ROOT / "examples/sweeps/data_size.toml"), "--out", "{out}"),
           "error_vs_data_size.png", True),
    Figure("hertz2d_pressure_profile.png", _case("hertz2d", "fischer_burmeister"), "pressure_profile.png", False),
    Figure("hertz2d_deformed.png", _case("hertz2d", "fischer_burmeister"), "deformed_classical.png", False),
    Figure("sweep_noise.png", ("ddcm-sweep", str(ROOT / "examples/sweeps/noise.toml"), "--out", "{out}"),
           "error_vs_noise.png", False),
    Figure("seal2d_force_indentation.png", ("ddcm-compare", "--config", str(ROOT / "examples/cases/seal2d_finite.toml"),
                                            "--out", "{out}", "-q"), "force_indentation.png", False),
    Figure("seal2d_deformed.png", ("ddcm-compare", "--config", str(ROOT / "examples/cases/seal2d_finite.toml"),
                                   "--formulations", "fischer_burmeister", "--variants", "classical",
                                   "--out", "{out}", "-q"), "deformed_classical.png", False),
    Figure("indentation3d_force_indentation.png", ("ddcm-compare", "--config",
                                                   str(ROOT / "examples/cases/indentation3d_finite.toml"),
                                                   "--formulations", "fischer_burmeister", "--out", "{out}", "-q"),
           "force_indentation.png", False),
    Figure("nafems1_pressure_profile.png", _case("nafems1", "fischer_burmeister,penalty"), "pressure_profile.png",
           False),
    Figure("nafems1_deformed.png", _case("nafems1", "fischer_burmeister"), "deformed_classical.png", False),
)


def readme_figures(readme: Path = ROOT / "README.md") -> set[str]:
    """The ``docs/*.png`` files the README shows."""
    return set(re.findall(r"docs/([A-Za-z0-9_]+\.png)", readme.read_text()))


def make(figure: Figure, scratch: Path, docs: Path = DOCS) -> Path:
    """Run ``figure``'s command in ``scratch`` and copy its output to ``docs/<name>`` atomically."""
    out = scratch / "out"
    if out.exists():
        shutil.rmtree(out)
    command = [part.replace("{out}", str(out)) for part in figure.command]
    subprocess.run(command, cwd=scratch, check=True, stdout=subprocess.DEVNULL)
    target = docs / figure.name
    with tempfile.NamedTemporaryFile(dir=docs, suffix=".png", delete=False) as tmp:
        shutil.copyfile(out / figure.output, tmp.name)
    os.replace(tmp.name, target)
    return target


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="only the figures made in seconds")
    ap.add_argument("--list", action="store_true", help="print which command makes which figure")
    ap.add_argument("--docs", default=str(DOCS), metavar="DIR", help="where the figures go (default docs/)")
    args = ap.parse_args(argv)
    if args.list:
        for f in FIGURES:
            print(f"docs/{f.name}: {' '.join(f.command)} -> {f.output}")
        return 0
    Path(args.docs).mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for f in FIGURES:
            if args.quick and not f.quick:
                continue
            print(f"docs/{f.name}", file=sys.stderr)
            make(f, Path(tmp), Path(args.docs))
    return 0


if __name__ == "__main__":
    sys.exit(main())
