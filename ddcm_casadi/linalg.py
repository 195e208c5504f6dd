"""Sparse linear algebra: the scipy -> CasADi conversion and the pluggable sparse linear solver.

Every factorisation in the package (Newton steps, cached active-set systems, exact enumeration,
the reference scales) goes through :func:`factorize`, so the solver is chosen in one place.

``"auto"`` (the default): ``"mumps"`` for matrices of :data:`MUMPS_MIN_SIZE` unknowns or more
where CasADi's MUMPS loads; else ``"pardiso"`` for matrices of :data:`PARDISO_MIN_SIZE` unknowns
or more (:data:`PARDISO_UNSYMMETRIC_MIN_SIZE` for unsymmetric ones) where ``pypardiso`` is
installed and loads; else ``"superlu"`` (:func:`chosen_solver`).

``"mumps"`` (no extra dependency where CasADi's wheel ships MUMPS, as its Linux, macOS and
Windows wheels do for IPOPT; :mod:`ddcm_casadi.mumps`): a symmetric matrix is factorised as
symmetric indefinite (``SYM = 2``), a definite one (:func:`factorize_definite`) without pivoting
(``SYM = 1``), others by LU; AMD or METIS ordering by the matrix's density
(:func:`ddcm_casadi.mumps.ordering_for`). It is the fastest of the three here from a few
thousand unknowns (``docs/performance.md``, 2026-11-26), and its Schur complement gives the
Delassus matrix with the factor (:func:`factorize_with_delassus`).

``"superlu"`` (always available, no extra dependency): scipy's SuperLU, with the ordering chosen by the
matrix's pattern. Every matrix this package factorises is a stiffness or the KKT matrix of a
projection, whose *pattern* is symmetric; for those, the minimum-degree ordering of ``A + A^T``
with diagonal pivots (SuperLU's symmetric mode) keeps the fill of a Cholesky-like factor. Its
default, COLAMD with partial pivoting, orders for ``A^T A`` and pivots off the diagonal, which on
a saddle-point matrix fills in badly: on the 2-D continuum's projection system of 99 687 unknowns
the factorisation took 2.9 s in symmetric mode and 13.8 s with the default (measured in one run;
``benchmarks/run.py``, ``linear solver`` records). Diagonal pivots without a threshold are not
backward stable in general, so every symmetric-mode factor is checked: the backward error of one
solve, ``||A x - b||_inf / (||A||_inf ||x||_inf + ||b||_inf)``, must stay below
:data:`BACKWARD_ERROR` (:data:`ITERATED_BACKWARD_ERROR` for callers that iterate), else two steps
of iterative refinement are tried, and only then partial pivoting. Matrices of fewer than
:data:`ORDERING_MIN_SIZE` unknowns, unsymmetric patterns and chain-like ones (bars, trusses:
:data:`CHAIN_ENVELOPE`) go straight to SuperLU's default.

``"pardiso"`` (optional: ``pip install ddcm-casadi[pardiso]``, Intel MKL through ``pypardiso``):
registered when ``pypardiso`` imports. A symmetric matrix is factorised as symmetric indefinite
(``mtype = -2``, Bunch-Kaufman pivots within supernodes, one factor of the upper triangle), other
matrices as general (``mtype = 11``). Others can be registered with :func:`register_solver` (a
CHOLMOD wrapper, say) and selected with :func:`use_solver`.

Symmetric positive definite systems (the reduction's ``K_C``, the reference scales' stiffness) go
through :func:`factorize_definite`: the selected direct solver by default, or, after
``use_definite_solver("amg")`` (optional: ``pip install ddcm-casadi[amg]``), pyamg's smoothed
aggregation hierarchy set up once and CG per solve (:class:`AMGFactor`): in 3-D a direct factor's
fill grows like ``n^(4/3)`` and no longer fits in memory at 5e5 dofs (``docs/performance.md``).

Low-rank updates of a factor (the active-set solver's, when a few pairs switch piece) are
:mod:`ddcm_casadi.factor_updates`'.

A factor of a definite ``K`` together with the Delassus matrix ``C K^-1 C^T`` of a few rows ``C``
(the classical problem's condensation on its contact pairs) is :func:`factorize_with_delassus`:
MUMPS's or PARDISO's Schur complement of ``[[K, C^T], [C, 0]]`` in one partial factorisation
where one runs, else a factor and back-solves.
"""

from __future__ import annotations

import atexit
import importlib
import importlib.util
import os
import queue
import sys
import threading
from typing import Callable, Iterator, Protocol

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ddcm_casadi.errors import InputError
from ddcm_casadi.heap import release_heap
from ddcm_casadi.schur import schur_columns


#: Bytes per stored material datum and Mandel component (strain and stress, 8 bytes each, about
#: three copies with the search tree and the working arrays).
DATA_BYTES_PER_VALUE = 48


def factor_bytes(n: int, stiffness_nonzeros: int, three_d: bool) -> float:
    """A rough estimate of the bytes of one sparse factor of a stiffness matrix and its operators.

    ``nnz(K)`` times a fill factor (``n^(1/3)`` in 3-D; ``log2 n`` otherwise, as nested
    dissection gives), 12 bytes an entry (value and index).

    Parameters
    ----------
    n : int
        Unknowns.
    stiffness_nonzeros : int
        Nonzeros of the stiffness pattern.
    three_d : bool
        A 3-D continuum (six Mandel components).

    Returns
    -------
    float
        Bytes, an estimate (within a factor of a few).
    """
    n = max(int(n), 2)
    fill = n ** (1.0 / 3.0) if three_d else float(np.log2(n))
    return 12.0 * max(int(stiffness_nonzeros), n) * max(fill, 1.0)


def to_casadi(A: sp.spmatrix) -> ca.DM:
    """A scipy sparse matrix as a sparse CasADi ``DM`` (same pattern, no densification)."""
    A = sp.csc_matrix(A)
    A.sort_indices()
    sparsity = ca.Sparsity(A.shape[0], A.shape[1], A.indptr.tolist(), A.indices.tolist())
    return ca.DM(sparsity, A.data.tolist())


class Factor(Protocol):
    """A factorised square sparse matrix."""

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``A^{-1} rhs`` for a vector or a matrix of right-hand sides."""


class SingularMatrix(ArithmeticError):
    """The matrix could not be factorised (exactly singular)."""


#: Largest backward error accepted from a symmetric-mode (diagonal pivot) SuperLU factor.
BACKWARD_ERROR = 1e-10
#: The same for a caller that corrects its solves by its own iteration (Newton, the active-set
#: solver's refinement): ``sqrt(eps)``, half the digits, is enough for that iteration to converge.
ITERATED_BACKWARD_ERROR = float(np.sqrt(np.finfo(float).eps))


#: Share of off-diagonal nonzeros with a transposed partner above which the ordering is symmetric.
SYMMETRIC_PATTERN = 0.5


def pattern_symmetry(A: sp.csc_matrix) -> float:
    """The share of the off-diagonal nonzeros ``a_ij`` of the square ``A`` whose ``a_ji`` is
    nonzero too (1 for a symmetric pattern; UMFPACK chooses its symmetric strategy on the same
    measure)."""
    P = sp.coo_matrix(A)
    keep = (P.data != 0) & (P.row != P.col)
    P = sp.csr_matrix((np.ones(int(keep.sum())), (P.row[keep], P.col[keep])), shape=A.shape)
    off = P.nnz
    return float(P.multiply(P.T).nnz) / off if off else 1.0


def backward_error(A: sp.spmatrix, x: np.ndarray, b: np.ndarray) -> float:
    """``||A x - b||_inf / (||A||_inf ||x||_inf + ||b||_inf)`` (0 for ``b = 0``, ``x = 0``)."""
    scale = spla.norm(A, np.inf) * float(np.max(np.abs(x), initial=0.0)) + float(np.max(np.abs(b), initial=0.0))
    return float(np.max(np.abs(A @ x - b), initial=0.0)) / scale if scale > 0 else 0.0


def _checked(lu: Factor, A: sp.csc_matrix, tolerance: float = BACKWARD_ERROR) -> bool:
    """Whether one solve with ``lu`` has a backward error within ``tolerance``."""
    b = A @ np.linspace(1.0, 2.0, A.shape[0])
    x = lu.solve(b)
    return bool(np.all(np.isfinite(x))) and backward_error(A, x, b) <= tolerance


def _splu(A: sp.csc_matrix, **options):
    try:
        return spla.splu(A, **options)
    except RuntimeError as exc:  # SuperLU: "Factor is exactly singular"
        raise SingularMatrix(str(exc)) from None


class _Refined:
    """A factor whose solves take :data:`REFINEMENT_STEPS` steps of iterative refinement
    ``x += lu.solve(b - A x)``: with pivot growth ``g`` each step cuts the error by about
    ``g eps cond(A)``, so a factor that misses :data:`BACKWARD_ERROR` by growth alone passes."""

    def __init__(self, lu, A: sp.csc_matrix) -> None:
        self._lu, self._A = lu, A
        self.nnz = getattr(lu, "nnz", None)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        x = self._lu.solve(rhs)
        for _ in range(REFINEMENT_STEPS):
            x = x + self._lu.solve(rhs - self._A @ x)
        return x


#: Steps of iterative refinement tried on a symmetric-mode factor that misses its check.
REFINEMENT_STEPS = 2


#: Below this many unknowns the ordering hardly matters and its checks would cost more than the
#: factorisation (a DDCM run of the paper's bar factorises hundreds of 1 to 6 unknown systems).
ORDERING_MIN_SIZE = 200


def _envelope(A: sp.csc_matrix) -> int:
    """The nonzeros of an LU factor within the envelope of ``A + A^T`` in reverse Cuthill-McKee
    order, ``n + 2 sum_i (i - f_i)`` (``f_i`` the first column of row ``i``): what a profile
    (banded) factorisation would store, near-optimal for the chain-like graphs of bars."""
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    S = (abs(A) + abs(A.T)).tocsr()
    perm = reverse_cuthill_mckee(S, symmetric_mode=True)
    P = S[perm][:, perm].tocsr()
    rows = np.arange(P.shape[0])
    first = rows.copy()  # an empty row (a singular matrix) adds nothing
    filled = np.diff(P.indptr) > 0
    if filled.any():
        first[filled] = np.minimum.reduceat(P.indices, P.indptr[:-1][filled])
    return int(P.shape[0] + 2 * np.sum(np.maximum(rows - first, 0)))


#: Whether minimum degree suits a sparsity pattern (:func:`_symmetric_mode`), remembered per
#: pattern (a model's systems keep their patterns from step to step, so each is judged once).
_MINIMUM_DEGREE: dict[bytes, bool] = {}
_PATTERNS_KEPT = 256


def _pattern_key(A: sp.csc_matrix) -> bytes:
    import hashlib

    h = hashlib.blake2b(np.asarray(A.shape, np.int64).tobytes(), digest_size=16)
    h.update(np.ascontiguousarray(A.indptr).tobytes())
    h.update(np.ascontiguousarray(A.indices).tobytes())
    return h.digest()


#: Envelope nonzeros per matrix nonzero below which a pattern counts as chain-like (bars,
#: trusses: 5.7 on a 90 030-unknown bar's projection system) and goes to SuperLU's default; a 2-D
#: mesh's envelope grows like ``n^1.5`` (52 per nonzero on a 99 687-unknown continuum's).
CHAIN_ENVELOPE = 8.0


def _suits_minimum_degree(A: sp.csc_matrix) -> bool:
    """Whether ``A``'s pattern is symmetric enough and not chain-like (:func:`_symmetric_mode`),
    remembered per pattern."""
    key = _pattern_key(A)
    suits = _MINIMUM_DEGREE.get(key)
    if suits is None:
        suits = pattern_symmetry(A) >= SYMMETRIC_PATTERN and _envelope(A) > CHAIN_ENVELOPE * A.nnz
        if len(_MINIMUM_DEGREE) < _PATTERNS_KEPT:
            _MINIMUM_DEGREE[key] = suits
    return suits


def ordering_of(A: sp.spmatrix) -> str:
    """The column ordering the ``"superlu"`` solver tries first for the square ``A``.

    Returns
    -------
    str
        ``"minimum_degree"``: the minimum-degree order of ``A + A^T`` with diagonal pivots
        (SuperLU's symmetric mode), for a matrix of at least :data:`ORDERING_MIN_SIZE` unknowns
        whose pattern is symmetric (:data:`SYMMETRIC_PATTERN`) and not chain-like
        (:data:`CHAIN_ENVELOPE`); a factor in that order that misses its backward-error check, even
        refined, falls back to the other. ``"colamd"``: SuperLU's default, with partial pivoting.
    """
    A = sp.csc_matrix(A)
    return "minimum_degree" if A.shape[0] >= ORDERING_MIN_SIZE and _suits_minimum_degree(A) else "colamd"


def _symmetric_mode(A: sp.csc_matrix) -> Factor | None:
    """A diagonal-pivot factor in SuperLU's minimum-degree order of ``A + A^T``, or ``None``
    (a zero pivot, an unsymmetric or a chain-like pattern: then SuperLU's default is used).

    Minimum degree is near-optimal on the 2-D and 3-D meshes of continua, where COLAMD with
    partial pivoting filled in 3x more and took 4.7x the time (99 687 unknowns). On the chain-like
    graphs of bars and trusses SuperLU's minimum degree filled in 11x more than COLAMD (90 030
    unknowns), while any order near a band is cheap. So a pattern whose profile factor
    (:func:`_envelope`) stays within :data:`CHAIN_ENVELOPE` nonzeros per matrix nonzero goes to
    the default; the verdict is remembered per pattern."""
    if not _suits_minimum_degree(A):
        return None
    try:
        return _splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))
    except SingularMatrix:
        return None


#: Square matrices of these sizes and at least :data:`DENSE_SHARE` full are factorised dense
#: (LAPACK's LU with partial pivoting): a condensed contact problem's systems (dense Delassus
#: blocks, docs/maths.md section 17). Measured on a 436-unknown matrix 17 % full: 2.1 ms
#: against SuperLU's 11 ms.
DENSE_MIN, DENSE_MAX = 64, 2000
DENSE_SHARE = 0.1


class _DenseFactor:
    """LAPACK's LU with partial pivoting of a small, dense-ish matrix."""

    def __init__(self, A: sp.csc_matrix) -> None:
        import warnings

        import scipy.linalg as sla

        with warnings.catch_warnings():  # an exactly singular matrix raises below instead
            warnings.simplefilter("ignore", sla.LinAlgWarning)
            self._lu = sla.lu_factor(A.toarray(), check_finite=False)
        if not np.all(np.diag(self._lu[0])):
            raise SingularMatrix("Factor is exactly singular")
        self.nnz = A.shape[0] ** 2

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        import scipy.linalg as sla

        return sla.lu_solve(self._lu, rhs, check_finite=False)


def _superlu(A: sp.csc_matrix, *, tolerance: float = BACKWARD_ERROR) -> Factor:
    if DENSE_MIN <= A.shape[0] <= DENSE_MAX and A.nnz >= DENSE_SHARE * A.shape[0] ** 2:
        return _DenseFactor(A)
    if A.shape[0] >= ORDERING_MIN_SIZE:
        lu = _symmetric_mode(A)  # None: partial pivoting instead
        if lu is not None:
            if _checked(lu, A, tolerance):
                return lu
            # Growth on the diagonal pivots: refining costs a few solves, partial pivoting
            # (COLAMD, off-diagonal pivots) far more fill (4.7x the time on a 1e5 KKT matrix).
            refined = _Refined(lu, A)
            if _checked(refined, A, tolerance):
                return refined
    return _splu(A)


#: PARDISO's iterative refinement steps on a solve with a factor whose pivots it perturbed.
PERTURBED_REFINEMENT = 2


def _upper_with_diagonal(A: sp.spmatrix, C: sp.spmatrix | None = None) -> sp.csr_matrix:
    """The upper triangle of the symmetric ``A``, or of ``[[A, C^T], [C, 0]]`` with the rows ``C``,
    with every diagonal entry stored, zeros too (PARDISO's symmetric storage requires them), in
    CSR with sorted indices. Each row is the diagonal, ``A``'s entries right of it and ``C^T``'s:
    placed by index arithmetic (no sort; building the augmented matrix by blocks, converting and
    sorting it took 0.29 s of the 1.3 s factorisation of a 95 266-dof stiffness). A CSC ``A``'s
    arrays are read as the CSR arrays of ``A^T = A``: no conversion (0.4-1.5 s at 1e6 dofs)."""
    if A.format == "csc":
        A = sp.csr_matrix((A.data, A.indices, A.indptr), shape=A.shape[::-1])
    else:
        A = sp.csr_matrix(A)
    if not A.has_canonical_format:  # duplicates summed and indices sorted, on a copy
        A = A.copy()
        A.sum_duplicates()
    n = A.shape[0]
    CT = sp.csr_matrix((0, n)).T.tocsr() if C is None else sp.csr_matrix(sp.csr_matrix(C).T)
    CT.sum_duplicates()
    nc = CT.shape[1]
    rows = np.repeat(np.arange(n, dtype=A.indices.dtype), np.diff(A.indptr))
    strict = A.indices > rows
    upper_indptr = np.concatenate([[0], np.cumsum(np.bincount(rows[strict], minlength=n))])
    upper_counts, c_counts = np.diff(upper_indptr), np.diff(CT.indptr)
    indptr = np.concatenate([[0], np.cumsum(np.concatenate([1 + upper_counts + c_counts, np.ones(nc, np.int64)]))])
    index_type = np.int32 if indptr[-1] < 2**31 else np.int64
    indices = np.empty(indptr[-1], dtype=index_type)
    data = np.zeros(indptr[-1])
    first = indptr[:-1]
    indices[first] = np.arange(n + nc)  # the diagonal, first in each row
    data[first[:n]] = A.diagonal()
    where = np.repeat(first[:n] + 1 - upper_indptr[:-1], upper_counts) + np.arange(upper_indptr[-1])
    indices[where], data[where] = A.indices[strict], A.data[strict]
    where = np.repeat(first[:n] + 1 + upper_counts - CT.indptr[:-1], c_counts) + np.arange(CT.indptr[-1])
    indices[where], data[where] = n + CT.indices, CT.data
    M = sp.csr_matrix((data, indices, indptr.astype(index_type)), shape=(n + nc, n + nc))
    M.has_sorted_indices = True
    return M


class _PardisoFactor:
    """A PARDISO factorisation (``pypardiso``), freed with the object."""

    def __init__(self, A: sp.csc_matrix, symmetric: bool) -> None:
        import pypardiso

        if symmetric:
            M = _upper_with_diagonal(A)
        else:
            M = A.tocsr()
            M.sort_indices()
        self._matrix = M
        self._solver = pypardiso.PyPardisoSolver(mtype=-2 if symmetric else 11)
        self._solver.set_iparm(18, -1)  # report the factor's nonzeros
        try:
            self._solver.factorize(M)
        except (pypardiso.pardiso_wrapper.PyPardisoError, ValueError) as exc:  # ValueError: an empty row
            raise SingularMatrix(f"PARDISO: {exc}") from None
        self.perturbed = int(self._solver.get_iparm(14))  # pivots PARDISO perturbed
        # iparm(1) = 0 made PARDISO fill in its defaults at the factorisation, two steps of
        # iterative refinement among them: each solve cost three (0.29 s against SuperLU's 0.10 s
        # on the 95 485-unknown Hertz piece matrix). The callers check or refine their solves, so
        # only a factor with perturbed pivots keeps them.
        self._solver.set_iparm(8, PERTURBED_REFINEMENT if self.perturbed else 0)
        # nonzeros of L and U (of L only for a symmetric factor, whose U is its transpose)
        self.nnz = int(self._solver.get_iparm(18)) * (2 if symmetric else 1)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        b = np.asarray(rhs, dtype=float)
        if b.shape[0] != self._matrix.shape[0]:
            raise InputError(f"right-hand side of {b.shape[0]} rows for a matrix of {self._matrix.shape[0]}")
        # Phase 33 (solve) straight away: pypardiso's solve() first compares the whole matrix
        # with the factorised one (0.5 s of 10 s in a 1e5 Hertz path's 49 solves).
        self._solver.set_phase(33)
        return self._solver._call_pardiso(self._matrix, np.asfortranarray(b))

    def __del__(self) -> None:
        solver = getattr(self, "_solver", None)
        if solver is not None:
            solver.free_memory(everything=True)


def _solves_generic(lu: Factor, A: sp.csc_matrix) -> bool:
    """Whether ``lu`` solves ``A x = b`` for a generic ``b`` to ``||A x - b|| <= 1e-6 ||b||``. A
    right-hand side outside the range of a singular ``A`` leaves a residual of the order of
    ``||b||``, whatever the (perturbed) factor; a nonsingular ``A`` of condition number below
    about 1e10 passes."""
    b = np.cos(np.arange(A.shape[0]))
    x = lu.solve(b)
    return bool(np.all(np.isfinite(x))) and float(np.max(np.abs(A @ x - b))) <= 1e-6 * float(np.max(np.abs(b)))


def numerically_symmetric(A: sp.spmatrix) -> bool:
    """Whether ``|A - A^T| <= 1e-14 max |A|`` entrywise (and ``A`` has a nonzero)."""
    return bool(A.nnz) and abs(A - A.T).max() <= 1e-14 * abs(A).max()


def _pardiso(A: sp.csc_matrix, *, tolerance: float = BACKWARD_ERROR) -> Factor:
    # PARDISO perturbs tiny pivots instead of failing (then refines the solution iteratively):
    # a factor with perturbed pivots is accepted only if it solves a generic system.
    if numerically_symmetric(A):
        lu = _PardisoFactor(A, True)
        if _checked(lu, A, tolerance) and (not lu.perturbed or _solves_generic(lu, A)):
            return lu
    lu = _PardisoFactor(A, False)
    if lu.perturbed and not _solves_generic(lu, A):
        raise SingularMatrix(f"PARDISO: {lu.perturbed} perturbed pivots and no accurate solve (singular matrix)")
    return lu


def _mumps_factor(A: sp.spmatrix, symmetric: int, C: sp.spmatrix | None = None) -> Factor:
    """:class:`~ddcm_casadi.mumps.MumpsFactor`, a singular matrix (``INFOG(1) = -10`` or null
    pivots) raised as :class:`SingularMatrix`."""
    from ddcm_casadi import mumps

    try:
        lu = mumps.MumpsFactor(A, symmetric, C)
    except mumps.MumpsError as exc:
        if exc.infog1 == -10:
            raise SingularMatrix(str(exc)) from None
        raise
    if lu.null_pivots:
        raise SingularMatrix(f"MUMPS: {lu.null_pivots} null pivots (a singular matrix)")
    return lu


def _mumps_definite(A: sp.csc_matrix, C: sp.spmatrix | None = None) -> Factor:
    """MUMPS's ``LDL^T`` without pivoting of a symmetric positive definite ``A`` (``SYM = 1``),
    with the Schur complement of the rows ``C`` if given. Positive pivots alone make it as
    backward stable as Cholesky's, so no solve is checked (0.1 s of 0.55 s at 95 266 dofs); a
    negative or null pivot (an indefinite or singular ``A``) raises :class:`SingularMatrix`."""
    lu = _mumps_factor(A, 1, C)
    if lu.negative_pivots:
        raise SingularMatrix(f"MUMPS: {lu.negative_pivots} negative pivots (the matrix is not positive definite)")
    return lu


def _mumps(A: sp.csc_matrix, *, tolerance: float = BACKWARD_ERROR) -> Factor:
    # a symmetric matrix as symmetric indefinite (LDL^T, 1x1 and 2x2 pivots: the saddle-point
    # systems too), others, and a symmetric one whose factor misses its check, by LU
    if numerically_symmetric(A):
        try:
            lu = _mumps_factor(A, 2)
        except SingularMatrix:
            lu = None
        if lu is not None and _checked(lu, A, tolerance):
            return lu
    lu = _mumps_factor(A, 0)
    if not _checked(lu, A, tolerance):
        refined = _Refined(lu, A)
        if not _checked(refined, A, tolerance):
            raise SingularMatrix("MUMPS: no solve within the backward error (a singular or ill-conditioned matrix)")
        return refined
    return lu


_SOLVERS: dict[str, Callable[[sp.csc_matrix], Factor]] = {"superlu": _superlu}
#: The library each registered solver loads on first use, by name (none for SuperLU).
_LIBRARIES: dict[str, str] = {}
_ACTIVE = ["superlu"]
#: Why a registered optional solver cannot run here (its library failed to load), by name.
_UNUSABLE: dict[str, str] = {}


def _check_loads(name: str) -> str | None:
    """Why solver ``name`` cannot run here, or ``None``: its library is imported here, once it is
    asked for, not at registration (PARDISO is registered when ``pypardiso`` is installed, without
    loading MKL; pypardiso installed without a findable MKL runtime raises ImportError)."""
    library = _LIBRARIES.get(name)
    if library is not None and name not in _UNUSABLE:
        try:
            importlib.import_module(library)
        except (ImportError, OSError) as exc:
            _UNUSABLE[name] = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return _UNUSABLE.get(name)


def register_solver(name: str, factorize_fn: Callable[[sp.csc_matrix], Factor], *,
                    library: str | None = None) -> None:
    """Register a sparse direct solver (again: replace it).

    Parameters
    ----------
    name : str
        The name :func:`use_solver` selects it by.
    factorize_fn : callable
        ``factorize_fn(A_csc, *, tolerance)`` returns an object with ``solve`` whose backward error
        stays within ``tolerance``, and raises :class:`SingularMatrix` for a singular matrix.
    library : str, optional
        The module the solver needs, imported when the solver is first listed or selected, not
        now: where it does not import the solver is neither listed by :func:`available_solvers`
        nor selectable, and :func:`unavailable_solvers` says why.
    """
    _SOLVERS[name] = factorize_fn
    _UNUSABLE.pop(name, None)
    if library is None:
        _LIBRARIES.pop(name, None)
    else:
        _LIBRARIES[name] = library


def unregister_solver(name: str) -> None:
    """Remove the solver ``name`` registered with :func:`register_solver` (if it is selected,
    ``"auto"``, the default, is selected instead).

    Raises
    ------
    ValueError
        ``name`` is ``"superlu"`` or ``"auto"``, which stay.
    """
    if name in ("superlu", "auto"):
        raise ValueError(f"the built-in linear solver {name!r} cannot be unregistered")
    _SOLVERS.pop(name, None)
    _LIBRARIES.pop(name, None)
    _UNUSABLE.pop(name, None)
    if _ACTIVE[0] == name:
        _ACTIVE[0] = "auto"


if importlib.util.find_spec("pypardiso") is not None:  # optional; imported on first use (it loads MKL)
    register_solver("pardiso", _pardiso, library="pypardiso")
# CasADi's own MUMPS (ddcm_casadi.mumps): loaded on first use, unavailable where CasADi's build has none
register_solver("mumps", _mumps, library="ddcm_casadi.mumps")


#: Unknowns from which ``"auto"`` factorises with MUMPS (CasADi's, :mod:`ddcm_casadi.mumps`)
#: where it loads (docs/performance.md, 2026-11-26): on the DDCM projection's KKT matrix (2-D
#: continuum, one thread) factor and solve took 0.008 s with either at 2 847 unknowns, 0.027 s
#: against SuperLU's 0.067 s at 9 999 and 0.44 s against SuperLU's 1.32 s and PARDISO's 0.88 s at
#: 99 687; the Hertz stiffness of 95 266 dofs 0.59 s against 2.0 s and 1.2 s. Below, SuperLU
#: (no set-up: MUMPS's costs about 0.6 ms a factorisation, which the DDCM runs of bars and trusses
#: would pay on hundreds of tiny systems).
MUMPS_MIN_SIZE = 5_000
#: Unknowns from which ``"auto"`` factorises a symmetric matrix with PARDISO where it runs and
#: MUMPS does not (docs/performance.md, 2026-11-26, issue 28 item 6). At 99 687 unknowns the DDCM
#: full path's symmetric KKT matrices (PARDISO's symmetric indefinite mode) took 0.85 s an
#: iteration with PARDISO against 0.61 s with SuperLU (5 factorisations against 3: its updates
#: missed their tolerance more often); on the Hertz stiffness at 991 936 dofs PARDISO took 14.0 s
#: against SuperLU's 72.4 s.
PARDISO_MIN_SIZE = 200_000
#: The same for an unsymmetric matrix (PARDISO's LU): the classical FB piece matrix of 95 485
#: unknowns factorised in 1.5 s against 4.4 s, its solves 0.05 s against 0.10 s. Below about 5e4
#: SuperLU was as fast or faster (MKL's start-up: 0.34 s against 0.29 s at 9 870 dofs).
PARDISO_UNSYMMETRIC_MIN_SIZE = 80_000


def chosen_solver(n: int, symmetric: bool = True) -> str:
    """The solver ``"auto"`` uses for a matrix of ``n`` unknowns, numerically symmetric or not
    (:func:`numerically_symmetric`): ``"mumps"`` from :data:`MUMPS_MIN_SIZE` unknowns where it
    loads; else ``"pardiso"`` from :data:`PARDISO_MIN_SIZE` unknowns
    (:data:`PARDISO_UNSYMMETRIC_MIN_SIZE` if unsymmetric) where it runs; else ``"superlu"``."""
    if n >= MUMPS_MIN_SIZE and _runs("mumps"):
        return "mumps"
    large = n >= (PARDISO_MIN_SIZE if symmetric else PARDISO_UNSYMMETRIC_MIN_SIZE)
    if large and _runs("pardiso"):
        return "pardiso"
    return "superlu"


def _auto(A: sp.csc_matrix, *, tolerance: float = BACKWARD_ERROR) -> Factor:
    n = A.shape[0]
    symmetric = n >= PARDISO_MIN_SIZE or n < PARDISO_UNSYMMETRIC_MIN_SIZE or numerically_symmetric(A)
    return _SOLVERS[chosen_solver(n, symmetric)](A, tolerance=tolerance)


def _runs(name: str) -> bool:
    """Whether solver ``name`` is registered and its library loads."""
    return name in _SOLVERS and _check_loads(name) is None


def _resolved(n: int) -> str:
    """The solver a symmetric matrix of ``n`` unknowns is factorised with: the selected one, or
    ``"auto"``'s choice (:func:`chosen_solver`)."""
    return chosen_solver(n) if _ACTIVE[0] == "auto" else _ACTIVE[0]


register_solver("auto", _auto)
_ACTIVE[0] = "auto"


def use_solver(name: str) -> None:
    """Select the sparse solver used by every factorisation from now on."""
    if name not in _SOLVERS:
        raise InputError(f"unknown linear solver {name!r}; known: {', '.join(_SOLVERS)}")
    reason = _check_loads(name)
    if reason is not None:
        raise InputError(f"linear solver {name!r} cannot run here: {reason}")
    _ACTIVE[0] = name


def solver_name() -> str:
    """The name of the selected solver."""
    return _ACTIVE[0]


def available_solvers() -> tuple[str, ...]:
    """The registered solvers that can run here (``"pardiso"`` only where ``pypardiso`` imports,
    which loads MKL)."""
    return tuple(name for name in _SOLVERS if _check_loads(name) is None)


def unavailable_solvers() -> dict[str, str]:
    """Registered solvers that cannot run here, with the reason (their library did not load)."""
    return {name: reason for name in _SOLVERS if (reason := _check_loads(name)) is not None}


#: Unknowns from which a factorisation called from the main thread runs in the factorising
#: thread (:class:`_FactorThread`), so that Ctrl-C acts at once (:func:`factorize`). SuperLU holds
#: no GIL while it factorises but Python runs its SIGINT handler only between bytecodes of the
#: main thread: called directly, a 3-D system of 64 000 unknowns took Ctrl-C 8.1 s to act (the
#: whole factorisation), and 263 s on a 3-D mesh of 1e5 dofs. Below this size a factorisation
#: takes well under a second and the hand-over (about 0.1 ms) is not worth it.
INTERRUPTIBLE_MIN_SIZE = 20_000
#: Seconds between two looks of the waiting main thread at the factorising thread (Ctrl-C needs
#: none: the wait itself is interrupted).
_WAIT = 0.25
#: The "done" events of factorisations left running after Ctrl-C (:func:`abandoned_work`): an
#: event, not ``Thread.is_alive``, which Python 3.11 reports false after an interrupted join.
_ABANDONED: list = []


def abandoned_work() -> bool:
    """Whether a factorisation abandoned by Ctrl-C is still running in the factorising thread.

    It cannot be stopped (the solver's C code knows no cancellation): it ends when the
    factorisation does. An interpreter that shuts down while it runs frees memory under it (and
    may crash on the way out), so a command that ends after Ctrl-C leaves at once instead
    (:func:`ddcm_casadi.commands.base.run_guarded`)."""
    _ABANDONED[:] = [done for done in _ABANDONED if not done.is_set()]
    return bool(_ABANDONED)


class _ThreadOwned:
    """A factor made in the factorising thread, released there too (:class:`_FactorThread`).

    scipy's SuperLU records every block it allocates in a table of the allocating thread and
    frees a block only if it is in the table of the thread that frees it: a factor made in one
    thread and dropped in another is never freed. Dropped from the main thread, each factor of
    the 20 478-unknown finite-strain projection leaked (memory grew past 16 GB); so this wrapper
    hands its factor back to the thread that made it."""

    def __init__(self, factor: Factor, release: Callable) -> None:
        self._factor, self._release = factor, release
        self.nnz = getattr(factor, "nnz", None)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._factor.solve(rhs)

    def __getattr__(self, name: str):  # the solver's own attributes (perturbed, L, U, ...)
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self._factor, name)

    def __del__(self) -> None:
        factor = self.__dict__.pop("_factor", None)
        if factor is not None:
            self._release(factor)  # a bound method: no module global is looked up at shutdown


class _FactorThread:
    """One long-lived daemon thread that makes, and releases, the large factors (see
    :class:`_ThreadOwned` for why one thread must do both): jobs and releases queue in order."""

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        #: Factors made so far and released so far (for the tests of their ownership).
        self.made, self.released = 0, 0
        self._closed = False

    def _run(self) -> None:
        trim = release_heap  # bound here: no module global is looked up at shutdown
        while True:
            item = self._queue.get()
            kind, payload = item
            del item
            if kind == "stop":
                return
            if kind == "release":
                del payload  # the factor's last reference: freed in this thread
                self.released += 1
                trim()
                continue
            fn, box, done = payload
            del payload
            try:
                box["factor"] = _ThreadOwned(fn(), self._release)
                self.made += 1
            except BaseException as exc:  # noqa: BLE001 - handed to the waiting thread and raised there
                box["error"] = exc
            finally:
                del fn, box  # an abandoned job's factor goes here, in this thread
                done.set()
                del done

    def _release(self, factor: Factor) -> None:
        """Queue ``factor`` (its last reference) to be dropped in this thread; once the
        interpreter exits (:meth:`close`), drop it here: the memory goes with the process."""
        if not self._closed:
            self._queue.put(("release", factor))

    @property
    def thread(self) -> threading.Thread | None:
        return self._thread

    def after_fork_in_child(self) -> None:
        """In a forked child: the thread was not copied. Start afresh with a new queue and lock;
        the child's copies of the parent's factors are freed with the child's memory (a thread of
        the child cannot free them, :class:`_ThreadOwned`)."""
        self._queue = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._thread = None

    def close(self) -> None:
        """At exit: stop the thread once its queue is done, unless a factorisation abandoned by
        Ctrl-C still runs (then the process leaves without waiting). Releases queued while the
        interpreter shuts down, with the thread frozen, printed errors at every exit."""
        self._closed = True
        thread = self._thread
        if thread is not None and thread.is_alive() and not abandoned_work():
            self._queue.put(("stop", None))
            thread.join()

    def submit(self, fn: Callable[[], Factor]) -> Factor:
        """``fn()`` in this thread while the caller waits; Ctrl-C (``KeyboardInterrupt``) reaches
        the caller within :data:`_WAIT` seconds and the job is abandoned (:func:`abandoned_work`).
        Its exceptions are raised here."""
        with self._lock:
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._run, name="ddcm-factorize", daemon=True)
                self._thread.start()
        box: dict = {}
        done = threading.Event()
        self._queue.put(("job", (fn, box, done)))
        try:
            while not done.wait(_WAIT):
                pass
        except KeyboardInterrupt:
            _ABANDONED.append(done)
            raise
        if "error" in box:
            raise box.pop("error")
        return box.pop("factor")


_FACTOR_THREAD = _FactorThread()
atexit.register(_FACTOR_THREAD.close)
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_FACTOR_THREAD.after_fork_in_child)


def fork_safe(thread: threading.Thread) -> bool:
    """Whether a fork may leave ``thread`` behind: the factorising thread while it has no
    abandoned work (it then waits on its own queue, which the child replaces,
    :meth:`_FactorThread.after_fork_in_child`). :func:`~ddcm_casadi.parallel.map_forked` forks
    only when every other thread is such."""
    return thread is _FACTOR_THREAD.thread and not abandoned_work()


def _interruptible(fn: Callable[[], Factor]) -> Factor:
    """``fn()`` in the factorising thread (:class:`_FactorThread`), the factor released there."""
    return _FACTOR_THREAD.submit(fn)


def factorize(A: sp.spmatrix, *, iterated: bool = False) -> Factor:
    """Factorise a square sparse matrix with the selected solver; raises :class:`SingularMatrix`.

    ``iterated``: the caller corrects its solves by its own iteration (Newton steps, iterative
    refinement), so a backward error up to :data:`ITERATED_BACKWARD_ERROR` is accepted instead of
    :data:`BACKWARD_ERROR` (a symmetric-mode factor then needs no refinement of its own).

    A matrix of :data:`INTERRUPTIBLE_MIN_SIZE` unknowns or more, factorised from the main thread,
    is factorised in the factorising thread (:func:`_interruptible`): Ctrl-C acts within a fraction
    of a second instead of at the end of the factorisation. Its factor is released in that thread
    too (:class:`_ThreadOwned`)."""
    tolerance = ITERATED_BACKWARD_ERROR if iterated else BACKWARD_ERROR
    A = sp.csc_matrix(A)
    solver = _SOLVERS[_ACTIVE[0]]
    return _made(lambda: solver(A, tolerance=tolerance), A.shape[0])


def _made(make: Callable[[], Factor], n: int) -> Factor:
    """``make()``, in the factorising thread for :data:`INTERRUPTIBLE_MIN_SIZE` unknowns or more
    when called from the main thread (:func:`factorize`)."""
    if n >= INTERRUPTIBLE_MIN_SIZE and threading.current_thread() is threading.main_thread():
        return _interruptible(make)
    return make()


# ---------------------------------------------------------------------- definite systems
#: Relative residual ``||A x - b||_2 <= DEFINITE_TOL ||b||_2`` of an iterative solve of a
#: definite system (:class:`AMGFactor`). The reduction's solves with ``K_C`` are the
#: projection's equilibrium and stationarity residuals (``docs/maths.md`` section 17), which the
#: formulations' Newton accepts at a scaled residual of 1e-9: a tenth of that leaves Newton its
#: margin, as the direct factor's backward error (:data:`BACKWARD_ERROR`) does.
DEFINITE_TOL = 1e-10
#: Conjugate-gradient steps after which an AMG-preconditioned solve counts as failed (a singular
#: or indefinite matrix): smoothed aggregation on 3-D elasticity takes 15-40 at any size.
AMG_MAX_ITERATIONS = 500
#: The solvers :func:`factorize_definite` can use: ``"direct"`` (the selected sparse direct
#: solver, :func:`use_solver`) and ``"amg"`` (pyamg, where it imports).
DEFINITE_SOLVERS = ("direct", "amg")
_DEFINITE = ["direct"]


class AMGFactor:
    r"""A symmetric positive definite ``A`` "factorised" by an algebraic multigrid hierarchy
    (pyamg's smoothed aggregation, set up once): each solve is a conjugate-gradient iteration
    preconditioned by one V-cycle, to ``||A x - b||_2 <= tolerance ||b||_2`` per column.

    Parameters
    ----------
    A : scipy.sparse matrix
        Symmetric positive definite (a stiffness ``B^T (W (x) C) B`` with enough supports).
    near_null : ndarray, optional
        ``(n, r)`` near-null space (an elastic body's rigid-body modes): smoothed aggregation
        interpolates it exactly, which keeps the iterations bounded as the mesh is refined.
        ``None``: constants.
    tolerance : float
        Relative residual of every solve (:data:`DEFINITE_TOL`).

    Attributes
    ----------
    iterations : list of int
        Conjugate-gradient steps of every column solved so far.
    nnz : int
        Nonzeros of the hierarchy's operators (operator complexity times ``nnz(A)``).
    """

    def __init__(self, A: sp.spmatrix, near_null: np.ndarray | None = None, *,
                 tolerance: float = DEFINITE_TOL) -> None:
        import pyamg

        self._A = sp.csr_matrix(A)
        self._ml = pyamg.smoothed_aggregation_solver(self._A, B=near_null, symmetry="symmetric")
        self._M = self._ml.aspreconditioner(cycle="V")
        self.tolerance = float(tolerance)
        self.iterations: list[int] = []
        self.nnz = int(self._ml.operator_complexity() * self._A.nnz)

    def _column(self, b: np.ndarray) -> np.ndarray:
        import pyamg

        norm_b = float(np.linalg.norm(b))
        if norm_b == 0.0:
            return np.zeros_like(b)
        residuals: list[float] = []
        x, _ = pyamg.krylov.cg(self._A, b, tol=self.tolerance, criteria="rr", maxiter=AMG_MAX_ITERATIONS,
                               M=self._M, residuals=residuals)
        self.iterations.append(len(residuals) - 1)
        # the recurrence's residual drifts from the true one: check the true one
        if not float(np.linalg.norm(self._A @ x - b)) <= 2.0 * self.tolerance * norm_b:
            raise SingularMatrix(f"AMG-preconditioned CG did not reach a relative residual of {self.tolerance:.0e} "
                                 f"in {AMG_MAX_ITERATIONS} steps (a singular or indefinite matrix)")
        return x

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``A^{-1} rhs`` for a vector or an ``n x k`` matrix of right-hand sides, column by column."""
        rhs = np.asarray(rhs, float)
        cols = rhs.reshape(rhs.shape[0], -1)
        out = np.empty_like(cols)
        for j in range(cols.shape[1]):
            out[:, j] = self._column(np.ascontiguousarray(cols[:, j]))
        return out.reshape(rhs.shape)


def use_definite_solver(name: str) -> None:
    """Select the solver of the symmetric positive definite systems (:func:`factorize_definite`):
    ``"direct"`` (the default) or ``"amg"`` (``pip install ddcm-casadi[amg]``)."""
    if name not in DEFINITE_SOLVERS:
        raise InputError(f"unknown definite solver {name!r}; known: {', '.join(DEFINITE_SOLVERS)}")
    if name == "amg" and importlib.util.find_spec("pyamg") is None:
        raise InputError("definite solver 'amg' cannot run here: pyamg is not installed (pip install pyamg)")
    _DEFINITE[0] = name


def definite_solver_name() -> str:
    """The name of the selected solver of definite systems."""
    return _DEFINITE[0]


def factorize_definite(A: sp.spmatrix, *, near_null: np.ndarray | None = None) -> Factor:
    """A kept solver of the symmetric positive definite ``A`` (the reduction's ``K_C``, the
    reference scales' stiffness): :func:`factorize` with the selected direct solver, or an
    :class:`AMGFactor` (set up once, each solve to :data:`DEFINITE_TOL`), as selected by
    :func:`use_definite_solver`. ``near_null``: the near-null space for AMG (ignored by a direct
    solver). Raises :class:`SingularMatrix`."""
    if _DEFINITE[0] == "amg":
        return AMGFactor(A, near_null)
    A = sp.csc_matrix(A)
    if _resolved(A.shape[0]) == "mumps":
        return _made(lambda: _mumps_definite(A), A.shape[0])  # no pivoting: the ordering's fill alone
    return factorize(A)


# ---------------------------------------------------------------------- Delassus matrices
#: Right-hand sides per back-solve where the Delassus matrix is assembled column by column:
#: SuperLU's solve with many columns is slower per column than with a few (measured on K_C of
#: 23 436 dofs: 109 columns at once 14.7 s, by 16 4.4 s, by 4 0.74 s, one by one 1.5 s).
SOLVE_BLOCK = 4


def solved_columns(solve: Callable[[np.ndarray], np.ndarray], columns: sp.spmatrix
                   ) -> Iterator[tuple[slice, np.ndarray]]:
    """``solve`` (a kept factor's) applied to the columns of ``columns``, :data:`SOLVE_BLOCK` at a
    time: yields each block's column slice and its solutions (``n x`` block)."""
    columns = sp.csc_matrix(columns)
    for j in range(0, columns.shape[1], SOLVE_BLOCK):
        block = columns[:, j:j + SOLVE_BLOCK].toarray()
        yield slice(j, j + block.shape[1]), np.asarray(solve(block), float).reshape(block.shape)


class _PardisoSchur:
    r"""PARDISO's partial factorisation of ``[[A, C^T], [C, 0]]`` (``A`` symmetric positive
    definite, ``mtype = -2``, Schur variables the last ``nc``): the factor of ``A`` and, from the
    same elimination, the Schur complement ``-C A^-1 C^T`` (``iparm[35] = 2``), dense. Solves with
    ``A`` alone are the forward, diagonal and backward substitutions (phases 331, 332, 333) with
    the Schur part of the intermediate vectors set to zero: with the Schur variables eliminated
    last, ``L = [[L_A, 0], [C L_A^-T D^-1, I]]``, so zeroing them leaves ``L_A^-T D^-1 L_A^-1 b``.

    Measured on the Hertz stiffness of 95 266 dofs and 219 contact rows: 1.8 s for the factor and
    the Schur complement together, where the factor alone and 219 back-solves (in blocks of 16)
    took 2.0 + 2.7 s.
    """

    def __init__(self, A: sp.csc_matrix, C: sp.spmatrix) -> None:
        import ctypes

        import pypardiso

        n, nc = A.shape[0], C.shape[0]
        M = _upper_with_diagonal(A, C)
        self.n, self.nc = n, nc
        self._data = M.data
        self._ia, self._ja = M.indptr.astype(np.int32) + 1, M.indices.astype(np.int32) + 1  # one-based
        del M
        self._solver = s = pypardiso.PyPardisoSolver(mtype=-2)
        s.perm = np.zeros(n + nc, dtype=np.int32)
        s.perm[n:] = 1  # the Schur variables
        for one_based, value in ((1, 1), (2, 2), (10, 8), (11, 0), (13, 0), (18, -1), (36, 2)):
            s.set_iparm(one_based, value)  # own settings; METIS; pivots perturbed below 1e-8; no scaling,
            # no matching (a symmetric definite A needs neither); report the factor's nonzeros; Schur
        self._ctypes = ctypes
        schur = np.zeros(max(nc * nc, n + nc))
        self._call(12, np.zeros(n + nc), schur)
        self.perturbed = int(s.get_iparm(14))
        self.nnz = int(s.get_iparm(18)) * 2
        self.schur = -schur[:nc * nc].reshape(nc, nc)  # C A^-1 C^T
        self.schur = 0.5 * (self.schur + self.schur.T)

    def _call(self, phase: int, b: np.ndarray, x: np.ndarray, nrhs: int = 1) -> None:
        ctypes, s = self._ctypes, self._solver
        P, i32 = ctypes.POINTER, ctypes.c_int32
        error = i32(0)
        s._mkl_pardiso(s.pt.ctypes.data_as(P(s._pt_type[0])), ctypes.byref(i32(1)), ctypes.byref(i32(1)),
                       ctypes.byref(i32(-2)), ctypes.byref(i32(phase)), ctypes.byref(i32(self.n + self.nc)),
                       self._data.ctypes.data_as(P(ctypes.c_double)), self._ia.ctypes.data_as(P(i32)),
                       self._ja.ctypes.data_as(P(i32)), s.perm.ctypes.data_as(P(i32)), ctypes.byref(i32(nrhs)),
                       s.iparm.ctypes.data_as(P(i32)), ctypes.byref(i32(0)), b.ctypes.data_as(P(ctypes.c_double)),
                       x.ctypes.data_as(P(ctypes.c_double)), ctypes.byref(error))
        if error.value:
            raise SingularMatrix(f"PARDISO (Schur complement): error {error.value} in phase {phase}")

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``A^-1 rhs`` (a vector or ``n x k`` columns)."""
        b, y = schur_columns(rhs, self.n, self.nc)
        k = y.shape[1]
        z = np.zeros_like(y)
        for phase in (331, 332, 333):
            self._call(phase, y, z, k)
            z[self.n:] = 0.0  # the Schur part: zero (the solve with A alone)
            y, z = z, y
        return y[:self.n].reshape(b.shape)

    def __del__(self) -> None:
        solver = getattr(self, "_solver", None)
        if solver is not None and sys.meta_path is not None:  # at interpreter exit the memory goes with the process
            self._call(-1, np.zeros(1), np.zeros(1))


#: Unknowns from which ``"auto"`` has :func:`factorize_with_delassus` take a Schur complement
#: (MUMPS's, else PARDISO's): below, a factor and back-solves cost little either way (the Hertz
#: body of 9 870 dofs and 71 pairs: SuperLU and 71 back-solves 0.21 s, PARDISO's Schur
#: complement 0.31 s, MKL's start-up included). Above it the classical condensation needs a Schur
#: complement (:func:`~ddcm_casadi.problems.reduction.classical_refusal`).
SCHUR_MIN_SIZE = 20_000
#: The solvers whose :func:`factorize_with_delassus` is a Schur complement (one elimination).
SCHUR_SOLVERS = ("mumps", "pardiso")


def delassus_solver(n: int) -> str:
    """How :func:`factorize_with_delassus` treats a matrix of ``n`` unknowns: a Schur complement
    (:data:`SCHUR_SOLVERS`) where MUMPS or PARDISO is selected, or with ``"auto"`` MUMPS's from
    :data:`MUMPS_MIN_SIZE` unknowns where it loads, else PARDISO's from :data:`SCHUR_MIN_SIZE`
    where it runs, with the direct definite solver; else the definite solver's factor and
    back-solves (``"superlu"``, the selected solver, or ``"amg"``). MUMPS first: on the Hertz
    stiffness of 95 266 dofs and 219 pairs its Schur complement (AMD ordering) took 0.50-0.66 s
    with the factor, PARDISO's 0.92-1.03 s (``docs/performance.md``, 2026-11-26)."""
    if _DEFINITE[0] != "direct":
        return _DEFINITE[0]
    name = _resolved(n)
    if name == "superlu" and _ACTIVE[0] == "auto" and n >= SCHUR_MIN_SIZE and _runs("pardiso"):
        return "pardiso"  # its Schur complement from a smaller size than its factors
    return name


def factorize_with_delassus(A: sp.spmatrix, C: sp.spmatrix, *, near_null: np.ndarray | None = None
                            ) -> tuple[Factor, np.ndarray]:
    r"""A kept solver of the symmetric positive definite ``A`` and the Delassus matrix
    ``D = C A^-1 C^T`` (dense, ``nc x nc``, symmetrised) of the few rows ``C``.

    With MUMPS or PARDISO (selected, or ``"auto"``'s choice by size, :func:`delassus_solver`) and
    the direct definite solver: one partial factorisation of
    ``[[A, C^T], [C, 0]]`` gives both (:class:`~ddcm_casadi.mumps.MumpsFactor`,
    :class:`_PardisoSchur`). Otherwise :func:`factorize_definite` and ``nc`` back-solves, by
    :data:`SOLVE_BLOCK`. Raises :class:`SingularMatrix`.
    """
    A, C = sp.csc_matrix(A), sp.csr_matrix(C)
    how = delassus_solver(A.shape[0]) if C.shape[0] else ""
    if how in SCHUR_SOLVERS:
        def make() -> Factor:
            if how == "mumps":
                return _mumps_definite(A, C)  # A definite: no pivoting, the ordering's fill alone
            factor = _PardisoSchur(A, C)
            if not _checked(factor, A) or (factor.perturbed and not _solves_generic(factor, A)):
                raise SingularMatrix(f"PARDISO (Schur complement): {factor.perturbed} perturbed pivots "
                                     "and no accurate solve (a singular matrix)")
            return factor
        factor = _made(make, A.shape[0])
        return factor, factor.schur
    factor = factorize_definite(A, near_null=near_null)
    D = np.empty((C.shape[0], C.shape[0]))
    for cols, X in solved_columns(factor.solve, C.T):
        D[:, cols] = C @ X
    return factor, 0.5 * (D + D.T)
