"""The scleral buckle as a rigid obstacle: an encircling band on a silicone tire.

Both are rings about the optic axis (z) whose cross-sections in the (ρ, z) half-plane
are rounded rectangles: the tire (``tire_width`` along z, ``tire_height`` radially)
against the sclera, the band (``band_width``, ``band_thickness``) outside it. The
obstacle is their union, so its signed distance is the smaller of the two. The whole
buckle moves radially inward by ``indentation`` (the load parameter of the buckling
step); ``base_radius`` is the radius of the tire's inner face before indentation.
"""

from __future__ import annotations

import dataclasses

import ufl

from eyemech.forms.contact import Ring, RoundedRectangle


@dataclasses.dataclass(frozen=True)
class BuckleShape:
    """Cross-section of band and tire (mm)."""

    band_width: float = 2.5
    band_thickness: float = 0.6
    tire_width: float = 7.0
    tire_height: float = 1.0
    corner_radius: float = 0.3

    @property
    def footprint(self) -> float:
        """Axial width of what can touch the sclera."""
        return max(self.tire_width, self.band_width) if self.tire_height > 0 else self.band_width


def buckle_rings(shape: BuckleShape, axial_position: float, base_radius, indentation):
    """(tire, band) obstacles; ``base_radius`` and ``indentation`` may be Constants."""
    height = max(shape.tire_height, 1e-6)
    tire = RoundedRectangle(center=(base_radius + 0.5 * height, axial_position),
                            width=height, height=shape.tire_width,
                            corner_radius=min(shape.corner_radius, 0.5 * height, 0.5 * shape.tire_width))
    band = RoundedRectangle(center=(base_radius + shape.tire_height + 0.5 * shape.band_thickness,
                                    axial_position),
                            width=shape.band_thickness, height=shape.band_width,
                            corner_radius=min(shape.corner_radius, 0.5 * shape.band_thickness))
    return Ring(indentation=indentation, profile=tire), Ring(indentation=indentation, profile=band)


@dataclasses.dataclass(frozen=True)
class Buckle:
    """Union of the tire and band rings: ``gap(x)`` is the smaller signed distance."""

    shape: BuckleShape
    axial_position: float
    base_radius: object
    indentation: object

    def gap(self, x):
        tire, band = buckle_rings(self.shape, self.axial_position, self.base_radius,
                                  self.indentation)
        return ufl.min_value(tire.gap(x), band.gap(x))
