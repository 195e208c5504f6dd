r"""Finite-strain kinematics of continua (total Lagrangian), for numbers and CasADi symbols.

With the displacement gradient ``H = du/dX`` at a quadrature point (:func:`~ddcm_casadi.models.continuum.fem.gradient_operator`):

.. math::  F = I + H ,\qquad C = F^T F ,\qquad E = (C - I)/2 = (H + H^T + H^T H)/2 ,\qquad J = \det F ,

``E`` in Mandel notation (``k = 3`` in plane strain, ``k = 6`` in 3-D; plane strain: ``F_33 = 1``,
``E_33 = 0``). The strains are written once per form: :func:`green_lagrange` for numbers,
:func:`green_lagrange_expression` for symbols (both from the same component formula,
:func:`_components`). The stresses of a law come from
:mod:`ddcm_casadi.data.hyperelastic` (``S = dW/dE``), the gaps at the current configuration from
the obstacles' :meth:`~ddcm_casadi.models.continuum.obstacles.Obstacle.phi_expression`.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ddcm_casadi.data.metric import MANDEL_INDEX

_SQRT2 = math.sqrt(2.0)


def _components(H, d: int) -> list:
    """Mandel components of ``E = (H + H^T + H^T H) / 2`` from ``H[a][b]`` (arrays or symbols of
    equal shape, one entry per point)."""
    out = []
    for a, b in MANDEL_INDEX[d]:
        e = 0.5 * (H[a][b] + H[b][a] + sum(H[c][a] * H[c][b] for c in range(d)))
        out.append(e if a == b else _SQRT2 * e)
    return out


def displacement_gradient(gradient_operator, u: np.ndarray, d: int) -> np.ndarray:
    """``(m, d, d)`` ``H`` of free displacements ``u``."""
    return (gradient_operator @ np.asarray(u, float)).reshape(-1, d, d)


def green_lagrange(H: np.ndarray) -> np.ndarray:
    """Mandel ``E`` ``(m, k)`` of displacement gradients ``(m, d, d)``."""
    d = H.shape[-1]
    return np.stack(_components([[H[:, a, b] for b in range(d)] for a in range(d)], d), axis=1)


def green_lagrange_expression(gradient_operator, u, d: int) -> ca.SX:
    """Mandel ``E`` (``m k``, point-major) for a CasADi symbol ``u``."""
    from ddcm_casadi.linalg import to_casadi

    h = ca.mtimes(to_casadi(gradient_operator), u)
    m = h.numel() // (d * d)
    rows = ca.reshape(h, d * d, m)  # column i: point i's H, row-major
    E = ca.vertcat(*_components([[rows[a * d + b, :] for b in range(d)] for a in range(d)], d))  # (k, m)
    return ca.reshape(E, E.numel(), 1)


def _element_gradients(u_e, geometry_e, d: int, n_loc: int, nq: int) -> list:
    """``H`` (as ``H[a][b]`` entries) of each of one element's ``nq`` points from its local
    displacements ``u_e`` and its flattened gradient blocks
    (:func:`~ddcm_casadi.models.continuum.fem.element_gradients`, one element: ``(nq, d^2, n_loc)``
    row-major), for CasADi symbols."""
    h = ca.mtimes(ca.reshape(geometry_e, n_loc, nq * d * d).T, u_e)  # row q d^2 + a d + b
    return [[[h[q * d * d + a * d + b] for b in range(d)] for a in range(d)] for q in range(nq)]


def element_strain(u_e, geometry_e, d: int, n_loc: int, nq: int):
    """Mandel ``E`` of one element's ``nq`` points (point-major), for CasADi symbols."""
    return ca.vertcat(*[e for H in _element_gradients(u_e, geometry_e, d, n_loc, nq) for e in _components(H, d)])


def element_volume_ratio(u_e, geometry_e, d: int, n_loc: int, nq: int):
    """``J = det(I + H)`` of one element's ``nq`` points, for CasADi symbols."""
    return ca.vertcat(*[ca.det(ca.SX.eye(d) + ca.vertcat(*[ca.horzcat(*row) for row in H]))
                        for H in _element_gradients(u_e, geometry_e, d, n_loc, nq)])


def deformation_gradient(H: np.ndarray) -> np.ndarray:
    """``F = I + H`` ``(m, d, d)``."""
    return H + np.eye(H.shape[-1])


def jacobian(H: np.ndarray) -> np.ndarray:
    """``J = det F`` per point."""
    return np.linalg.det(deformation_gradient(H))


def safe_norm(v: ca.SX) -> ca.SX:
    """Row norms of an ``(n, d)`` symbol, with a zero (not NaN) derivative at zero."""
    s = ca.sum2(v * v)
    return ca.if_else(s > 0, ca.sqrt(ca.if_else(s > 0, s, 1.0)), 0.0)
