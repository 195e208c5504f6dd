"""``ddcm-sweep``: parameter sweeps and Monte Carlo over generated data on dask.distributed.

A small sweep (4 cases of a 4-step bar) runs on a LocalCluster of two worker processes; an
interrupted sweep resumes with only the missing cases and gives the same ``sweep.csv`` as an
uninterrupted one (every column but the wall times); a failing case is recorded without stopping
the sweep; bad specs are refused with one line and nothing written; the data generators are
reproducible and their noise has the stated statistics.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import logging
from pathlib import Path

import numpy as np
import pytest

from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.errors import InputError
from ddcm_casadi.sweep import generator_from_dict, load_spec, run_case, run_sweep
from ddcm_casadi.commands.compare import main as cli_main
from ddcm_casadi.commands.sweep import main as sweep_main
from ddcm_casadi.sweep.runner import CASES, read_record
from ddcm_casadi.sweep.table import TIMINGS, fit_loglog

from .test_bad_input import case_toml

distributed = pytest.importorskip("distributed")

ROOT = Path(__file__).resolve().parent.parent
BASE = case_toml(positions="[1.002, 1.0, 0.998, 0.996]",
                 data="hookean = { strain_min = -0.01, strain_max = 0.002, points = 50, youngs_modulus = 200e9 }")
SPEC = """
base = "base.toml"
variants = ["classical", "ddcm"]
formulations = ["fischer_burmeister"]
seeds = 2

[generate]
noise = 0.01

[grid]
"generate.points" = [30, 60]

[[figures]]
kind = "rate"
x = "generate.points"
y = "max_error_p"

[[figures]]
kind = "band"
x = "generate.points"
y = "max_error_u"
file = "band.png"
"""


def write_spec(folder: Path, spec: str = SPEC, base: str = BASE) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "base.toml").write_text(base)
    path = folder / "spec.toml"
    path.write_text(spec)
    return path


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def reproducible(rows: list[dict]) -> list[dict]:
    """The rows without the wall-time columns (measurements, different in every run)."""
    return [{k: v for k, v in r.items() if k not in TIMINGS} for r in rows]


@pytest.fixture(scope="module")
def scheduler():
    """A LocalCluster of two single-threaded worker processes shared by the tests of this module
    (they reach it with ``scheduler=ADDRESS``, as ``ddcm-sweep --scheduler`` does)."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=logging.ERROR) as cluster:
        yield cluster.scheduler_address


# ------------------------------------------------------------------------------------------ sweeps
def test_local_cluster_of_two_workers_runs_a_small_sweep(tmp_path):
    spec = load_spec(write_spec(tmp_path / "spec"))
    assert len(spec.cases) == 4 and spec.columns == ["generate.points", "seed"]
    out = tmp_path / "out"
    report = run_sweep(spec, out, workers=2)
    assert report.workers == 2 and report.ran == 4 and not report.failed and not report.lost

    rows = read_csv(out / "sweep.csv")
    assert len(rows) == 4 * 2  # case x variant x formulation
    assert list(rows[0])[:4] == ["case", "status", "generate.points", "seed"]
    assert [(r["generate.points"], r["seed"], r["variant"]) for r in rows[:4]] == [
        ("30", "0", "classical"), ("30", "0", "ddcm"), ("30", "1", "classical"), ("30", "1", "ddcm")]
    assert all(r["status"] == "ok" and r["converged_steps"] == r["steps"] == "4" for r in rows)
    ddcm = [r for r in rows if r["variant"] == "ddcm"]
    assert all(r["data_points"] == r["generate.points"] for r in ddcm)
    assert all(float(r["max_error_p"]) > 0 and float(r["distance_max"]) > 0 for r in ddcm)
    # the data never enter the classical problem: its error is the same in every case
    assert len({r["max_error_p"] for r in rows if r["variant"] == "classical"}) == 1

    meta = json.loads((out / "sweep.json").read_text())
    assert meta["cases"] == 4 and meta["finished"] == 4 and meta["workers"] == 2
    assert {"dask", "distributed", "ddcm_casadi", "casadi"} <= set(meta["versions"])
    assert meta["spec"]["grid"] == {"generate.points": [30, 60]}
    # a log-log slope is fitted where the error is positive: DDCM; the classical error is roundoff
    # (0, or an ulp where the condensation solves with the reference scales' factor over c = s_d / s_f:
    # a flat line of nothing if fitted)
    assert "ddcm/fischer_burmeister" in [f["series"] for f in meta["fits"]]
    assert all(float(r["max_error_p"]) <= 64 * np.finfo(float).eps for r in rows if r["variant"] == "classical")
    assert (out / "band.png").stat().st_size > 0 and (out / "rate_max_error_p_vs_generate_points.png").is_file()

    # each case's folder: its record and the results of ddcm-compare; the same metrics in process
    case = spec.cases[3]
    folder = out / CASES / case.id
    assert sorted(p.name for p in folder.iterdir()) == ["case.json", "results.csv", "results.json"]
    record = read_record(out, case.id)
    assert record["params"] == {"generate.points": 60, "seed": 1} and record["generate"]["seed"] == 1
    direct = run_case(dict(case=dataclasses.asdict(case), base=str(spec.base), variants=["classical", "ddcm"],
                           formulations=["fischer_burmeister"]))
    assert direct["status"] == "ok" and len(direct["rows"]) == len(record["rows"]) == 2
    for mine, theirs in zip(direct["rows"], record["rows"]):
        assert {k: v for k, v in mine.items() if k not in TIMINGS} == {k: v for k, v in theirs.items()
                                                                      if k not in TIMINGS}
    assert len(read_csv(folder / "results.csv")) == 2 * 4  # per step


def test_case_results_json_is_the_document_of_ddcm_compare(tmp_path, scheduler):
    """A sweep case's results.json comes from the same builder as ddcm-compare's
    (ddcm_casadi.run.results_document): warnings, fields, files and overrides included."""
    base = case_toml(positions="[0.9995, 0.999, 0.998]", extra="[formulations.penalty]\ngamma = 2e15\n",
                     data="hookean = { strain_min = -0.01, strain_max = 0.002, points = 40, youngs_modulus = 200e9 }")
    spec_text = ('base = "base.toml"\nvariants = ["classical", "ddcm"]\nformulations = ["fischer_burmeister"]\n'
                 '[set]\n"bar.elements" = 2\n[grid]\n"ddcm.c" = [3e11]\n')
    spec = load_spec(write_spec(tmp_path / "spec", spec_text, base))
    out = tmp_path / "out"
    report = run_sweep(spec, out, scheduler=scheduler, figures=False)
    assert report.ran == 1 and not report.failed
    folder = out / CASES / spec.cases[0].id
    doc = json.loads((folder / "results.json").read_text())
    # the obstacle starts inside the bar: the warning ddcm-compare records too
    assert doc["warnings"] and "start inside the body" in doc["warnings"][0]
    assert set(doc["fields"]) == {"classical/fischer_burmeister", "ddcm/fischer_burmeister"}  # two elements
    assert doc["files"] == ["results.csv", "results.json"] == sorted(p.name for p in folder.glob("results.*"))
    assert doc["parameters"]["overrides"] == {"bar.elements": 2, "ddcm.c": 3e11}

    # ddcm-compare on the same case writes the same keys
    case_file = tmp_path / "case.toml"
    case_file.write_text(base)
    assert cli_main(["--config", str(case_file), "--set", "bar.elements=2", "--set", "ddcm.c=3e11",
                     "--formulations", "fischer_burmeister", "--no-plots", "-q", "--out", str(tmp_path / "cmp")]) == 0
    direct = json.loads((tmp_path / "cmp" / "results.json").read_text())
    assert list(direct) == list(doc)
    assert direct["parameters"]["overrides"] == doc["parameters"]["overrides"]
    assert direct["fields"].keys() == doc["fields"].keys() and direct["warnings"] == doc["warnings"]


def test_noiseless_error_is_at_most_half_a_data_spacing(tmp_path):
    """Without noise the DDCM pressure error is the stress error of the nearest datum: at most half
    a data spacing, ``0.5 E 0.012 / (n - 1)`` over ``max p = E 0.004`` (the base case's strain
    range and largest compression), so it falls as ``1/n`` (slope -1)."""
    spec = load_spec(write_spec(tmp_path, 'base = "base.toml"\nvariants = ["ddcm"]\nformulations = ["fischer_burmeister"]\n'
                                          '[generate]\n[grid]\n"generate.points" = [50, 200, 800]\n'))
    n = np.array([c.params["generate.points"] for c in spec.cases], dtype=float)
    runs = [run_case(dict(case=dataclasses.asdict(c), base=str(spec.base), variants=["ddcm"],
                          formulations=["fischer_burmeister"])) for c in spec.cases]
    assert all(r["status"] == "ok" for r in runs)
    err = np.array([float(r["rows"][0]["max_error_p"]) for r in runs])
    assert np.all(err <= 0.5 * 0.012 / (n - 1) / 0.004 * (1 + 1e-9))  # roundoff of the ratio
    assert fit_loglog(n, err)[0] == pytest.approx(-1.0, abs=0.05)


def test_interrupted_sweep_resumes_with_the_missing_cases_only(tmp_path, scheduler):
    spec = load_spec(write_spec(tmp_path / "spec"))
    whole = run_sweep(spec, tmp_path / "whole", scheduler=scheduler, figures=False)
    assert whole.ran == 4

    def interrupt_after_two(done, total, case, record, error):
        if done == 2:
            raise KeyboardInterrupt

    out = tmp_path / "resumed"
    with pytest.raises(KeyboardInterrupt):
        run_sweep(spec, out, scheduler=scheduler, figures=False, progress=interrupt_after_two)
    finished = sorted(p.name for p in (out / CASES).iterdir())
    assert len(finished) == 2 and not (out / "sweep.csv").exists()

    ran = []
    report = run_sweep(spec, out, scheduler=scheduler, figures=False,
                       progress=lambda done, total, case, record, error: ran.append(case.id))
    assert report.skipped == 2 and report.ran == 2
    assert sorted(ran) == sorted(c.id for c in spec.cases if c.id not in finished)
    expected = read_csv(tmp_path / "whole" / "sweep.csv")
    assert reproducible(read_csv(out / "sweep.csv")) == reproducible(expected)

    # a case folder lost after the fact (deleted): only that case runs again
    lost = spec.cases[1].id
    for p in (out / CASES / lost).iterdir():
        p.unlink()
    (out / CASES / lost).rmdir()
    again = run_sweep(spec, out, scheduler=scheduler, figures=False)
    assert again.ran == 1 and again.skipped == 3
    assert reproducible(read_csv(out / "sweep.csv")) == reproducible(expected)
    # a finished sweep reruns nothing (no cluster needed); --force reruns everything
    assert run_sweep(spec, out, scheduler="tcp://127.0.0.1:1", figures=False).ran == 0
    assert run_sweep(spec, out, scheduler=scheduler, figures=False, force=True).ran == 4
    assert reproducible(read_csv(out / "sweep.csv")) == reproducible(expected)


def test_failing_case_is_recorded_and_the_sweep_goes_on(tmp_path, scheduler):
    """A case that fails when it runs (here: refused from its computed strain, which needs the
    case's solve; a value its case file refuses is refused before the sweep, see
    tests/test_issue29_sweep.py) is recorded and the sweep goes on."""
    spec_text = """
base = "base.toml"
variants = ["ddcm"]
formulations = ["fischer_burmeister"]
[grid]
"obstacle.positions" = [[1.002, 1.0, 0.998], [1.0, 0.5, -0.5], [1.0, 0.999, 0.997]]
"""
    spec = load_spec(write_spec(tmp_path / "spec", spec_text))
    out = tmp_path / "out"
    report = run_sweep(spec, out, scheduler=scheduler, figures=False)
    assert report.ran == 3 and report.failed == [spec.cases[1].id]
    rows = read_csv(out / "sweep.csv")
    assert [r["status"] for r in rows] == ["ok", "failed", "ok"]
    assert "pushed past a fixed end or through the body" in rows[1]["message"]
    assert rows[1]["variant"] == "ddcm" and rows[1]["max_error_p"] == ""
    assert float(rows[2]["max_error_p"]) > 0
    assert json.loads((out / "sweep.json").read_text())["failed"] == 1
    # a failure is a result: a rerun skips it, --retry-failed runs it again
    assert run_sweep(spec, out, scheduler=scheduler, figures=False).ran == 0
    assert run_sweep(spec, out, scheduler=scheduler, figures=False, retry_failed=True).ran == 1


def test_cli_runs_on_an_existing_scheduler_with_one_line_per_case(tmp_path, scheduler, capsys):
    path = write_spec(tmp_path / "spec")
    out = tmp_path / "out"
    assert sweep_main([str(path), "--out", str(out), "--scheduler", scheduler, "--no-plots"]) == 0
    err = capsys.readouterr().err.splitlines()
    per_case = [line for line in err if line.startswith("ddcm-sweep: ") and " ok " in line]
    assert len(per_case) == 4 and per_case[-1].startswith("ddcm-sweep: 4/4 ")
    assert not list(out.glob("*.png")) and len(read_csv(out / "sweep.csv")) == 8
    assert sweep_main([str(path), "--out", str(out), "--scheduler", scheduler, "-q"]) == 0
    assert "ran 0, skipped 4" in capsys.readouterr().out


@pytest.mark.parametrize("name", ["data_size.toml", "noise.toml"])
def test_example_specs_load(name):
    spec = load_spec(ROOT / "examples" / "sweeps" / name)  # the first case built in full
    expected = {"data_size.toml": 13, "noise.toml": 7 * 20}[name]
    assert len(spec.cases) == expected == len({c.id for c in spec.cases})


# --------------------------------------------------------------------------------------- bad specs
BAD_SPECS = {
    "unknown key": ('base = "base.toml"\nbogus = 1\n[grid]\n"ddcm.c" = [1e11]\n', "unknown key 'bogus'"),
    "empty grid": ('base = "base.toml"\n[grid]\n', "empty grid"),
    "no grid": ('base = "base.toml"\n', "empty grid"),
    "empty values": ('base = "base.toml"\n[grid]\n"ddcm.c" = []\n', "non-empty list"),
    "repeated value": ('base = "base.toml"\n[grid]\n"ddcm.c" = [1e11, 1e11]\n', "lists a value twice"),
    "no base": ('[grid]\n"ddcm.c" = [1e11]\n', "needs base"),
    "base missing": ('base = "nowhere.toml"\n[grid]\n"ddcm.c" = [1e11]\n', "base case not found"),
    "unknown case key": ('base = "base.toml"\n[grid]\n"bar.lenght" = [1.0]\n', "unknown key 'lenght' in [bar]"),
    "unknown option": ('base = "base.toml"\n[grid]\n"formulations.penalty.gama" = [1e14]\n',
                       "unknown option 'gama'"),
    "bad index": ('base = "base.toml"\n[grid]\n"obstacle.positions.9" = [1.0]\n', "index 9 out of range"),
    "unknown generate key": ('base = "base.toml"\n[generate]\nnoize = 0.1\n[grid]\n"generate.points" = [10]\n',
                             "unknown key 'noize' in [generate]"),
    "generate without table": ('base = "base.toml"\n[grid]\n"generate.points" = [10]\n', "needs a [generate]"),
    "seeds without generate": ('base = "base.toml"\nseeds = 3\n', "seeds need a [generate]"),
    "bad noise": ('base = "base.toml"\n[generate]\n[grid]\n"generate.noise" = [0.0, -0.1]\n', "noise must be >= 0"),
    "unknown formulation": ('base = "base.toml"\nformulations = ["nope"]\n[grid]\n"ddcm.c" = [1e11]\n',
                            "unknown formulation 'nope'"),
    "bad figure": ('base = "base.toml"\n[grid]\n"ddcm.c" = [1e11]\n[[figures]]\nkind = "rate"\nx = "ddcm.c"\n'
                   'y = "speed"\n', "y must be a metric"),
}


@pytest.mark.parametrize("name", sorted(BAD_SPECS))
def test_bad_spec_is_one_line_exit_2_nothing_written(tmp_path, capsys, name):
    text, message = BAD_SPECS[name]
    path = write_spec(tmp_path / "spec", text)
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_spec(path)
    out = tmp_path / "out"
    assert sweep_main([str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("ddcm-sweep: error: ") and message in err
    assert not out.exists()


def test_missing_spec_and_bad_options(tmp_path, capsys):
    assert sweep_main([str(tmp_path / "none.toml"), "--out", str(tmp_path / "o")]) == 2
    assert "sweep spec not found" in capsys.readouterr().err
    path = write_spec(tmp_path / "spec")
    assert sweep_main([str(path), "--out", str(tmp_path / "o"), "--workers", "0"]) == 2
    assert sweep_main([str(path), "--out", str(tmp_path / "o"), "--workers", "2", "--scheduler", "tcp://x:1"]) == 2
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:  # --out is required: argparse's one-line usage error
        sweep_main([str(path)])
    assert exc.value.code == 2 and capsys.readouterr().err.count("\n") == 1
    assert not (tmp_path / "o").exists()


# -------------------------------------------------------------------------------------- generators
def _gen(**kw):
    table = dict(youngs_modulus=200e9, strain_min=-0.05, strain_max=0.01, points=500)
    table.update(kw)
    return generator_from_dict(table, {})


def test_noiseless_hookean_generator_is_the_papers_data_set(tmp_path):
    strain, stress = _gen().sample()
    paper = MaterialDataset.hookean(200e9, -0.05, 0.01, 500, c=300e9)
    assert np.array_equal(strain, paper.strain) and np.array_equal(stress, paper.stress)
    # through the CSV file the case reads: exact (17 significant digits)
    read = MaterialDataset.from_csv(_gen().write_csv(tmp_path / "d.csv"), c=300e9)
    assert np.array_equal(read.strain, paper.strain) and np.array_equal(read.stress, paper.stress)


@pytest.mark.parametrize("kind", ["multiplicative", "additive"])
def test_noise_is_reproducible_with_the_stated_spread(kind):
    n, eta = 20000, 0.02
    a = _gen(points=n, noise=eta, noise_kind=kind, seed=7)
    strain, stress = a.sample()
    again = a.sample()
    assert np.array_equal(stress, again[1]) and not np.array_equal(stress, _gen(points=n, noise=eta,
                                                                                 noise_kind=kind, seed=8).sample()[1])
    clean = 200e9 * strain
    if kind == "multiplicative":
        xi = (stress[clean != 0] / clean[clean != 0] - 1) / eta
    else:
        xi = (stress - clean) / (eta * np.max(np.abs(clean)))
    # standard normal draws: mean 0 and std 1 within 5 standard errors of n samples
    assert abs(np.mean(xi)) < 5 / np.sqrt(n) and abs(np.std(xi) - 1) < 5 / np.sqrt(2 * n)


def test_nonlinear_laws_and_strain_noise():
    strain, stress = _gen(law="tanh", stress_scale=1e9, points=101).sample()
    assert np.allclose(stress, 1e9 * np.tanh(200e9 * strain / 1e9), rtol=1e-15, atol=0)
    strain, stress = _gen(law="cubic", beta=-100.0, points=101).sample()
    assert np.allclose(stress, 200e9 * strain * (1 - 100.0 * strain**2), rtol=1e-15, atol=0)
    grid = np.linspace(-0.05, 0.01, 101)
    s_noisy, _ = _gen(points=101, noise=0.01, noise_on="both", noise_kind="additive").sample()
    assert not np.array_equal(s_noisy, grid) and np.max(np.abs(s_noisy - grid)) < 6 * 0.01 * 0.05
    r_strain, _ = _gen(points=1000, sampling="random", seed=3).sample()
    assert np.all(np.diff(r_strain) >= 0) and r_strain.min() >= -0.05 and r_strain.max() <= 0.01


@pytest.mark.parametrize("table, message", [
    (dict(law="tanh"), "needs stress_scale"),
    (dict(law="hookean", beta=1.0), "beta applies to law = \"cubic\" only"),
    (dict(points=0), "points must be an integer"),
    (dict(points=2.5), "points must be an integer"),
    (dict(strain_min=0.1), "strain_min must be <= strain_max"),
    (dict(noise_kind="gaussian"), "noise_kind must be one of"),
    (dict(youngs_modulus=-1.0), "youngs_modulus must be finite and positive"),
    (dict(noise=10 ** 400), "noise must be"),  # too large for a float: one line, no OverflowError
])
def test_bad_generator_values(table, message):
    with pytest.raises(InputError, match=message):
        _gen(**table)


def test_generator_without_points():
    with pytest.raises(InputError, match="missing key 'points'"):
        generator_from_dict(dict(youngs_modulus=1.0, strain_min=0.0, strain_max=1.0), {})
