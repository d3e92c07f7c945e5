"""Isochoric hyperelastic laws and the incompressible mixed u–p energy.

The buckling paper's strain energy (seed 002, §2.1) is the polynomial

    W = Σ c_rs (Ī1 − 3)^r (Ī2 − 3)^s

in the reduced invariants of C. Incompressibility is enforced by a pressure
multiplier p:  Π = ∫ W(Ī1, Ī2) + p (J − 1) dV. The paper writes 2λ(J − 1); our
p = 2λ is the (negative) hydrostatic Cauchy pressure correction, so that for the
neo-Hookean law σ = 2 c10 dev(b̄) + p I.
"""

from __future__ import annotations

import dataclasses
from typing import Protocol

import ufl

from eyemech.forms.kinematics import isochoric_invariants


class Material(Protocol):
    """An isochoric law: its energy, and the moduli of its linearisation at F = I (the
    law is incompressible at small strain: Young's modulus is 3μ, the bulk stiffness
    comes from the pressure multiplier or :func:`volumetric_energy`)."""

    def strain_energy(self, F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """Isochoric strain energy density per reference volume."""
        ...

    @property
    def shear_modulus(self) -> float | ufl.core.expr.Expr:
        """Small-strain shear modulus μ (MPa)."""
        ...

    @property
    def youngs_modulus(self) -> float | ufl.core.expr.Expr:
        """Small-strain Young's modulus of the incompressible law, 3μ (MPa)."""
        ...


@dataclasses.dataclass(frozen=True)
class PolynomialIsochoric:
    """W = Σ c_rs (Ī1 − 3)^r (Ī2 − 3)^s; ``coefficients`` maps (r, s) to c_rs in MPa."""

    coefficients: tuple[tuple[int, int, float], ...]

    def __post_init__(self) -> None:
        for r, s, c in self.coefficients:
            if r < 0 or s < 0 or (r, s) == (0, 0):
                raise ValueError(f"polynomial term ({r}, {s}) must have r, s >= 0, not both 0")

    @property
    def shear_modulus(self) -> float | ufl.core.expr.Expr:
        """Small-strain shear modulus μ = 2 (c10 + c01): the terms of higher order vanish
        to second order at F = I (tests/test_moduli.py)."""
        linear = [c for r, s, c in self.coefficients if (r, s) in ((1, 0), (0, 1))]
        return 2.0 * sum(linear[1:], linear[0]) if linear else 0.0

    @property
    def youngs_modulus(self) -> float | ufl.core.expr.Expr:
        """Small-strain Young's modulus of the incompressible law, E = 3μ."""
        return 3.0 * self.shear_modulus

    def strain_energy(self, F):
        I1b, I2b, _ = isochoric_invariants(F)
        return sum(c * (I1b - 3) ** r * (I2b - 3) ** s for r, s, c in self.coefficients)


def NeoHooke(c10: float) -> PolynomialIsochoric:
    """W = c10 (Ī1 − 3): the law of every soft tissue in the buckling paper (Table 1)."""
    return PolynomialIsochoric(((1, 0, c10),))


def MooneyRivlin(c10: float, c01: float) -> PolynomialIsochoric:
    """W = c10 (Ī1 − 3) + c01 (Ī2 − 3)."""
    return PolynomialIsochoric(((1, 0, c10), (0, 1, c01)))


@dataclasses.dataclass(frozen=True)
class Yeoh:
    """W = c10 (Ī1 − 3) + c20 (Ī1 − 3)² + c30 (Ī1 − 3)³ (Yeoh 1993): the paper's polynomial
    with the higher powers of Ī1 that stiffen a collagenous coat with strain. The
    coefficients may be numbers, Constants or cellwise fields (MPa); with c20 = c30 = 0
    it is the neo-Hookean law."""

    c10: float | ufl.core.expr.Expr
    c20: float | ufl.core.expr.Expr = 0.0
    c30: float | ufl.core.expr.Expr = 0.0

    @property
    def shear_modulus(self) -> float | ufl.core.expr.Expr:
        """Small-strain shear modulus μ = 2 c10 (c20 and c30 stiffen at finite strain only)."""
        return 2.0 * self.c10

    @property
    def youngs_modulus(self) -> float | ufl.core.expr.Expr:
        """Small-strain Young's modulus of the incompressible law, E = 3μ = 6 c10."""
        return 3.0 * self.shear_modulus

    def strain_energy(self, F):
        x = isochoric_invariants(F)[0] - 3
        return self.c10 * x + self.c20 * x**2 + self.c30 * x**3


@dataclasses.dataclass(frozen=True)
class TangentialFibres:
    """A collagenous coat whose stiffening is carried by tension-only fibres in its own
    surface: a neo-Hookean matrix and fibre families along ``directions`` (unit vectors in
    the reference configuration, tangent to the coat: :func:`meridian_and_latitude`),

        W = c10 (Ī1 − 3) + c4 Σ_a max(Ī4,a − 1, 0)⁴,    Ī4,a = a·C̄a.

    The switch is max(·, 0), not a smooth ramp: a shortened fibre carries exactly nothing
    (collagen buckles), so under in-plane compression -- the sclera's hoop strain under a
    band -- the coat is as soft as its matrix, where Yeoh's c20 (Ī1 − 3)² stiffens it
    (Ī1 − 3 ≥ 0 for every isochoric strain). The fourth power makes W three times
    differentiable at the fibre's rest length, so Newton's tangent is continuous across the
    switch and a smooth ramp would only leak stiffness into compression. In equibiaxial
    stretch ε of the coat (inflation) Ī1 − 3 ≈ 12 ε² and each family's Ī4 − 1 ≈ 2 ε, so two
    families with c4 = 4.5 c20 store Yeoh's energy to leading order: the same
    pressure–volume curve (tests/test_eye_calibration.py, tests/test_living_eye.py). The
    moduli may be numbers, Constants or cellwise fields (MPa)."""

    c10: float | ufl.core.expr.Expr
    c4: float | ufl.core.expr.Expr
    directions: tuple = ()

    @property
    def shear_modulus(self) -> float | ufl.core.expr.Expr:
        """Small-strain shear modulus μ = 2 c10 (the quartic fibres stiffen at finite
        stretch only)."""
        return 2.0 * self.c10

    @property
    def youngs_modulus(self) -> float | ufl.core.expr.Expr:
        """Small-strain Young's modulus of the incompressible law, E = 3μ = 6 c10."""
        return 3.0 * self.shear_modulus

    def strain_energy(self, F):
        I1b, _, J = isochoric_invariants(F)
        Cb = J ** (-2.0 / 3.0) * F.T * F
        fibres = sum((ufl.max_value(ufl.dot(a, Cb * a) - 1.0, 0.0) ** 4 for a in self.directions), 0.0)
        return self.c10 * (I1b - 3) + self.c4 * fibres


def meridian_and_latitude(X) -> tuple:
    """Unit vectors along the meridian and the circle of latitude about the z axis (the
    eye's optic axis) at the reference point ``X``: the fibre directions of a coat of
    revolution. Undefined on the axis itself, where no quadrature point lies."""
    rho = ufl.sqrt(X[0] ** 2 + X[1] ** 2)
    around = ufl.as_vector((-X[1] / rho, X[0] / rho, 0.0))
    along = ufl.cross(around, X / ufl.sqrt(ufl.dot(X, X)))
    return (along, around)


def incompressible_energy_density(material: Material, F, p):
    """Mixed u–p energy density W(F) + p (J − 1); its stationary point is the
    incompressible equilibrium and p the Lagrange multiplier."""
    return material.strain_energy(F) + p * (ufl.det(F) - 1)


def cauchy_stress(material: Material, F, p=0.0):
    """σ = J⁻¹ P Fᵀ of the mixed energy, P = ∂W/∂F + p J F⁻ᵀ; ``F`` a ``ufl.variable``
    (:func:`eyemech.forms.kinematics.deformation_gradient`). With p = 0 it is the
    isochoric part: its deviator is the whole deviatoric stress."""
    P = ufl.diff(incompressible_energy_density(material, F, p), F)
    return P * F.T / ufl.det(F)


def von_mises(sigma):
    """√(3/2 dev σ : dev σ): the equivalent stress; a pressure does not change it."""
    deviator = ufl.dev(sigma)
    return ufl.sqrt(1.5 * ufl.inner(deviator, deviator))


def volumetric_energy(J, bulk_modulus, kind: str = "log"):
    """Volumetric (bulk) energy U(J) of the nearly incompressible variant.

    ``"quadratic"``: U = K/2 (J − 1)²;  ``"log"``: U = K/4 (J² − 1 − 2 ln J)
    (Simo–Taylor; U → ∞ as J → 0 and as J → ∞). Both give p = U'(J) ≈ K (J − 1)
    for small volume change, K the small-strain bulk modulus.
    """
    if kind == "quadratic":
        return 0.5 * bulk_modulus * (J - 1) ** 2
    if kind == "log":
        return 0.25 * bulk_modulus * (J**2 - 1 - 2 * ufl.ln(J))
    raise ValueError(f"unknown volumetric energy {kind!r}: quadratic | log")


def nearly_incompressible_energy_density(material: Material, F, bulk_modulus, kind: str = "log"):
    """Displacement-only energy density W(F) + U(J): the isochoric law (invariants
    of C̄ = J^(-2/3) C) plus a bulk penalty. With K ≫ μ and low-order elements it
    locks volumetrically (the point of the ``P1`` family)."""
    return material.strain_energy(F) + volumetric_energy(ufl.det(F), bulk_modulus, kind)


def mean_dilatation_pressure(mean_jacobian, bulk_modulus):
    """p̄ = U'(J̄) = κ (J̄ − 1), U = κ/2 (J̄ − 1)²: the pressure of the mean-dilatation
    method (Nagtegaal, Parks & Rice 1974; Simo, Taylor & Pister 1985), with J̄ the cell
    mean of J, (1/|K|) ∫_K J dX, a DG0 field. It is Q1P0's DG0 multiplier of the
    perturbed constraint ∫ (J − 1 − p/κ) q dX = 0, eliminated cell by cell; κ → ∞ gives
    the incompressible mixed element back, at a distance O(μ/κ)."""
    return bulk_modulus * (mean_jacobian - 1)


def mean_dilatation_energy_density(material: Material, F, mean_jacobian, bulk_modulus):
    """W(F) + U(J̄), U = κ/2 (J̄ − 1)²: integrated over a cell, ∫_K W dX + |K| U(J̄_K),
    the stored energy of the condensed Q1P0 element. J̄ is a DG0 coefficient computed from
    u outside UFL, so UFL cannot differentiate through it: the residual is the variation
    with the pressure p̄ = U'(J̄) held fixed, :func:`mean_dilatation_work_density`."""
    return material.strain_energy(F) + volumetric_energy(mean_jacobian, bulk_modulus, "quadratic")


def mean_dilatation_work_density(material: Material, F, mean_pressure):
    """W(F) + p̄ J: its variation in u with p̄ held fixed is the condensed residual
    ∫ (∂W/∂F + p̄ J F⁻ᵀ) : ∇v dX, the gradient of the energy of
    :func:`mean_dilatation_energy_density` (Σ_K |K| U'(J̄_K) δJ̄_K = ∫ p̄ δJ dX). Its second
    variation is the tangent without the cells' rank-one volumetric part
    (κ/|K|) b_K b_Kᵀ, b_K = ∫_K δJ dX, which is added element by element."""
    return material.strain_energy(F) + mean_pressure * ufl.det(F)
