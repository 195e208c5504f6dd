r"""Hertz contact: the closed forms a continuum model is validated against.

A rigid cylinder (2-D, plane strain) or sphere (3-D) of radius ``R`` pressed into an isotropic
elastic body (``E``, ``nu``) with a frictionless contact; against a rigid indenter the effective
modulus is ``E* = E / (1 - nu^2)`` (``docs/maths.md``, "Hertz contact").

2-D, load ``P`` per unit thickness:

.. math::  a = 2 \sqrt{R P / (\pi E^*)},\qquad p_0 = 2 P / (\pi a),\qquad
           p(x) = p_0 \sqrt{1 - x^2 / a^2} .

3-D, force ``F``:

.. math::  a = (3 F R / (4 E^*))^{1/3},\qquad p_0 = 3 F / (2 \pi a^2),\qquad
           p(r) = p_0 \sqrt{1 - r^2 / a^2} .

The indentation depth of a 2-D body depends on its size, so the reference is evaluated for the
*measured* contact force of the finite-element solution, and the finite-element pressure is
compared with that Hertz profile. The finite-element pressure is the one every measure uses,
:func:`~ddcm_casadi.models.continuum.pressure.measured_pressure` (on linear tetrahedra the
pressure recovered from the boundary elements' stresses, elsewhere the nodal pressure):

- ``p0``: its largest value over the pairs;
- ``a`` from the pressure's second moment, which for the Hertz profile is
  ``int x^2 p / int p = a^2 / 4`` (2-D) and ``int r^2 p dA / int p dA = 2 a^2 / 5`` (3-D): an
  integral measure, free of the one-element uncertainty of "the last node in contact";
- the relative L2 error of the pressure over the contact surface, with the nodal (lumped)
  quadrature of the tributary areas;
- ``scatter``: the largest deviation, relative to ``p0`` of the fit, of the pressure at the pairs
  with ``r < 0.8 a`` from a least-squares fit ``c0 + c1 (r/a)^2 + c2 (r/a)^4`` through them (node-to-node
  noise, free of the discretisation's smooth error); NaN with fewer than 4 such pairs.

The force is the nodal forces' resultant along the indenter's travel (the one the solution is in
equilibrium with). A model of a symmetric part of the body (half in 2-D, a quarter in 3-D) has
the model's ``symmetry_factor`` (2 or 4; ``force_factor`` here, the same number: the model
refuses two different ones): the measured force is multiplied by it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ddcm_casadi.errors import InputError


def effective_modulus(youngs_modulus: float, poisson_ratio: float) -> float:
    """``E* = E / (1 - nu^2)`` of an elastic body against a rigid one."""
    return float(youngs_modulus) / (1.0 - float(poisson_ratio) ** 2)


def _compressive(load: float) -> None:
    if not (math.isfinite(load) and load >= 0):
        raise InputError(f"the Hertz solution needs a finite compressive load >= 0, got {load!r}")


def hertz_2d(load: float, radius: float, e_star: float) -> tuple[float, float]:
    """Half-width ``a`` and peak pressure ``p0`` for a load ``P >= 0`` per unit thickness."""
    _compressive(load)
    a = 2.0 * math.sqrt(radius * load / (math.pi * e_star))
    return a, 2.0 * load / (math.pi * a) if a > 0 else 0.0


def hertz_3d(force: float, radius: float, e_star: float) -> tuple[float, float]:
    """Contact radius ``a`` and peak pressure ``p0`` for a force ``F >= 0``."""
    _compressive(force)
    a = (3.0 * force * radius / (4.0 * e_star)) ** (1.0 / 3.0)
    return a, 3.0 * force / (2.0 * math.pi * a ** 2) if a > 0 else 0.0


def profile(x: np.ndarray, a: float, p0: float) -> np.ndarray:
    """``p0 sqrt(1 - x^2/a^2)`` inside the contact, zero outside."""
    x = np.asarray(x, dtype=float)
    if a <= 0:
        return np.zeros_like(x)
    return p0 * np.sqrt(np.clip(1.0 - (x / a) ** 2, 0.0, None))


def scatter(r: np.ndarray, p: np.ndarray, a: float, inside: float = 0.8) -> float:
    """Node-to-node scatter of a pressure ``p`` at distances ``r`` from the axis: the largest
    ``|p - fit| / fit(0)`` over the points with ``r < inside a``, ``fit = c0 + c1 (r/a)^2 + c2 (r/a)^4``
    by least squares through them (smooth in ``r`` like the Hertz profile, so the fit keeps the
    discretisation's smooth error and leaves the noise); NaN with fewer than 4 such points."""
    r, p = np.asarray(r, float), np.asarray(p, float)
    keep = r < inside * a if a > 0 else np.zeros(r.shape, bool)
    if int(np.sum(keep)) < 4:
        return float("nan")
    V = np.vander((r[keep] / a) ** 2, 3, increasing=True)
    c = np.linalg.lstsq(V, p[keep], rcond=None)[0]
    return float(np.max(np.abs(p[keep] - V @ c)) / c[0]) if c[0] > 0 else float("nan")


class _HertzMeasures:
    """What every Hertz reference measures, given where its pairs are (:meth:`coordinates`),
    the direction its force is resolved along (:meth:`direction`) and its radius and modulus
    (:meth:`geometry`)."""

    force_factor: float

    def _check_force_factor(self) -> None:
        if not (math.isfinite(self.force_factor) and self.force_factor >= 1):
            raise InputError(f"[hertz] force_factor must be a number >= 1, got {self.force_factor!r}")

    def measure(self, model, pressure: np.ndarray, stress: np.ndarray | None = None) -> dict:
        """Compare one step's contact pressures (Pa, one per pair) with Hertz.

        Parameters
        ----------
        model : ContinuumModel
        pressure : ndarray, shape (nc,)
            The solvers' nodal pressures.
        stress : ndarray, shape (m k,), optional
            The step's material-point stresses; required on linear tetrahedra, whose measures
            use the recovered pressure (:func:`~ddcm_casadi.models.continuum.pressure.measured_pressure`).

        Returns
        -------
        dict
            ``force`` (the full body's, along :meth:`direction`), ``a_hertz``, ``p0_hertz``,
            ``a_fe``, ``p0_fe``, ``error_a``, ``error_p0`` (relative), ``error_l2`` (relative L2
            of the pressure profile), ``scatter`` (see the module), ``nodes_in_contact``,
            ``p0_nodal`` (the largest nodal pressure, for comparison) and ``pressure_measure``
            (``"recovered"`` or ``"nodal"``).
        """
        from ddcm_casadi.models.continuum.pressure import measured_pressure, uses_recovered

        pairs, x = self.coordinates(model)
        radius, e_star = self.geometry(model)
        p = measured_pressure(model, pressure, stress)[pairs]
        area = model.contact_area[pairs]
        # The contact forces a p n resolved along the direction. A step without contact sums
        # roundoff of either sign (penalty: -1e-20 Pa): no load.
        along = model.contact_force_vectors(pressure)[pairs] @ self.direction(model)
        force = max(0.0, self.force_factor * float(np.sum(along)))
        w = area * p
        moment = float(np.sum(w * x ** 2) / np.sum(w)) if np.sum(w) > 0 else 0.0
        if model.dimension == 2:
            a_h, p0_h = hertz_2d(force, radius, e_star)
            a_fe = 2.0 * math.sqrt(moment)
        else:
            a_h, p0_h = hertz_3d(force, radius, e_star)
            a_fe = math.sqrt(2.5 * moment)
        ref = profile(x, a_h, p0_h)
        den = math.sqrt(float(np.sum(area * ref ** 2)))
        l2 = math.sqrt(float(np.sum(area * (p - ref) ** 2))) / den if den > 0 else float("nan")
        p0_fe = float(np.max(p)) if p.size else 0.0
        rel = (lambda v, r: abs(v - r) / r if r > 0 else float("nan"))  # noqa: E731
        nodal = np.asarray(pressure, float)[pairs]
        return dict(force=force, a_hertz=a_h, p0_hertz=p0_h, a_fe=a_fe, p0_fe=p0_fe,
                    error_a=rel(a_fe, a_h), error_p0=rel(p0_fe, p0_h), error_l2=l2,
                    scatter=scatter(np.abs(x), p, a_h), nodes_in_contact=int(np.sum(model.active_contacts(nodal))),
                    p0_nodal=float(np.max(nodal)) if nodal.size else 0.0,
                    pressure_measure="recovered" if uses_recovered(model) else "nodal")

    def step_summary(self, model, pressure: np.ndarray, stress: np.ndarray | None = None) -> dict:
        """The per-step columns of ``results.csv``: the full body's force along the travel,
        ``a`` and ``p0`` errors, the profile's L2 error and scatter (:meth:`measure`)."""
        m = self.measure(model, pressure, stress)
        return dict(hertz_force=m["force"], hertz_error_a=m["error_a"], hertz_error_p0=m["error_p0"],
                    hertz_error_l2=m["error_l2"], hertz_pressure_scatter=m["scatter"])

    def curve(self, model, pressure: np.ndarray, stress: np.ndarray | None = None, n: int = 201) -> dict:
        """The Hertz profile for the measured force, for figures: ``{"x", "pressure", "label"}``."""
        m = self.measure(model, pressure, stress)
        a = m["a_hertz"]
        lo = -1.3 * a if model.dimension == 2 and self._two_sided(model) else 0.0
        x = np.linspace(lo, 1.3 * a, n)
        return dict(x=x, pressure=profile(x, a, m["p0_hertz"]),
                    label=f"Hertz (F = {m['force']:.4g} N{'/m' if model.dimension == 2 else ''})")

    def _two_sided(self, model) -> bool:
        _, x = self.coordinates(model)
        return bool(np.any(x < 0) and np.any(x > 0))


@dataclass(frozen=True)
class HertzReference(_HertzMeasures):
    """The Hertz solution for one rigid round obstacle of a continuum model.

    Parameters
    ----------
    youngs_modulus, poisson_ratio : float
        The body's isotropic law.
    obstacle : int
        Index of the indenter among the model's obstacles (a :class:`~.obstacles.Ball`).
    force_factor : float
        The full body's force over the modelled part's (2 for a half, 4 for a quarter): the
        model's ``symmetry_factor`` (a model refuses a reference with another one).
    """

    youngs_modulus: float
    poisson_ratio: float
    obstacle: int = 0
    force_factor: float = 1.0

    def __post_init__(self) -> None:
        self._check_force_factor()

    @property
    def e_star(self) -> float:
        return effective_modulus(self.youngs_modulus, self.poisson_ratio)

    def describe(self) -> dict:
        return dict(kind="hertz", youngs_modulus=self.youngs_modulus, poisson_ratio=self.poisson_ratio,
                    e_star=self.e_star, obstacle=self.obstacle, force_factor=self.force_factor)

    # ------------------------------------------------------------------ geometry
    def _indenter(self, model):
        try:
            ob = model.obstacles[self.obstacle]
        except IndexError:
            raise InputError(f"[hertz] obstacle {self.obstacle} does not exist") from None
        if getattr(ob, "kind", None) != "ball":
            raise InputError("[hertz] needs a circle (2-D) or sphere (3-D) obstacle")
        return ob

    def geometry(self, model) -> tuple[float, float]:
        """The indenter's radius and ``E*`` of the body against a rigid one."""
        return self._indenter(model).radius, self.e_star

    def direction(self, model) -> np.ndarray:
        """The indenter's direction of travel."""
        d = np.asarray(self._indenter(model).direction, float)
        return d / np.linalg.norm(d)

    def coordinates(self, model) -> tuple[np.ndarray, np.ndarray]:
        """The indenter's pairs and their distance from its axis (2-D: signed ``x``; 3-D: ``r``)."""
        ob = self._indenter(model)
        pairs = np.flatnonzero(model.contact_obstacle == self.obstacle)
        return pairs, _lateral(model.contact_points[pairs] - ob.center, self.direction(model))


@dataclass(frozen=True)
class BodyHertzReference(_HertzMeasures):
    """The Hertz solution for a contact between two round elastic bodies (a cylinder or sphere on
    a block, two cylinders or spheres): the pairs of the model's contact ``contact``
    (:class:`~.inputs.BodyContact`), with the effective radius ``1/R* = 1/R1 + 1/R2`` and the
    combined modulus ``1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2`` of the slave's and the master's
    materials (read off the model: one material on each side).

    The line of centres passes through the pair that is closest at the first step (the first
    point of contact), along ``direction``; the force is resolved along it.

    Parameters
    ----------
    radius : float
        ``R*`` (a flat master: the slave's radius).
    contact : int
        Index of the contact among the model's contacts.
    force_factor : float
        The model's ``symmetry_factor``.
    direction : sequence of float, optional
        The line of centres, from the slave towards the master. Default: the normal of the first
        point of contact (on a symmetry plane give it: a node there has half its facets, and a
        tilted normal).
    """

    radius: float
    contact: int = 0
    force_factor: float = 1.0
    direction_of_centres: tuple | None = None

    def __post_init__(self) -> None:
        self._check_force_factor()
        if not (math.isfinite(self.radius) and self.radius > 0):
            raise InputError(f"[hertz] radius must be a positive length, got {self.radius!r}")

    def describe(self) -> dict:
        return dict(kind="hertz between bodies", radius=self.radius, contact=self.contact,
                    force_factor=self.force_factor,
                    direction=None if self.direction_of_centres is None else list(self.direction_of_centres))

    def _pairs(self, model) -> np.ndarray:
        pairs = np.flatnonzero(model.contact_obstacle == self.contact)
        surface = model.obstacles[self.contact] if self.contact < len(model.obstacles) else None
        if getattr(surface, "kind", None) != "surface" or not pairs.size:
            raise InputError(f"[hertz] contact {self.contact} is not a contact between bodies with pairs")
        return pairs

    def _first(self, model) -> int:
        pairs = self._pairs(model)
        return int(pairs[np.argmin(model.gap_offsets[0, pairs])])

    def direction(self, model) -> np.ndarray:
        """The line of centres (from the slave to the master)."""
        if self.direction_of_centres is None:
            return model.contact_normals[self._first(model)]
        d = np.asarray(self.direction_of_centres, float)
        if d.shape != (model.dimension,) or not np.all(np.isfinite(d)) or not np.any(d):
            raise InputError(f"[hertz] direction must be {model.dimension} finite numbers, not all zero")
        return d / np.linalg.norm(d)

    def coordinates(self, model) -> tuple[np.ndarray, np.ndarray]:
        pairs = self._pairs(model)
        return pairs, _lateral(model.contact_points[pairs] - model.contact_points[self._first(model)],
                               self.direction(model))

    def geometry(self, model) -> tuple[float, float]:
        """``R*`` and the combined modulus of the two sides' materials."""
        laws = []
        for facets in (model.contact_facets[self.contact], model.obstacles[self.contact].facets):
            points = model.mesh.f2t[0, facets] * model.discretisation.points_per_element
            E, nu = np.unique(model.youngs_modulus[points]), np.unique(model.poisson_ratio[points])
            if E.size != 1 or nu.size != 1:
                raise InputError(f"[hertz] contact {self.contact}: each side needs one isotropic material")
            laws.append((float(E[0]), float(nu[0])))
        return self.radius, combined_modulus(*laws[0], *laws[1])


def combined_modulus(e1: float, nu1: float, e2: float, nu2: float) -> float:
    """``E*`` of two elastic bodies: ``1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2``."""
    return 1.0 / ((1.0 - nu1 ** 2) / e1 + (1.0 - nu2 ** 2) / e2)


def _lateral(rel: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Distances of points ``rel`` (relative to a point of the axis ``d``) from the axis: signed
    along the in-plane tangent in 2-D, radial in 3-D."""
    lateral = rel - np.outer(rel @ d, d)
    if rel.shape[1] == 2:
        return lateral @ np.array([-d[1], d[0]])
    return np.linalg.norm(lateral, axis=1)
