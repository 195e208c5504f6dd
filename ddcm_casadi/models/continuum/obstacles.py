r"""Rigid obstacles for node-to-surface contact (frictionless; linearised or at the current configuration).

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
With finite kinematics the gap is exact instead, ``g = phi(X + u - s_t d)``
(:meth:`Obstacle.phi_expression`), its normal ``grad phi`` at the current point: large sliding.

Obstacles: :class:`Plane`, :class:`Ball` (a circle in 2-D, i.e. a cylinder in plane strain; a
sphere in 3-D), :class:`Cylinder` (3-D, a finite axis direction, infinite length) and
:class:`FlatPunch` (a flat punch with rounded edges, 2-D or 3-D) and :class:`SignedDistance` (any function).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import casadi as ca
import numpy as np

from ddcm_casadi.errors import InputError
from ddcm_casadi.models.continuum.finite import safe_norm


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
    motion : sequence of sequences of float, optional
        The obstacle's displacement vector per step (any path, e.g. pressed, then pushed
        sideways), instead of ``direction`` and ``travel``; its ``travel`` is then the path's
        length so far (the load parameter), set by :func:`moving`.
    """

    direction: Sequence[float] = field(default=(0.0, -1.0), kw_only=True)
    travel: float | Sequence[float] = field(default=0.0, kw_only=True)
    name: str = field(default="obstacle", kw_only=True)
    motion: Sequence | None = field(default=None, kw_only=True)

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

    def phi_expression(self, x: ca.SX) -> ca.SX:
        """:meth:`phi` for a CasADi symbol ``x`` ``(n, d)`` (rows: points): the exact gap at the
        current configuration (finite kinematics), its normal by automatic differentiation."""
        raise InputError(f"obstacle {self.name!r} ({self.kind}) has no symbolic signed distance: finite "
                         f"kinematics needs a plane, circle, sphere, cylinder or punch")

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

    def displacements(self, n_steps: int) -> np.ndarray:
        """The obstacle's displacement per step, ``(n_steps, d)``: ``motion``, else ``s_t d``."""
        if self.motion is None:
            return np.stack([self.offset(st) for st in self.travels(n_steps)])
        m = np.asarray(self.motion, dtype=float)
        if m.shape != (n_steps, self.dimension):
            raise InputError(f"obstacle {self.name!r}: motion has {m.shape[0]} displacements of {m.shape[-1]} "
                             f"components, the load path {n_steps} steps in {self.dimension}-D")
        return m

    def gap_offsets(self, x: np.ndarray, n_steps: int) -> np.ndarray:
        """``phi(X - m_t)`` per step and point: ``(n_steps, n)`` (``m_t`` :meth:`displacements`)."""
        return np.stack([self.phi(x - m) for m in self.displacements(n_steps)])

    def normals(self, x: np.ndarray, n_steps: int) -> np.ndarray:
        """Normals at the reference configuration (obstacle at its first position): ``(n, d)``."""
        return self.grad_phi(x - self.displacements(n_steps)[0])

    def describe(self) -> dict:
        """A small record for results files."""
        out = dict(kind=self.kind, name=self.name, direction=list(map(float, self.direction)),
                   travel=np.asarray(self.travel, dtype=float).tolist())
        if self.motion is not None:
            out["motion"] = np.asarray(self.motion, dtype=float).tolist()
        return out

    def drawing(self, step_travel: float) -> dict | None:
        """What :func:`~ddcm_casadi.outputs.continuum.figure_deformed_body` draws (2-D), or ``None``."""
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

    def phi_expression(self, x):
        return ca.mtimes(x - ca.repmat(ca.DM(self.point).T, x.size1(), 1), ca.DM(self.normal))

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

    def phi_expression(self, x):
        return safe_norm(x - ca.repmat(ca.DM(self.center).T, x.size1(), 1)) - self.radius

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


@dataclass(frozen=True, eq=False)
class FlatPunch(Obstacle):
    r"""A rigid flat punch with rounded edges: a strip of half-width ``half_width`` (2-D, plane
    strain) or a cylinder of radius ``half_width`` (3-D), its flat face through ``center`` with
    outward normal ``normal`` (towards the body), the edge rounded with ``edge_radius``.

    With the height above the face ``h = n . (x - c)`` and the lateral distance
    ``rho = |x - c - h n|``, the punch is the set ``{rho <= a - r, h <= -r}`` grown by ``r``
    (``a`` the half-width, ``r`` the edge radius), so its signed distance is

    .. math::  \phi = |\max(q, 0)| + \min(\max(q_1, q_2), 0) - r ,\qquad
               q = (
ho - (a - r),\; h + r) .

    ``edge_radius = 0`` gives a sharp-edged punch, whose edge normal is not defined; a small
    radius resolved by a few contact nodes is the usual model of a machined edge.
    """

    center: Sequence[float] = (0.0, 0.0)
    normal: Sequence[float] = (0.0, 1.0)
    half_width: float = 1.0
    edge_radius: float = 0.0
    kind = "punch"

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _vector("punch center", self.center))
        object.__setattr__(self, "normal", _unit("punch normal", self.normal, self.center.size))
        object.__setattr__(self, "half_width", _radius(self.half_width))
        r = float(self.edge_radius)
        if not (math.isfinite(r) and 0.0 <= r <= self.half_width):
            raise InputError(f"punch edge_radius must be in [0, half_width = {self.half_width:g}], got {self.edge_radius!r}")
        object.__setattr__(self, "edge_radius", r)

    @property
    def dimension(self) -> int:
        return self.center.size

    def _local(self, x):
        v = np.asarray(x, dtype=float) - self.center
        h = v @ self.normal
        lateral = v - h[:, None] * self.normal
        rho = np.linalg.norm(lateral, axis=1)
        q = np.column_stack([rho - (self.half_width - self.edge_radius), h + self.edge_radius])
        return q, lateral, rho

    def phi(self, x):
        q, _, _ = self._local(np.atleast_2d(x))
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0) - self.edge_radius

    def phi_expression(self, x):
        v = x - ca.repmat(ca.DM(self.center).T, x.size1(), 1)
        h = ca.mtimes(v, ca.DM(self.normal))
        rho = safe_norm(v - ca.mtimes(h, ca.DM(self.normal).T))
        q1, q2 = rho - (self.half_width - self.edge_radius), h + self.edge_radius
        outside = safe_norm(ca.horzcat(ca.fmax(q1, 0), ca.fmax(q2, 0)))
        return outside + ca.fmin(ca.fmax(q1, q2), 0) - self.edge_radius

    def grad_phi(self, x):
        q, lateral, rho = self._local(np.atleast_2d(x))
        out = np.maximum(q, 0.0)
        norm = np.linalg.norm(out, axis=1)
        inside = norm == 0.0  # the nearest face decides
        out[inside] = np.where((q[inside, 0] > q[inside, 1])[:, None], [1.0, 0.0], [0.0, 1.0])
        out /= np.linalg.norm(out, axis=1, keepdims=True)
        e_rho = np.divide(lateral, rho[:, None], out=np.zeros_like(lateral), where=rho[:, None] > 0)
        if np.any((out[:, 0] > 0) & (rho == 0)):
            raise InputError(f"obstacle {self.name!r}: a contact node sits on the punch axis at its edge")
        return out[:, :1] * e_rho + out[:, 1:] * self.normal

    def describe(self) -> dict:
        return dict(super().describe(), center=self.center.tolist(), normal=self.normal.tolist(),
                    half_width=self.half_width, edge_radius=self.edge_radius)

    def drawing(self, step_travel: float) -> dict | None:
        if self.dimension != 2:
            return None
        a, r, n = self.half_width, self.edge_radius, self.normal
        t = np.array([-n[1], n[0]])
        # The outline in the face's frame (lateral, height): up the sides to 4 half-widths,
        # round the edges (arcs about (+-(a - r), -r)) along the face.
        s = np.linspace(0.0, 0.5 * np.pi, 12)
        right = np.column_stack([a - r + r * np.sin(s), -r + r * np.cos(s)])
        left = right[::-1] * [-1.0, 1.0]
        pts = np.vstack([[(-a, -4 * a)], left, right, [(a, -4 * a)]])
        c = self.center + self.offset(step_travel)
        return dict(kind="outline", points=[tuple(c + x * t + y * n) for x, y in pts])


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

    def phi_expression(self, x):
        r = x - ca.repmat(ca.DM(self.point).T, x.size1(), 1)
        a = ca.DM(self.axis)
        return safe_norm(r - ca.mtimes(ca.mtimes(r, a), a.T)) - self.radius

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


def moving(obstacle: Obstacle, motion) -> Obstacle:
    """``obstacle`` moved along ``motion`` (one displacement vector per step, ``(n_steps, d)``):
    its ``travel`` becomes the path's length so far (the load parameter of tables and figures)
    and its ``direction`` that of its first move (a press, then a shear: the pressing direction,
    along which the contact force is resolved)."""
    import dataclasses

    m = np.asarray(motion, dtype=float)
    if m.ndim != 2 or m.shape[1] != obstacle.dimension or not m.shape[0]:
        raise InputError(f"obstacle {obstacle.name!r}: motion must be a list of {obstacle.dimension}-component "
                         f"displacements, one per step")
    if not np.all(np.isfinite(m)):
        raise InputError(f"obstacle {obstacle.name!r}: motion must be finite")
    steps = np.diff(np.vstack([np.zeros((1, m.shape[1])), m]), axis=0)
    length = np.cumsum(np.linalg.norm(steps, axis=1))
    moved = [v for v in steps if np.any(v)]
    first = moved[0] if moved else np.eye(m.shape[1])[-1]  # a path that stands still: any direction
    return dataclasses.replace(obstacle, motion=m, travel=length, direction=tuple(first))
