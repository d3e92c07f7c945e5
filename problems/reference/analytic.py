"""Exact solutions used by benchmarks, tests and convergence studies.

Thick incompressible neo-Hookean sphere under internal pressure
---------------------------------------------------------------
A sphere A ≤ R ≤ B deforms radially to a ≤ r ≤ b. Incompressibility fixes
r³ − R³ = a³ − A³, so the hoop stretch λ(r) = r / R(r) with R³ = r³ − a³ + A³ and the
radial stretch is λ⁻². For W = c10 (I1 − 3) (μ = 2 c10) the principal Cauchy stress
difference is σθθ − σrr = μ (λ² − λ⁻⁴). Radial equilibrium dσrr/dr = 2(σθθ − σrr)/r,
with σrr(a) = −p and σrr(b) = −p_out, integrates to

    p − p_out = ∫_a^b 2μ/r (λ(r)² − λ(r)⁻⁴) dr.

Given p we solve this scalar equation for a (monotone up to the limit point).
"""

from __future__ import annotations

import numpy as np


def _stretch(r, a, A):
    return r / np.cbrt(r**3 - a**3 + A**3)


# numpy only (scipy's import costs a scene 0.6 s of start-up): composite Gauss–Legendre
# quadrature, bisection and golden-section search, each to round-off for these smooth
# scalar functions
_GAUSS_POINTS, _GAUSS_WEIGHTS = np.polynomial.legendre.leggauss(40)


def _integral(f, a: float, b: float, panels: int = 8) -> float:
    edges = np.linspace(a, b, panels + 1)
    mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * np.diff(edges)
    r = (mid[:, None] + half[:, None] * _GAUSS_POINTS[None, :]).ravel()
    return float(np.sum(f(r).reshape(panels, -1) * _GAUSS_WEIGHTS[None, :] * half[:, None]))


def _root(f, lower: float, upper: float) -> float:
    """x in [lower, upper] with f(x) = 0, f changing sign there (bisection to round-off)."""
    f_lower = f(lower)
    if f_lower * f(upper) > 0:
        raise ValueError("the root is not bracketed")
    for _ in range(200):
        middle = 0.5 * (lower + upper)
        if middle in (lower, upper):
            break
        f_middle = f(middle)
        if f_middle == 0:
            return middle
        if (f_middle > 0) == (f_lower > 0):
            lower, f_lower = middle, f_middle
        else:
            upper = middle
    return 0.5 * (lower + upper)


def _maximum(f, lower: float, upper: float, tolerance: float = 1e-10) -> float:
    """Argument of the maximum of a unimodal f on [lower, upper] (golden-section search)."""
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = upper - ratio * (upper - lower), lower + ratio * (upper - lower)
    f1, f2 = f(x1), f(x2)
    while upper - lower > tolerance:
        if f1 < f2:
            lower, x1, f1 = x1, x2, f2
            x2 = lower + ratio * (upper - lower)
            f2 = f(x2)
        else:
            upper, x2, f2 = x2, x1, f1
            x1 = upper - ratio * (upper - lower)
            f1 = f(x1)
    return 0.5 * (lower + upper)


def sphere_pressure(a: float, A: float, B: float, c10: float) -> float:
    """Pressure difference p − p_out that holds the inner radius at ``a``."""
    mu = 2.0 * c10
    b = np.cbrt(a**3 + B**3 - A**3)
    integrand = lambda r: 2.0 * mu / r * (_stretch(r, a, A) ** 2 - _stretch(r, a, A) ** -4)
    return _integral(integrand, a, b)


def sphere_limit_point(A: float, B: float, c10: float) -> tuple[float, float]:
    """(a, p) at the pressure maximum: beyond p_max no radial equilibrium exists."""
    a_max = _maximum(lambda a: sphere_pressure(a, A, B, c10), A * 1.01, A * 5.0)
    return float(a_max), float(sphere_pressure(a_max, A, B, c10))


def sphere_inner_radius(pressure: float, A: float, B: float, c10: float) -> float:
    """Deformed inner radius a for a pressure difference below the limit point."""
    if pressure == 0:
        return A
    a_max, p_max = sphere_limit_point(A, B, c10)
    if pressure >= p_max:
        raise ValueError(f"pressure {pressure} is beyond the limit point {p_max:.6g}")
    lower = A * (1 - 0.5) if pressure < 0 else A
    upper = a_max if pressure > 0 else A
    return float(_root(lambda a: sphere_pressure(a, A, B, c10) - pressure, lower, upper))


def sphere_outer_radius(a: float, A: float, B: float) -> float:
    return float(np.cbrt(a**3 + B**3 - A**3))


# Thick sphere around a liquid, squeezed by an external pressure
# ----------------------------------------------------------------
# The same radial deformation holds (incompressible wall, a ≤ r ≤ b), now with
# σrr(a) = −P (the liquid) and σrr(b) = −p_ext, so the wall relation above reads
#
#     P − p_ext = f(a),   f(a) = ∫_a^b 2μ/r (λ² − λ⁻⁴) dr   (sphere_pressure).
#
# The liquid fills the cavity: V/V_ini = (a/A)³ with V_ini the stress-free cavity,
# and its law (seed 002, eq. 5) closes the problem,
#
#     P = P_ini − K ((a/A)³ − 1).
#
# Eliminating P leaves one scalar equation for a,
#
#     h(a) = f(a) + p_ext − P_ini + K ((a/A)³ − 1) = 0,
#
# with h increasing in a below the limit point of f (f' > 0 there, K > 0), so the
# root is unique and bracketed by [A/2, a_max]; then P follows from the law.

def liquid_sphere(A: float, B: float, c10: float, bulk_modulus: float, initial_pressure: float,
                  external_pressure: float) -> tuple[float, float]:
    """(a, P): deformed inner radius and cavity pressure of the liquid-filled sphere."""
    def h(a):
        return (sphere_pressure(a, A, B, c10) + external_pressure - initial_pressure
                + bulk_modulus * ((a / A) ** 3 - 1.0))

    a_max, _ = sphere_limit_point(A, B, c10)
    if h(a_max) < 0:
        raise ValueError("no equilibrium below the limit point (the liquid pushes too hard)")
    a = float(_root(h, 0.5 * A, a_max))
    pressure = initial_pressure - bulk_modulus * ((a / A) ** 3 - 1.0)
    return a, float(pressure)
