"""The MPCC formulation with Coulomb friction, on FCLIB local problems generated here (small random
SPD Delassus operators, written in the FCLIB format and read back): the classical problem against
the augmented Lagrangian (Alart--Curnier), ``mu = 0`` against the frictionless problem, and a
frictional projection (a distance objective) against the augmented Lagrangian."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

from ddcm_casadi import formulations
from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.models.coulomb import blocks, contact_status
from ddcm_casadi.problems.fclib import LocalProblem, as_complementarity_problem, read_fclib, write_fclib
from ddcm_casadi.problems.maps import Affine, Distance
from ddcm_casadi.problems.parameters import Parameters

pytest.importorskip("h5py")

#: (contacts, seed) of the generated problems.
GENERATED = [(1, 0), (1, 1), (3, 0), (3, 1), (8, 0), (8, 1)]
#: FCLIB's strict level of the natural-map error.
FCLIB_TOL = 1e-8
#: The augmented Lagrangian accepts a frictional solve at this natural-map residual (scaled);
#: the MPCC at its ``comp_tol`` (1e-11), below it.
AL_COMP_TOL = 1e-9


def local_problem(nc: int, seed: int, mu: float = 0.3) -> LocalProblem:
    """``W = A A^T / (3 nc) + I / 2`` (SPD, eigenvalues >= 1/2, about 4.5 at most), ``q`` normal:
    normal components of mean -1 (most contacts pressed), tangential ones of deviation 0.4 (a mix
    of stick and slip at ``mu = 0.3``)."""
    rng = np.random.default_rng(1000 * nc + seed)
    A = rng.normal(size=(3 * nc, 3 * nc))
    q = rng.normal(size=3 * nc) * np.tile([1.0, 0.4, 0.4], nc)
    q[0::3] -= 1.0
    return LocalProblem(sp.csr_matrix(A @ A.T / (3 * nc) + 0.5 * np.eye(3 * nc)), q, np.full(nc, mu), f"{nc} contacts")


def tolerance(local: LocalProblem) -> float:
    """Two solutions whose law residuals are at most ``AL_COMP_TOL`` differ by about that times
    the conditioning of ``W`` (the sensitivity of ``u = W r + q``); a factor 10 of margin."""
    return 10.0 * AL_COMP_TOL * np.linalg.cond(local.W.toarray())


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> dict:
    """The generated problems, through FCLIB files."""
    folder = tmp_path_factory.mktemp("fclib")
    return {key: read_fclib(write_fclib(folder / f"local_{key[0]}_{key[1]}.hdf5", local_problem(*key)))
            for key in GENERATED}


@pytest.fixture(scope="module")
def solved(generated) -> dict:
    """Per problem: the FCLIB problem, and the MPCC and augmented Lagrangian solutions from ``r = 0``."""
    out = {}
    for key, local in generated.items():
        fc = as_complementarity_problem(local)
        out[key] = fc, {name: formulations.get(name).build(fc.problem).solve(fc.params, *fc.start())
                        for name in ("mpcc", "augmented_lagrangian")}
    return out


def test_mpcc_supports_coulomb():
    assert "coulomb" in formulations.get("mpcc").supported_contact_laws


@pytest.mark.parametrize("key", GENERATED, ids=[f"{nc}c-{s}" for nc, s in GENERATED])
def test_classical_matches_augmented_lagrangian(solved, generated, key):
    fc, sol = solved[key]
    mpcc, al = sol["mpcc"], sol["augmented_lagrangian"]
    assert mpcc.converged and al.converged, (mpcc.message, al.message)
    assert fc.error(mpcc.x, mpcc.p) <= FCLIB_TOL
    r, r_al = fc.reactions(mpcc.p), fc.reactions(al.p)
    assert np.max(np.abs(r - r_al)) <= tolerance(generated[key]) * max(1.0, np.max(np.abs(r_al)))


def test_generated_problems_have_open_stick_and_slip_contacts(solved):
    """The comparisons above exercise every branch of the law."""
    seen = set()
    for fc, sol in solved.values():
        s = sol["augmented_lagrangian"]
        u = blocks(fc.problem.gap_map.value(np.concatenate([s.x, s.p]), fc.params), 3)
        seen.update(contact_status(u, blocks(s.p, 3), fc.source.mu, 1e-9, 1e-9))
    assert seen == {"open", "stick", "slip"}


def test_friction_and_load_are_parameters(generated):
    """One build, several friction coefficients and loads (the NLPs are built once)."""
    local = generated[(3, 1)]
    fc = as_complementarity_problem(local)
    P = fc.problem.parameters
    mpcc = formulations.get("mpcc").build(fc.problem)
    al = formulations.get("augmented_lagrangian").build(fc.problem)
    for mu, load in [(0.1, 1.0), (0.8, 1.0), (0.3, 1.7)]:
        params = P.pack(friction=mu, traction0=0.0, q=load * P.get(fc.params, "q"))
        a, b = mpcc.solve(params, *fc.start()), al.solve(params, *fc.start())
        assert a.converged and b.converged
        assert np.max(np.abs(a.p - b.p)) <= tolerance(local) * max(1.0, np.max(np.abs(b.p)))


def test_warm_start_solves_the_branch_nlp_first(generated):
    """A load step from the last solution with its state: the branch NLP of its statuses first
    (without the classical active set, which comes before it)."""
    local = generated[(8, 0)]
    fc = as_complementarity_problem(local)
    P = fc.problem.parameters
    mpcc = formulations.get("mpcc", active_set=False).build(fc.problem)
    first = mpcc.solve(fc.params, *fc.start())
    params = P.pack(friction=local.mu, traction0=0.0, q=1.01 * P.get(fc.params, "q"))
    second = mpcc.solve(params, first.x, first.p, first.state)
    assert second.converged and second.message == "converged (branch NLP from the start's branch)"
    reference = formulations.get("augmented_lagrangian").build(fc.problem).solve(params, *fc.start())
    assert np.max(np.abs(second.p - reference.p)) <= tolerance(local) * max(1.0, np.max(np.abs(reference.p)))


def frictionless(local: LocalProblem) -> ComplementarityProblem:
    """The normal problem of ``local`` (``u_N = W_NN r_N + q_N``, Signorini), unscaled: ``x = u_N``,
    parameter ``q = q_N``."""
    nc = local.n_contacts
    I, O = sp.identity(nc, format="csr"), sp.csr_matrix((nc, nc))
    return ComplementarityProblem(
        kind="mcp", parameters=Parameters(q=nc), unknowns=(("u", nc),),
        residual_map=Affine(sp.hstack([I, -local.W[0::3, 0::3]]), -I), gap_map=Affine(sp.hstack([I, O]), O),
        distance=None, gap_ref=1.0, pressure_ref=1.0, contact_stiffness=1.0, fb_alpha=1.0, fb_beta=1.0)


@pytest.mark.parametrize("active_set", [False, True], ids=["homotopy", "active set"])
@pytest.mark.parametrize("key", [(3, 0), (8, 1)], ids=["3c", "8c"])
def test_zero_friction_is_the_frictionless_problem(key, active_set):
    local = dataclasses.replace(local_problem(*key), mu=np.zeros(key[0]))
    fc = as_complementarity_problem(local)
    sol = formulations.get("mpcc", active_set=active_set).build(fc.problem).solve(fc.params, *fc.start())
    normal = frictionless(local)
    ref = formulations.get("mpcc").build(normal).solve(normal.parameters.pack(q=local.q[0::3]), np.zeros(key[0]),
                                                       np.zeros(key[0]))
    assert sol.converged and ref.converged
    r = fc.reactions(sol.p).reshape(-1, 3)
    scale = tolerance(local) * max(1.0, np.max(np.abs(ref.p)))
    if active_set:  # the branch NLP in r: its slip rule r_T = -mu p_N s_T / |s_T| = 0, to roundoff
        assert np.max(np.abs(r[:, 1:])) <= scale
    else:
        assert np.all(r[:, 1:] == 0.0)  # the relaxed NLP's r_T = mu p_N rho: exactly zero
    assert np.max(np.abs(r[:, 0] - ref.p)) <= scale


def projection(fc) -> ComplementarityProblem:
    """The frictional projection of ``fc``'s problem onto data ``(u*, r*)`` (scaled): minimise
    ``|u - u*|^2 / 2 + |r - r*|^2 / 2`` subject to ``u = W r + q`` and Coulomb's law (kind ``mpcc``,
    parameters ``u_star`` and ``r_star``), as a DDCM projection with a frictional interface."""
    pb = fc.problem
    n = pb.n_x
    P = pb.parameters.extend(u_star=n, r_star=n)

    def pad(A: Affine) -> Affine:
        return Affine(A.z, sp.hstack([A.params, sp.csr_matrix((A.rows, 2 * n))]))

    d = Affine(sp.identity(2 * n), sp.hstack([sp.csr_matrix((2 * n, pb.parameters.size)), -sp.identity(2 * n)]))
    return dataclasses.replace(pb, kind="mpcc", parameters=P, residual_map=pad(pb.residual_map),
                               gap_map=pad(pb.gap_map), distance=Distance(d, sp.identity(2 * n, format="csr")))


@pytest.mark.parametrize("key", [(3, 0), (8, 1)], ids=["3c", "8c"])
def test_frictional_projection(solved, generated, key):
    """Data: the classical solution perturbed; the start: the classical solution (on the
    admissible set, as a DDCM projection starts from the last state)."""
    fc, sol = solved[key]
    classical = sol["augmented_lagrangian"]
    problem = projection(fc)
    rng = np.random.default_rng(key[1])
    n = problem.n_x
    params = problem.parameters.pack(fc.params, u_star=classical.x + 0.3 * rng.normal(size=n),
                                     r_star=classical.p + 0.3 * rng.normal(size=n))
    mpcc = formulations.get("mpcc").build(problem).solve(params, classical.x, classical.p)
    assert mpcc.converged and mpcc.complementarity <= formulations.get("mpcc").options.comp_tol
    other = formulations.get("augmented_lagrangian").build(problem).solve(params, classical.x, classical.p)
    assert other.converged
    tol = tolerance(generated[key])
    assert np.max(np.abs(mpcc.p - other.p)) <= tol * max(1.0, np.max(np.abs(other.p)))
    assert abs(mpcc.objective - other.objective) <= tol * max(1.0, other.objective)
