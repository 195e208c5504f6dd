r"""The DDCM metric: one object shared by the data sets, the problems, the search and the checks.

A material point carries ``k`` strain and ``k`` stress components (``k = 1`` for bars and
trusses; 3 in plane strain and 6 in 3-D, in Mandel notation, so that the Euclidean product of two
component vectors is the tensor product ``e : s``). The distance between a state ``(e, s)`` and a
datum ``(e*, s*)`` is

.. math::  d^2 = (e - e^*)^T C\, (e - e^*) + (s - s^*)^T C^{-1} (s - s^*)

with a symmetric positive definite ``C`` (k x k; a scalar ``c`` is the 1 x 1 case). With the
Cholesky factor ``C = L L^T`` the *scaled coordinates* ``[L^T e, L^{-1} s]`` turn ``d`` into the
Euclidean distance, which is what the KD-tree searches. This module is the only place the formula
is written: :meth:`Metric.distance2` (numbers) and :func:`weighted_distance2` (the symbolic
objective of the ``Z_E`` projection, many points at once, as one sparse quadratic form).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ddcm_casadi.errors import InputError
from ddcm_casadi.linalg import to_casadi

#: Mandel strain components per spatial dimension (1-D members, plane strain, 3-D).
COMPONENTS = {1: 1, 2: 3, 3: 6}


class Metric:
    """A symmetric positive definite metric ``C`` (k x k) of one material.

    Parameters
    ----------
    C : float or (k, k) array_like
        A positive number (``k = 1``) or an SPD matrix, in Pa.

    Raises
    ------
    InputError
        Non-finite, non-square, non-symmetric or not positive definite ``C``.
    """

    def __init__(self, C) -> None:
        if isinstance(C, Metric):
            C = C.matrix
        try:
            M = np.array(C, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"metric c must be a number or a matrix, got {C!r}") from None
        if M.ndim == 0:
            M = M.reshape(1, 1)
        if M.ndim != 2 or M.shape[0] != M.shape[1] or M.size == 0:
            raise InputError(f"metric C must be a positive number or a square matrix, got shape {M.shape}")
        if not np.all(np.isfinite(M)):
            raise InputError(f"metric c must be finite and positive, got {C!r}" if M.size == 1
                             else "metric C must be finite")
        if M.size == 1 and not M[0, 0] > 0:
            raise InputError(f"metric c must be finite and positive, got {C!r}")
        if not np.allclose(M, M.T, rtol=1e-12, atol=0.0):
            raise InputError("metric C must be symmetric")
        try:
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            raise InputError("metric C must be positive definite (its Cholesky factorisation fails)") from None
        self.matrix = M
        self._L = L
        self._L_inv_T = np.linalg.inv(L).T
        self.inverse = np.array([[1.0 / M[0, 0]]]) if M.size == 1 else self._L_inv_T @ self._L_inv_T.T

    @property
    def k(self) -> int:
        """Strain (and stress) components per material point."""
        return self.matrix.shape[0]

    @property
    def c(self) -> float:
        """The scalar metric of a one-component material."""
        if self.k != 1:
            raise InputError("a matrix metric has no scalar c")
        return float(self.matrix[0, 0])

    @property
    def modulus(self) -> float:
        """The largest eigenvalue of ``C`` (Pa): the stiffness scale of the metric."""
        return float(np.linalg.eigvalsh(self.matrix)[-1])

    @property
    def scales(self) -> np.ndarray | None:
        """Where ``C`` is diagonal, the factors ``[sqrt(C_ii), 1 / sqrt(C_ii)]`` (``(2k,)``) that
        make :meth:`coordinates` column by column (up to its rounding); else ``None``."""
        d = np.diag(self.matrix)
        if np.count_nonzero(self.matrix - np.diag(d)):
            return None
        r = np.sqrt(d)
        return np.concatenate([r, 1.0 / r])

    def coordinates(self, strain, stress) -> np.ndarray:
        """Scaled coordinates ``[L^T e, L^{-1} s]`` of states, ``(N, 2k)``; Euclidean distance
        between them is the metric distance. ``strain``, ``stress``: ``(N,)`` for ``k = 1`` or
        ``(N, k)``."""
        e = np.asarray(strain, dtype=float).reshape(-1, self.k)
        s = np.asarray(stress, dtype=float).reshape(-1, self.k)
        # Written into one array: at 1e8 data points each temporary would be another 0.8-1.6 GB.
        k = self.k
        out = np.empty((e.shape[0], 2 * k))
        if k == 1:  # the common case, without matrix products
            rc = math.sqrt(self.matrix[0, 0])
            np.multiply(e[:, 0], rc, out=out[:, 0])
            np.divide(s[:, 0], rc, out=out[:, 1])
        else:  # einsum's own loop: no temporary, and faster than BLAS on k x k factors
            np.einsum("ij,jk->ik", e, self._L, out=out[:, :k])
            np.einsum("ij,jk->ik", s, self._L_inv_T, out=out[:, k:])
        return out

    def distance2(self, d_strain, d_stress) -> np.ndarray:
        """Squared distance ``d^2`` of strain and stress differences, one per state."""
        e = np.asarray(d_strain, dtype=float).reshape(-1, self.k)
        s = np.asarray(d_stress, dtype=float).reshape(-1, self.k)
        if self.k == 1:
            c = self.matrix[0, 0]
            return c * e[:, 0] ** 2 + s[:, 0] ** 2 / c
        return np.einsum("ij,jk,ik->i", e, self.matrix, e) + np.einsum("ij,jk,ik->i", s, self.inverse, s)

    def __eq__(self, other) -> bool:
        return isinstance(other, Metric) and np.array_equal(self.matrix, other.matrix)

    __hash__ = None  # mutable numpy state: not hashable

    def __repr__(self) -> str:
        return f"Metric(c={self.c:g})" if self.k == 1 else f"Metric(k={self.k})"

    def describe(self) -> float | list:
        """``c`` (k = 1) or ``C`` as nested lists, for results files."""
        return self.c if self.k == 1 else self.matrix.tolist()

    @classmethod
    def isotropic(cls, youngs_modulus: float, poisson_ratio: float, dimension: int) -> "Metric":
        """The isotropic elasticity tensor in Mandel notation as the metric
        (:func:`isotropic_elasticity`; ``dimension`` 1 gives ``E``)."""
        return cls(isotropic_elasticity(youngs_modulus, poisson_ratio, dimension)[0])

    @classmethod
    def estimated(cls, strain, stress) -> "Metric":
        r"""A metric estimated from data (as ddfenics does): the least-squares fit of
        ``stress = C strain`` over the data, symmetrised,

        .. math::  C = \operatorname{sym}\big(S^T E (E^T E)^{-1}\big)

        with ``E``, ``S`` the ``(N, k)`` strain and stress columns (for Hookean data ``C`` is the
        elasticity tensor to roundoff).

        Raises
        ------
        InputError
            Data that do not determine ``C`` (fewer independent strains than components) or an
            estimate that is not positive definite.
        """
        E = np.asarray(strain, dtype=float)
        S = np.asarray(stress, dtype=float)
        E = E.reshape(E.shape[0], -1)
        S = S.reshape(S.shape[0], -1)
        k = E.shape[1]
        if E.shape[0] < k or np.linalg.matrix_rank(E) < k:
            raise InputError(f"cannot estimate the metric: the data's strains do not span {k} components")
        X, *_ = np.linalg.lstsq(E, S, rcond=None)  # S ~ E X, so C = X^T
        C = 0.5 * (X + X.T)
        try:
            return cls(C)
        except InputError:
            raise InputError("the metric estimated from the data is not positive definite; give [data] c") from None


#: The tensor index ``(a, b)`` of each Mandel component (shear ones scaled by ``sqrt 2``):
#: 2-D ``[a11, a22, sqrt2 a12]``, 3-D ``[a11, a22, a33, sqrt2 a23, sqrt2 a13, sqrt2 a12]``.
MANDEL_INDEX = {2: [(0, 0), (1, 1), (0, 1)], 3: [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]}


def mandel_to_tensor(values, dim: int, out_of_plane=None) -> np.ndarray:
    """Symmetric ``3 x 3`` tensors ``(N, 3, 3)`` from Mandel vectors ``(N, k)`` (:data:`MANDEL_INDEX`).

    ``out_of_plane`` (2-D only, ``(N,)`` or a scalar): the ``a33`` component the 2-D Mandel vector
    does not carry (plane strain: ``e33 = 0``, but not ``sigma_33``); NaN marks it unknown. Default 0.
    """
    if dim not in MANDEL_INDEX:
        raise InputError(f"dim must be 2 or 3, got {dim!r}")
    try:
        v = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise InputError("Mandel values must be numbers") from None
    k = len(MANDEL_INDEX[dim])
    if v.ndim != 2 or v.shape[1] != k:
        raise InputError(f"Mandel values for dim={dim} must have shape (N, {k}), got {v.shape}")
    t = np.zeros((v.shape[0], 3, 3))
    for c, (i, j) in enumerate(MANDEL_INDEX[dim]):
        t[:, i, j] = t[:, j, i] = v[:, c] if i == j else v[:, c] / np.sqrt(2.0)
    if out_of_plane is not None:
        if dim != 2:
            raise InputError("out_of_plane is the 2-D a33 component; a 3-D Mandel vector carries it")
        t[:, 2, 2] = np.broadcast_to(np.asarray(out_of_plane, dtype=float), (v.shape[0],))
    return t


def tensor_to_mandel(tensors: np.ndarray, dim: int) -> np.ndarray:
    """Mandel vectors ``(N, k)`` of symmetric tensors ``(N, 3, 3)`` (2-D: the in-plane part)."""
    T = np.asarray(tensors, dtype=float)
    return np.stack([T[:, i, j] if i == j else np.sqrt(2.0) * T[:, i, j] for i, j in MANDEL_INDEX[dim]], axis=1)


def isotropic_elasticity(youngs_modulus, poisson_ratio, dimension: int) -> np.ndarray:
    r"""Isotropic elasticity matrices in Mandel notation, one per value: ``(m, k, k)``.

    ``dimension`` 1: ``E`` (a bar); 2: plane strain (``k = 3``); 3: ``k = 6``. With the Lame
    constants ``lambda = E nu / ((1 + nu)(1 - 2 nu))``, ``mu = E / (2 (1 + nu))``:

    .. math::  C = 2 \mu I + \lambda\, m m^T ,

    ``m`` one on the normal components and zero on the (``sqrt 2``-scaled) shear ones, so that
    ``sigma = C eps`` component by component in Mandel notation. This is the one place the
    formula is written (the classical law of continua, the isotropic metric, Hookean data),
    and the one place its arguments are checked.

    Raises
    ------
    InputError
        ``E`` not finite and positive, ``nu`` outside ``(-1, 0.5)``, or ``dimension`` not 1, 2, 3.
    """
    try:
        E = np.atleast_1d(np.asarray(youngs_modulus, dtype=float))
        nu = np.broadcast_to(np.asarray(poisson_ratio, dtype=float), E.shape)
    except (TypeError, ValueError):
        raise InputError(f"youngs_modulus and poisson_ratio must be numbers, got {youngs_modulus!r}, "
                         f"{poisson_ratio!r}") from None
    if not np.all(np.isfinite(E) & (E > 0)):
        raise InputError(f"youngs_modulus must be finite and positive, got {youngs_modulus!r}")
    if not np.all(np.isfinite(nu) & (nu > -1.0) & (nu < 0.5)):
        raise InputError(f"poisson_ratio must be in (-1, 0.5), got {poisson_ratio!r}")
    if dimension not in COMPONENTS:
        raise InputError(f"dimension must be 1, 2 or 3, got {dimension!r}")
    k = COMPONENTS[dimension]
    if dimension == 1:
        return E[:, None, None].copy()
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    C = 2 * mu[:, None, None] * np.eye(k)
    C[:, :dimension, :dimension] += lam[:, None, None]
    return C


def block_diagonal(blocks: np.ndarray) -> sp.csr_matrix:
    """Sparse block diagonal of ``blocks`` (m, k, k), built without a loop over blocks."""
    m, k, _ = blocks.shape
    # as a block-sparse matrix: no triplets to sort (13x faster than from coordinates at 1e6 points:
    # 0.1 s against 1.3 s; the same arrays, zeros inside a block kept)
    return sp.bsr_matrix((np.asarray(blocks), np.arange(m), np.arange(m + 1)), shape=(m * k, m * k)).tocsr()


def weighted_distance2(d_strain: ca.SX, d_stress: ca.SX, metrics: list[Metric], material: np.ndarray,
                       weights: np.ndarray) -> ca.SX:
    r"""Symbolic ``sum_i w_i d_i^2`` over ``m`` points (one sparse quadratic form per half).

    Parameters
    ----------
    d_strain, d_stress : casadi.SX
        Stacked differences ``e - e*`` and ``s - s*``, point-major (``m k`` entries).
    metrics : list of Metric
        The metrics of the materials (same ``k``).
    material : (m,) int
        The material of each point.
    weights : (m,)
        ``w_i`` (volumes).
    """
    w = np.asarray(weights, dtype=float)[:, None, None]
    C = np.stack([mt.matrix for mt in metrics])[material] * w
    Cinv = np.stack([mt.inverse for mt in metrics])[material] * w
    WC, WCinv = to_casadi(block_diagonal(C)), to_casadi(block_diagonal(Cinv))
    return ca.dot(d_strain, ca.mtimes(WC, d_strain)) + ca.dot(d_stress, ca.mtimes(WCinv, d_stress))
