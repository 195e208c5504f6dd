r"""Coulomb's law on blocks of contact components, for numbers (one place for the cone maths).

A frictional problem (:attr:`~ddcm_casadi.problems.contract.ComplementarityProblem.block` ``b > 1``)
carries per contact ``c`` a block of ``b`` components, *component-major* in the problem's vectors
(entry ``j nc + c`` is component ``j`` of contact ``c``, normal first):

- the "gaps" ``u_c = (g_N, s_T)``: the normal gap and the tangential slip (the tangential
  displacement relative to the obstacle since the last converged step);
- the "pressures" ``r_c = (p_N, r_T)``: the contact pressure and the tangential traction on the
  body (positive along the tangent vectors that ``s_T`` is measured along).

Coulomb's law with De Saxcé's modified slip ``\hat u = u + \mu |s_T| e_N`` is the cone
complementarity

.. math::  K_\mu \ni r \perp \hat u \in K_\mu^*, \qquad K_\mu = \{|r_T| \le \mu p_N\},
           \quad K_\mu^* = \{\mu |u_T| \le u_N\},

which holds exactly when ``g_N >= 0, p_N >= 0, g_N p_N = 0`` and ``|r_T| <= mu p_N`` with
``r_T = -mu p_N s_T / |s_T|`` wherever ``s_T != 0`` (stick: ``s_T = 0``; slip: the traction on
the cone's surface, opposing the slip). Its natural-map residual ``r - P_K(r - \hat u)``
vanishes exactly there (:func:`natural_map`); FCLIB measures solutions with it
(:mod:`ddcm_casadi.problems.fclib`).
"""

from __future__ import annotations

import numpy as np


def blocks(v: np.ndarray, block: int) -> np.ndarray:
    """``(nc, b)``: a component-major vector of ``nc b`` entries, one row per contact."""
    v = np.asarray(v, float).reshape(-1)
    return v.reshape(block, -1).T


def flat(blocked: np.ndarray) -> np.ndarray:
    """The component-major vector of ``(nc, b)`` rows (inverse of :func:`blocks`)."""
    return np.asarray(blocked, float).T.reshape(-1)


def project_cone(x: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Projection of the rows of ``x`` ``(nc, b)`` (normal first) onto the cones
    ``|x_T| <= mu x_N``: the apex in the polar cone (``mu |x_T| <= -x_N``), ``x`` inside, else
    ``s (1, mu x_T/|x_T|)`` with ``s = (x_N + mu |x_T|) / (1 + mu^2)``."""
    x = np.asarray(x, float)
    x = x.reshape(-1, x.shape[-1]) if x.ndim > 1 else x.reshape(1, -1)
    mu = np.broadcast_to(np.asarray(mu, float).reshape(-1), (x.shape[0],))
    n, t = x[:, 0], np.linalg.norm(x[:, 1:], axis=1)
    out = x.copy()
    polar = mu * t <= -n
    out[polar] = 0.0
    between = ~polar & (t > mu * n)
    s = (mu[between] * t[between] + n[between]) / (1.0 + mu[between] ** 2)
    out[between, 0] = s
    direction = x[between, 1:] / np.where(t[between] > 0, t[between], 1.0)[:, None]
    out[between, 1:] = (mu[between] * s)[:, None] * direction
    return out


def modified_slip(u: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """De Saxcé's ``u_hat = u + mu |u_T| e_N`` of the rows of ``u`` ``(nc, b)``."""
    u = np.array(u, float)
    u[:, 0] += np.asarray(mu, float).reshape(-1) * np.linalg.norm(u[:, 1:], axis=1)
    return u


def natural_map(u: np.ndarray, r: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """``r - P_K(r - u_hat)`` per contact ``(nc, b)``: zero exactly where Coulomb's law holds."""
    r = np.asarray(r, float)
    return r - project_cone(r - modified_slip(u, mu), mu)


def tangent_basis(normals: np.ndarray) -> np.ndarray:
    """``(nc, d - 1, d)``: unit tangents orthogonal to each unit normal, right-handed with it
    (2-D: ``t = (n_y, -n_x)``; 3-D: ``t_1`` along ``e x n`` for the axis ``e`` least aligned
    with ``n``, ``t_2 = n x t_1``)."""
    n = np.asarray(normals, float)
    if n.shape[1] == 2:
        return np.stack([n[:, 1], -n[:, 0]], axis=1)[:, None, :]
    e = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    t1 = np.cross(e, n)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    return np.stack([t1, np.cross(n, t1)], axis=1)


def contact_status(u: np.ndarray, r: np.ndarray, mu: np.ndarray, tol: float, slip_tol: float) -> np.ndarray:
    """Per contact ``"open"``, ``"stick"`` or ``"slip"``: open where ``p_N <= tol``, slip where
    the traction is on the cone's surface (``|r_T| >= mu p_N - tol``) and the slip exceeds
    ``slip_tol``, stick otherwise."""
    u, r = np.asarray(u, float), np.asarray(r, float)
    mu = np.asarray(mu, float).reshape(-1)
    p, t, s = r[:, 0], np.linalg.norm(r[:, 1:], axis=1), np.linalg.norm(u[:, 1:], axis=1)
    return np.where(p <= tol, "open", np.where((t >= mu * p - tol) & (s > slip_tol), "slip", "stick"))
