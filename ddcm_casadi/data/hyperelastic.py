r"""Hyperelastic laws at finite strain, written once as a stored energy ``W(E)`` in Mandel notation.

A law is its stored-energy density as a function of the Green-Lagrange strain ``E`` (Mandel
components: ``k = 3`` in plane strain, ``k = 6`` in 3-D) and the Lame constants
``lambda = E nu / ((1 + nu)(1 - 2 nu))``, ``mu = E / (2 (1 + nu))`` (:func:`lame`). The second
Piola-Kirchhoff stress is its derivative, by CasADi's automatic differentiation:

.. math::  S = \partial W / \partial E ,

component by component in Mandel notation (the Mandel inner product is the tensor one, so the
gradient with respect to the Mandel vector is the Mandel vector of the tensor derivative). The
laws (:data:`LAWS`, ``[material] law = ...`` and ``[data] law = ...``):

- ``"saint_venant_kirchhoff"``: ``W = lambda/2 (tr E)^2 + mu tr(E^2)``;
- ``"neo_hookean"``: ``W = mu/2 (I_1 - 3) - mu ln J + lambda/2 (ln J)^2`` with ``C = I + 2 E``,
  ``I_1 = tr C`` of the 3-D tensor (plane strain: ``C_33 = 1``) and ``ln J = ln det C / 2``;
- ``"linear"``: the small-strain law ``W = lambda/2 (tr eps)^2 + mu tr(eps^2)`` (the formula of
  Saint Venant-Kirchhoff, on the small strain): allowed with small kinematics only.

Both ``E`` and ``S`` are symmetric, so data pairs ``(E, S)`` satisfy the balance of angular
momentum by construction (``docs/maths.md``, "Finite-strain continua").

:func:`neo_hookean_stress` is the closed form ``S = mu (I - C^-1) + lambda ln J C^-1``, written
independently of the energy, so that tests check the automatic derivative against it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import casadi as ca
import numpy as np

from ddcm_casadi.data.metric import COMPONENTS, MANDEL_INDEX, mandel_to_tensor, tensor_to_mandel
from ddcm_casadi.errors import InputError

_SQRT2 = math.sqrt(2.0)


def lame(youngs_modulus, poisson_ratio) -> tuple[np.ndarray, np.ndarray]:
    """``(lambda, mu)`` from Young's modulus and Poisson's ratio (arrays broadcast)."""
    E, nu = np.asarray(youngs_modulus, float), np.asarray(poisson_ratio, float)
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def mandel_tensor(v, dimension: int):
    """The symmetric ``3 x 3`` tensor (a list of lists of entries) of a Mandel vector ``v``
    (``k`` entries; ``SX`` or numbers; :data:`~ddcm_casadi.data.metric.MANDEL_INDEX`). Plane
    strain: the third row and column are zero."""
    T = [[0, 0, 0], [0, 0, 0], [0, 0, 0]]
    for c, (a, b) in enumerate(MANDEL_INDEX[dimension]):
        T[a][b] = T[b][a] = v[c] if a == b else v[c] / _SQRT2
    return T


def _det3(A) -> object:
    return (A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) - A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0])
            + A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]))


def _trace(A) -> object:
    return A[0][0] + A[1][1] + A[2][2]


def _trace_square(A) -> object:
    return sum(A[i][j] * A[j][i] for i in range(3) for j in range(3))


def _svk(E, lam, mu, dimension: int):
    T = mandel_tensor(E, dimension)
    return 0.5 * lam * _trace(T) ** 2 + mu * _trace_square(T)


def _neo_hookean(E, lam, mu, dimension: int):
    T = mandel_tensor(E, dimension)
    C = [[(1.0 if i == j else 0.0) + 2 * T[i][j] for j in range(3)] for i in range(3)]
    log_J = 0.5 * ca.log(_det3(C))
    return 0.5 * mu * (_trace(C) - 3) - mu * log_J + 0.5 * lam * log_J ** 2


@dataclass(frozen=True)
class HyperelasticLaw:
    """A stored energy ``energy(E, lambda, mu, dimension)`` (Mandel ``E``, CasADi symbols).

    Attributes
    ----------
    name : str
    energy : callable
    finite : bool
        Whether the law is meant for finite strain (``"linear"`` is not).
    """

    name: str
    energy: Callable
    finite: bool = True


#: The laws by name (``[material] law = ...``).
LAWS: dict[str, HyperelasticLaw] = {
    "linear": HyperelasticLaw("linear", _svk, finite=False),
    "saint_venant_kirchhoff": HyperelasticLaw("saint_venant_kirchhoff", _svk),
    "neo_hookean": HyperelasticLaw("neo_hookean", _neo_hookean),
}


def get_law(name: str) -> HyperelasticLaw:
    """The law called ``name``, or a one-line :class:`InputError` naming the choices."""
    try:
        return LAWS[name]
    except (KeyError, TypeError):
        raise InputError(f"unknown material law {name!r}; choose one of {', '.join(map(repr, LAWS))}") from None


@lru_cache(maxsize=None)
def stress_function(name: str, dimension: int) -> ca.Function:
    """``S(E, lambda, mu)`` of one material point, ``S = dW/dE`` by automatic differentiation
    (built once per law and dimension)."""
    k = COMPONENTS[dimension]
    E, lam, mu = ca.SX.sym("E", k), ca.SX.sym("lam"), ca.SX.sym("mu")
    W = get_law(name).energy(E, lam, mu, dimension)
    return ca.Function(f"{name}_S{dimension}", [E, lam, mu], [ca.gradient(W, E)])


@lru_cache(maxsize=None)
def energy_function(name: str, dimension: int) -> ca.Function:
    """``W(E, lambda, mu)`` of one material point."""
    k = COMPONENTS[dimension]
    E, lam, mu = ca.SX.sym("E", k), ca.SX.sym("lam"), ca.SX.sym("mu")
    return ca.Function(f"{name}_W{dimension}", [E, lam, mu], [get_law(name).energy(E, lam, mu, dimension)])


def second_piola(name: str, strain: np.ndarray, youngs_modulus, poisson_ratio, dimension: int) -> np.ndarray:
    """Numbers: the stresses ``S`` ``(n, k)`` of strains ``E`` ``(n, k)`` (Mandel), per row
    ``E``/``nu`` given once or per row. Non-finite where the law is undefined (``det C <= 0``)."""
    E = np.atleast_2d(np.asarray(strain, float))
    n = E.shape[0]
    lam, mu = lame(np.broadcast_to(youngs_modulus, (n,)), np.broadcast_to(poisson_ratio, (n,)))
    if n == 0:
        return E.copy()
    with np.errstate(invalid="ignore"):
        out = stress_function(name, dimension).map(n)(E.T, lam[None, :], mu[None, :])
    return np.asarray(out, float).T


def law_of(name: str, youngs_modulus: float, poisson_ratio: float, dimension: int) -> Callable[[np.ndarray], np.ndarray]:
    """``stress = law(strain)`` (``(n, k) -> (n, k)``) for data sets
    (:meth:`~ddcm_casadi.data.dataset.MaterialDataset.from_law`)."""
    get_law(name)
    return lambda strain: second_piola(name, strain, youngs_modulus, poisson_ratio, dimension)


# ------------------------------------------------------------- independent closed forms
def principal_strains_within(strain: np.ndarray, dimension: int, low: float, high: float) -> np.ndarray:
    """Which Mandel strain rows have every principal strain (eigenvalue of the tensor) in
    ``[low, high]``: the states a strain range means for a finite-strain law. With ``low > -1/2``
    it keeps ``det C = prod (1 + 2 E_i) >= (1 + 2 low)^d > 0``, so the stresses stay bounded (a
    Mandel box holds states near ``det C = 0``, whose Neo-Hookean stresses grow without bound)."""
    T = mandel_to_tensor(strain, dimension)[:, :dimension, :dimension]
    e = np.linalg.eigvalsh(T)
    return np.all((e >= low) & (e <= high), axis=1)


def neo_hookean_stress(strain: np.ndarray, youngs_modulus: float, poisson_ratio: float, dimension: int) -> np.ndarray:
    """``S = mu (I - C^-1) + lambda ln J C^-1`` (Mandel rows), the textbook form, for checks."""
    lam, mu = lame(youngs_modulus, poisson_ratio)
    C = np.eye(3) + 2 * mandel_to_tensor(strain, dimension)
    if dimension == 2:
        C[:, 2, 2] = 1.0
    Ci = np.linalg.inv(C)
    log_J = 0.5 * np.log(np.linalg.det(C))
    S = mu * (np.eye(3) - Ci) + lam * log_J[:, None, None] * Ci
    return tensor_to_mandel(S, dimension)


def cauchy_stress(second_piola_stress: np.ndarray, deformation_gradient: np.ndarray, dimension: int) -> np.ndarray:
    """Cauchy stress ``sigma = F S F^T / J`` as ``(n, 3, 3)`` tensors, from Mandel ``S`` ``(n, k)``
    and ``F`` ``(n, d, d)`` (plane strain: ``F_33 = 1``; ``sigma_33`` is left out, the in-plane
    law does not give ``S_33``)."""
    S = mandel_to_tensor(second_piola_stress, dimension)
    n = S.shape[0]
    F = np.tile(np.eye(3), (n, 1, 1))
    F[:, :dimension, :dimension] = deformation_gradient
    J = np.linalg.det(F)
    return np.einsum("nij,njk,nlk->nil", F, S, F) / J[:, None, None]
