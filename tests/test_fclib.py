"""FCLIB problems: files written and read back, the Coulomb cone's projection, the natural-map
error, and the reference solver against single-contact closed forms (open, stick, slip)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from ddcm_casadi.errors import InputError
from ddcm_casadi.problems.fclib import (GlobalProblem, LocalProblem, natural_map_error, project_cone, read_fclib,
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
