"""FCLIB problems: files written and read back, the Coulomb cone's projection, the natural-map
error, and the reference solver against single-contact closed forms (open, stick, slip)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from ddcm_casadi.errors import InputError
from ddcm_casadi.models.coulomb import project_cone
from ddcm_casadi.problems.fclib import (GlobalProblem, LocalProblem, natural_map_error, read_fclib,
                                        solve_projected_gauss_seidel, write_fclib)

pytest.importorskip("h5py")
#: Round-off of a few operations on O(1) numbers.
ROUNDOFF = 1e-14


def single_contact(q, mu: float) -> tuple[LocalProblem, np.ndarray]:
    """``W = I``: the closed form. Open if ``q_N >= 0`` (``r = 0``); stick if
    ``|q_T| <= -mu q_N`` (``r = -q``); else slip: the contact stays closed (``u_N = 0``, so
    ``r_N = -q_N``) and the friction force is on the cone's edge against the sliding,
    ``r_T = -mu r_N q_T / |q_T|`` (then ``u_hat = (mu |u_T|, u_T)`` lies on the dual cone's edge,
    orthogonal to ``r``)."""
    q = np.asarray(q, float)
    t = np.linalg.norm(q[1:])
    if q[0] >= 0:
        r = np.zeros(3)
    elif t <= -mu * q[0]:
        r = -q
    else:
        rn = -q[0]
        r = np.concatenate([[rn], -mu * rn * q[1:] / t])
    return LocalProblem(sp.identity(3, format="csr"), q, [mu]), r


@pytest.mark.parametrize("q", [[0.5, 0.1, 0.0], [-1.0, 0.1, 0.2], [-1.0, 0.4, -0.3]], ids=["open", "stick", "slip"])
def test_single_contact_closed_forms(q):
    problem, r = single_contact(q, 0.3)
    assert natural_map_error(problem, r) < ROUNDOFF
    s = solve_projected_gauss_seidel(problem, tol=1e-12)
    assert s.converged and np.max(np.abs(s.r.ravel() - r)) < 1e-10


def test_cone_projection_is_a_projection():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(200, 3))
    mu = rng.uniform(0.1, 1.0, size=200)
    p = project_cone(x, mu)
    assert np.all(np.linalg.norm(p[:, 1:], axis=1) <= mu * p[:, 0] + ROUNDOFF)  # in the cone
    assert np.allclose(project_cone(p, mu), p, atol=ROUNDOFF)  # idempotent
    # x - P(x) is in the polar cone and orthogonal to P(x) (Moreau's decomposition)
    d = x - p
    assert np.all(mu * np.linalg.norm(d[:, 1:], axis=1) <= -d[:, 0] + 1e-12)
    assert np.allclose(np.einsum("ij,ij->i", d, p), 0.0, atol=1e-12)


def test_local_problem_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    A = rng.normal(size=(6, 6))
    problem = LocalProblem(sp.csr_matrix(A @ A.T + 6 * np.eye(6)), rng.normal(size=6), [0.3, 0.5], "two contacts")
    back = read_fclib(write_fclib(tmp_path / "local.hdf5", problem))
    assert isinstance(back, LocalProblem) and back.title == "two contacts"
    assert np.array_equal(back.W.toarray(), problem.W.toarray()) and np.array_equal(back.q, problem.q)
    assert np.array_equal(back.mu, problem.mu)


def test_global_problem_reduces_to_its_local_one(tmp_path):
    """A spring chain (M) touching at one node (H): the reduction ``W = H^T M^-1 H``,
    ``q = H^T M^-1 f + w`` and the solution of the global problem from the local one."""
    n = 6
    M = sp.diags([np.full(n - 1, -1.0), np.full(n, 2.0), np.full(n - 1, -1.0)], [-1, 0, 1], format="csr")
    H = sp.csr_matrix(([1.0, 1.0, 1.0], ([0, 1, 2], [0, 1, 2])), shape=(n, 3))
    f = np.linspace(-1.0, 0.5, n)
    problem = GlobalProblem(M, H, f, np.zeros(3), np.array([0.4]), "chain")
    back = read_fclib(write_fclib(tmp_path / "global.hdf5", problem))
    assert isinstance(back, GlobalProblem)
    local = back.local()
    Minv = np.linalg.inv(M.toarray())
    assert np.allclose(local.W.toarray(), H.T @ Minv @ H, atol=ROUNDOFF)
    assert np.allclose(local.q, H.T @ Minv @ f, atol=ROUNDOFF)
    s = solve_projected_gauss_seidel(local, tol=1e-10)
    assert s.converged and s.error <= 1e-10


@pytest.mark.parametrize("content, message", [(b"not hdf5", "not a readable HDF5"), (None, "not an FCLIB problem")])
def test_bad_files_are_one_line_errors(tmp_path, content, message):
    path = tmp_path / "bad.hdf5"
    if content is None:
        import h5py

        with h5py.File(path, "w") as f:
            f.create_group("something_else")
    else:
        path.write_bytes(content)
    with pytest.raises(InputError, match=message) as err:
        read_fclib(path)
    assert "\n" not in str(err.value)


def test_malformed_problem_is_refused():
    with pytest.raises(InputError, match="needs W"):
        LocalProblem(sp.identity(3, format="csr"), np.zeros(6), [0.3])


# ------------------------------------------------------------------ solve_fclib on generated problems
from ddcm_casadi import formulations  # noqa: E402
from ddcm_casadi.drivers.fclib import FORMULATION_METHODS, solve_fclib  # noqa: E402
from ddcm_casadi.problems.fclib import as_complementarity_problem  # noqa: E402

#: The natural-map error every exact method must reach (the FCLIB benchmarks' strict level).
TOL = 1e-8


def random_global(seed: int, n: int = 30, nc: int = 8, mu=(0.1, 0.8)) -> GlobalProblem:
    """``M = A A^T + n I`` (SPD), random ``H`` (``n x 3 nc``: ``W = H^T M^-1 H`` is SPD when
    ``n >= 3 nc``, singular when ``3 nc > n``), random ``f`` and ``w`` with ``w_N <= 0`` (approaching contacts), ``mu`` uniform."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    w = rng.normal(size=3 * nc)
    w[0::3] = -np.abs(w[0::3])
    return GlobalProblem(sp.csr_matrix(A @ A.T + n * np.eye(n)), sp.csr_matrix(rng.normal(size=(n, 3 * nc))),
                         rng.normal(size=n), w, rng.uniform(*mu, size=nc), f"random {seed}")


def random_local(seed: int, nc: int = 5, mu=(0.1, 0.8), spectrum=(1.0, 2.0)) -> LocalProblem:
    """``W = Q diag(lambda) Q^T`` with ``lambda`` uniform in ``spectrum``, random ``q`` (``q_N < 0``
    at most contacts), ``mu`` uniform."""
    rng = np.random.default_rng(seed)
    Q = np.linalg.qr(rng.normal(size=(3 * nc, 3 * nc)))[0]
    W = Q @ np.diag(rng.uniform(*spectrum, size=3 * nc)) @ Q.T
    q = rng.normal(size=3 * nc)
    q[0::3] -= 0.5
    return LocalProblem(sp.csr_matrix(0.5 * (W + W.T)), q, rng.uniform(*mu, size=nc), f"random {seed}")


def penalty_bound(problem, r: np.ndarray) -> float:
    """The penalty solution satisfies Coulomb's law exactly for the shifted velocity
    ``u + r / gamma`` (normal ``u_N + r_N/gamma = 0`` in contact; stick ``u_T + r_T/gamma = 0``;
    slip: the shift is along ``u_T``). The natural map is 1-Lipschitz in ``u_hat`` and
    ``u -> u_hat`` is ``(1 + mu)``-Lipschitz, so its error is at most ``(1 + mu) |r| / (gamma |q|)``."""
    fc = as_complementarity_problem(problem)
    gamma = formulations.get("penalty").gamma(fc.problem)
    local = problem.local()
    return (1 + float(np.max(local.mu))) * float(np.linalg.norm(r)) / (gamma * float(np.linalg.norm(local.q)))


@pytest.mark.parametrize("kind", ["local", "global", "global, singular W"])
@pytest.mark.parametrize("method", ["default", "pgs", *FORMULATION_METHODS])
def test_generated_problems_are_solved_by_every_method(tmp_path, kind, method):
    """Written in the FCLIB format, read back and solved: the natural-map error at ``TOL`` (the
    penalty: at its own bound, :func:`penalty_bound`)."""
    for seed in range(2):
        problem = (random_local(seed) if kind == "local" else
                   random_global(seed) if kind == "global" else random_global(seed, n=12))
        back = read_fclib(write_fclib(tmp_path / f"{kind[:6]}{seed}.hdf5", problem))
        s = solve_fclib(back, method, tol=TOL, max_sweeps=20_000)
        assert s.r.shape == s.u.shape == (problem.n_contacts, 3) and s.method == method
        assert np.allclose(s.u.ravel(), problem.local().W @ s.r.ravel() + problem.local().q, atol=1e-10)
        if method == "penalty":
            assert s.error <= penalty_bound(problem, s.r)
        else:
            assert s.converged and s.error <= TOL, (seed, s.error, s.message)


def error_bound_factor(local: LocalProblem) -> float:
    """``|r - r*| <= C |R(r)|`` for Coulomb's problem as the variational inequality of
    ``F(r) = W r + q + mu |u_T| e_N`` over the cones: ``F`` is strongly monotone with modulus
    ``m >= lambda_min(W) - mu_max |W|`` (the De Saxce term is ``mu |W|``-Lipschitz) and Lipschitz
    with ``L <= (1 + mu_max) |W|``, so ``C = (1 + L) / m`` (the natural map's error bound for
    strongly monotone variational inequalities); ``m > 0`` makes the solution unique."""
    W = local.W.toarray()
    eig = np.linalg.eigvalsh(W)
    mu = float(np.max(local.mu))
    m = eig[0] - mu * eig[-1]
    assert m > 0
    return (1 + (1 + mu) * eig[-1]) / m


@pytest.mark.parametrize("method", ["default", "fischer_burmeister", "natural_map", "augmented_lagrangian"])
def test_unique_solution_equals_projected_gauss_seidel(method):
    """Small ``mu`` and a well-conditioned ``W``: one solution, which every method finds; the
    distance between two answers is at most ``C (e1 + e2) |q|`` (:func:`error_bound_factor`)."""
    problem = random_local(3, nc=6, mu=(0.1, 0.3))
    ref = solve_fclib(problem, "pgs", tol=1e-13, max_sweeps=100_000)
    s = solve_fclib(problem, method, tol=TOL)
    assert ref.converged and s.converged
    bound = error_bound_factor(problem) * (ref.error + s.error) * float(np.linalg.norm(problem.q))
    assert np.linalg.norm(s.r - ref.r) <= bound + ROUNDOFF * float(np.linalg.norm(ref.r))


def signorini_lcp(W: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The frictionless reactions by enumerating the active sets of the LCP
    ``0 <= W r + q perp r >= 0`` (``W`` SPD: exactly one satisfies every sign)."""
    n = q.size
    for mask in range(2 ** n):
        active = np.array([(mask >> i) & 1 for i in range(n)], bool)
        r = np.zeros(n)
        if active.any():
            r[active] = np.linalg.solve(W[np.ix_(active, active)], -q[active])
        u = W @ r + q
        if np.all(r >= -1e-12) and np.all(u[~active] >= -1e-12):
            return r
    raise AssertionError("no active set solves the LCP")


@pytest.mark.parametrize("method", ["default", "pgs", "fischer_burmeister", "natural_map", "augmented_lagrangian"])
def test_frictionless_problem_is_the_signorini_lcp(method):
    """``mu = 0``: no tangential reactions and the normal ones solve the LCP of ``W_NN, q_N``
    (unique: ``W`` is SPD), to the error bound with ``mu = 0``."""
    problem = random_local(4, nc=5, mu=(0.0, 0.0))
    W = problem.W.toarray()
    rn = signorini_lcp(W[0::3, 0::3], problem.q[0::3])
    s = solve_fclib(problem, method, tol=TOL, max_sweeps=100_000)
    assert s.converged
    assert np.max(np.abs(s.r[:, 1:])) <= ROUNDOFF * np.max(np.abs(rn))
    bound = error_bound_factor(problem) * s.error * float(np.linalg.norm(problem.q))
    assert np.linalg.norm(s.r[:, 0] - rn) <= bound + ROUNDOFF * float(np.linalg.norm(rn))


def hyperstatic(seed: int, nc: int = 6, n: int = 6) -> GlobalProblem:
    """A body of ``n`` freedoms (``M = I``) pressed onto ``nc`` sticking contacts by
    ``f = -H r_bar`` with ``r_bar`` inside the cones: ``3 nc > n`` reaction components, so the
    reactions are not unique (``r_bar`` plus the null space of ``H``) and ``W = H^T H`` is
    singular; Newton's Jacobian on the stick pieces is then singular."""
    rng = np.random.default_rng(seed)
    H = rng.normal(size=(n, 3 * nc))
    r_bar = np.column_stack([rng.uniform(1, 2, nc), rng.uniform(-0.1, 0.1, (nc, 2))]).ravel()
    return GlobalProblem(sp.identity(n, format="csr"), sp.csr_matrix(H), -H @ r_bar, np.zeros(3 * nc),
                         rng.uniform(0.3, 0.8, nc), "hyperstatic")


@pytest.mark.parametrize("seed", [0, 3])
def test_default_method_solves_a_hyperstatic_problem(seed):
    """Its local problem (``W = H^T H``, singular): plain semismooth Newton stalls on the
    singular stick pieces; the default method's proximal steps (``W + eta I``) reach ``TOL``
    (at one of the many solutions: some contacts may open or slip). PGS, which solves these
    well-conditioned examples alone, is held to one sweep per stage."""
    local = hyperstatic(seed).local()
    s = solve_fclib(local, "default", tol=TOL, max_sweeps=1)
    assert s.converged and natural_map_error(local, s.r) == s.error <= TOL, s.log
    assert "proximal" in [stage["stage"] for stage in s.log]


@pytest.mark.parametrize("kind", ["local", "global"])
def test_proximal_problem_is_solved_at_its_centre(kind):
    """With the centre at a solution, the proximal term vanishes there: Newton on the proximal
    problem from that point stays at it (the maps of ``eta (r - r_c)``)."""
    problem = random_local(5) if kind == "local" else random_global(5)
    s = solve_fclib(problem, "default", tol=1e-12)
    fc = as_complementarity_problem(problem, proximal=0.5)
    built = formulations.get("fischer_burmeister", coulomb_function="natural_map").build(fc.problem)
    sol = built.solve(fc.centred(s.r), *fc.point(s.r))
    assert sol.converged and fc.error(sol.x, sol.p) <= 1e-10
    assert np.allclose(fc.reactions(sol.p), s.r.ravel(), atol=1e-9 * np.abs(s.r).max())


@pytest.mark.parametrize("call, message", [
    (dict(method="newton"), "unknown FCLIB method"),
    (dict(newton="pgs"), "unknown Newton formulation"),
    (dict(tol=0.0), "tol must be"),
    (dict(tol=float("nan")), "tol must be"),
    (dict(max_sweeps=0), "max_sweeps must be"),
    (dict(max_rounds=2.5), "max_rounds must be"),
    (dict(r0=np.zeros(4)), "r0 must hold"),
    (dict(method="pgs", max_iter=3), "takes no formulation options"),
    (dict(method="natural_map", nonsense=1), "unknown option 'nonsense'"),
])
def test_solve_fclib_bad_input_is_one_line(call, message):
    with pytest.raises(InputError, match=message) as err:
        solve_fclib(random_local(0, nc=2), **call)
    assert "\n" not in str(err.value)


def test_bad_proximal_and_missing_file(tmp_path):
    with pytest.raises(InputError, match="proximal must be"):
        as_complementarity_problem(random_local(0, nc=2), proximal=-1.0)
    with pytest.raises(InputError, match="not a readable HDF5") as err:
        solve_fclib(tmp_path / "missing.hdf5")
    assert "\n" not in str(err.value)


def benchmark_module():
    """``benchmarks/fclib.py`` (a script, not a package)."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("fclib_benchmark",
                                                  Path(__file__).resolve().parent.parent / "benchmarks" / "fclib.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_performance_profiles():
    """Dolan-More: times ``[[1, 2], [inf, 3]]`` give ratios ``[[1, 2], [inf, 1]]``: at ``tau = 1``
    each method is fastest on one problem of two; from ``tau = 2`` the second solves both."""
    tau, rho = benchmark_module().profiles(np.array([[1.0, 2.0], [np.inf, 3.0]]))
    assert tau[0] == 1.0 and np.array_equal(rho[0], [0.5, 0.5])
    assert np.array_equal(rho[tau >= 2.0][0], [0.5, 1.0]) and np.array_equal(rho[-1], [0.5, 1.0])


def test_benchmark_writes_table_and_profiles(tmp_path):
    """The benchmark on two generated files: one row per problem and method, both levels, the
    figure and the summary."""
    import json

    pytest.importorskip("matplotlib")
    data = tmp_path / "data"
    data.mkdir()
    write_fclib(data / "a.hdf5", random_local(0))
    write_fclib(data / "b.hdf5", random_global(1))
    out = tmp_path / "out"
    assert benchmark_module().main(["--data", str(data), "--out", str(out), "--methods", "default,pgs,natural_map"]) == 0
    table = json.loads((out / "fclib.json").read_text())
    assert [(r["problem"], r["method"]) for r in table["rows"]] == [
        (p, m) for p in ("a.hdf5", "b.hdf5") for m in ("default", "pgs", "natural_map")]
    assert all(r["solved_1e-08"] and r["solved_0.0001"] for r in table["rows"])
    assert table["profiles"]["1e-08"]["default"]["solved"] == 1.0
    assert (out / "fclib_profiles.png").stat().st_size > 0 and (out / "fclib.md").exists()
