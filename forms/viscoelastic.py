"""Finite-strain incompressible viscoelasticity of Le Tallec type (cornea paper, seed 003).

Model
-----
Multiplicative split of the viscous branch, ``F = Fe Fv``, with the internal variable
``Cv = Fvᵀ Fv`` (symmetric positive definite, ``det Cv = 1``: the flow is isochoric).
With ``J = det F``, ``C = FᵀF`` and the isochoric ``C̄ = J^(-2/3) C`` the free energy is

    Ψ(C, Cv) = Ψ∞(C̄) + Ψv(C̄, Cv)
    Ψ∞ = μ∞/2 (tr C̄ − 3)                 equilibrium branch (neo-Hooke)
    Ψv = μv/2 (tr(C̄ Cv⁻¹) − 3)           non-equilibrium branch: tr C̄e with Ce = Fv⁻ᵀ C Fv⁻¹,
                                          since tr Ce = tr(C Cv⁻¹) (cyclic trace)

and incompressibility is a pressure multiplier: Π = ∫ Ψ + p (J − 1) dV (p is the
Cauchy pressure correction, as in :mod:`eyemech.forms.hyperelastic`). At fixed Cv,

    S = 2 ∂Ψ/∂C = μ∞ J^(-2/3) (I − ⅓ tr C C⁻¹) + μv J^(-2/3) (Cv⁻¹ − ⅓ tr(C Cv⁻¹) C⁻¹) + p J C⁻¹
    σ = J⁻¹ F S Fᵀ = μ∞ dev b̄ + μv dev(F̄ Cv⁻¹ F̄ᵀ) + p I.

Evolution (the seed's linear-rate law, §2.3.3, written so that det Cv stays 1)
-----------------------------------------------------------------------------
    τ Ċv = C̄ − ⅓ tr(C̄ Cv⁻¹) Cv,                τ = ν/μv the relaxation time.        (E)

It keeps the constraint: d(det Cv)/dt = det Cv tr(Cv⁻¹ Ċv) = det Cv (tr(C̄Cv⁻¹) − tr(C̄Cv⁻¹))/τ = 0;
the term ⅓ tr(C̄ Cv⁻¹) Cv is exactly the multiplier of det Cv = 1. Dissipation: with the
Mandel-like driving force, ``−∂Ψv/∂Cv : Ċv = μv/(2τ) [Cv⁻¹C̄Cv⁻¹ : C̄ − ⅓ (tr C̄Cv⁻¹)²] ≥ 0``
(Cauchy–Schwarz on the symmetric ``A = Cv^(-1/2) C̄ Cv^(-1/2)``: tr(A²) ≥ (tr A)²/3).
At small strain (C̄ = I + 2ε, Cv = I + 2εv, ε deviatoric) (E) is τ ε̇v = ε − εv and the
stress σ = 2μ∞ ε + 2μv (ε − εv) + p I: the standard linear solid of the seed's §2.3.1 in
shear; in uniaxial tension (ε = diag(ε, −ε/2, −ε/2)) σ/ε = 3(μ∞ + μv e^(−t/τ)) after a step.

Time integration
----------------
Backward Euler of (E) with the multiplier treated implicitly as the multiplier of
det Cv_{n+1} = 1 (λ replaces ⅓ tr(C̄ Cv⁻¹), which differs from it by O(Δt)):

    Cv_{n+1} − Cv_n = (Δt/τ) (C̄_{n+1} − λ Cv_{n+1})
    ⇒ (1 + λΔt/τ) Cv_{n+1} = X := Cv_n + (Δt/τ) C̄_{n+1}
    ⇒ Cv_{n+1} = X / det(X)^(1/3)                (det Cv_{n+1} = 1 fixes the scalar).

So Cv_{n+1} is a closed-form UFL expression of the displacement u_{n+1} and of the stored
Cv_n: the internal variable is eliminated from the global system (seed §5) and the
consistent tangent follows from ``ufl.derivative`` of the residual through Cv_{n+1}(u)
(it is unsymmetric, as the seed notes). X is symmetric positive definite for any Δt > 0
(sum of two SPD tensors), so the update is unconditionally well defined: as Δt/τ → ∞ it
gives Cv → C̄ (relaxed), as Δt → 0 it gives Cv_n.

Forward Euler (for the stability study only) uses the converged state of step n:

    Cv_{n+1} = Cv_n + (Δt/τ) (C̄_n − ⅓ tr(C̄_n Cv_n⁻¹) Cv_n);

linearised about equilibrium the error is multiplied by (1 − Δt/τ) per step, so it is
stable only for Δt < 2τ (and loses positive definiteness of Cv soon after).

A point of this module is that (E), the backward and forward Euler updates, and the test's
scalar ODE are the same law: the tests integrate (E) with Cv = diag(a, a^-1/2, a^-1/2).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import ufl

from eyemech.forms.kinematics import deformation_gradient

TimeScheme = Literal["backward-euler", "forward-euler"]
TIME_SCHEMES: tuple[str, ...] = ("backward-euler", "forward-euler")


@dataclasses.dataclass(frozen=True)
class Viscoelastic:
    """μ∞ (equilibrium shear modulus, MPa), μv (viscous-branch shear modulus, MPa),
    τ (relaxation time, s): numbers, or UFL constants (a sweep over them then compiles
    the forms once; numbers are checked here, constants by the scene's parameters)."""

    mu_inf: float | ufl.core.expr.Expr
    mu_v: float | ufl.core.expr.Expr
    tau: float | ufl.core.expr.Expr

    def __post_init__(self) -> None:
        for name in ("mu_inf", "mu_v", "tau"):
            value = getattr(self, name)
            if isinstance(value, (int, float)) and not value > 0:
                raise ValueError(f"{name} must be > 0, got {value!r}")

    @property
    def shear_modulus(self) -> float | ufl.core.expr.Expr:
        """Small-strain shear modulus of the relaxed solid (Cv = C̄: the viscous branch
        carries no stress), μ∞."""
        return self.mu_inf

    @property
    def glassy_shear_modulus(self) -> float | ufl.core.expr.Expr:
        """Small-strain shear modulus of an instantaneous load (Cv = I, the viscous
        branch not yet flowed), μ∞ + μv."""
        return self.mu_inf + self.mu_v

    @property
    def youngs_modulus(self) -> float | ufl.core.expr.Expr:
        """Relaxed Young's modulus of the incompressible solid, 3μ∞."""
        return 3.0 * self.shear_modulus

    @property
    def glassy_youngs_modulus(self) -> float | ufl.core.expr.Expr:
        """Instantaneous Young's modulus of the incompressible solid, 3(μ∞ + μv)."""
        return 3.0 * self.glassy_shear_modulus

    @property
    def retardation_time(self) -> float:
        """Creep time of the small-strain standard linear solid: τ (μ∞ + μv) / μ∞."""
        return self.tau * self.glassy_shear_modulus / self.shear_modulus

    def free_energy(self, F, Cv):
        """Ψ = μ∞/2 (tr C̄ − 3) + μv/2 (tr(C̄ Cv⁻¹) − 3)."""
        Cbar = isochoric_cauchy_green(F)
        return (0.5 * self.mu_inf * (ufl.tr(Cbar) - 3)
                + 0.5 * self.mu_v * (ufl.tr(Cbar * ufl.inv(Cv)) - 3))


def isochoric_cauchy_green(F):
    """C̄ = J^(-2/3) FᵀF."""
    return ufl.det(F) ** (-2.0 / 3.0) * F.T * F


def evolution_rate(Cbar, Cv, tau):
    """Ċv of (E): (C̄ − ⅓ tr(C̄ Cv⁻¹) Cv) / τ."""
    return (Cbar - ufl.tr(Cbar * ufl.inv(Cv)) / 3.0 * Cv) / tau


def backward_euler(Cbar, Cv_n, dt, tau):
    """Cv_{n+1} = X / det(X)^(1/3), X = Cv_n + (Δt/τ) C̄_{n+1}."""
    X = Cv_n + (dt / tau) * Cbar
    return X / ufl.det(X) ** (1.0 / 3.0)


def forward_euler(Cbar_n, Cv_n, dt, tau):
    """Cv_{n+1} = Cv_n + Δt Ċv(C̄_n, Cv_n)."""
    return Cv_n + dt * evolution_rate(Cbar_n, Cv_n, tau)


def first_piola(material: Viscoelastic, F, p, Cv):
    """P = ∂(Ψ + p(J − 1))/∂F at fixed Cv, ``F`` a ``ufl.variable``. Cv may itself depend on
    u: built from another :func:`deformation_gradient` (each call is a new variable) it is
    held fixed in this partial derivative and differentiated only by the tangent."""
    energy = material.free_energy(F, Cv) + p * (ufl.det(F) - 1)
    return ufl.diff(energy, F)


def residual(material: Viscoelastic, u, p, v, q, Cv, dx):
    """Mixed u–p residual ∫ P : Grad v + q (J − 1) dV (no loads; add tractions outside)."""
    F = deformation_gradient(u)
    return (ufl.inner(first_piola(material, F, p, Cv), ufl.grad(v)) * dx
            + q * (ufl.det(F) - 1) * dx)


def cauchy_stress(material: Viscoelastic, F, p, Cv):
    """σ = J⁻¹ P Fᵀ, ``F`` a ``ufl.variable``."""
    return first_piola(material, F, p, Cv) * F.T / ufl.det(F)


def current_internal_variable(scheme: str, material: Viscoelastic, F, Cv_n, Cbar_n, dt):
    """Cv_{n+1} as a UFL expression for the chosen time scheme: a function of F for
    backward Euler, of the stored previous state (Cv_n, C̄_n) for forward Euler."""
    if scheme == "backward-euler":
        return backward_euler(isochoric_cauchy_green(F), Cv_n, dt, material.tau)
    if scheme == "forward-euler":
        return forward_euler(Cbar_n, Cv_n, dt, material.tau)
    raise ValueError(f"unknown time scheme {scheme!r}; choose one of {', '.join(TIME_SCHEMES)}")
