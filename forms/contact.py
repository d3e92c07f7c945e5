"""Penalty contact with analytic rigid obstacles, in UFL.

Each obstacle is a small dataclass with a signed distance ``gap(x)`` of the
deformed position x = X + u: g > 0 outside the obstacle (free), g < 0 inside
(penetration). Its outward unit normal is n = ∂g/∂x (``normal``). The obstacle
moves by a prescribed motion — a translation vector and, for bodies of
revolution, a radial ``indentation`` towards their axis — given as dolfinx
Constants (or any UFL expression), so the load parameter of a scene can be the
obstacle's position.

The penalty energy on the slave surface Γ_s (reference area, seed 002 eq. 9) is

    Π_c = ∫_Γs ½ α ⟨−g(X + u)⟩² dA,      ⟨a⟩ = max(a, 0),

whose first variation δΠ_c = −∫ α ⟨−g⟩ n·δu dA is the contact traction
t = α ⟨−g⟩ n pushing the body out of the obstacle. UFL differentiates it exactly
(curvature of the obstacle included), so Newton sees the consistent tangent.

Obstacles of revolution use cylindrical coordinates about an axis (point a, unit
direction e): z = (x − a)·e and ρ = |x − a − z e|; a ring is any 2D profile in
the (ρ, z) half-plane swept about the axis: the encircling band and the
silicone tire of scleral buckling are rounded rectangles or polygons there.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np
import ufl

Vector3 = tuple[float, float, float]


def _unit(v: Sequence[float]) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    norm = np.linalg.norm(v)
    if not norm > 0:
        raise ValueError("a direction must be a nonzero vector")
    return v / norm


def _vec(v: Sequence[float]) -> ufl.core.expr.Expr:
    return ufl.as_vector([float(c) for c in v])


def _translated(x, translation):
    return x if translation is None else x - translation


def _soft_norm(w):
    """|w|, kept differentiable at w = 0 (an axis point of an obstacle of revolution)."""
    return ufl.sqrt(ufl.dot(w, w) + 1e-24)


# -- obstacles -------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Plane:
    """Half-space {(x − p)·m < 0}; the body lives where (x − p)·m > 0.

    ``normal`` m points from the obstacle into the body's side.
    """

    point: Vector3
    normal: Vector3
    translation: object | None = None  # UFL vector (dolfinx Constant of shape (3,))

    def gap(self, x):
        m = _vec(_unit(self.normal))
        return ufl.dot(_translated(x, self.translation) - _vec(self.point), m)


@dataclasses.dataclass(frozen=True)
class Sphere:
    """A rigid ball (body outside it) or a spherical cup (``inside=True``: body inside)."""

    center: Vector3
    radius: float
    inside: bool = False
    translation: object | None = None

    def gap(self, x):
        distance = _soft_norm(_translated(x, self.translation) - _vec(self.center))
        return self.radius - distance if self.inside else distance - self.radius


@dataclasses.dataclass(frozen=True)
class _OfRevolution:
    """Cylindrical coordinates about an axis, with a radial indentation δ that
    moves the obstacle δ towards the axis (the band tightening around the eye)."""

    axis_point: Vector3 = (0.0, 0.0, 0.0)
    axis: Vector3 = (0.0, 0.0, 1.0)
    translation: object | None = None
    indentation: object | None = None  # UFL scalar (dolfinx Constant)

    def _rho_z(self, x):
        y = _translated(x, self.translation) - _vec(self.axis_point)
        e = _vec(_unit(self.axis))
        z = ufl.dot(y, e)
        rho = _soft_norm(y - z * e)
        if self.indentation is not None:  # the profile moved inwards = the point moved outwards
            rho = rho + self.indentation
        return rho, z


@dataclasses.dataclass(frozen=True)
class Cylinder(_OfRevolution):
    """An infinite circular cylinder of ``radius``; ``inside=True``: the body is inside
    (a tube, the band's inner face), else outside (a rod)."""

    radius: float = 1.0
    inside: bool = True

    def gap(self, x):
        rho, _ = self._rho_z(x)
        return self.radius - rho if self.inside else rho - self.radius


@dataclasses.dataclass(frozen=True)
class Torus(_OfRevolution):
    """A torus: circle of ``tube_radius`` at distance ``major_radius`` from the axis;
    the body is outside the tube (a round band or an O-ring)."""

    major_radius: float = 1.0
    tube_radius: float = 0.1

    def gap(self, x):
        rho, z = self._rho_z(x)
        return ufl.sqrt((rho - self.major_radius) ** 2 + z**2 + 1e-24) - self.tube_radius


# -- 2D profiles in the (ρ, z) half-plane --------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class RoundedRectangle:
    """Centre (ρc, zc), full ``width`` (along ρ) and ``height`` (along z), corners
    rounded with ``corner_radius`` (0 = sharp). Signed distance (Quílez). The sizes
    may be UFL values (Constants): then the caller keeps the corner radius in range."""

    center: tuple[float, float]
    width: float
    height: float
    corner_radius: float = 0.0

    def __post_init__(self):
        sizes = (self.corner_radius, self.width, self.height)
        if not all(isinstance(a, (int, float)) for a in sizes):
            return
        if not 0 <= self.corner_radius <= 0.5 * min(self.width, self.height):
            raise ValueError("corner_radius must lie in [0, min(width, height)/2]")

    def distance(self, rho, z):
        r = self.corner_radius
        qx = abs(rho - self.center[0]) - (0.5 * self.width - r)
        qz = abs(z - self.center[1]) - (0.5 * self.height - r)
        outside = ufl.sqrt(ufl.max_value(qx, 0.0) ** 2 + ufl.max_value(qz, 0.0) ** 2 + 1e-24)
        return outside + ufl.min_value(ufl.max_value(qx, qz), 0.0) - r


@dataclasses.dataclass(frozen=True)
class Polygon:
    """A simple closed polygon through ``points`` [(ρ, z), ...], optionally rounded by
    offsetting it outwards by ``rounding``. Signed distance: the nearest edge gives
    the magnitude, the crossing number the sign (Quílez's polygon SDF)."""

    points: tuple[tuple[float, float], ...]
    rounding: float = 0.0

    def __post_init__(self):
        if len(self.points) < 3:
            raise ValueError("a polygon needs at least 3 points")

    def distance(self, rho, z):
        p = ufl.as_vector([rho, z])
        vertices = [ufl.as_vector([float(a), float(b)]) for a, b in self.points]
        first = p - vertices[0]
        squared = ufl.dot(first, first)
        sign = 1.0
        for i, vi in enumerate(vertices):
            vj = vertices[i - 1]
            e, w = vj - vi, p - vi
            t = ufl.min_value(ufl.max_value(ufl.dot(w, e) / ufl.dot(e, e), 0.0), 1.0)
            b = w - t * e
            squared = ufl.min_value(squared, ufl.dot(b, b))
            c1, c2 = ufl.ge(p[1], vi[1]), ufl.lt(p[1], vj[1])
            c3 = ufl.gt(e[0] * w[1], e[1] * w[0])
            crossing = ufl.Or(ufl.And(ufl.And(c1, c2), c3),
                              ufl.And(ufl.And(ufl.Not(c1), ufl.Not(c2)), ufl.Not(c3)))
            sign = sign * ufl.conditional(crossing, -1.0, 1.0)
        return sign * ufl.sqrt(squared + 1e-24) - self.rounding


@dataclasses.dataclass(frozen=True)
class Ring(_OfRevolution):
    """A ring swept about the axis from a 2D ``profile`` (RoundedRectangle, Polygon,
    or anything with ``distance(rho, z)``); the body is outside the profile."""

    profile: object = None

    def gap(self, x):
        rho, z = self._rho_z(x)
        return self.profile.distance(rho, z)


# -- energy, traction, normal -----------------------------------------------------------------
def deformed_position(u):
    return ufl.SpatialCoordinate(u.ufl_function_space().mesh) + u


def obstacle_normal(obstacle, u):
    """n = ∂g/∂x at x = X + u: unit outward normal of the obstacle's level set."""
    x = ufl.variable(deformed_position(u))
    return ufl.diff(obstacle.gap(x), x)


def penetration(obstacle, u):
    """⟨−g⟩: how deep the deformed point lies inside the obstacle (0 when free)."""
    return ufl.max_value(-obstacle.gap(deformed_position(u)), 0.0)


def penalty_energy(obstacle, u, penalty, measure):
    """Π_c = ∫ ½ α ⟨−g(X + u)⟩² dA over ``measure`` (the slave surface, reference area)."""
    return 0.5 * penalty * penetration(obstacle, u) ** 2 * measure


def smoothed_penalty_density(g, penalty, smoothing):
    """The penalty energy per area φ(g) with its kink rounded off over |g| < ε (UFL):

        φ = ½ α g² + α ε²/6        g ≤ −ε
        φ = α (ε − g)³ / (12 ε)    −ε < g < ε
        φ = 0                      g ≥ ε

    so the pressure p = −φ' is α⟨−g⟩ outside the band and α (ε − g)²/(4ε) inside it
    (:func:`smoothed_penalty_pressure` evaluates the same law on arrays). ε = 0 is the
    plain ½ α ⟨−g⟩². Why: a C² energy keeps Newton from cycling on points that sit at
    g ≈ 0 (measured on the buckle: a 2-cycle at residual 1e-4 without it); the price is a
    pressure up to αε/4 for gaps below ε (a stand-off ≤ ε). ε = 0 (a number) and ε > 0
    are two forms; ε > 0 may be a Constant, so that its value compiles nothing new."""
    if isinstance(smoothing, (int, float)) and smoothing <= 0:
        return 0.5 * penalty * ufl.max_value(-g, 0.0) ** 2
    eps = smoothing
    return ufl.conditional(
        ufl.ge(g, eps), 0.0,
        ufl.conditional(ufl.le(g, -eps), 0.5 * penalty * g**2 + penalty * eps**2 / 6,
                        penalty * (eps - g) ** 3 / (12 * eps)))


def smoothed_penalty_energy(obstacle, u, penalty, smoothing, measure, multiplier=None):
    """Π_c = ∫ φ(g(X + u)) dA over ``measure`` with φ of :func:`smoothed_penalty_density`;
    with a ``multiplier`` λ (a UFL scalar, e.g. a nodal Function) the augmented Lagrangian
    energy ∫ φ(g − λ/α) dA of :func:`augmented_gap` (None: the penalty, the λ = 0 case)."""
    gap = obstacle.gap(deformed_position(u))
    if multiplier is not None:
        gap = augmented_gap(gap, multiplier, penalty)
    return smoothed_penalty_density(gap, penalty, smoothing) * measure


def augmented_gap(g, multiplier, penalty):
    """g − λ/α: the augmented Lagrangian contact law is the penalty law of this shifted gap.

    With the multiplier λ ≥ 0 (a contact pressure) held fixed, the pressure
    p = α⟨−(g − λ/α)⟩ = ⟨λ − α g⟩ (Simo & Laursen 1992; Laursen 2002, §5.3), and the
    energy density φ(g − λ/α) of :func:`smoothed_penalty_density` (up to a constant) has
    p = −∂φ/∂g; λ = 0 is the penalty. Uzawa's update after each converged solve is
    λ ← p(g − λ/α) (:func:`augmented_pressure`); at its fixed point a point in contact
    carries the pressure λ at g = 0 (with the round-off ε: at the gap where p(g) = λ),
    whatever α. Works on UFL expressions and on numpy arrays."""
    return g - multiplier / penalty


def augmented_pressure(g, multiplier, penalty, smoothing):
    """p = −φ'(g − λ/α) ≥ 0 in UFL (φ of :func:`smoothed_penalty_density`, ε = ``smoothing``):
    the contact pressure with the multiplier λ held fixed, and Uzawa's next λ."""
    shifted = augmented_gap(g, multiplier, penalty)
    if isinstance(smoothing, (int, float)) and smoothing <= 0:
        return ufl.max_value(-penalty * shifted, 0.0)
    eps = smoothing
    return ufl.conditional(
        ufl.ge(shifted, eps), 0.0,
        ufl.conditional(ufl.le(shifted, -eps), -penalty * shifted,
                        penalty * (eps - shifted) ** 2 / (4 * eps)))


def smoothed_penalty_pressure(gaps: np.ndarray, penalty: float,
                              smoothing: float) -> tuple[np.ndarray, np.ndarray]:
    """p(g) = −φ'(g) ≥ 0 of :func:`smoothed_penalty_density` and its slope dp/dg, on
    arrays of gaps (for the node-wise contacts evaluated in numpy)."""
    gaps = np.asarray(gaps, dtype=float)
    if smoothing <= 0.0:
        return penalty * np.maximum(-gaps, 0.0), np.where(gaps < 0, -penalty, 0.0)
    eps = smoothing
    blend = (gaps > -eps) & (gaps < eps)
    pressure = np.where(gaps <= -eps, -penalty * gaps, 0.0)
    slope = np.where(gaps <= -eps, -penalty, 0.0)
    pressure = np.where(blend, penalty * (eps - gaps) ** 2 / (4 * eps), pressure)
    slope = np.where(blend, -penalty * (eps - gaps) / (2 * eps), slope)
    return pressure, slope


def tangential_slips(normal: np.ndarray, anchor: np.ndarray, positions: np.ndarray):
    """Lagged Coulomb friction's slips on arrays: projectors P = I − n⊗n onto the contact
    planes, slips s = P (x − a) from the anchors a, and |s| (one row per slider)."""
    projector = np.eye(3)[None] - np.einsum("ni,nj->nij", normal, normal)
    slip = np.einsum("nij,nj->ni", projector, positions - anchor)
    return projector, slip, np.linalg.norm(slip, axis=1)


def contact_pressure(obstacle, u, penalty, multiplier=None):
    """α ⟨−g⟩, or ⟨λ − α g⟩ with an augmented Lagrangian ``multiplier`` λ."""
    if multiplier is None:
        return penalty * penetration(obstacle, u)
    return augmented_pressure(obstacle.gap(deformed_position(u)), multiplier, penalty, 0.0)


def contact_traction(obstacle, u, penalty, multiplier=None):
    """t = α ⟨−g⟩ n (⟨λ − α g⟩ n with a ``multiplier``): the force per reference area the
    obstacle exerts on the body."""
    return contact_pressure(obstacle, u, penalty, multiplier) * obstacle_normal(obstacle, u)


def default_penalty(youngs_modulus: float, mesh_size: float, factor: float = 30.0) -> float:
    """α = factor · E / h (MPa/mm). The penetration of a penalty traction p is p/α,
    so relative to the element size h it is (p/E)/factor: small for factor ≫ p/E.
    ``factor`` = 30 is what the hertz penalty study (docs/contact.md) justifies: the
    penetration is below 1 % of the indentation and the force within 0.7 % of its
    α → ∞ limit at 15 Newton iterations, where 100 and 300 cost 18 and 21.
    """
    if not (youngs_modulus > 0 and mesh_size > 0 and factor > 0):
        raise ValueError("penalty scaling needs E > 0, h > 0, factor > 0")
    return factor * youngs_modulus / mesh_size
