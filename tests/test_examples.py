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


# --------------------------------------------------------------- contact examples (quick runs)
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from ddcm_casadi import formulations  # noqa: E402
from ddcm_casadi.data.dataset import PointData  # noqa: E402

CONTACT_EXAMPLES = ("bar_on_stops", "truss_bridge", "truss_3d_plane")
FIGURES = ("structure_classical.png", "structure_ddcm.png", "contact_history.png")
EXACT = ("augmented_lagrangian", "fischer_burmeister", "mpcc")


_RUNS: dict = {}


def _quick(name, tmp_path_factory):
    """Run an example once (quick) per test session; the checks below share the result."""
    if name not in _RUNS:
        out = tmp_path_factory.mktemp(name)
        _RUNS[name] = (_load(name).main(out, quick=True), out)
    return _RUNS[name]


def _material_sets(dataset) -> list:
    """``(member mask, data set)`` per data set of a model's DDCM data."""
    if isinstance(dataset, PointData):
        return [(dataset.material == k, d) for k, d in enumerate(dataset.datasets)]
    return [(slice(None), dataset)]


@pytest.mark.parametrize("name", CONTACT_EXAMPLES)
def test_contact_example_converges_and_writes_figures(name, tmp_path_factory):
    cmp, out = _quick(name, tmp_path_factory)
    assert {v for v, _ in cmp.results} == {"classical", "ddcm"}
    assert len(cmp.results) == 8
    for (variant, formulation), r in cmp.results.items():
        bad = [s.step for s in r.steps if not s.converged]
        assert not bad, f"{name}: {variant} {formulation} did not converge at steps {bad}"
    for fig in FIGURES:
        assert (out / fig).stat().st_size > 10_000, fig
    # Contacts really close, and not all at once.
    force = cmp.fields("classical", "fischer_burmeister")["contact_force"]
    assert np.all(force[-1] > 0)
    first = [int(np.argmax(force[:, j] > 1e-6 * force[-1].max())) for j in range(force.shape[1])]
    assert len(set(first)) > 1, first
    # Strains stay inside the data range (DDCM cannot represent stresses beyond it).
    for mask, data in _material_sets(cmp.model.dataset):  # each member within its own data set
        for variant, formulation in cmp.results:
            strain = cmp.fields(variant, formulation)["strain"][:, mask]
            assert data.strain.min() < strain.min() and strain.max() < data.strain.max()


def test_bar_on_stops_exact_formulations_match_closed_form(tmp_path_factory):
    cmp, _ = _quick("bar_on_stops", tmp_path_factory)
    for formulation in EXACT:
        err = cmp.errors("classical", formulation)
        assert np.max(err["u"]) < 1e-8 and np.max(err["p"]) < 1e-8, formulation


@pytest.mark.parametrize("name", ("truss_bridge", "truss_3d_plane"))
@pytest.mark.parametrize("formulation", EXACT)
def test_truss_ddcm_error_within_its_constitutive_residual(name, formulation, tmp_path_factory):
    """A priori bound: DDCM and classical solutions differ in the energy norm by at most the DDCM
    solution's constitutive residual r = sigma - E eps,  ||u - u_c||_K <= ||r||_(W/E).

    (Both are admissible and satisfy the contact inequalities; subtracting the two variational
    inequalities gives ||e||_K^2 <= (B^T W r) . e <= ||r||_(W/E) ||e||_K.) Exact formulations only:
    the penalty's compliant pairs allow a penetration p / gamma.
    """
    cmp, _ = _quick(name, tmp_path_factory)
    m = cmp.model
    K = m.stiffness()
    u_c = cmp.fields("classical", "fischer_burmeister")["u"]
    f = cmp.fields("ddcm", formulation)
    for k in range(m.n_steps):
        e = f["u"][k] - u_c[k]
        r = f["stress"][k] - m.youngs_modulus * f["strain"][k]
        energy_error = np.sqrt(e @ (K @ e))
        bound = np.sqrt(np.sum(m.volumes * r**2 / m.youngs_modulus))
        # Roundoff: the solvers' own relative tolerance (Newton's increment test) of the energy scale.
        opts = [formulations.get(n).options for n in ("fischer_burmeister", formulation)]
        tol = max(o.tol if hasattr(o, "tol") else o.residual_tol for o in opts)
        assert energy_error <= bound + tol * np.sqrt(u_c[k] @ (K @ u_c[k])), (k, energy_error, bound)


def test_contact_figures_many_pairs_and_failed_steps(tmp_path):
    """More than 8 pairs: totals and active-contact counts; a failed step is flagged, not hidden."""
    from ddcm_casadi import compare
    from ddcm_casadi.outputs.plots import figure_contact_history, figure_structure, save_figure
    from ddcm_casadi.models.truss import bar_chain

    model = bar_chain(length=1.0, elements=12, youngs_modulus=200e9, tip_positions=np.linspace(1.0, 0.99, 5),
                      stops={k: 0.001 * k for k in range(1, 12)})
    cmp = compare(model, ["fischer_burmeister"], variants=["classical"])
    assert model.n_contacts > 8
    r = cmp["classical", "fischer_burmeister"]
    history = figure_contact_history(cmp)
    assert "NOT CONVERGED" not in [t.get_text() for t in history.axes[0].get_legend().get_texts()]
    r.steps[-1].converged = False
    history, structure = figure_contact_history(cmp), figure_structure(cmp, "classical", "fischer_burmeister")
    assert len(history.axes) == 2  # totals, and the active-contact count on a twin axis
    assert "NOT CONVERGED" in [t.get_text() for t in history.axes[0].get_legend().get_texts()]
    assert structure._suptitle is not None and structure._suptitle.get_text() == "NOT CONVERGED"
    active = int(np.sum(model.active_contacts(r.steps[-1].p)))
    assert f"{active}/{model.n_contacts} contacts active" in structure.axes[0].get_title()
    paths = [save_figure(history, tmp_path / "history.png"), save_figure(structure, tmp_path / "structure.png")]
    assert all(p.stat().st_size > 10_000 for p in paths)


def test_von_mises_snap_example(tmp_path):
    """Finite kinematics: Fischer-Burmeister (classical) and MPCC (DDCM) cross the snap; every
    converged step of every run has the closed form's contact status; figures are written."""
    module = _load("von_mises_snap")
    cmp = module.main(tmp_path, quick=True)
    assert len(cmp.results) == 8
    for key in (("classical", "fischer_burmeister"), ("ddcm", "mpcc")):
        assert all(s.converged for s in cmp.results[key].steps), key
    from ddcm_casadi.validation.finite_rungs import contact_status, snap_table

    m = cmp.model
    p_ref = np.array([m.closed_form(k)[1] for k in range(m.n_steps)])
    expected = contact_status(m, p_ref)
    spacing = float(np.max(np.diff(np.sort(m.dataset.stress))))  # the data's stress spacing
    for (variant, name), r in cmp.results.items():
        ok = np.array([s.converged for s in r.steps])
        if variant == "classical":
            assert np.all(contact_status(m, r.array("p"))[ok] == expected[ok]), name
        else:  # DDCM: within the data's stress spacing (the pressure is a member stress times 2 (h - w) / L0 < 1)
            assert np.max(np.abs(r.array("p") - p_ref)[ok]) <= spacing, name
    assert "travel" in snap_table(cmp)
    for fig in FIGURES:
        assert (tmp_path / fig).stat().st_size > 10_000, fig


def test_continuum_api_example(tmp_path):
    """The API example: every step converges; classical against Hertz within the quick mesh's
    discretisation error (two grading levels, about 0.06 mm elements at the contact: measured
    3.6 % in p0 and 4.9 % in a; bound 10 %); DDCM's force within the accuracy its graded 41^3
    data give (README: graded grids carry 90 % or more of the classical force on hertz2d)."""
    module = _load("continuum_api")
    cmp = module.main(tmp_path, quick=True)
    assert all(r.converged for r in cmp.results.values())
    measured = module.hertz(cmp)
    classical, ddcm = measured["classical/fischer_burmeister"], measured["ddcm/fischer_burmeister"]
    assert classical["error_p0"] < 0.10 and classical["error_a"] < 0.10
    assert 0.85 * classical["force"] <= ddcm["force"] <= classical["force"] * 1.02
    assert any(p.suffix == ".pvd" for p in tmp_path.rglob("*"))
