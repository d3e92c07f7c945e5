"""The scleral buckle as a rigid obstacle: an encircling band and/or a silicone tire.

A buckle is the union of its elements, each a class below that owns its geometry: its
signed distance ``gap`` (UFL), the footprint it presses (``footprint_weight`` in UFL,
``footprint_mask`` on points), how deep a point lies through it (``depth_through``), the
span its flat inner face must clear (``span_mask``), where a suture crosses it (``bites``,
``anchor``, ``inward``) and its outline in the symmetry plane (``section``, for pictures).
The elements are rings swept about an axis whose cross-sections are rounded rectangles:

- :class:`Band`: the encircling band about the optic axis (z), ``band_width`` along z,
  ``band_thickness`` radially, all round the eye;
- :class:`ArcTire`: the silicone tire about z (``tire_width``, ``tire_height``) over an
  arc of ``tire_arc_deg`` centred on the tear's meridian (azimuth 0, the +y axis); a
  full ring at 360°;
- :class:`RadialTire`: the tire along the tear's meridian instead of across it: a ring
  about the x axis (the normal of the symmetry plane, through the eye's centre) whose
  cross-section in the (ρ', x) half-plane is the same rounded rectangle, ``tire_width``
  across the meridian (along x) and ``tire_height`` radially, cut by the wedge
  |β − β₀| ≤ ``tire_length``/(2 R) about x (β = atan2(y, z) the polar angle along the
  meridian, β₀ the tire's centre, R the sclera's radius on which the length is measured).

Which elements a buckle has is its :class:`BuckleShape`'s ``kind`` and ``orientation``
(:meth:`BuckleShape.parts`, the one place that chooses): the operations surgeons perform,

- ``encircling``: the band alone;
- ``segmental``: the tire alone (seed 002 §1, the segmental operation), across the
  meridian (``circumferential``) or along it (``radial``);
- ``encircling+segmental``: the band all round and the tire under it at the tear
  (seed 002 §3, the paper's operation).

Every element starts with its inner face at ``base_radius`` from its axis (the clearance
from the inflated sclera) and moves towards the axis: the band by ``indentation``
(tightened), the tire by ``tire_indentation`` (pressed in by the band and by its
sutures; the band's travel when not given). Where the tire lies the band runs over it,
so the obstacle is the union of the two, and its signed distance the smaller one.

An arc-limited tire is the intersection of the swept ring with a wedge about its axis;
its signed distance is approximated by the larger of the ring's and the wedge's (exact
away from the edges where both are positive). The wedge's distance is ρ sin(|φ| − φ₀/2),
clamped to ±90° of overshoot so that points deep inside the wedge stay inside.

Sutured buckle: the sclera under the buckle's footprint is tied to it tangentially
(:func:`tangential_tie_energy`): sutures hold band and tire on the sclera, which must
not slide along them (with a frictionless obstacle it does: the eye is squeezed forward
through the band).

Force-driven tire (:func:`tire_travel_residual`): a suture is a loop through the sclera
at two bites and over the tire; its tension T pulls each bite towards the tire and pushes
the tire inward with the resultant of T turning over it. The tire's radial travel δ is
then one more unknown, whose equation is the balance of the contact force the sclera
exerts on the tire against that inward pull (plus the band's push).

Adding a shape: a class with the methods of :class:`Band` (and, for a tire, of
:class:`ArcTire`), chosen in :meth:`BuckleShape.parts` under a new ``kind`` or
``orientation`` (the scene's parameters offer :data:`KINDS` and :data:`ORIENTATIONS`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import ufl

from eyemech.forms.contact import Ring, RoundedRectangle

KINDS = ("encircling+segmental", "encircling", "segmental")
ORIENTATIONS = ("circumferential", "radial")
OUTLINE_PLANE = -0.01  # the pictures' outline: just in front of the symmetry plane x = 0


@dataclasses.dataclass(frozen=True)
class BuckleShape:
    """Cross-section of band and tire (mm), which of them there are, and the tire's arc
    (circumferential) or length (radial)."""

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
        """Index of the elements' common axis of revolution: z (2) for band and
        circumferential tire, x (0, the symmetry plane's normal) for a radial tire."""
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

    def parts(self, sizes: BuckleSizes, axial_position, base_radius, indentation,
              tire_indentation=None, polar_angle=0.0) -> tuple:
        """The buckle's elements, the tire first: the union's order."""
        parts: list = []
        if self.has_tire:
            tire = RadialTire if self.radial else ArcTire
            travel = indentation if tire_indentation is None else tire_indentation
            parts.append(tire(self, sizes, axial_position, base_radius, travel, polar_angle))
        if self.has_band:
            parts.append(Band(self, sizes, axial_position, base_radius, indentation))
        return tuple(parts)

    def placed(self) -> Buckle:
        """The buckle of these sizes as numbers, centred at the origin (for questions
        about its extent: which element a meridian crosses, how wide it is)."""
        return Buckle(self, 0.0, 0.0, 0.0)

    @property
    def footprint(self) -> float:
        """Axial width of what can touch the sclera (the widest element)."""
        return self.placed().footprint

    def on_tire(self, azimuth_deg: float) -> bool:
        """Whether the meridian at ``azimuth_deg`` from the tear passes under the tire
        (a radial tire lies on the tear's meridian only)."""
        return any(part.is_tire and part.covers(azimuth_deg) for part in self.placed().parts)

    def element_at(self, azimuth_deg: float) -> tuple[float, float] | None:
        """(axial width, radial height) of what the sclera meets at this meridian."""
        part = self.placed().part_at(azimuth_deg)
        return None if part is None else part.cross_section

    def placement_problem(self, position: float, meridian: float) -> tuple[str, str] | None:
        """Whether a buckle centred ``position`` mm behind the limbus (along the sclera)
        lies on the sclera, whose meridian runs ``meridian`` mm from the limbus to the
        optic nerve's margin: None, or (what, why) with what "position" or "length"."""
        return self.placed().parts[0].placement_problem(position, meridian)


@dataclasses.dataclass(frozen=True)
class BuckleSizes:
    """The buckle's dimensions as they enter the forms (mm; the tire's half arc in
    radians): dolfinx Constants in a scene, so that new sizes reuse the compiled forms
    (tests/test_compile_once.py), or floats. :meth:`of` makes them from a
    :class:`BuckleShape` with ``constant`` (a float → UFL-value factory), in this order."""

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


def _number(c) -> float:
    """The float of a Constant (its ``value``) or of a plain number."""
    return float(np.asarray(getattr(c, "value", c)))


def _axis_distance(x, axis: int):
    """Distance of x from the coordinate axis ``axis`` (UFL or arrays (n, 3))."""
    i, j = (axis + 1) % 3, (axis + 2) % 3
    if isinstance(x, np.ndarray):
        return np.hypot(x[..., i], x[..., j])
    return ufl.sqrt(x[i] ** 2 + x[j] ** 2 + 1e-24)


def _wedge_gap(angle_off, half_arc, rho):
    """Signed distance to the wedge |angle_off| ≤ half_arc: ρ sin(|off| − half),
    the overshoot clamped to ±90° so that points deep inside stay inside."""
    over = ufl.min_value(ufl.max_value(angle_off - half_arc, -0.5 * math.pi), 0.5 * math.pi)
    return rho * ufl.sin(over)


def _depth(across, rho, width: float, thickness: float, corner: float, face: float,
           within: np.ndarray) -> np.ndarray:
    """ρ − ρ_face over an element's span as a fraction of its radial ``thickness``, the
    inner face at ``face`` from its axis raised by the rounded corners near its edges;
    −inf outside the span (``within``, |across| ≤ width/2)."""
    r = min(corner, 0.5 * thickness, 0.5 * width)
    edge = np.clip(np.abs(across) - (0.5 * width - r), 0.0, r)
    face = face + r - np.sqrt(r * r - edge**2)
    inside = within & (np.abs(across) <= 0.5 * width)
    return np.where(inside, (rho - face) / thickness, -np.inf)


def _meridian_bites(azimuth_deg: float, width: float, radius: float, polar: float):
    """Both bites of a suture ``width`` apart along the meridian at ``azimuth_deg``,
    centred on the polar angle ``polar`` (rad), on the sphere of ``radius``:
    (azimuth, side, centre), side +1 the anterior bite (the smaller polar angle)."""
    half = width / 2 / radius
    psi = math.radians(azimuth_deg)
    bites = []
    for side in (-1, 1):
        t = polar - side * half
        rho = radius * math.sin(t)
        bites.append((azimuth_deg, side, (rho * math.sin(psi), rho * math.cos(psi),
                                          radius * math.cos(t))))
    return bites


def _polyline(points: list[tuple[float, float]]) -> list[tuple[float, float, float]]:
    """A closed polygon of (y, z) points as line segments at x = OUTLINE_PLANE."""
    closed = points + points[:1]
    segments = []
    for (ya, za), (yb, zb) in zip(closed[:-1], closed[1:]):
        segments += [(OUTLINE_PLANE, ya, za), (OUTLINE_PLANE, yb, zb)]
    return segments


@dataclasses.dataclass(frozen=True)
class Band:
    """The encircling band: a ring about the optic axis, all round the eye."""

    shape: BuckleShape
    sizes: BuckleSizes
    axial_position: object
    base_radius: object
    travel: object

    axis = 2
    is_tire = False

    def ring(self) -> Ring:
        s = self.sizes
        profile = RoundedRectangle(center=(self.base_radius + 0.5 * s.band_thickness, self.axial_position),
                                   width=s.band_thickness, height=s.band_width,
                                   corner_radius=ufl.min_value(s.corner_radius, 0.5 * s.band_thickness))
        return Ring(indentation=self.travel, profile=profile)

    def gap(self, x):
        return self.ring().gap(x)

    def footprint_weight(self, x):
        return ufl.conditional(ufl.le(abs(x[2] - self.axial_position), 0.5 * self.sizes.band_width),
                               1.0, 0.0)

    def footprint_mask(self, x: np.ndarray) -> np.ndarray:
        return np.abs(x[:, 2] - float(self.axial_position)) <= 0.5 * float(self.sizes.band_width)

    def span_mask(self, x: np.ndarray) -> np.ndarray:
        return np.abs(x[:, 2] - _number(self.axial_position)) <= 0.5 * self.width

    def depth_through(self, x: np.ndarray, _tire_travel: float) -> np.ndarray:
        s = self.sizes
        return _depth(x[:, 2] - _number(self.axial_position), np.hypot(x[:, 0], x[:, 1]),
                      _number(s.band_width), _number(s.band_thickness), _number(s.corner_radius),
                      _number(self.base_radius) - _number(self.travel), np.ones(len(x), bool))

    @property
    def width(self) -> float:
        return _number(self.sizes.band_width)

    @property
    def cross_section(self) -> tuple[float, float]:
        return _number(self.sizes.band_width), _number(self.sizes.band_thickness)

    def covers(self, _azimuth_deg: float) -> bool:
        return True

    def bites(self, azimuth_deg: float, width: float, radius: float, polar: float):
        return _meridian_bites(azimuth_deg, width, radius, polar)

    def anchor(self, bite, base_radius: float, band_travel: float,
               _tire_travel: float | None) -> list[float]:
        """Where a suture leaves the band: its outer corner on the bite's side, in the
        suture's meridional plane."""
        return _meridian_anchor(bite, self.cross_section, _number(self.axial_position),
                                base_radius - band_travel)

    def inward(self, bite) -> np.ndarray:
        return _towards_z(bite)

    def section(self, _tire_travel: float, floor: float) -> tuple[list, float]:
        """The band's cross-section in the symmetry plane, over what lies under it
        (``floor``: the top of the tire it runs over); and its own top."""
        bottom = max(_number(self.base_radius) - _number(self.travel), floor)
        width, thickness = self.cross_section
        return _rectangle(bottom, thickness, width, _number(self.axial_position)), bottom + thickness

    def placement_problem(self, position: float, meridian: float):
        return _circumferential_placement(position, meridian, self.shape.footprint)


def _meridian_anchor(bite, cross_section: tuple[float, float], axial: float,
                     face: float, own_travel: float = 0.0) -> list[float]:
    """The outer corner of an element about z on a bite's side: ``face`` its inner
    face's radius, moved outward by ``own_travel`` (a tire that travels on its own)."""
    azimuth, side, _centre = bite
    width, height = cross_section
    rho = face + height
    if own_travel:
        rho += own_travel
    psi = math.radians(azimuth)
    return [rho * math.sin(psi), rho * math.cos(psi), axial + side * 0.5 * width]


def _towards_z(bite) -> np.ndarray:
    """The inward direction of an element about z at a bite's meridian: −e_ρ."""
    psi = math.radians(bite[0])
    return -np.array([math.sin(psi), math.cos(psi), 0.0])


def _rectangle(bottom: float, height: float, width: float, z0: float) -> list:
    return _polyline([(bottom, z0 - width / 2), (bottom + height, z0 - width / 2),
                      (bottom + height, z0 + width / 2), (bottom, z0 + width / 2)])


def _circumferential_placement(position: float, meridian: float, footprint: float):
    if not footprint < position < meridian:
        return "position", (f"must put the buckle on the sclera between the limbus and the "
                            f"optic nerve ({footprint:.1f}–{meridian:.1f} mm)")
    return None


@dataclasses.dataclass(frozen=True)
class ArcTire:
    """The silicone tire across the meridian: a ring about the optic axis over an arc
    centred on the tear's meridian (a full ring at 360°)."""

    shape: BuckleShape
    sizes: BuckleSizes
    axial_position: object
    base_radius: object
    travel: object
    polar_angle: object = 0.0

    axis = 2
    is_tire = True

    @property
    def arc_limited(self) -> bool:
        """Whether the tire is cut to an arc: a wedge in the forms (structural)."""
        return self.shape.tire_arc_deg < 360.0

    def ring(self) -> Ring:
        s = self.sizes
        height = ufl.max_value(s.tire_height, 1e-6)
        profile = RoundedRectangle(center=(self.base_radius + 0.5 * height, self._centre()),
                                   width=height, height=s.tire_width,
                                   corner_radius=ufl.min_value(s.corner_radius, ufl.min_value(
                                       0.5 * height, 0.5 * s.tire_width)))
        return Ring(axis=tuple(float(i == self.axis) for i in range(3)), indentation=self.travel,
                    profile=profile)

    def _centre(self):
        """The profile's centre along the axis."""
        return self.axial_position

    def angle_off(self, x):
        """|φ| ∈ [0, π], the angle about z from the tear's meridian (+y)."""
        return ufl.atan2(ufl.sqrt(x[0] ** 2 + 1e-24), x[1])

    def across(self, x):
        """Distance across the tire's long direction from its centre line."""
        return abs(x[2] - self.axial_position)

    def angle_off_points(self, x: np.ndarray) -> np.ndarray:
        return np.arctan2(np.abs(x[:, 0]), x[:, 1])

    def across_points(self, x: np.ndarray) -> np.ndarray:
        return x[:, 2] - _number(self.axial_position)

    def gap(self, x):
        g = self.ring().gap(x)
        if self.arc_limited:
            g = ufl.max_value(g, _wedge_gap(self.angle_off(x), self.sizes.tire_half_arc,
                                            _axis_distance(x, self.axis)))
        return g

    def footprint_weight(self, x):
        inside = ufl.le(self.across(x), 0.5 * self.sizes.tire_width)
        if self.arc_limited:
            inside = ufl.And(inside, ufl.le(self.angle_off(x), self.sizes.tire_half_arc))
        return ufl.conditional(inside, 1.0, 0.0)

    def footprint_mask(self, x: np.ndarray) -> np.ndarray:
        within = np.abs(self.across_points(x)) <= 0.5 * float(self.sizes.tire_width)
        if self.arc_limited:
            within &= self.angle_off_points(x) <= float(self.sizes.tire_half_arc)
        return within

    def span_mask(self, x: np.ndarray) -> np.ndarray:
        """All round the axis: the flat face is placed to clear every meridian."""
        return np.abs(self.across_points(x)) <= 0.5 * self.width

    def depth_through(self, x: np.ndarray, tire_travel: float) -> np.ndarray:
        s = self.sizes
        within = self.angle_off_points(x) <= _number(s.tire_half_arc) if self.arc_limited \
            else np.ones(len(x), bool)
        return _depth(self.across_points(x), _axis_distance(x, self.axis), _number(s.tire_width),
                      max(_number(s.tire_height), 1e-6), _number(s.corner_radius),
                      _number(self.base_radius) - tire_travel, within)

    @property
    def width(self) -> float:
        return _number(self.sizes.tire_width)

    @property
    def cross_section(self) -> tuple[float, float]:
        return _number(self.sizes.tire_width), _number(self.sizes.tire_height)

    def covers(self, azimuth_deg: float) -> bool:
        return abs(azimuth_deg) <= 0.5 * self.shape.tire_arc_deg + 1e-9

    def bites(self, azimuth_deg: float, width: float, radius: float, polar: float):
        return _meridian_bites(azimuth_deg, width, radius, polar)

    def anchor(self, bite, base_radius: float, band_travel: float,
               tire_travel: float | None) -> list[float]:
        """Where a suture leaves the tire: its outer corner on the bite's side, in the
        suture's meridional plane; at the band's travel, or at its own (``tire_travel``,
        a tire the sutures' loop drives)."""
        own = 0.0 if tire_travel is None else band_travel - tire_travel
        return _meridian_anchor(bite, self.cross_section, _number(self.axial_position),
                                base_radius - band_travel, own)

    def inward(self, bite) -> np.ndarray:
        return _towards_z(bite)

    def section(self, tire_travel: float, _floor: float) -> tuple[list, float]:
        """The tire's cross-section in the symmetry plane at its travel; and its top."""
        bottom = _number(self.base_radius) - tire_travel
        width, height = self.cross_section
        return _rectangle(bottom, height, width, _number(self.axial_position)), bottom + height

    def placement_problem(self, position: float, meridian: float):
        return _circumferential_placement(position, meridian, self.shape.footprint)


@dataclasses.dataclass(frozen=True)
class RadialTire(ArcTire):
    """The silicone tire along the tear's meridian: a ring about the x axis through the
    eye's centre, cut to its length along the meridian about the polar angle
    ``polar_angle`` of its centre; sutured across it on the tear's meridian."""

    axis = 0

    @property
    def arc_limited(self) -> bool:
        return True

    def _centre(self):
        return 0.0

    def angle_off(self, x):
        """|β − β₀|: along the meridian from the tire's centre."""
        return abs(ufl.atan2(x[1], x[2]) - self.polar_angle)

    def across(self, x):
        return abs(x[0])

    def angle_off_points(self, x: np.ndarray) -> np.ndarray:
        return np.abs(np.arctan2(x[:, 1], x[:, 2]) - _number(self.polar_angle))

    def across_points(self, x: np.ndarray) -> np.ndarray:
        return x[:, 0]

    def span_mask(self, x: np.ndarray) -> np.ndarray:
        """Its footprint: the flat face lies along the meridian."""
        return self.footprint_mask(x)

    def covers(self, azimuth_deg: float) -> bool:
        return abs(azimuth_deg) < 1e-9

    def bites(self, _azimuth_deg: float, width: float, radius: float, polar: float):
        """The sutures cross the tire at a quarter of its length either side of its
        centre, each with its bites ``width`` apart across the meridian: the bite at
        x = +w/2 is in the half model (side +1), its mirror at −w/2 the symmetry's (the
        half model carries half of each suture)."""
        across = 0.5 * width
        ring = math.sqrt(radius**2 - across**2)  # the bite's distance from the x axis
        quarter = 0.5 * _number(self.sizes.tire_half_arc)
        return [(0.0, 1, (across, ring * math.sin(t), ring * math.cos(t)))
                for t in (polar - quarter, polar + quarter)]

    def anchor(self, bite, base_radius: float, band_travel: float,
               tire_travel: float | None) -> list[float]:
        """Where a suture leaves the tire: its outer corner on the bite's side
        (x = +w/2), in the plane through the x axis and the bite."""
        width, height = self.cross_section
        rho = base_radius + height
        rho -= band_travel if tire_travel is None else tire_travel
        t = math.atan2(bite[2][1], bite[2][2])
        return [0.5 * width, rho * math.sin(t), rho * math.cos(t)]

    def inward(self, bite) -> np.ndarray:
        """Towards the x axis in the bite's plane."""
        t = math.atan2(bite[2][1], bite[2][2])
        return -np.array([0.0, math.sin(t), math.cos(t)])

    def section(self, tire_travel: float, _floor: float, segments: int = 24) -> tuple[list, float]:
        """The annular sector between the inner face (at its travel) and the outer one,
        over its length along the meridian."""
        inner = _number(self.base_radius) - tire_travel
        height = self.cross_section[1]
        angles = _number(self.polar_angle) \
            + _number(self.sizes.tire_half_arc) * np.linspace(-1.0, 1.0, segments + 1)
        ring = [(inner, t) for t in angles] + [(inner + height, t) for t in angles[::-1]]
        return _polyline([(r * math.sin(t), r * math.cos(t)) for r, t in ring]), inner + height

    def placement_problem(self, position: float, meridian: float):
        length = self.shape.tire_length
        if length >= meridian:
            return "length", (f"{length} mm is longer than the meridian from the limbus to "
                              f"the optic nerve ({meridian:.1f} mm)")
        half = 0.5 * length
        if not half < position < meridian - half:
            return "position", (f"puts the {length} mm radial tire off the sclera: its centre "
                                f"must lie {half:.1f}–{meridian - half:.1f} mm behind the limbus")
        return None


@dataclasses.dataclass(frozen=True)
class Buckle:
    """The union of the buckle's elements (:meth:`BuckleShape.parts`): ``gap(x)`` is the
    smaller signed distance. ``shape`` decides the forms' structure (band, tire,
    arc-limited or not); ``sizes`` and ``axial_position`` are the numbers in them
    (Constants in a scene; floats from ``shape`` when ``sizes`` is None)."""

    shape: BuckleShape
    axial_position: object
    base_radius: object
    indentation: object
    tire_indentation: object | None = None  # None: the tire moves with the band
    sizes: BuckleSizes | None = None
    polar_angle: object = 0.0  # radial tire: its centre's angle β₀ from +z along the meridian

    @property
    def dimensions(self) -> BuckleSizes:
        return self.sizes if self.sizes is not None else BuckleSizes.of(self.shape)

    @property
    def parts(self) -> tuple:
        return self.shape.parts(self.dimensions, self.axial_position, self.base_radius,
                                self.indentation, self.tire_indentation, self.polar_angle)

    @property
    def tire(self):
        """The tire element, None without one."""
        return next((part for part in self.parts if part.is_tire), None)

    @property
    def band(self):
        """The band element, None without one."""
        return next((part for part in self.parts if not part.is_tire), None)

    @property
    def backs_tire(self) -> bool:
        """Whether an element runs over the tire and pushes it in (the band)."""
        return self.tire is not None and self.band is not None

    def band_push(self, tire_travel, stiffness):
        """The inward force on the tire from the band over it (:func:`band_stop_force`),
        0 when no band backs it."""
        return band_stop_force(tire_travel, self.indentation, stiffness) if self.backs_tire else 0

    @property
    def axis(self) -> int:
        """The elements' common axis of revolution (2: z; 0: x, a radial tire)."""
        return self.parts[0].axis if self.parts else 2

    def axis_distance(self, x):
        """Distance of x from the buckle's axis of revolution (UFL or arrays (n, 3))."""
        return _axis_distance(x, self.axis)

    def gap(self, x):
        gaps = [part.gap(x) for part in self.parts]
        return gaps[0] if len(gaps) == 1 else ufl.min_value(*gaps)

    def footprint_weight(self, x):
        """1 on the sclera under the buckle (axially within the element's width at
        that meridian), 0 elsewhere; ``x`` a position that does not depend on the
        unknowns (the pre-operative one), so the weight carries no derivative."""
        weights = [part.footprint_weight(x) for part in self.parts]
        return weights[0] if len(weights) == 1 else ufl.max_value(*weights)

    def footprint_mask(self, x: np.ndarray) -> np.ndarray:
        """:meth:`footprint_weight` on an array of points (n, 3), from the same numbers
        (a Constant's current value)."""
        mask = np.zeros(len(x), bool)
        for part in self.parts:
            mask |= part.footprint_mask(x)
        return mask

    def span_mask(self, x: np.ndarray) -> np.ndarray:
        """The points (n, 3) within the buckle's span, which its flat inner faces must
        clear when it is placed."""
        mask = np.zeros(len(x), bool)
        for part in self.parts:
            mask |= part.span_mask(x)
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
        depth = np.full(len(x), -np.inf)
        for part in self.parts:
            depth = np.maximum(depth, part.depth_through(x, tire_travel))
        return depth

    @property
    def footprint(self) -> float:
        """Width of what can touch the sclera across the buckle (the widest element)."""
        return max((part.width for part in self.parts), default=_number(self.dimensions.band_width))

    def part_at(self, azimuth_deg: float):
        """The element the meridian at ``azimuth_deg`` crosses (the tire where it lies), None
        where none does."""
        return next((part for part in self.parts if part.covers(azimuth_deg)), None)

    def suture_bites(self, azimuths, width: float, radius: float, polar: float) -> list:
        """Every suture's bites on the sphere of ``radius``, ``width`` apart, across the
        element at each azimuth: (azimuth, side, centre)."""
        return [bite for azimuth in azimuths
                for bite in self.part_at(azimuth).bites(azimuth, width, radius, polar)]

    def suture_anchors(self, bites, tire_travel: float | None) -> np.ndarray:
        """Where each bite's suture leaves the buckle (the outer corner of the element it
        crosses, on its side); ``tire_travel`` the tire's own, None: the band's."""
        base, band = _number(self.base_radius), _number(self.indentation)
        return np.array([self.part_at(b[0]).anchor(b, base, band, tire_travel) for b in bites])

    def inward(self, bite) -> np.ndarray:
        """The direction the element under a bite travels in (towards its axis)."""
        return self.part_at(bite[0]).inward(bite)

    def outline(self, tire_travel: float) -> np.ndarray | None:
        """The cross-sections in the symmetry plane (the tear's meridian) of the elements
        that cross it, the band over the tire, as line segments (pairs of points) just in
        front of the plane; None when none crosses it."""
        segments, floor = [], -math.inf
        for part in self.parts:
            if part.covers(0.0):
                section, floor = part.section(tire_travel, floor)
                segments += section
        return np.array(segments) if segments else None


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
    along, around = tangential_components(x0, u - u_tied, buckle.axis)
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


def band_length(centre_radius, band_travel, tire_height=0.0, tire_arc=0.0):
    """Centreline length of an encircling band moved ``band_travel`` towards its axis:
    L = 2π (ρ_c − δ) + h_t φ_t, ρ_c the centreline's radius where it was laid, the band
    raised by the tire's height h_t over the tire's arc φ_t (radians) that rides under
    it (its two ramps on and off the tire are left out: h_t² over their length, ≈ 0.1 mm
    of 76 mm with the default 1 mm tire). dL/dδ = −2π whatever the tire."""
    return 2.0 * math.pi * (centre_radius - band_travel) + tire_height * tire_arc


def band_tension(length, set_length, modulus_area):
    """Hoop tension of the elastic band, T = E A (L − L_set)/L_set: its length L
    (:func:`band_length`) against the loop's length after the surgeon shortened it,
    L_set = L_laid − ΔL. Linear both ways: a band looser than its set length pushes out,
    which keeps its travel defined before it touches the eye."""
    return modulus_area * (length - set_length) / set_length


def band_hoop_residual(contact_energy, band_travel, test, tension, share, other_inward,
                       measure, area):
    """Row of the elastic band's radial travel δ (a Real-space unknown): the sclera's
    push on the band (and the tire under it), ∂Π_c/∂δ, balances the inward resultant of
    its hoop tension, 2π T (a ring of tension T and radius ρ presses with T/ρ per unit
    length, over 2π ρ), of which the model carries ``share`` (½ for the half eye), plus
    ``other_inward`` (the sutures' pull on the tire the band carries):

        r_δ = ∂Π_c/∂δ − share · 2π T(δ) − F_other = 0,

    the stationarity in δ of Π_c + share · ½ E A (L − L_set)²/L_set − F_other δ, since
    dL/dδ = −2π (:func:`band_length`)."""
    return tire_travel_residual(contact_energy, band_travel, test,
                                share * 2.0 * math.pi * tension + other_inward, measure, area)
