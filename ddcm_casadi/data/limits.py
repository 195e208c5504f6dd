"""What a material data set may hold: its size, its file's size, the range of its search
coordinates and the balance of its metric.

The limits are read when a data set is built or read (:mod:`ddcm_casadi.data.dataset`,
:mod:`ddcm_casadi.data.files`), so that a data set that would overflow the search, or whose metric
would drown stress in strain, is refused with one line before any work.
"""

from __future__ import annotations

import math

import numpy as np

from ddcm_casadi.data.metric import Metric
from ddcm_casadi.errors import InputError

#: Data files larger than this are rejected before reading (bytes).
MAX_DATA_FILE_BYTES = 2 * 1024**3
#: Data sets generated (or read from CSV) with more points than this are rejected before allocating them.
MAX_DATA_POINTS = 10**8
#: Points of a ``.npy`` data file, which is memory-mapped, not read (a float32 file of one component
#: holds 8 bytes a point; the strip search adds 12 or, beyond 2^31 points, 16).
MAX_MAPPED_DATA_POINTS = 4 * 10**9
#: Largest scaled coordinate the search accepts: squared distances (sums of squares) stay below
#: the largest double, 1.8e308, with room for a sum over 12 components.
MAX_COORDINATE = 1e150
#: The metric must balance strain and stress: ``d^2 = c de^2 + ds^2 / c`` keeps both terms only while
#: their ratio ``(E / c)^2`` (``E`` the data's own modulus) is within ``[eps, 1 / eps]``, i.e. ``c / E``
#: within ``[sqrt(eps), 1 / sqrt(eps)]`` = ``[1.5e-8, 6.7e7]``; beyond, one term is below the other's
#: roundoff and the search ignores stress (or strain) altogether.
METRIC_RATIO_LIMIT = 1.0 / math.sqrt(np.finfo(float).eps)


def searchable_coordinates(metric: Metric, strain: np.ndarray, stress: np.ndarray, *,
                           first: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The data's scaled coordinates ``X`` (:meth:`Metric.coordinates`) and their column ranges
    ``lo``, ``hi``, refused where the data are not finite or the search would overflow
    (``first``: the index of the first row, for the message, when given a block of a data set;
    the balance of the metric is :func:`check_balance` of the whole set's ranges).

    Raises
    ------
    InputError
        NaN or infinite data, or a coordinate beyond :data:`MAX_COORDINATE` (e.g. a stress of
        1e300 Pa in a CSV file, or a metric ``c`` of 1e300).
    """
    with np.errstate(over="ignore", invalid="ignore"):
        X = metric.coordinates(strain, stress)
    # Column ranges by reductions, column by column (30x faster than along axis 0; NaN
    # propagates): no temporary the size of the data.
    lo = np.array([X[:, i].min() for i in range(X.shape[1])])
    hi = np.array([X[:, i].max() for i in range(X.shape[1])])
    if not np.all(np.maximum(-lo, hi) <= MAX_COORDINATE):
        if not all(np.isfinite(v.min()) and np.isfinite(v.max()) for v in (strain, stress)):
            raise InputError("material data set contains NaN or infinite values")
        k = metric.k
        big = ~(np.abs(X) <= MAX_COORDINATE)
        row = int(np.argmax(big.any(axis=1)))
        which, value = ("strain", strain) if big[row, :k].any() else ("stress", stress)
        raise InputError(f"material data set: {which} {np.ravel(value[row])[0]:.3g} of data point {first + row} is "
                         f"out of range for the metric {_label(metric)} (the scaled coordinates must stay below "
                         f"{MAX_COORDINATE:.0e} so that squared distances do not overflow)")
    return X, lo, hi


def _label(metric: Metric) -> str:
    return f"c = {metric.c:.3g} Pa" if metric.k == 1 else f"C (norm {np.linalg.norm(metric.matrix, 2):.3g} Pa)"


def check_balance(metric: Metric, lo: np.ndarray, hi: np.ndarray) -> None:
    """Refuse a metric that drowns stress in strain (or the reverse), from the ranges ``lo``, ``hi``
    of the data's scaled coordinates (:func:`searchable_coordinates`).

    Raises
    ------
    InputError
        A metric out of balance with the data (:data:`METRIC_RATIO_LIMIT`).
    """
    k = metric.k
    # Ranges, not variances: squares of tiny spreads would underflow to zero.
    spread_e = float(np.max(hi[:k] - lo[:k]))
    spread_s = float(np.max(hi[k:] - lo[k:]))
    if spread_e > 0 and spread_s > 0:
        ratio = spread_s / spread_e  # E / c for one component
        if not 1.0 / METRIC_RATIO_LIMIT <= ratio <= METRIC_RATIO_LIMIT:
            times = f"about 1e{math.log10(spread_e) - math.log10(spread_s):+.0f}"  # may overflow as a ratio
            raise InputError(f"material data set: the metric {_label(metric)} is {times} times the data's "
                             f"own modulus; it must be within {1 / METRIC_RATIO_LIMIT:.1e} to "
                             f"{METRIC_RATIO_LIMIT:.1e} times it, else one term of the distance is below "
                             f"the other's roundoff")
