r"""Inertia of a shell (Kirchhoff–Love: translational inertia of the mid-surface only).

With mass density ρ (tonne/mm³) and thickness h (mm, a number or a field) the
kinetic energy per reference area and the consistent mass form are

    T = ½ ∫ ρ h  u̇·u̇ dA,         m(a, v) = ∫ ρ h  a·v dA,

so the semi-discrete equations are  M ü + C u̇ + f_int(u) = f_ext  with M the matrix of
m. Rotary inertia (ρ h³/12 |ṅ|²) is left out, as in the Euler–Bernoulli beam and the
Kirchhoff plate: it is O((h/L)²) smaller. Damping standing in for the surrounding
fluid is mass proportional, C = c M (c in 1/s): a drag on the absolute velocity.
"""

from __future__ import annotations

import ufl


def kinetic_energy(velocity, density, thickness, dx: ufl.Measure):
    """T = ½ ∫ ρ h u̇·u̇ dA."""
    return 0.5 * density * thickness * ufl.dot(velocity, velocity) * dx


def mass_form(trial, test, density, thickness, dx: ufl.Measure):
    """m(a, v) = ∫ ρ h a·v dA (the second variation of T in the velocity)."""
    return density * thickness * ufl.inner(trial, test) * dx
