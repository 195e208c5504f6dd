r"""One factorisation of a model's stiffness for its reference scales and its classical
condensation (``docs/maths.md``, section 17, "One factorisation for the scales and the
condensation").

The reference scales (:mod:`ddcm_casadi.models.scales`) solve with the representative stiffness
``K`` and with ``K + G^T S G`` (a stiff spring ``S = kappa diag(a)`` on every pair); the classical
problem's Delassus condensation (:class:`~ddcm_casadi.problems.reduction.ClassicalReduction`)
factorises its stiffness ``K_s = c K`` (the nondimensional problem's: ``c = s_d / s_f``) and needs
``D_s = G K_s^-1 G^T``. Where the condensation may apply (:meth:`ContactModel.delassus_rows
<ddcm_casadi.models.base.ContactModel.delassus_rows>`), the scales' first factorisation is the
condensation's (:class:`StiffnessFactor`: :func:`~ddcm_casadi.linalg.factorize_with_delassus`,
the factor of ``K`` and ``D = G K^-1 G^T``):

- ``K_s^-1 = K^-1 / c`` and ``D_s = D / c`` (:meth:`StiffnessFactor.scaled`);
- by Woodbury, ``(K + G^T S G)^-1 = K^-1 - K^-1 G^T (S^-1 + D)^-1 G K^-1``
  (:meth:`StiffnessFactor.with_springs`: two solves with ``K`` and an ``nc x nc`` Cholesky factor).

The model keeps it (:meth:`ContactModel.stiffness_factor
<ddcm_casadi.models.base.ContactModel.stiffness_factor>`), so that every condensation of its
classical problem solves with the same factor (repeated runs are bit-identical), until a
reduction that cannot use it lets it go (:meth:`StiffnessFactor.release`).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ddcm_casadi.heap import release_heap
from ddcm_casadi.linalg import (
    BACKWARD_ERROR, SCHUR_MIN_SIZE, SCHUR_SOLVERS, Factor, backward_error, definite_solver_name, delassus_solver,
    factorize_with_delassus, solver_name,
)

#: Contact pairs up to which the classical problem is condensed (:class:`ClassicalReduction
#: <ddcm_casadi.problems.reduction.ClassicalReduction>`: it keeps nothing ``n x nc``; its cost is
#: the condensed problem's dense ``nc x nc`` block). Measured (FB on a dense condensed problem,
#: most pairs closed): 705 pairs built in 0.28 s and solved in 0.19 s, 1000 in 0.61 s and 0.55 s;
#: the dense block grows like ``nc^2``, its solves like ``nc^3``.
MAX_CLASSICAL_PAIRS = 1000


def condensation_size_refusal(n: int, n_pairs: int, max_pairs: int | None = None) -> str:
    """Why a classical problem of ``n`` unknowns and ``n_pairs`` Signorini pairs is not condensed
    for its sizes (one line), or ``""``: 1 to ``max_pairs`` pairs (default
    :data:`MAX_CLASSICAL_PAIRS`) and, above :data:`~ddcm_casadi.linalg.SCHUR_MIN_SIZE` unknowns,
    a Schur complement for ``D`` (MUMPS's or PARDISO's, :func:`~ddcm_casadi.linalg.delassus_solver`):
    ``nc`` back-solves with SuperLU cost more than the full path (measured on the Hertz body of
    95 266 dofs, 219 pairs: 15.4 s for the factor and back-solves, where the full path took 6.6 s;
    PARDISO's Schur complement 0.9 s, MUMPS's 0.5-0.7 s)."""
    max_pairs = MAX_CLASSICAL_PAIRS if max_pairs is None else max_pairs
    if not n_pairs:
        return "no contact pairs (nothing to condense)"
    if n_pairs > max_pairs:
        return f"{n_pairs} contact pairs (the condensed problem is assembled up to {max_pairs})"
    if n > SCHUR_MIN_SIZE and delassus_solver(n) not in SCHUR_SOLVERS:
        return (f"{n} unknowns without a Schur complement (MUMPS or PARDISO; {n_pairs} back-solves would "
                "cost more than the full path's factorisation)")
    return ""


#: Largest condition number of ``D`` for which :meth:`StiffnessFactor.with_springs` is used:
#: beyond, ``K`` is numerically singular on the pairs' rows (a body held only by its contacts
#: shows as ``1 / eps``), and Woodbury's correction, which cancels the springs' stiffness, would
#: carry ``cond(K) eps`` amplified past any use; the springs' system is then factorised itself.
WOODBURY_MAX_CONDITION = 1.0 / np.sqrt(np.finfo(float).eps)


class Scaled:
    """A factor of ``beta A`` from one of ``A``: ``(beta A)^-1 rhs = A^-1 rhs / beta``."""

    def __init__(self, lu: Factor, beta: float) -> None:
        self.lu, self.beta = lu, beta

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self.lu.solve(rhs) / self.beta


class StiffnessFactor:
    r"""A kept factor of a symmetric positive definite ``K`` and the Delassus matrix ``D = G K^-1
    G^T`` of the contact rows ``G``, from one factorisation
    (:func:`~ddcm_casadi.linalg.factorize_with_delassus`), serving solves with ``K``, with any
    multiple ``c K`` (:meth:`scaled`) and with ``K + G^T S G`` for a positive diagonal ``S``
    (:meth:`with_springs`, Woodbury).

    Raises :class:`~ddcm_casadi.linalg.SingularMatrix` where ``K`` is singular.

    Attributes
    ----------
    factor : Factor
        The factor of ``K``.
    D : ndarray
        ``G K^-1 G^T`` (``nc x nc``, symmetric).
    seconds : float
        Wall time of the factorisation (with ``D``).
    solvers : tuple of str
        The definite and the sparse solver it was made with (:func:`scaled` serves those only).

    Parameters
    ----------
    K, G : sparse matrix
        The stiffness and the contact rows.
    near_null : ndarray, optional
        ``K``'s near-null space, for an algebraic multigrid solver.
    classical : bool
        ``K`` is the model's classical stiffness: kept until handed over (:meth:`hand_over`).
    """

    def __init__(self, K: sp.spmatrix, G: sp.spmatrix, near_null: np.ndarray | None = None, *,
                 classical: bool = False) -> None:
        start = time.perf_counter()
        self.solvers = (definite_solver_name(), solver_name())
        release_heap()  # the model's and K's assembly temporaries, before the factor's pages
        self.factor, self.D = factorize_with_delassus(K, G, near_null=near_null)
        # and after it: the matrix's copies in the solver's format (the Hertz body's classical run
        # of 95 485 unknowns: 74 MiB given back, its peak 396 -> 364 MiB; docs/performance.md)
        release_heap()
        self.seconds = time.perf_counter() - start
        self.G = sp.csr_matrix(G)
        self.diagonal = np.asarray(K.diagonal(), float)  # to recognise a multiple of K (scaled)
        # the model's classical stiffness, for its classical problem (hand_over): alive through the
        # factorisation anyway
        self._K = K if classical else None

    def hand_over(self) -> sp.spmatrix | None:
        """``K`` itself, once, where made ``classical`` (the model's classical stiffness: not
        assembled twice), then ``None``."""
        K, self._K = self._K, None
        return K

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``K^-1 rhs``."""
        return self.factor.solve(rhs)

    @property
    def released(self) -> bool:
        """Whether :meth:`release` was called."""
        return self.factor is None

    def release(self) -> None:
        """Let the factor go (a reduction that cannot use it, before a factorisation of its own):
        its memory is freed unless a user of :meth:`scaled` still holds it."""
        self.factor = self.D = self._K = None

    def with_springs(self, S: np.ndarray) -> "_WithSprings | None":
        """A solver of ``K + G^T diag(S) G`` (``S > 0``, one per row of ``G``), by Woodbury; ``None``
        where ``cond(D)`` exceeds :data:`WOODBURY_MAX_CONDITION` (``K`` numerically singular on
        the pairs' rows)."""
        S = np.asarray(S, float)
        if not (np.all(np.isfinite(self.D)) and np.all(np.isfinite(S)) and np.all(S > 0)):
            return None  # an overflow (out-of-range input): the springs' own factor reports it
        eig = np.linalg.eigvalsh(self.D) if self.D.size else np.ones(1)
        if not eig[0] > eig[-1] / WOODBURY_MAX_CONDITION:
            return None
        return _WithSprings(self, S)

    def adopted(self, K_s: sp.spmatrix, G_s: sp.spmatrix) -> tuple[Factor, np.ndarray] | None:
        """:meth:`scaled`, for a reduction about to factorise ``K_s`` itself where this factor
        cannot serve it: then released first (its memory gone before the other factorisation)."""
        scaled = self.scaled(K_s, G_s)
        if scaled is None:
            self.release()
        return scaled

    def scaled(self, K_s: sp.spmatrix, G_s: sp.spmatrix) -> tuple[Factor, np.ndarray] | None:
        """``(factor of K_s, G_s K_s^-1 G_s^T)`` where ``K_s = c K`` and ``G_s = G`` (``K_s^-1 =
        K^-1 / c``, ``D_s = D / c``), with the solvers selected now; else ``None``.

        ``c`` is the ratio of the diagonals (all equal to ``16 eps``: a few roundings of each
        entry, the nondimensional problem's ``K s_d / s_f``); a solve with ``K_s`` must then
        have a backward error within :data:`~ddcm_casadi.linalg.BACKWARD_ERROR` (one solve:
        ``K_s`` is ``c K`` off the diagonal too)."""
        G_s = sp.csr_matrix(G_s)
        if self.released or self.solvers != (definite_solver_name(), solver_name()) \
                or K_s.shape[0] != self.diagonal.size or G_s.shape != self.G.shape or (G_s != self.G).nnz:
            return None
        d = np.asarray(K_s.diagonal(), float)
        if not (np.all(self.diagonal > 0) and np.all(d > 0)):
            return None
        ratio = d / self.diagonal
        c = float(np.median(ratio))
        if not np.all(np.abs(ratio - c) <= 16 * np.finfo(float).eps * c):
            return None
        factor = Scaled(self.factor, c)
        b = K_s @ np.linspace(1.0, 2.0, K_s.shape[0])
        x = factor.solve(b)
        if not (np.all(np.isfinite(x)) and backward_error(K_s, x, b) <= BACKWARD_ERROR):
            return None
        return factor, self.D / c


class _WithSprings:
    r"""Solves with ``K + G^T S G`` from a :class:`StiffnessFactor` of ``K`` (Woodbury):
    ``x = K^-1 (r - G^T z)`` with ``z = (S^-1 + D)^-1 G K^-1 r`` (two solves with ``K``; the
    ``nc x nc`` matrix ``S^-1 + D`` is symmetric positive definite)."""

    def __init__(self, base: StiffnessFactor, S: np.ndarray) -> None:
        self.base = base
        self._small = sla.cho_factor(np.diag(1.0 / S) + base.D)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        r = np.asarray(rhs, float)
        G = self.base.G
        z = sla.cho_solve(self._small, G @ self.base.solve(r), check_finite=False)  # an overflow propagates
        return self.base.solve(r - G.T @ z)
