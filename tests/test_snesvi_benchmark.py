"""``benchmarks/snesvi.py`` (a script, not a package): without the peer's Python it skips."""

import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent.parent / "benchmarks" / "snesvi.py"


def test_snesvi_benchmark_skips_in_one_line_without_the_peer(tmp_path):
    absent = tmp_path / "no-such-python"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--peer-python", str(absent), "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines() == [
        f"snesvi: skipped, no Python with petsc4py at {absent} (--peer-python or DDCM_PETSC_PYTHON)"]
    assert not (tmp_path / "out").exists()
