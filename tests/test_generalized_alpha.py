"""Generalised-α (Chung & Hulbert, J. Appl. Mech. 60:371, 1993) in problems/solve/time_integration.py.

- The one-mode recurrence against closed forms: ρ∞ = 1 is the trapezoidal rule (its phase
  ω_h Δt = 2 atan(ωΔt/2), exact to round-off); the amplification matrix' spectral radius
  tends to ρ∞ as ωΔt → ∞ (the method's defining property; the roots meet at −ρ∞ in a
  Jordan block, so they approach it like (ωΔt)^(−2/3): 1e-4 at ωΔt = 1e6, 1e-3 asserted); the period
  error is second order (the phase error per step is O((ωΔt)³): halving ωΔt divides it by 8 ± 10 %).
- The shell (cantilever-vibration, as tests/test_shell_dynamics.py does for Newmark)
  follows the same recurrence: period within 0.5 % of the single-mode recurrence of the
  same scheme and Δt, and the tip history within 2 % (the same tolerances as Newmark's,
  same reasons: the P2 spatial error in ω₁ is 0.07 %).
"""

from __future__ import annotations

import numpy as np
import pytest

from eyemech.problems import cantilever_vibration
from eyemech.problems.run.context import RunOptions
from eyemech.problems.solve.time_integration import (
    generalized_alpha,
    oscillator_response,
    oscillator_step,
)


def _amplification(scheme, omega_dt: float, damping: float = 0.0) -> np.ndarray:
    return np.column_stack([oscillator_step(scheme, omega_dt, damping, 1.0, e) for e in np.eye(3)])


def test_rho_one_is_the_trapezoidal_rule():
    omega, dt, steps = 2.0, 0.05, 400
    u = oscillator_response(omega, 0.0, dt, steps, generalized_alpha(1.0))
    t = dt * np.arange(steps + 1)
    assert np.allclose(u, np.cos(2.0 * np.arctan(omega * dt / 2.0) / dt * t), atol=1e-10)


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.8])
def test_high_frequency_spectral_radius_is_rho_infinity(rho):
    scheme = generalized_alpha(rho)
    radius = np.max(np.abs(np.linalg.eigvals(_amplification(scheme, 1e6))))
    assert radius == pytest.approx(rho, abs=1e-3)
    # and it never amplifies at any ωΔt (unconditional stability)
    for omega_dt in np.logspace(-2, 4, 25):
        assert np.max(np.abs(np.linalg.eigvals(_amplification(scheme, omega_dt)))) <= 1.0 + 1e-12


def test_period_error_is_second_order():
    scheme = generalized_alpha(0.8)

    def phase_error(omega_dt):
        roots = np.linalg.eigvals(_amplification(scheme, omega_dt))
        principal = roots[np.argmax(np.abs(roots.imag))]
        return abs(np.angle(principal) - omega_dt)

    ratio = phase_error(0.1) / phase_error(0.05)
    # relative period error O((ωΔt)²), i.e. phase error per step O((ωΔt)³): halving ωΔt → ÷ 8
    assert ratio == pytest.approx(8.0, rel=0.1)


def test_the_shell_follows_the_generalized_alpha_recurrence():
    params = cantilever_vibration.Parameters(scheme="generalized-alpha")
    q = cantilever_vibration.run(params, options=RunOptions(fields=False, pictures=False)).quantities
    assert abs(q["period_error"]) < 5e-3
    assert q["history_deviation"] < 2e-2
