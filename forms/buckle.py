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


def smoothed_penalty_energy(obstacle, u, penalty, smoothing: float, measure):
    """Π_c = ∫ φ(g(X + u)) dA with the penalty's kink rounded off over |g| < ε:

        φ = ½ α g² + α ε²/6        g ≤ −ε
        φ = α (ε − g)³ / (12 ε)    −ε < g < ε
        φ = 0                      g ≥ ε

    so p = −φ' is α⟨−g⟩ outside the band and joins it with matching slope
    (the pressure law of :func:`eyemech.problems.contact.node_to_surface.penalty_pressure`).
    ε = 0 is the plain ½ α ⟨−g⟩². A C² energy keeps Newton from cycling on
    quadrature points that sit at g ≈ 0 (measured on the buckle: a 2-cycle at
    residual 1e-4 without it)."""
    from eyemech.forms.contact import deformed_position, penalty_energy

    if smoothing <= 0:
        return penalty_energy(obstacle, u, penalty, measure)
    g = obstacle.gap(deformed_position(u))
    eps = smoothing
    density = ufl.conditional(
        ufl.ge(g, eps), 0.0,
        ufl.conditional(ufl.le(g, -eps), 0.5 * penalty * g**2 + penalty * eps**2 / 6,
                        penalty * (eps - g) ** 3 / (12 * eps)))
    return density * measure
