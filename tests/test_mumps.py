"""MUMPS through CasADi's own library (:mod:`ddcm_casadi.mumps`): the structure read from the
header CasADi ships, every ``SYM`` mode's solves, the Schur complement against a dense Delassus
matrix, singular matrices, and factors freed with their objects."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from ddcm_casadi import linalg

mumps = pytest.importorskip("ddcm_casadi.mumps", reason="CasADi's build ships no MUMPS")
EPS = np.finfo(float).eps


def laplacian(m: int) -> sp.csc_matrix:
    """The 2-D grid Laplacian (``m^2`` unknowns) with a Dirichlet boundary: SPD, condition ~ m^2."""
    T = sp.diags([-np.ones(m - 1), 2 * np.ones(m), -np.ones(m - 1)], [-1, 0, 1])
    return sp.kronsum(T, T, format="csc")


def test_the_structure_is_read_from_a_header(tmp_path):
    """Types, pointers, several declarators on a line, arrays sized by macros; a type the reader
    does not know is an ImportError (so ``"mumps"`` is listed as unavailable, not misread)."""
    (tmp_path / "dmumps_c.h").write_text("""
#define MUMPS_VERSION "9.9.9"
#define MUMPS_VERSION_MAX_LEN 30
typedef struct {
    MUMPS_INT sym, par;  /* two */
    MUMPS_INT icntl[60];
    DMUMPS_REAL cntl[15];
    MUMPS_INT8 nnz;
    DMUMPS_COMPLEX *rhs, *redrhs;
    char version_number[MUMPS_VERSION_MAX_LEN + 1 + 1];
} DMUMPS_STRUC_C;
""")
    Struct, version = mumps._structure(str(tmp_path / "dmumps_c.h"))
    assert version == "9.9.9"
    assert [name for name, _ in Struct._fields_] == ["sym", "par", "icntl", "cntl", "nnz", "rhs", "redrhs",
                                                     "version_number"]
    assert Struct.icntl.size == 60 * 4 and Struct.cntl.size == 15 * 8 and Struct.version_number.size == 32
    assert Struct.rhs.size == ctypes.sizeof(ctypes.c_void_p) and Struct.nnz.offset % 8 == 0
    (tmp_path / "dmumps_c.h").write_text('#define MUMPS_VERSION "1"\ntypedef struct { FOO x; } DMUMPS_STRUC_C;')
    with pytest.raises(ImportError, match="unknown type 'FOO'"):
        mumps._structure(str(tmp_path / "dmumps_c.h"))


def test_the_library_is_casadis_and_matches_its_header():
    """The library loaded is CasADi's, and it reports its header's version once initialised (a
    structure laid out from another header would not read it back)."""
    import casadi

    assert Path(mumps.library_path()).parent == Path(casadi.__file__).resolve().parent
    lu = mumps.MumpsFactor(laplacian(4), 1)
    assert bytes(lu._s.version_number).split(b"\0")[0].decode() == mumps.version()


@pytest.mark.parametrize("symmetric", [0, 1, 2])
def test_every_mode_solves_to_backward_error(symmetric):
    """LU, LDL^T without and with pivoting: one and several right-hand sides, each within the
    backward error of a stable elimination, ``3 n eps`` (Wilkinson's bound with a growth of
    order one, as the tests of :mod:`ddcm_casadi.linalg`)."""
    A = laplacian(30)
    lu = mumps.MumpsFactor(A, symmetric)
    b = np.cos(np.arange(A.shape[0]))
    B = np.column_stack([b, np.sin(np.arange(A.shape[0])), np.zeros(A.shape[0])])
    for rhs in (b, B):
        x = lu.solve(rhs)
        assert x.shape == rhs.shape
        for j in range(x.reshape(A.shape[0], -1).shape[1]):
            column = lambda v: v.reshape(A.shape[0], -1)[:, j]
            assert linalg.backward_error(A, column(x), column(rhs)) <= 3 * A.shape[0] * EPS
    assert lu.nnz >= A.nnz and lu.null_pivots == 0
    with pytest.raises(ValueError, match="right-hand side of 3 rows"):
        lu.solve(np.ones(3))


def test_a_saddle_point_matrix_needs_the_pivoting_mode():
    """``[[K, B^T], [B, 0]]`` has zero pivots on its diagonal: ``SYM = 2`` (2x2 pivots) solves it."""
    K = laplacian(20)
    B = sp.random(5, K.shape[0], 0.05, random_state=2, format="csr")
    A = sp.bmat([[K, B.T], [B, None]], format="csc")
    x_true = np.cos(np.arange(A.shape[0]))
    x = mumps.MumpsFactor(A, 2).solve(A @ x_true)
    assert linalg.backward_error(A, x, A @ x_true) <= 3 * A.shape[0] * EPS


@pytest.mark.parametrize("symmetric", [1, 2])
def test_the_schur_complement_is_the_delassus_matrix(symmetric):
    """``C A^-1 C^T`` from the elimination against the dense one, to ``cond(A) eps`` relative
    (``cond`` of the 30 x 30 grid Laplacian: about 400); the solves are with ``A`` alone."""
    A = laplacian(30)
    C = sp.random(12, A.shape[0], 0.02, random_state=5, format="csr")
    lu = mumps.MumpsFactor(A, symmetric, C)
    dense = C @ np.linalg.solve(A.toarray(), C.T.toarray())
    assert lu.schur.shape == (12, 12) and np.array_equal(lu.schur, lu.schur.T)
    assert np.max(np.abs(lu.schur - dense)) <= 400 * A.shape[0] * EPS * np.max(np.abs(dense))
    b = np.cos(np.arange(A.shape[0]))
    assert linalg.backward_error(A, lu.solve(b), b) <= 3 * A.shape[0] * EPS
    with pytest.raises(ValueError, match="needs a symmetric A"):
        mumps.MumpsFactor(A, 0, C)


@pytest.mark.parametrize("symmetric", [0, 2])
def test_a_singular_matrix_shows_its_null_pivots(symmetric):
    lu = mumps.MumpsFactor(sp.csc_matrix(np.array([[1.0, 1.0], [1.0, 1.0]])), symmetric)
    assert lu.null_pivots == 1


def test_an_indefinite_matrix_shows_its_negative_pivots():
    """``SYM = 1`` counts negative pivots (``INFOG(12)``): the definite path of
    :mod:`ddcm_casadi.linalg` refuses the factor rather than check a solve."""
    indefinite = sp.csc_matrix(np.array([[1.0, 2.0], [2.0, 1.0]]))  # eigenvalues 3 and -1
    assert mumps.MumpsFactor(indefinite, 1).negative_pivots == 1
    assert mumps.MumpsFactor(laplacian(5), 1).negative_pivots == 0
    previous = linalg.solver_name()
    linalg.use_solver("mumps")
    try:
        with pytest.raises(linalg.SingularMatrix, match="1 negative pivots"):
            linalg.factorize_definite(indefinite)
        with pytest.raises(linalg.SingularMatrix, match="1 negative pivots"):
            linalg.factorize_with_delassus(indefinite, sp.csr_matrix(np.array([[1.0, 0.0]])))
    finally:
        linalg.use_solver(previous)


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads Linux's resident memory")
def test_factors_are_freed_with_their_objects():
    """30 factors of a 40 000-unknown Laplacian (each ``nnz`` about 4.5e6 entries, 36 MB) made
    and dropped: the process grows by less than three factors (the allocator keeps some)."""
    from tests.test_linalg import resident_megabytes

    A = laplacian(200)
    size = mumps.MumpsFactor(A, 1).nnz / 2 * 8 / 2**20
    start = resident_megabytes()
    for _ in range(30):
        mumps.MumpsFactor(A, 1)
    assert resident_megabytes() - start < 3 * size


def test_a_working_space_too_small_is_retried_larger(monkeypatch):
    """``INFOG(1) = -9`` (MUMPS's working space too small) makes the factorisation run again with
    ``ICNTL(14)`` at least :data:`~ddcm_casadi.mumps.WORKSPACE_PERCENT` (doubled each time); the
    factor then solves as any other. Simulated: the first factorisation call reports -9 without
    running."""
    calls = []
    real = mumps._dmumps_c

    def first_too_small(ref):
        s = ref._obj
        calls.append((s.job, s.icntl[13]))
        if s.job == 4 and sum(job == 4 for job, _ in calls) == 1:
            s.infog[0] = -9
            return
        real(ref)

    monkeypatch.setattr(mumps, "_dmumps_c", first_too_small)
    A = laplacian(10)
    lu = mumps.MumpsFactor(A, 1, icntl={14: 0})
    assert [icntl for job, icntl in calls if job == 4] == [0, mumps.WORKSPACE_PERCENT]
    b = np.cos(np.arange(A.shape[0]))
    assert linalg.backward_error(A, lu.solve(b), b) <= 3 * A.shape[0] * EPS
