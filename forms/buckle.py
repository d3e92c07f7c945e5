"""The scleral buckle as a rigid obstacle: an encircling band and/or a silicone tire.

Both are rings about the optic axis (z) whose cross-sections in the (ρ, z) half-plane
are rounded rectangles: the band (``band_width`` along z, ``band_thickness``
radially) all round the eye, the tire (``tire_width``, ``tire_height``) over an arc
of ``tire_arc_deg`` centred on the tear's meridian (azimuth 0, the +y axis). The
kinds (``kind``) are the operations surgeons perform:

- ``encircling``: the band alone;
- ``segmental``: the tire alone (seed 002 §1, the segmental operation);
- ``encircling+segmental``: the band all round and the tire under it at the tear
  (seed 002 §3, the paper's operation).

Both elements start with their inner faces at ``base_radius`` (the clearance from the
inflated sclera) and move radially inward: the band by ``indentation`` (tightened),
the tire by ``tire_indentation`` (pressed in by the band and by its sutures; the band's
travel when not given); where the tire lies the band runs over it, so the obstacle is
the union of the two, and its signed distance the smaller one.

An arc-limited tire is the intersection of the swept ring with the wedge
|φ| ≤ φ₀/2 about the axis; its signed distance is approximated by the larger of
the ring's and the wedge's (exact away from the edges where both are positive).
The wedge's distance is ρ sin(|φ| − φ₀/2), clamped to ±90° of overshoot so that
points deep inside the wedge stay inside.

A radial tire (``orientation = radial``, segmental only) lies along the tear's
meridian instead of across it: a ring about the x axis (the normal of the symmetry
plane, through the eye's centre) whose cross-section in the (ρ', x) half-plane is the
same rounded rectangle, ``tire_width`` across the meridian (along x) and
``tire_height`` radially, cut by the wedge |β − β₀| ≤ ``tire_length``/(2 R) about x
(β = atan2(y, z) the polar angle along the meridian, β₀ the tire's centre, R the
sclera's radius on which the length is measured). Its base radius is measured from
the x axis, and it travels towards the eye's centre.

Sutured buckle: the sclera under the buckle's footprint is tied to it tangentially
(:func:`tangential_tie_energy`): sutures hold band and tire on the sclera, which
must not slide along them (with a frictionless obstacle it does: the eye is
squeezed forward through the band).

Force-driven tire (:func:`tire_travel_residual`): a suture is a loop through the
sclera at two bites and over the tire; its tension T pulls each bite towards the tire
and pushes the tire inward with the resultant of T turning over it. The tire's radial
travel δ is then one more unknown, whose equation is the balance of the contact force
the sclera exerts on the tire against that inward pull (plus the band's push).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import ufl

from eyemech.forms.contact import Ring, RoundedRectangle

KINDS = ("encircling+segmental", "encircling", "segmental")
ORIENTATIONS = ("circumferential", "radial")


@dataclasses.dataclass(frozen=True)
class BuckleShape:
    """Cross-section of band and tire (mm), which of them there are, and the tire's arc."""

    band_width: float = 2.5
    band_thickness: float = 0.6
    tire_width: float = 7.0
    tire_height: float = 1.0
    corner_radius: float = 0.3
    kind: str = "encircling+segmental"
    tire_arc_deg: float = 360.0
    orientation: str = "circumferential"
    tire_length: float = 12.0    # radial tire: its extent along the meridian (mm)
    sclera_radius: float = 11.5  # radial tire: the sphere on which tire_length is measured

    def __post_init__(self):
        if self.orientation not in ORIENTATIONS:
            raise ValueError(f"orientation {self.orientation!r}: one of {ORIENTATIONS}")
        if self.radial and self.has_band:
            # the tie and the band's stop act about one axis: a radial tire is segmental
            raise ValueError("a radial tire is segmental: no band with it")

    @property
    def radial(self) -> bool:
        return self.orientation == "radial"

    @property
    def axis(self) -> int:
        """Index of the tire's axis of revolution: z (2) for band and circumferential
        tire, x (0, the symmetry plane's normal) for a radial tire."""
        return 0 if self.radial else 2

    @property
    def half_arc(self) -> float:
        """Half the tire's angular extent (rad): about z (circumferential), or along
        the meridian about x (radial)."""
        if self.radial:
            return 0.5 * self.tire_length / self.sclera_radius
        return math.radians(0.5 * self.tire_arc_deg)

    @property
    def has_band(self) -> bool:
        return self.kind in ("encircling", "encircling+segmental")

    @property
    def has_tire(self) -> bool:
        return self.kind in ("segmental", "encircling+segmental") and self.tire_height > 0

    @property
    def footprint(self) -> float:
        """Axial width of what can touch the sclera (the widest element)."""
        widths = ([self.band_width] if self.has_band else []) + \
            ([self.tire_width] if self.has_tire else [])
        return max(widths) if widths else self.band_width

    def on_tire(self, azimuth_deg: float) -> bool:
        """Whether the meridian at ``azimuth_deg`` from the tear passes under the tire
        (a radial tire lies on the tear's meridian only)."""
        if self.radial:
            return self.has_tire and abs(azimuth_deg) < 1e-9
        return self.has_tire and abs(azimuth_deg) <= 0.5 * self.tire_arc_deg + 1e-9

    def element_at(self, azimuth_deg: float) -> tuple[float, float] | None:
        """(axial width, radial height) of what the sclera meets at this meridian."""
        if self.on_tire(azimuth_deg):
            return self.tire_width, self.tire_height
        if self.has_band:
            return self.band_width, self.band_thickness
        return None


def _abs_azimuth(x):
    """|φ| ∈ [0, π], the angle about the z axis from the tear's meridian (+y)."""
    return ufl.atan2(ufl.sqrt(x[0] ** 2 + 1e-24), x[1])


def _wedge_gap(angle_off, half_arc, rho):
    """Signed distance to the wedge |angle_off| ≤ half_arc: ρ sin(|off| − half),
    the overshoot clamped to ±90° so that points deep inside stay inside."""
    over = ufl.min_value(ufl.max_value(angle_off - half_arc, -0.5 * math.pi), 0.5 * math.pi)
    return rho * ufl.sin(over)


@dataclasses.dataclass(frozen=True)
class BuckleSizes:
    """The buckle's dimensions as they enter the forms (mm; the tire's half arc in
    radians): dolfinx Constants in a scene, so that new sizes reuse the compiled forms
    (tests/test_compile_once.py), or floats. :meth:`of` makes them from a
    :class:`BuckleShape` with ``constant`` (a float → UFL-value factory)."""

    band_width: object
    band_thickness: object
    tire_width: object
    tire_height: object
    corner_radius: object
    tire_half_arc: object  # radians: about z (circumferential) or along the meridian (radial)

    @classmethod
    def of(cls, shape: BuckleShape, constant=float) -> BuckleSizes:
        return cls(constant(shape.band_width), constant(shape.band_thickness),
                   constant(shape.tire_width), constant(shape.tire_height),
                   constant(shape.corner_radius), constant(shape.half_arc))


def buckle_rings(sizes: BuckleSizes, axial_position, base_radius, indentation,
                 tire_indentation=None, tire_axis: int = 2):
    """(tire, band) ring obstacles (both at ``base_radius``); the sizes, the axial
    position, ``base_radius`` and the travels may be Constants or Real-space Functions;
    the tire's travel is the band's unless ``tire_indentation`` is given. The corner
    radius is capped by half of each profile's sides (UFL ``min_value``, so that it
    stays a Constant). ``tire_axis`` = 0: a radial tire, about the x axis through the
    eye's centre, centred on the symmetry plane x = 0."""
    height = ufl.max_value(sizes.tire_height, 1e-6)
    tire_centre = 0.0 if tire_axis == 0 else axial_position
    tire = RoundedRectangle(center=(base_radius + 0.5 * height, tire_centre),
                            width=height, height=sizes.tire_width,
                            corner_radius=ufl.min_value(sizes.corner_radius, ufl.min_value(
                                0.5 * height, 0.5 * sizes.tire_width)))
    band = RoundedRectangle(center=(base_radius + 0.5 * sizes.band_thickness, axial_position),
                            width=sizes.band_thickness, height=sizes.band_width,
                            corner_radius=ufl.min_value(sizes.corner_radius, 0.5 * sizes.band_thickness))
    tire_travel = indentation if tire_indentation is None else tire_indentation
    axis = tuple(float(i == tire_axis) for i in range(3))
    return (Ring(axis=axis, indentation=tire_travel, profile=tire),
            Ring(indentation=indentation, profile=band))


@dataclasses.dataclass(frozen=True)
class Buckle:
    """Union of the band ring and the (arc-limited) tire: ``gap(x)`` is the smaller
    signed distance. ``shape`` decides the forms' structure (band, tire, arc-limited or
    not); ``sizes`` and ``axial_position`` are the numbers in them (Constants in a
    scene; floats from ``shape`` when ``sizes`` is None)."""

    shape: BuckleShape
    axial_position: object
    base_radius: object
    indentation: object
    tire_indentation: object | None = None  # None: the tire moves with the band
    sizes: BuckleSizes | None = None
    polar_angle: object = 0.0  # radial tire: its centre's angle β₀ from +z along the meridian

    def _tire_angle_off(self, x):
        """|angle| of x from the tire's centre about its axis: |φ| about z from the
        tear's meridian (circumferential), |β − β₀| along the meridian (radial)."""
        if self.shape.radial:
            return abs(ufl.atan2(x[1], x[2]) - self.polar_angle)
        return _abs_azimuth(x)

    def axis_distance(self, x):
        """Distance of x from the tire's axis of revolution (UFL or arrays (n, 3))."""
        i, j = (self.shape.axis + 1) % 3, (self.shape.axis + 2) % 3
        if isinstance(x, np.ndarray):
            return np.hypot(x[..., i], x[..., j])
        return ufl.sqrt(x[i] ** 2 + x[j] ** 2 + 1e-24)

    @property
    def dimensions(self) -> BuckleSizes:
        return self.sizes if self.sizes is not None else BuckleSizes.of(self.shape)

    @property
    def arc_limited(self) -> bool:
        """Whether the tire is cut to an arc: a wedge in the forms (structural)."""
        return self.shape.radial or self.shape.tire_arc_deg < 360.0

    def gap(self, x):
        tire, band = buckle_rings(self.dimensions, self.axial_position, self.base_radius,
                                  self.indentation, self.tire_indentation, self.shape.axis)
        gaps = []
        if self.shape.has_tire:
            g = tire.gap(x)
            if self.arc_limited:
                g = ufl.max_value(g, _wedge_gap(self._tire_angle_off(x), self.dimensions.tire_half_arc,
                                                self.axis_distance(x)))
            gaps.append(g)
        if self.shape.has_band:
            gaps.append(band.gap(x))
        return gaps[0] if len(gaps) == 1 else ufl.min_value(*gaps)

    def footprint_weight(self, x):
        """1 on the sclera under the buckle (axially within the element's width at
        that meridian), 0 elsewhere; ``x`` a position that does not depend on the
        unknowns (the pre-operative one), so the weight carries no derivative."""
        sizes = self.dimensions
        z = abs(x[2] - self.axial_position)
        weights = []
        if self.shape.has_tire:
            across = abs(x[0]) if self.shape.radial else z
            inside = ufl.le(across, 0.5 * sizes.tire_width)
            if self.arc_limited:
                inside = ufl.And(inside, ufl.le(self._tire_angle_off(x), sizes.tire_half_arc))
            weights.append(ufl.conditional(inside, 1.0, 0.0))
        if self.shape.has_band:
            weights.append(ufl.conditional(ufl.le(z, 0.5 * sizes.band_width), 1.0, 0.0))
        return weights[0] if len(weights) == 1 else ufl.max_value(*weights)

    def footprint_mask(self, x: np.ndarray) -> np.ndarray:
        """:meth:`footprint_weight` on an array of points (n, 3), from the same numbers
        (a Constant's current value)."""
        sizes = self.dimensions
        z = np.abs(x[:, 2] - float(self.axial_position))
        if self.shape.radial:
            across = np.abs(x[:, 0])
            angle = np.abs(np.arctan2(x[:, 1], x[:, 2]) - float(self.polar_angle))
        else:
            across, angle = z, np.arctan2(np.abs(x[:, 0]), x[:, 1])
        mask = np.zeros(len(x), bool)
        if self.shape.has_tire:
            within = across <= 0.5 * float(sizes.tire_width)
            if self.arc_limited:
                within &= angle <= float(sizes.tire_half_arc)
            mask |= within
        if self.shape.has_band:
            mask |= z <= 0.5 * float(sizes.band_width)
        return mask

    def depth_through(self, x: np.ndarray, tire_travel: float) -> np.ndarray:
        """How far each point (n, 3) lies beyond the inner (contact) face of the element
        over it, into or past its body, as a fraction of that element's radial thickness
        (the tire's height, the band's thickness): ρ − ρ_face over the element's span
        (across its width, within the tire's arc), ρ the distance from the element's axis,
        ρ_face the inner face's (raised by the rounded corners near the edges); −inf
        outside every span. A point that crossed the contact face and the body's far side
        has a fraction above 1, where the penalty's signed distance is positive again and
        pushes it no more; a sclera point in contact sits beyond the face only by the
        penalty's penetration. The band travels with ``indentation``, the tire by
        ``tire_travel`` (the value of a Real unknown in a scene)."""
        sizes, shape = self.dimensions, self.shape
        base, band_travel = _number(self.base_radius), _number(self.indentation)
        value = _number
        corner = value(sizes.corner_radius)
        depth = np.full(len(x), -np.inf)

        def element(across, rho, width, thickness, travel, within):
            r = min(corner, 0.5 * thickness, 0.5 * width)
            edge = np.clip(np.abs(across) - (0.5 * width - r), 0.0, r)
            face = base - travel + r - np.sqrt(r * r - edge**2)
            inside = within & (np.abs(across) <= 0.5 * width)
            return np.where(inside, (rho - face) / thickness, -np.inf)

        if shape.has_tire:
            if shape.radial:
                across = x[:, 0]
                within = np.abs(np.arctan2(x[:, 1], x[:, 2]) - value(self.polar_angle)) \
                    <= value(sizes.tire_half_arc)
            else:
                across = x[:, 2] - value(self.axial_position)
                within = np.arctan2(np.abs(x[:, 0]), x[:, 1]) <= value(sizes.tire_half_arc) \
                    if self.arc_limited else np.ones(len(x), bool)
            depth = np.maximum(depth, element(across, self.axis_distance(x), value(sizes.tire_width),
                                              max(value(sizes.tire_height), 1e-6), tire_travel,
                                              within))
        if shape.has_band:
            depth = np.maximum(depth, element(x[:, 2] - value(self.axial_position),
                                              np.hypot(x[:, 0], x[:, 1]), value(sizes.band_width),
                                              value(sizes.band_thickness), band_travel,
                                              np.ones(len(x), bool)))
        return depth


def _number(c) -> float:
    """The float of a Constant (its ``value``) or of a plain number."""
    return float(np.asarray(getattr(c, "value", c)))


def tangential_components(x, w, axis: int = 2):
    """(w·e_a, w·e_φ) of a vector w at position x: the directions along which the
    sclera slides on a buckle of revolution about the coordinate axis ``axis`` (z: band
    and circumferential tire; x: radial tire)."""
    i, j = (axis + 1) % 3, (axis + 2) % 3
    rho = ufl.sqrt(x[i] ** 2 + x[j] ** 2 + 1e-24)
    return w[axis], (x[i] * w[j] - x[j] * w[i]) / rho


def tangential_tie_energy(buckle: Buckle, u, u_tied, stiffness, measure):
    """Π_t = ∫ ½ k_t w(x₀) |(u − u₀)_t|² dA: a penalty on the sclera's tangential
    motion relative to the buckle under its footprint, w of
    :meth:`Buckle.footprint_weight` at the tied position x₀ = X + u₀. The buckle moves
    only radially, so its tangential displacement is zero and the slip is the
    sclera's own (axial and circumferential) displacement since it was tied;
    the radial direction stays free for the contact."""
    X = ufl.SpatialCoordinate(measure.ufl_domain())
    x0 = X + u_tied
    along, around = tangential_components(x0, u - u_tied, buckle.shape.axis)
    return 0.5 * stiffness * buckle.footprint_weight(x0) * (along**2 + around**2) * measure


def slip(x0: np.ndarray, du: np.ndarray, axis: int = 2) -> np.ndarray:
    """|(du)_t| at positions x0 (numpy twin of :func:`tangential_components`)."""
    i, j = (axis + 1) % 3, (axis + 2) % 3
    rho = np.hypot(x0[:, i], x0[:, j])
    around = (x0[:, i] * du[:, j] - x0[:, j] * du[:, i]) / rho
    return np.hypot(du[:, axis], around)


def forward_slip(x0: np.ndarray, du: np.ndarray, axis: int = 2) -> np.ndarray:
    """The slip's component towards the cornea along the tire's long direction: +z on
    a buckle about z; on a radial tire (about x) −e_β, e_β = (0, cos β, −sin β) the
    direction of growing polar angle β = atan2(y, z) along the meridian."""
    if axis == 2:
        return du[:, 2]
    beta = np.arctan2(x0[:, 1], x0[:, 2])
    return -np.cos(beta) * du[:, 1] + np.sin(beta) * du[:, 2]


def band_stop_force(tire_travel, band_travel, stiffness):
    """The band's push on the tire it runs over: a unilateral penalty k ⟨δ_band − δ_tire⟩
    (the band is rigid and cannot pull the tire out; the tire may go deeper than it)."""
    return stiffness * ufl.max_value(band_travel - tire_travel, 0.0)


def tire_travel_residual(contact_energy, tire_travel, test, inward_force, measure, area):
    """Row of the tire's radial travel δ (a Real-space unknown with test function ``test``):

        r_δ = ∂Π_c/∂δ − F_in = 0,

    ∂Π_c/∂δ = ∫ α ⟨−g⟩ (−∂g/∂δ) dA the sclera's contact force on the tire along its
    inward travel (Π_c the buckle's penalty energy, which depends on δ through the
    tire's obstacle only), F_in the inward force on the tire from everything else (the
    sutures' resultant, the band's push): a UFL scalar, spread over ``measure`` of
    reference ``area`` so that the row is one form."""
    return ufl.derivative(contact_energy, tire_travel, test) - inward_force / area * test * measure


def pinned_travel_residual(tire_travel, target, test, stiffness, measure, area):
    """Row of a prescribed tire travel: k (δ − δ_target) = 0, k a stiffness of the size
    of the free row's so that switching between the two keeps the Jacobian's scale."""
    return stiffness * (tire_travel - target) / area * test * measure
