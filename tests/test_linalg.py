"""The sparse linear solvers of :mod:`ddcm_casadi.linalg`: every registered solver solves the
matrices the package factorises (stiffness, saddle-point systems of projections, nonsymmetric
Newton Jacobians) to its backward error, and reports a singular matrix as
:class:`~ddcm_casadi.linalg.SingularMatrix`."""

from __future__ import annotations

import sys
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from ddcm_casadi import formulations as registry
from ddcm_casadi import InputError, linalg, paper_bar
from ddcm_casadi.factor_updates import ReferenceFactor, UpdatedFactor
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.validation.ladder import warren_truss

EPS = np.finfo(float).eps


@pytest.fixture(params=linalg.available_solvers())
def solver(request):
    previous = linalg.solver_name()
    linalg.use_solver(request.param)
    yield request.param
    linalg.use_solver(previous)


def saddle_matrix(model) -> sp.csc_matrix:
    """The projection's piece (KKT) matrix at the zero start, a third of the pairs in contact."""
    problems = build_problems(model)
    system = registry.get("fischer_burmeister").build(problems.projection).system
    rj, _, jacobian, _ = system.branch_system()
    nc = system.nc
    mk = model.n_points * model.strain_components
    P = problems.projection_params(model.n_steps - 1, np.zeros(mk), np.zeros(mk))
    branch = (np.arange(nc) < max(1, nc // 3)).astype(float)
    z = system.start(np.zeros(problems.projection.n_x), np.zeros(nc), None)
    _, J = rj(z, system.piece_parameters.pack(P, branch=branch, corner=np.zeros(nc)))
    return jacobian(J)


def grid_kkt(m: int = 40) -> sp.csc_matrix:
    """The KKT matrix of a 2-D grid Laplacian (``m^2`` unknowns) with ``m`` constraints: large
    enough that a factorisation costs many solves, so low-rank updates are worth their rank."""
    T = sp.diags([-np.ones(m - 1), 2 * np.ones(m), -np.ones(m - 1)], [-1, 0, 1])
    K = sp.kronsum(T, T, format="csc")
    B = sp.csc_matrix((np.ones(m), (np.arange(m), np.arange(m) * m)), shape=(m, m * m))
    return sp.bmat([[K, B.T], [B, None]], format="csc")


@cache
def matrices():
    rng = np.random.default_rng(3)
    n = 60
    general = sp.random(n, n, 0.08, random_state=4, format="csc") + 4 * sp.identity(n, format="csc")
    spd = (general @ general.T).tocsc()
    K = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csc")
    B = sp.csc_matrix(rng.standard_normal((3, n)))
    kkt = sp.bmat([[K, B.T], [B, None]], format="csc")  # zero diagonal block: needs off-diagonal pivots
    return dict(general=general, spd=spd, kkt=kkt, bar_projection=saddle_matrix(paper_bar()),
                truss_projection=saddle_matrix(warren_truss(n_data=201)))


@pytest.mark.parametrize("name", ["general", "spd", "kkt", "bar_projection", "truss_projection"])
def test_solves_to_backward_error(solver, name):
    A = matrices()[name]
    x_true = np.cos(np.arange(A.shape[0]))
    b = A @ x_true
    x = linalg.factorize(A).solve(b)
    # Wilkinson's bound for Gaussian elimination, |dA| <= gamma_3n |L| |U| ~ 3 n eps with a
    # growth factor of order one (diagonally dominant or well-scaled saddle systems).
    assert linalg.backward_error(A, x, b) <= 3 * A.shape[0] * EPS


def test_saddle_systems_use_the_symmetric_ordering():
    """A saddle-point matrix with a symmetric pattern is ordered by minimum degree on A + A^T with
    diagonal pivots: its factor fills in much less than (here about half) with scipy's default (COLAMD, partial
    pivoting)."""
    import scipy.sparse.linalg as spla

    A = grid_kkt()
    assert A.shape[0] >= linalg.ORDERING_MIN_SIZE and linalg.pattern_symmetry(A) == 1.0
    assert linalg.ordering_of(A) == "minimum_degree"
    previous = linalg.solver_name()
    linalg.use_solver("superlu")
    try:
        chosen = linalg.factorize(A)
    finally:
        linalg.use_solver(previous)
    default = spla.splu(A)
    assert chosen.nnz < 0.6 * default.nnz  # measured: 40 181 against 77 788 nonzeros


def test_chain_like_patterns_keep_the_default_ordering():
    """A chain (a bar's graph) has a symmetric pattern but a thin profile, within CHAIN_ENVELOPE
    nonzeros per matrix nonzero, and goes to SuperLU's default; a 2-D grid's profile is far wider."""
    n = 2000
    chain = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csc")
    assert n >= linalg.ORDERING_MIN_SIZE and linalg.pattern_symmetry(chain) == 1.0
    assert linalg.ordering_of(chain) == "colamd"
    assert linalg.ordering_of(grid_kkt()) == "minimum_degree"
    assert linalg.ordering_of(grid_kkt(5)) == "colamd"  # below ORDERING_MIN_SIZE unknowns


def test_pattern_symmetry():
    A = sp.csc_matrix(np.array([[1.0, 2.0, 0.0], [3.0, 1.0, 0.0], [5.0, 0.0, 1.0]]))
    assert linalg.pattern_symmetry(A) == pytest.approx(2 / 3)  # (0,1), (1,0) paired; (2,0) alone
    assert linalg.pattern_symmetry(sp.identity(4, format="csc")) == 1.0


@pytest.mark.parametrize("rows", [[[1.0, 1.0], [1.0, 1.0]], [[1.0, 2.0], [2.0, 4.0]], [[0.0, 0.0], [0.0, 1.0]]])
def test_singular_matrix_raises(solver, rows):
    with pytest.raises(linalg.SingularMatrix):
        linalg.factorize(sp.csc_matrix(np.array(rows)))


def test_auto_chooses_by_size():
    """The default ``"auto"`` factorises small matrices with SuperLU (no set-up), larger ones with
    MUMPS where it loads (CasADi ships it), else the largest (smaller if unsymmetric) with PARDISO
    where it runs; the Delassus matrix likewise, PARDISO's Schur complement from its own size."""
    assert linalg.solver_name() == "auto"
    mumps = "mumps" in linalg.available_solvers()
    pardiso = "pardiso" in linalg.available_solvers()
    assert linalg.chosen_solver(linalg.MUMPS_MIN_SIZE - 1) == "superlu"
    assert linalg.chosen_solver(linalg.MUMPS_MIN_SIZE) == ("mumps" if mumps else "superlu")
    large = "mumps" if mumps else "pardiso" if pardiso else "superlu"
    assert linalg.chosen_solver(linalg.PARDISO_MIN_SIZE) == large
    assert linalg.chosen_solver(linalg.PARDISO_UNSYMMETRIC_MIN_SIZE, symmetric=False) == large
    assert linalg.delassus_solver(linalg.MUMPS_MIN_SIZE - 1) == "superlu"
    assert linalg.delassus_solver(linalg.SCHUR_MIN_SIZE) == large


def test_unknown_solver_is_an_input_error():
    from ddcm_casadi.errors import InputError

    with pytest.raises(InputError, match="unknown linear solver 'nosuch'"):
        linalg.use_solver("nosuch")


def _switched(A: sp.csc_matrix, rows) -> sp.csc_matrix:
    """``A`` with ``rows`` and the matching columns changed (a pair switching piece changes its
    row of the KKT matrix and, symmetrically, its column)."""
    B = sp.lil_matrix(A)
    for i in rows:
        B[i, i] += 1.5
        B[i, (i + 7) % A.shape[0]] += 0.25
        B[(i + 7) % A.shape[0], i] += 0.25
    return sp.csc_matrix(B)


def test_update_solves_the_changed_matrix(solver):
    A0 = grid_kkt()
    reference = ReferenceFactor(A0)
    assert reference.new_columns >= 2
    A = _switched(A0, [3])
    up = reference.update(A)
    assert up is not None and up.rank == 2  # row 3 and its partner 10
    b = A @ np.cos(np.arange(A.shape[0]))
    # Woodbury adds a solve with A0 and two thin products: the backward-error bound of a solve.
    assert linalg.backward_error(A, up.solve(b), b) <= 3 * A.shape[0] * EPS
    # the same rows again: no new column is solved for
    again = reference.update(_switched(A0, [3]) * 1.0)
    assert again is not None and reference.kept_columns == 2


def test_update_limits_and_no_change():
    A0 = grid_kkt()
    reference = ReferenceFactor(A0)
    assert reference.update(A0).rank == 0
    too_many = _switched(A0, range(0, A0.shape[0], 2))
    assert sp.csr_matrix(too_many - A0).getnnz(axis=1).astype(bool).sum() > reference.max_rank
    assert reference.update(too_many) is None


def test_update_to_a_singular_matrix_raises():
    A0 = grid_kkt()
    reference = ReferenceFactor(A0)
    A = sp.lil_matrix(A0)
    A[2, :] = 0.0  # a zero row: singular
    A = sp.csc_matrix(A)
    with pytest.raises(linalg.SingularMatrix):
        if reference.update(A) is None:  # refused the update: the full factorisation must raise
            linalg.factorize(A)


def test_low_rank_updates_give_the_factorised_path(monkeypatch):
    """DDCM on a P2 Hertz block: the path solved with low-rank factor updates equals the path
    solved with a factorisation per active set. Both solve every piece system to the Newton
    tolerances (relative increment 1e-9 of the scaled unknowns), so they agree to 1e-7 of each
    field's maximum (a margin of 100 for the conditioning of the projection)."""
    from ddcm_casadi.validation.continuum import hertz_block
    from ddcm_casadi.drivers.ddcm_options import DDCMOptions
    from ddcm_casadi.drivers.harness import compare

    model = hertz_block(2, degree=2, data=True)
    update, used = ReferenceFactor.update, []

    def counted(self, A):
        lu = update(self, A)
        used.append(lu is not None)
        return lu

    monkeypatch.setattr(ReferenceFactor, "update", counted)
    full = DDCMOptions(reduce=False)  # the full saddle point's factors (the reduced path's are small)
    with_updates = compare(model, ["fischer_burmeister"], variants=["ddcm"], ddcm=full)["ddcm", "fischer_burmeister"]
    assert sum(used) >= 10  # the comparison means something: the path did switch by updates
    monkeypatch.setattr(ReferenceFactor, "update", lambda self, A: None)
    factorised = compare(model, ["fischer_burmeister"], variants=["ddcm"], ddcm=full)["ddcm", "fischer_burmeister"]
    assert with_updates.converged and factorised.converged
    for field in ("u", "p", "stress"):
        a, b = with_updates.array(field), factorised.array(field)
        assert np.max(np.abs(a - b)) <= 1e-7 * np.max(np.abs(b))


def test_piece_factor_cache_keeps_few_full_factorisations():
    """The active-set solver's cache of piece factors holds at most ``FACTORS_KEPT`` full
    factorisations (an update holds its base's; GBs each at 1e6 unknowns), the least recently
    used going first."""
    from ddcm_casadi.loops.active_set import ActiveSetSolver, PieceFactorCache

    assert ActiveSetSolver.FACTORS_KEPT == 2
    cache = PieceFactorCache(ActiveSetSolver.LU_CACHE, ActiveSetSolver.FACTORS_KEPT)  # the solver's sizes
    A = sp.csc_matrix(np.diag([2.0, 3.0, 4.0]))
    f1, f2, f3 = (linalg.factorize(A) for _ in range(3))

    def update(base):
        return UpdatedFactor(base, np.zeros((3, 1)), sp.csr_matrix((1, 3)))

    for key, lu in [(b"a", f1), (b"b", update(f1)), (b"c", f2), (b"d", update(f2)), (b"e", f3)]:
        cache.put(key, lu)
    assert cache.keys() == [b"c", b"d", b"e"]  # f1 and the update resting on it went
    for key in (b"f", b"g"):
        cache.put(key, update(f3))
    assert cache.keys() == [b"d", b"e", b"f", b"g"]  # at most LU_CACHE pieces
    assert cache.take(b"e") is f3 and cache.take(b"e") is None
    cache.put(b"e", f3)  # back, as the most recently used
    assert cache.keys() == [b"d", b"f", b"g", b"e"]


def test_an_optional_solver_whose_library_does_not_load_is_not_offered(monkeypatch):
    """A solver registered with the library it loads on first use, as PARDISO is with pypardiso
    (which, installed without a findable MKL runtime, raises ImportError on import): where that
    library does not import, the solver is neither listed nor selectable, with the reason in one
    line."""
    monkeypatch.setitem(sys.modules, "ddcm_test_solver_library", None)  # importing it raises ImportError
    linalg.register_solver("test_solver", lambda A, *, tolerance: linalg.factorize(A),
                           library="ddcm_test_solver_library")
    try:
        assert "test_solver" not in linalg.available_solvers() and "superlu" in linalg.available_solvers()
        assert "test_solver" in linalg.unavailable_solvers()
        with pytest.raises(InputError, match="linear solver 'test_solver' cannot run here: "):
            linalg.use_solver("test_solver")
        assert linalg.solver_name() == "auto"
    finally:
        linalg.unregister_solver("test_solver")
    assert "test_solver" not in linalg.unavailable_solvers()
    with pytest.raises(InputError, match="unknown linear solver 'test_solver'"):
        linalg.use_solver("test_solver")


def resident_megabytes() -> float:
    """The process's resident memory (``VmRSS`` of ``/proc/self/status``), MB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise AssertionError("no VmRSS in /proc/self/status")


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads Linux's resident memory")
def test_factors_of_the_factorising_thread_are_freed(monkeypatch):
    """A large matrix is factorised in the factorising thread (so that Ctrl-C acts at once), and its
    factor must be freed in that thread: scipy's SuperLU frees a block only in the thread that
    allocated it, so a factor dropped in the main thread leaked whole (the 20 478-unknown
    finite-strain projection grew past 16 GB). Here every size goes to that thread, and 30
    factors of a 10 000-unknown Laplacian (about 370 000 nonzeros, 4.5 MB each) are made and
    dropped: leaked, the 5th to the 30th would add about 110 MB; the allowance, 25 MB, is well
    above the allocator's slack and well below that. No factor made there may stay alive."""
    monkeypatch.setattr(linalg, "INTERRUPTIBLE_MIN_SIZE", 0)
    n = 100
    second = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    A = (sp.kron(sp.identity(n), second) + sp.kron(second, sp.identity(n))).tocsc()
    b = np.ones(A.shape[0])
    owner = linalg._FACTOR_THREAD
    resident = []
    for _ in range(30):
        factor = linalg.factorize(A)
        x = factor.solve(b)
        del factor
        resident.append(resident_megabytes())
    assert np.max(np.abs(A @ x - b)) <= 1e-8 * np.max(np.abs(b))
    assert resident[-1] - resident[4] <= 25.0, resident
    linalg.factorize(A)  # the releases queued before this job are done when it is
    assert owner.made - owner.released <= 1


def test_small_dense_matrices_are_factorised_dense():
    """A condensed contact problem's systems (dense Delassus blocks) go to LAPACK's LU: the
    solve is exact to the backward error of partial pivoting; an exactly singular one raises."""
    from ddcm_casadi.linalg import DENSE_MIN, SingularMatrix, backward_error, factorize

    rng = np.random.default_rng(3)
    n = DENSE_MIN + 36
    A = rng.standard_normal((n, n))
    A[rng.random((n, n)) < 0.5] = 0.0
    A = sp.csc_matrix(A + n * np.eye(n))
    b = rng.standard_normal(n)
    assert backward_error(A, factorize(A).solve(b), b) <= 1e-14
    singular = A.tolil()
    singular[:, 0] = 0.0
    with pytest.raises(SingularMatrix):
        factorize(sp.csc_matrix(singular))


def test_amg_factor_solves_a_3d_stiffness_to_its_tolerance():
    """An elastic 3-D stiffness (the Hertz example's block, supported): every column to the
    relative residual DEFINITE_TOL (checked on the true residual, at most twice it), in a few
    tens of CG steps with the rigid-body modes; a singular matrix is refused."""
    pytest.importorskip("pyamg")
    from ddcm_casadi.casefiles.base import read_document
    from ddcm_casadi.casefiles.config import case_from_dict
    from ddcm_casadi.validation.continuum import EXAMPLE_3D

    doc = read_document(EXAMPLE_3D)
    doc["mesh"]["divisions"] = [5, 5, 5]
    doc["mesh"].pop("refine_near", None)
    model = case_from_dict(doc, base_dir=EXAMPLE_3D.parent, source="3-D block").model
    K = model.stiffness()
    rhs = np.cos(np.arange(2 * K.shape[0])).reshape(-1, 2)
    factor = linalg.AMGFactor(K, model.near_null_space())
    x = factor.solve(rhs)
    assert np.all(np.linalg.norm(K @ x - rhs, axis=0) <= 2 * linalg.DEFINITE_TOL * np.linalg.norm(rhs, axis=0))
    assert max(factor.iterations) <= 50
    np.testing.assert_array_equal(factor.solve(np.zeros(K.shape[0])), 0.0)
    # a free chain's Laplacian (constants in its null space), a right-hand side outside its range
    n = 400
    L = sp.diags([-np.ones(n - 1), np.r_[1.0, 2.0 * np.ones(n - 2), 1.0], -np.ones(n - 1)], [-1, 0, 1], format="csr")
    with pytest.raises(linalg.SingularMatrix):
        linalg.AMGFactor(L).solve(np.cos(np.arange(n)) + 1.0)


def test_definite_solver_selection():
    with pytest.raises(InputError, match="unknown definite solver"):
        linalg.use_definite_solver("cholmod")
    assert linalg.definite_solver_name() == "direct"
    A = sp.csc_matrix(sp.diags([4.0] * 300) + sp.diags([1.0] * 299, 1) + sp.diags([1.0] * 299, -1))
    b = np.ones(300)
    assert np.max(np.abs(A @ linalg.factorize_definite(A).solve(b) - b)) <= 1e-12


@pytest.mark.parametrize("with_rows", [False, True])
@pytest.mark.parametrize("fmt", ["coo", "csr", "csc"])
def test_upper_triangle_storage_of_the_augmented_matrix(with_rows, fmt):
    """PARDISO's symmetric storage of ``A`` (or of ``[[A, C^T], [C, 0]]``): the upper triangle in
    CSR with every diagonal entry stored (a missing one as an explicit zero), duplicates summed and
    indices sorted, equal entry by entry to the triangle of the assembled matrix (no arithmetic
    but the duplicates' sums: exact), from any storage of the symmetric ``A``."""
    A = sp.coo_matrix(([1.0, 1.0, 2.0, 0.5, 0.5, 0.5, 0.5, 4.0], ([0, 1, 1, 1, 2, 1, 2, 3], [1, 0, 1, 2, 1, 2, 1, 3])),
                      shape=(4, 4))  # A[0, 0] and A[2, 2] not stored, A[1, 2] in two pieces
    C = sp.csr_matrix(np.array([[1.0, 0.0, -2.0, 0.0], [0.0, 0.0, 0.0, 3.0]])) if with_rows else None
    M = linalg._upper_with_diagonal(A.asformat(fmt), C)
    full = A.toarray() if C is None else sp.bmat([[A, C.T], [C, None]]).toarray()
    assert M.has_sorted_indices
    assert np.array_equal(M.toarray(), np.triu(full))
    rows = np.repeat(np.arange(M.shape[0]), np.diff(M.indptr))
    assert np.array_equal(rows[M.indices == rows], np.arange(M.shape[0]))  # each diagonal entry stored once
    assert np.all(np.diff(M.indices)[np.diff(rows) == 0] > 0)
