"""placeholder"""
from __future__ import annotations

import numpy as np

from ddcm_casadi.data.metric import Metric


def law_data(n: int, components: int, *, seed: int = 0, noise: float = 0.01, dtype=np.float64) -> np.ndarray:
    """``n`` points of a noisy linear law in the search's coordinates: strain uniform in a box,
    stress ``C strain`` plus Gaussian noise of ``noise`` times the stress range (``C``: ``E = 1``,
    1 component; isotropic 3-D, ``nu = 0.3``, 6 components), scaled by the metric ``C``, centred
    and rotated to the principal axes (as :class:`~ddcm_casadi.MaterialDataset` does)."""
    rng = np.random.default_rng(seed)
    metric = Metric(1.0) if components == 1 else Metric.isotropic(1.0, 0.3, 3)
    C = metric.matrix
    lo, hi = (-0.05, 0.01) if components == 1 else (-0.01, 0.01)
    X = np.empty((n, 2 * components), dtype=dtype)
    chunk = 1 << 22
    frame = None
    for a in range(0, n, chunk):
        m = min(chunk, n - a)
        e = rng.uniform(lo, hi, (m, components))
        s = e @ C.T + rng.normal(0.0, noise * (hi - lo) * np.linalg.norm(C, 2), (m, components))
        x = metric.coordinates(e, s)
        if frame is None:
            mean = x.mean(axis=0)
            _, axes = np.linalg.eigh((x - mean).T @ (x - mean))
            frame = (mean, axes[:, ::-1])
        X[a:a + m] = (x - frame[0]) @ frame[1]
    return X


def states(X: np.ndarray, n: int, *, seed: int = 1, spread: float = 0.05) -> np.ndarray:
    """``n`` query states near the data: random data points moved by Gaussian steps of
    ``spread`` times the data's standard deviation along each axis (float64)."""
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, X.shape[0], n)
    sd = X[rng.integers(0, X.shape[0], min(X.shape[0], 100_000))].astype(np.float64).std(axis=0)
    return X[pick].astype(np.float64) + rng.normal(0.0, 1.0, (n, X.shape[1])) * spread * sd
