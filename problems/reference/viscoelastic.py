"""Reference solutions for the viscoelastic bar scenes (used by the scenes' pictures
and by the stability study; the tests derive and integrate their own copy).

Homogeneous incompressible uniaxial tension: F = diag(λ, λ^-1/2, λ^-1/2), C̄ = C, and by
symmetry Cv = diag(a, a^-1/2, a^-1/2) (det Cv = 1). Then tr(C̄ Cv⁻¹) = λ²/a + 2 a^½/λ and
the 11-component of τ Ċv = C̄ − ⅓ tr(C̄ Cv⁻¹) Cv is

    τ ȧ = λ² − ⅓ (λ²/a + 2 a^½/λ) a = ⅔ (λ² − a^(3/2)/λ),

(the 22-component gives the same equation). With traction-free lateral faces σ22 = 0
fixes p, and σ = μ∞ dev b̄ + μv dev(F̄Cv⁻¹F̄ᵀ) + pI leaves

    σ11 = μ∞ (λ² − 1/λ) + μv (λ²/a − a^½/λ).
"""

from __future__ import annotations

from typing import Callable

import numpy as np


def axial_stress(stretch: float, a: float, mu_inf: float, mu_v: float) -> float:
    return mu_inf * (stretch**2 - 1 / stretch) + mu_v * (stretch**2 / a - np.sqrt(a) / stretch)


def relaxation(times, stretch: Callable[[float], float], mu_inf: float, mu_v: float, tau: float,
               breaks: tuple[float, ...] = (), rtol: float = 1e-11) -> np.ndarray:
    """σ11 at ``times`` for a prescribed stretch history λ(t), a(0) = 1; the ODE is
    integrated piecewise between ``breaks`` (kinks of λ(t))."""
    from scipy.integrate import solve_ivp  # here, not at import: scipy costs 0.6 s of start-up

    times = np.asarray(times, dtype=float)
    rate = lambda t, y: [2.0 / 3.0 * (stretch(t) ** 2 - y[0] ** 1.5 / stretch(t)) / tau]
    edges = sorted({0.0, float(times.max()), *[b for b in breaks if 0 < b < times.max()]})
    a0, pieces = 1.0, []
    for start, end in zip(edges[:-1], edges[1:]):
        sol = solve_ivp(rate, (start, end), [a0], method="DOP853", rtol=rtol, atol=1e-14,
                        dense_output=True)
        pieces.append((start, end, sol.sol))
        a0 = sol.y[0, -1]
    out = np.empty_like(times)
    for i, t in enumerate(times):
        start, end, dense = next(p for p in pieces if p[0] <= t <= p[1])
        out[i] = axial_stress(stretch(t), dense(t)[0], mu_inf, mu_v)
    return out


def sls_creep_strain(times, stress: float, mu_inf: float, mu_v: float, tau: float) -> np.ndarray:
    """Small strain, step stress (seed §2.3.1 in uniaxial form, E = 3μ):
    ε(t) = σ/(3μ∞) − (σ/(3μ∞) − σ/(3(μ∞+μv))) e^(−t/τc), τc = τ (μ∞ + μv)/μ∞."""
    t = np.asarray(times, dtype=float)
    glassy, relaxed = stress / (3 * (mu_inf + mu_v)), stress / (3 * mu_inf)
    retardation = tau * (mu_inf + mu_v) / mu_inf
    return relaxed - (relaxed - glassy) * np.exp(-t / retardation)
