r"""Rigid obstacles for node-to-surface contact (frictionless, small deformation).

An obstacle is a rigid body described by a signed distance ``phi(x)``: positive outside the
obstacle (where the deformable body may be), zero on its surface, negative inside. It moves by
translation along the load path: at step ``t`` its surface is ``phi(x - s_t d) = 0`` with a unit
direction ``d`` and a travel ``s_t`` per step.

A contact node at reference position ``X`` with displacement ``u`` has the linearised gap

.. math::  g = \phi(X - s_t d) + n \cdot u \;\ge 0 ,\qquad n = \nabla\phi(X - s_0 d) ,

the normal taken at the reference configuration (body undeformed, obstacle at its first
position), so that the gap operator is one constant sparse matrix and the obstacle's motion enters
only through ``phi`` (``gap0``, a parameter of the problems). This is the small-deformation
assumption: the obstacle's travel and the displacements are small against its curvature radius.

Obstacles: :class:`Plane`, :class:`Ball` (a circle in 2-D, i.e. a cylinder in plane strain; a
sphere in 3-D), :class:`Cylinder` (3-D, a finite axis direction, infinite length) and
:class:`SignedDistance` (any function).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from ..errors import InputError


def _vector(name: str, value, dimension: int | None = None) -> np.ndarray:
    v = np.asarray(value, dtype=float).ravel()
    if v.size not in (2, 3) or (dimension is not None and v.size != dimension):
        want = f"{dimension}" if dimension else "2 or 3"
        raise InputError(f"{name} must have {want} components, got {v.size}")
    if not np.all(np.isfinite(v)):
        raise InputError(f"{name} must be finite, got {value!r}")
    return v


def _radius(value) -> float:
    r = float(value)
    if not (math.isfinite(r) and r > 0):
        raise InputError(f"obstacle radius must be finite and positive, got {value!r}")
    return r


def _unit(name: str, value, dimension: int | None = None) -> np.ndarray:
    v = _vector(name, value, dimension)
    norm = float(np.linalg.norm(v))
    if not norm > 0:
        raise InputError(f"{name} must be a non-zero vector")
    return v / norm


@dataclass(frozen=True, eq=False)
class Obstacle:
    """Base of the rigid obstacles: a signed distance, a motion and a name.

    Parameters
    ----------
    direction : sequence of float
        Direction of travel ``d`` (normalised here).
    travel : float or sequence of float
        ``s_t`` (m), one per load step (a constant: the obstacle stands still there).
    name : str
        A label for tables and figures.
    """

    direction: Sequence[float] = field(default=(0.0, -1.0), kw_only=True)
    travel: float | Sequence[float] = field(default=0.0, kw_only=True)
    name: str = field(default="obstacle", kw_only=True)

    kind = "obstacle"

    @property
    def dimension(self) -> int:  # pragma: no cover - every obstacle overrides
        raise NotImplementedError

    def phi(self, x: np.ndarray) -> np.ndarray:
        """Signed distance of points ``x`` (n, d) to the obstacle at its reference position."""
        raise NotImplementedError  # pragma: no cover

    def grad_phi(self, x: np.ndarray) -> np.ndarray:
        """Unit outward normal ``grad phi`` at points ``x`` (n, d)."""
        raise NotImplementedError  # pragma: no cover

    # -- motion
    def travels(self, n_steps: int) -> np.ndarray:
        """``s_t`` for ``n_steps`` steps."""
        s = np.asarray(self.travel, dtype=float)
        if s.ndim == 0:
            return np.full(n_steps, float(s))
        if s.shape != (n_steps,):
            raise InputError(f"obstacle {self.name!r}: travel has {s.size} values, the load path {n_steps} steps")
        return s

    def offset(self, step_travel: float) -> np.ndarray:
        """The translation ``s d`` of the obstacle for a travel ``s``."""
        return step_travel * _unit(f"obstacle {self.name!r} direction", self.direction, self.dimension)

    def gap_offsets(self, x: np.ndarray, n_steps: int) -> np.ndarray:
        """``phi(X - s_t d)`` per step and point: ``(n_steps, n)``."""
        s = self.travels(n_steps)
        return np.stack([self.phi(x - self.offset(st)) for st in s])

    def normals(self, x: np.ndarray, n_steps: int) -> np.ndarray:
        """Normals at the reference configuration (obstacle at its first position): ``(n, d)``."""
        return self.grad_phi(x - self.offset(self.travels(n_steps)[0]))

    def describe(self) -> dict:
        """A small record for results files."""
        return dict(kind=self.kind, name=self.name, direction=list(map(float, self.direction)),
                    travel=np.asarray(self.travel, dtype=float).tolist())

    def drawing(self, step_travel: float) -> dict | None:
        """What :func:`~ddcm_casadi.continuum.output.figure_deformed_body` draws (2-D), or ``None``."""
        return None


@dataclass(frozen=True, eq=False)
class Plane(Obstacle):
    """The half-space ``n . (x - point) <= 0`` is rigid; the body stays on the side ``n`` points to.

    Parameters
    ----------
    point : sequence of float
        A point of the plane (at the reference position).
    normal : sequence of float
        Outward normal of the obstacle (pointing into the admissible side).
    """

    point: Sequence[float] = (0.0, 0.0)
    normal: Sequence[float] = (0.0, 1.0)
    kind = "plane"

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", _vector("plane point", self.point))
        object.__setattr__(self, "normal", _unit("plane normal", self.normal, self.point.size))

    @property
    def dimension(self) -> int:
        return self.point.size

    def phi(self, x):
        return (np.asarray(x) - self.point) @ self.normal

    def grad_phi(self, x):
        return np.broadcast_to(self.normal, np.shape(x)).copy()

    def describe(self) -> dict:
        return dict(super().describe(), point=self.point.tolist(), normal=self.normal.tolist())

    def drawing(self, step_travel: float) -> dict:
        return dict(kind="plane", point=tuple(self.point + self.offset(step_travel)), normal=tuple(self.normal))


@dataclass(frozen=True, eq=False)
class Ball(Obstacle):
    """A rigid disc (2-D: a cylinder in plane strain) or sphere (3-D) of ``radius`` at ``center``:
    ``phi = |x - center| - radius``."""

    center: Sequence[float] = (0.0, 0.0)
    radius: float = 1.0
    kind = "ball"

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _vector("obstacle center", self.center))
        object.__setattr__(self, "radius", _radius(self.radius))

    @property
    def dimension(self) -> int:
        return self.center.size

    def phi(self, x):
        return np.linalg.norm(np.asarray(x) - self.center, axis=-1) - self.radius

    def grad_phi(self, x):
        r = np.asarray(x) - self.center
        norm = np.linalg.norm(r, axis=-1, keepdims=True)
        if np.any(norm == 0):
            raise InputError(f"obstacle {self.name!r}: a contact node sits at the obstacle's center")
        return r / norm

    @property
    def kind_name(self) -> str:
        return "circle" if self.dimension == 2 else "sphere"

    def describe(self) -> dict:
        return dict(super().describe(), kind=self.kind_name, center=self.center.tolist(), radius=self.radius)

    def drawing(self, step_travel: float) -> dict:
        return dict(kind="circle", center=tuple(self.center + self.offset(step_travel)), radius=self.radius)


def Circle(center, radius, **kw) -> Ball:
    """A rigid cylinder in plane strain (2-D): :class:`Ball` in two dimensions."""
    return Ball(center=_vector("circle center", center, 2), radius=radius, **kw)


def Sphere(center, radius, **kw) -> Ball:
    """A rigid sphere (3-D): :class:`Ball` in three dimensions."""
    return Ball(center=_vector("sphere center", center, 3), radius=radius, **kw)


@dataclass(frozen=True, eq=False)
class Cylinder(Obstacle):
    """A rigid circular cylinder in 3-D: axis through ``point`` along ``axis``, ``radius``;
    ``phi`` = distance to the axis minus the radius."""

    point: Sequence[float] = (0.0, 0.0, 0.0)
    axis: Sequence[float] = (0.0, 1.0, 0.0)
    radius: float = 1.0
    kind = "cylinder"

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", _vector("cylinder point", self.point, 3))
        object.__setattr__(self, "axis", _unit("cylinder axis", self.axis, 3))
        object.__setattr__(self, "radius", _radius(self.radius))

    @property
    def dimension(self) -> int:
        return 3

    def _radial(self, x):
        r = np.asarray(x) - self.point
        return r - np.outer(r @ self.axis, self.axis)

    def phi(self, x):
        return np.linalg.norm(self._radial(x), axis=-1) - self.radius

    def grad_phi(self, x):
        r = self._radial(x)
        norm = np.linalg.norm(r, axis=-1, keepdims=True)
        if np.any(norm == 0):
            raise InputError(f"obstacle {self.name!r}: a contact node sits on the cylinder's axis")
        return r / norm

    def describe(self) -> dict:
        return dict(super().describe(), point=self.point.tolist(), axis=self.axis.tolist(), radius=self.radius)


@dataclass(frozen=True, eq=False)
class SignedDistance(Obstacle):
    """Any rigid surface given by its signed distance ``function(x) -> (n,)`` (``x`` (n, d)),
    positive on the admissible side; ``gradient`` (optional, ``(n, d)``) defaults to central
    differences with step ``1e-6`` times ``length``, normalised."""

    function: Callable[[np.ndarray], np.ndarray] | None = None
    gradient: Callable[[np.ndarray], np.ndarray] | None = None
    dim: int = 2
    length: float = 1.0
    kind = "signed_distance"

    def __post_init__(self) -> None:
        if not callable(self.function):
            raise InputError("a signed-distance obstacle needs a function phi(x)")
        if self.dim not in (2, 3):
            raise InputError(f"dimension must be 2 or 3, got {self.dim!r}")

    @property
    def dimension(self) -> int:
        return self.dim

    def phi(self, x):
        out = np.asarray(self.function(np.asarray(x, dtype=float)), dtype=float).reshape(-1)
        if out.size != np.shape(x)[0] or not np.all(np.isfinite(out)):
            raise InputError(f"obstacle {self.name!r}: phi(x) must give one finite value per point")
        return out

    def grad_phi(self, x):
        x = np.asarray(x, dtype=float)
        if self.gradient is not None:
            g = np.asarray(self.gradient(x), dtype=float).reshape(x.shape)
        else:
            h = 1e-6 * float(self.length)
            g = np.column_stack([(self.phi(x + h * e) - self.phi(x - h * e)) / (2 * h) for e in np.eye(x.shape[1])])
        norm = np.linalg.norm(g, axis=1, keepdims=True)
        if not np.all(norm > 0) or not np.all(np.isfinite(g)):
            raise InputError(f"obstacle {self.name!r}: the gradient of phi vanishes at a contact node")
        return g / norm
