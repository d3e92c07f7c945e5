"""Compressible isotropic hyperelasticity for bodies that are not nearly
incompressible (contact benchmarks, stiff supports)."""

from __future__ import annotations

import dataclasses

import ufl


def lame(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """(μ, λ) from E and ν (ν < 0.5)."""
    mu = youngs_modulus / (2.0 * (1.0 + poisson_ratio))
    lmbda = youngs_modulus * poisson_ratio / ((1.0 + poisson_ratio) * (1.0 - 2.0 * poisson_ratio))
    return mu, lmbda


@dataclasses.dataclass(frozen=True)
class CompressibleNeoHooke:
    """W = μ/2 (I1 − 3 − 2 ln J) + λ/2 (ln J)², with I1 = tr(FᵀF) and (μ, λ) the Lamé
    constants of (E, ν): linear elasticity with (E, ν) at small strain, well behaved under
    large compression."""

    youngs_modulus: float
    poisson_ratio: float

    @property
    def shear_modulus(self) -> float:
        """Small-strain shear modulus μ = E / (2 (1 + ν))."""
        return lame(self.youngs_modulus, self.poisson_ratio)[0]

    @property
    def bulk_modulus(self) -> float:
        """Small-strain bulk modulus K = λ + 2μ/3."""
        mu, lmbda = lame(self.youngs_modulus, self.poisson_ratio)
        return lmbda + 2.0 * mu / 3.0

    def strain_energy(self, F):
        mu, lmbda = lame(self.youngs_modulus, self.poisson_ratio)
        J = ufl.det(F)
        return 0.5 * mu * (ufl.tr(F.T * F) - 3 - 2 * ufl.ln(J)) + 0.5 * lmbda * ufl.ln(J) ** 2


def compressible_neo_hooke(F, youngs_modulus: float, poisson_ratio: float):
    """The energy density of :class:`CompressibleNeoHooke` (E, ν) at ``F``."""
    return CompressibleNeoHooke(youngs_modulus, poisson_ratio).strain_energy(F)


def spring_support_energy(u, stiffness, measure):
    """Elastic (Winkler) support of a boundary: Π_s = ∫ ½ k |u|² dA over ``measure``
    (reference area), k in MPa/mm. Its variation ∫ k u·δu dA is a traction −k u: the
    boundary is held by distributed springs in all three directions. A stand-in for
    the tissue beyond the boundary (the sclera at the corneal limbus): k ≈ E_s / ℓ for
    a support of modulus E_s acting over a length ℓ; k → ∞ is the clamp."""
    return 0.5 * stiffness * ufl.dot(u, u) * measure
