"""Low-rank updates of a sparse factorisation, for the active-set solver
(:class:`~ddcm_casadi.loops.active_set.ActiveSetSolver`).

When a few contact pairs switch piece, a few rows of the piece (KKT) matrix change: the new matrix
is solved from the factor of the old one by the Sherman-Morrison-Woodbury formula
(:class:`UpdatedFactor`), as long as that costs less than a factorisation
(:class:`ReferenceFactor` decides, and keeps the columns it solved for). Every factorisation is
:func:`ddcm_casadi.linalg.factorize`'s.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ddcm_casadi.linalg import Factor, SingularMatrix, factorize


class UpdatedFactor:
    """``A^{-1}`` from a factor of a nearby ``A0``: ``A = A0 + E_R D_R`` differs from ``A0`` in the
    ``r`` rows ``R`` only (``E_R`` the identity's columns ``R``, ``D_R`` those rows of ``A - A0``),
    so by the Sherman-Morrison-Woodbury formula

    ``A^{-1} b = y - W C^{-1} D_R y``, with ``y = A0^{-1} b``, ``W = A0^{-1} E_R`` and the
    capacitance matrix ``C = I_r + D_R W`` (dense ``r x r``).

    Each solve costs one solve with ``A0`` and two thin products; ``C`` is singular exactly when
    ``A`` is. Built by :meth:`ReferenceFactor.update`, which keeps the columns of ``W``.
    """

    def __init__(self, base: Factor, W: np.ndarray, D_rows: sp.csr_matrix) -> None:
        import scipy.linalg as sla

        r = W.shape[1]
        C = np.eye(r) + D_rows @ W
        if not np.all(np.isfinite(C)):
            raise SingularMatrix("the capacitance matrix of the update is not finite")
        lu, piv = sla.lu_factor(C, check_finite=False)
        # A pivot at roundoff: C, hence A, is singular (with a merely ill-conditioned C the
        # caller's solves miss their tolerance, and it factorises A itself).
        if np.min(np.abs(np.diag(lu)), initial=np.inf) <= r * np.finfo(float).eps * max(1.0, np.max(np.abs(C), initial=0.0)):
            raise SingularMatrix("the updated matrix is singular (a capacitance pivot at roundoff)")
        self.base, self.rank = base, r
        self._W, self._C, self._D = W, (lu, piv), D_rows

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        import scipy.linalg as sla

        y = np.asarray(self.base.solve(rhs))
        if not self.rank:
            return y
        return y - self._W @ sla.lu_solve(self._C, self._D @ y, check_finite=False)


#: A factorisation costs about ``nnz(L+U) / (2 n)`` solves (flops ``~ sum_j c_j^2 >= nnz^2 / n``
#: against ``2 nnz`` per solve, ``c_j`` the factor's column counts). An update may spend a quarter
#: of that on new columns of ``W``, and its rank may reach ``nnz / (2 n)`` (then the product with
#: ``W`` costs at most a quarter of a solve).
UPDATE_COST_SHARE = 0.25
#: Columns ``A0^{-1} e_i`` kept per unit of the largest rank (memory: ``n`` floats each, 8 MB at
#: 1e6 unknowns); once full, the next change of rows is factorised, which starts afresh.
KEPT_COLUMNS_PER_RANK = 4
#: New columns solved for together: one solve with many right-hand sides costs less per column
#: (the 95 485-unknown Hertz FB piece: 0.033 s for one column with SuperLU, 0.018 s a column by
#: 16; PARDISO 0.049 s and 0.009 s). At 1e6 the path's 32 new columns took 14 s one by one.
COLUMN_BLOCK = 16


class ReferenceFactor:
    """A factorisation of ``A0`` from which nearby matrices are solved by low-rank updates
    (:class:`UpdatedFactor`), for the active-set solver: when a few contact pairs switch piece,
    their rows of the KKT matrix change, and the symmetric entries in the rows of the unknowns
    their gaps involve. The columns ``A0^{-1} e_i`` are kept, since the same pairs switch back
    and forth: an update pays a solve only for rows not seen before.

    Parameters
    ----------
    A0 : sparse matrix
        Factorised with :func:`~ddcm_casadi.linalg.factorize`.
    """

    def __init__(self, A0: sp.spmatrix, *, iterated: bool = False) -> None:
        self.matrix = sp.csc_matrix(A0)
        self.factor = factorize(self.matrix, iterated=iterated)
        n = self.matrix.shape[0]
        nnz = getattr(self.factor, "nnz", None)
        per_factorisation = nnz / (2 * n) if nnz and n else 0.0
        #: most new columns of ``W`` per update, and the largest rank
        self.new_columns, self.max_rank = int(UPDATE_COST_SHARE * per_factorisation), int(per_factorisation)
        self._columns: dict[int, np.ndarray] = {}

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self.factor.solve(rhs)

    @property
    def kept_columns(self) -> int:
        """How many columns ``A0^{-1} e_i`` are kept: later updates that change those rows need no
        solve for them (at most :data:`KEPT_COLUMNS_PER_RANK` ``*`` :attr:`max_rank`)."""
        return len(self._columns)

    def update(self, A: sp.spmatrix) -> UpdatedFactor | None:
        """A factor of ``A`` (same shape as ``A0``) as a low-rank update, or ``None`` if ``A - A0``
        has more nonzero rows than :attr:`max_rank`, needs more than :attr:`new_columns` new
        columns or more kept columns than :data:`KEPT_COLUMNS_PER_RANK` ``* max_rank``: then
        factorise ``A`` itself. Raises :class:`SingularMatrix` for a singular
        ``A``. Not checked here: the caller verifies its solves (the active-set solver's
        refinement step does) and factorises ``A`` itself if they miss."""
        if not self.new_columns:
            return None  # a small system: factorising costs no more than an update
        D = sp.csr_matrix(A - self.matrix)
        D.eliminate_zeros()
        rows = np.flatnonzero(np.diff(D.indptr))
        new = sum(int(i) not in self._columns for i in rows)
        if (rows.size > self.max_rank or new > self.new_columns
                or len(self._columns) + new > KEPT_COLUMNS_PER_RANK * self.max_rank):
            return None
        self._solve_columns([int(i) for i in rows if int(i) not in self._columns])
        W = np.empty((D.shape[0], rows.size))
        for j, i in enumerate(rows):
            W[:, j] = self._columns[int(i)]
        return UpdatedFactor(self.factor, W, D[rows])

    def _solve_columns(self, new: list[int]) -> None:
        """Keep ``A0^{-1} e_i`` for the rows ``new``, :data:`COLUMN_BLOCK` right-hand sides a solve."""
        n = self.matrix.shape[0]
        for start in range(0, len(new), COLUMN_BLOCK):
            block = new[start:start + COLUMN_BLOCK]
            E = np.zeros((n, len(block)))
            E[block, np.arange(len(block))] = 1.0
            X = np.asarray(self.factor.solve(E)).reshape(n, len(block))
            for j, i in enumerate(block):
                self._columns[i] = np.ascontiguousarray(X[:, j])


class UpdatingFactors:
    """Factors of a sequence of matrices that differ in a few rows (piece systems as contacts
    switch piece): a low-rank update of the last full factorisation where it is cheaper
    (:meth:`ReferenceFactor.update`), else a factorisation of its own, which becomes the
    reference. Its :meth:`factor` serves :func:`~ddcm_casadi.loops.newton.newton_solve`'s
    ``factors``; ``stats`` counts ``updates`` and ``factorizations``."""

    def __init__(self) -> None:
        self.reference: ReferenceFactor | None = None
        self.stats = dict(updates=0, factorizations=0)

    def reset(self) -> None:
        self.reference = None

    def factor(self, A: sp.spmatrix, *, update: bool = True):
        """A factor of ``A``: updated from the reference if ``update`` and it can be, else new."""
        if update and self.reference is not None:
            lu = self.reference.update(A)
            if lu is not None:
                self.stats["updates"] += 1
                return lu
        self.reference = None  # its factor and kept columns may go before the new one is made
        self.reference = ReferenceFactor(A, iterated=True)
        self.stats["factorizations"] += 1
        return self.reference
