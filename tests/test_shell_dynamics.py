"""Shell mass + implicit time integration (forms/dynamics.py, problems/solve/time_integration.py).

Reference: free vibration of a clamped strip (ν = 0, so a beam) released from its first
Euler–Bernoulli mode, ω₁ = (1.8751)² √(EI/(ρA))/L² (Blevins, *Formulas for Natural
Frequency and Mode Shape*, 1979, Table 8-1). The shell's tip history is compared with the
single-mode oscillator integrated by the same scheme and Δt (so the time error cancels and
what is left is the spatial error of the shell and its consistent mass), and its period
with the continuous one.

Tolerances: the spatial error of P2 with 12 divisions in ω is O(h²) and measured at
-0.07 %; 0.5 % leaves room for another CPU's round-off and none for a wrong mass
(a factor ρh error would show as a √ of it). The history deviation (max |w - w_ref| / A
over two periods) was 0.7 % (trapezoidal, the higher modes the finite-element mode
shape excites are undamped) and 0.13 % (backward Euler with c = 0.2 ω₁); 2 % and 1 %.
"""

from __future__ import annotations

import numpy as np
import pytest

from eyemech.problems import cantilever_vibration
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError
from eyemech.problems.solve.time_integration import oscillator_response

QUIET = RunOptions(fields=False, pictures=False)


def _run(**overrides):
    params = cantilever_vibration.Parameters(**overrides)
    return cantilever_vibration.run(params, options=QUIET).quantities


def test_trapezoidal_period_of_the_first_mode():
    q = _run(scheme="newmark")
    assert abs(q["period_error"]) < 5e-3
    assert q["period"] == pytest.approx(q["period_exact"], rel=5e-3)
    assert q["history_deviation"] < 2e-2
    assert q["time_error_estimate"] is None  # not for the trapezoidal rule (module doc)


def test_trapezoidal_rule_stays_bounded_with_small_steps():
    """The trapezoidal rule is unconditionally stable only on a positive definite
    stiffness: an indefinite one (a clamped edge's interior penalty too weak for its
    stretched cells: −3.7e8 s⁻² for ω² at α = 1 with the cell diameter as h) grows like
    |1 + λΔt/2| / |1 − λΔt/2| per step, which at 80 steps per period blew the tip up to
    1.6e9 × the amplitude. With the normal height the lowest ω² is ω₁² (11,201 against
    11,195 s⁻²)."""
    q = _run(scheme="newmark", steps_per_period=80)
    assert abs(q["period_error"]) < 5e-3  # measured −1e-3 order, as at 40 steps
    assert q["history_deviation"] < 2e-2


def test_backward_euler_with_damping_follows_the_damped_mode():
    q = _run(scheme="backward-euler", damping=0.2)
    assert abs(q["period_error"]) < 5e-3
    assert q["history_deviation"] < 1e-2
    # and it did decay: backward Euler + c = 0.2 ω₁ leaves ~10 % after two periods
    assert abs(q["final_tip_w"]) < 0.2 * 0.01 * 6.0
    # the reported time error: the sum of the local estimates (0.249 of the amplitude)
    # against the discrete single mode's deviation from the exact one (0.207): an upper
    # estimate within 1.5×
    assert q["time_error_single_mode"] <= q["time_error_estimate"] <= 1.5 * q["time_error_single_mode"]


def test_oscillator_recurrence_matches_closed_forms():
    omega, dt, steps = 2.0, 0.05, 400
    # trapezoidal rule: |amplification| = 1 and phase ω_h Δt = 2 atan(ω Δt / 2)
    u = oscillator_response(omega, 0.0, dt, steps, "newmark")
    t = dt * np.arange(steps + 1)
    assert np.allclose(u, np.cos(2.0 * np.arctan(omega * dt / 2.0) / dt * t), atol=1e-10)
    # backward Euler on a first-order-reduced oscillator: eigenvalues of the step matrix
    u = oscillator_response(omega, 0.0, dt, steps, "backward-euler")
    step = np.linalg.inv(np.array([[1.0, -dt], [omega ** 2 * dt, 1.0]]))
    state, expected = np.array([1.0, 0.0]), [1.0]
    for _ in range(steps):
        state = step @ state
        expected.append(state[0])
    assert np.allclose(u, expected, atol=1e-12)


def test_bad_scheme_and_overdamping_are_refused():
    with pytest.raises(ParameterError, match="scheme"):
        cantilever_vibration.Parameters(scheme="euler").validate()
    with pytest.raises(ParameterError, match="damping"):
        cantilever_vibration.Parameters(damping=3.0).validate()
