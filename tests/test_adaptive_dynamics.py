"""Error-controlled time steps for the implicit dynamics (issue 27, item 2):
:func:`local_error_estimate` / :meth:`ImplicitDynamics.local_error` and
:func:`march_dynamics`, against the exact damped oscillator

    ü + c u̇ + ω² u = 0,  u(0) = 1, u̇(0) = 0:
    u(t) = A e^{r₁t} + B e^{r₂t},  r = −c/2 ± √(c²/4 − ω²).

The estimates are the leading local error terms; at ω Δt = 0.05 they match the exact one-step
errors over a period to 0.6 % (backward Euler) and 0.01 % (Newmark), in root mean square. The march runs on
a finite-element system whose every mode is this oscillator (K = ω² M), so its result is the exact u(t) up
to the time discretisation.
"""

from __future__ import annotations

import cmath
import math

import dolfinx
import dolfinx.fem
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from eyemech.problems.solve.adaptive_dynamics import TimeErrorControl, march_dynamics, march_steps
from eyemech.problems.solve.driver import NewtonOptions, NonlinearSolver
from eyemech.problems.solve.time_integration import (
    ImplicitDynamics,
    local_error_estimate,
    oscillator_step,
    scheme,
)

OMEGA, DAMPING = 2.0 * math.pi, 1.0  # 1 Hz, ζ = 0.08: lightly damped
OVERDAMPED = 20.0  # ζ = 1.6


def exact(t: float, omega: float = OMEGA, c: float = DAMPING) -> np.ndarray:
    """(u, v, a) of the damped oscillator at t: A e^{r₁t} + B e^{r₂t} with the roots
    r = −c/2 ± √(c²/4 − ω²) (complex when underdamped), A + B = 1, r₁A + r₂B = 0."""
    root = cmath.sqrt(0.25 * c * c - omega * omega)
    r1, r2 = -0.5 * c + root, -0.5 * c - root
    A, B = r2 / (r2 - r1), -r1 / (r2 - r1)
    e1, e2 = cmath.exp(r1 * t), cmath.exp(r2 * t)
    u, v = (A * e1 + B * e2).real, (A * r1 * e1 + B * r2 * e2).real
    return np.array([u, v, -c * v - omega ** 2 * u])


@pytest.mark.parametrize("name", ["backward-euler", "newmark"])
def test_local_estimate_is_the_one_step_error(name):
    """From the exact state at 40 times over a period, one step of ω Δt = 0.05: the
    estimates against the exact one-step errors |u_h − u(t + Δt)|, as root mean squares
    over the period (measured ratio 1.0054 for backward Euler, 1.0001 for Newmark; single
    steps differ more near the zeros of the leading term)."""
    s, dt = scheme(name), 0.05 / OMEGA
    estimates, errors = [], []
    for t in np.linspace(0.0, 1.0, 41)[:-1]:
        start = exact(t)
        new = oscillator_step(s, OMEGA, DAMPING, dt, start)
        errors.append(new[0] - exact(t + dt)[0])
        estimates.append(local_error_estimate(s, dt, start[2], new[2]))
    assert np.linalg.norm(estimates) / np.linalg.norm(errors) == pytest.approx(1.0, abs=0.02)


def test_schemes_without_an_estimate_are_refused():
    with pytest.raises(ValueError, match="newmark-damped"):
        local_error_estimate(scheme("newmark-damped"), 0.01, 0.0, 1.0)


def _oscillators(scheme_name: str, damping: float):
    """A P1 field on an interval with K = ω² M: every mode is the oscillator above."""
    mesh = dolfinx.mesh.create_unit_interval(MPI.COMM_WORLD, 4)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    u.x.array[:] = 1.0
    dynamics = ImplicitDynamics(u, ufl.TrialFunction(V) * v * ufl.dx, scheme_name=scheme_name,
                                damping=damping)
    static = OMEGA ** 2 * u * v * ufl.dx
    # a linear system: one Newton step, its residual at round-off of α_u M ~ 1/Δt²
    solver = NonlinearSolver(static, u, [], options=NewtonOptions(rtol=1e-7, atol=1e-12),
                             residual_hooks=[dynamics.residual_hook],
                             jacobian_hooks=[dynamics.jacobian_hook])
    if scheme_name != "backward-euler":
        dynamics.initial_acceleration(static)
    return u, dynamics, solver


# backward Euler on the lens's regime, strongly damped (c = 20/s: ζ = 1.6, as the lens in
# viscoelastic fluid); Newmark on the lightly damped oscillator (ζ = 0.08)
CASES = [("backward-euler", OVERDAMPED, 1e-2), ("backward-euler", OVERDAMPED, 1e-3),
         ("newmark", DAMPING, 1e-2), ("newmark", DAMPING, 1e-3)]


@pytest.mark.parametrize("name, damping, tolerance", CASES)
def test_march_meets_its_tolerance(name, damping, tolerance):
    """Two seconds with error-controlled steps: the reported estimate (the sum of the local
    ones) stays below the tolerance, and so does the true error at the end (measured:
    backward Euler 1e-2: 1.7e-3 true, 8.3e-3 estimated, 370 steps; 1e-3: 2.0e-4, 8.9e-4,
    3,639 steps; Newmark 1e-2: 9.6e-4, 7.0e-3, 93 steps; 1e-3: 1.4e-4, 7.6e-4, 279 steps).
    The steps land on the stop at 0.5 s. Not a bound for backward Euler on a lightly
    damped oscillation: its numerical damping accumulates into an amplitude error the
    local estimates do not sum to (c = 1/s, tolerance 2e-2: 3.0e-2 true)."""
    u, dynamics, solver = _oscillators(name, damping)
    times = []
    control = TimeErrorControl(tolerance=tolerance, time_scale=2.0, first_dt=0.01)
    summary = march_dynamics(solver, dynamics, lambda t, dt: None, 2.0, control,
                             lambda step, t, dt, iterations, error: times.append(t), stops=(0.5,))
    true = float(np.max(np.abs(u.x.array - exact(2.0, c=damping)[0])))
    assert summary.time_error_estimate <= tolerance
    assert true <= tolerance
    assert times[-1] == pytest.approx(2.0, abs=1e-12) and 0.5 in times
    assert summary.time_steps == len(times) and summary.cuts == 0


class _OscillatorStepper:
    """The exact-solution oscillator as a ``march_steps`` Stepper (its own step loop)."""

    def __init__(self, name: str, damping: float):
        self.scheme, self.damping = scheme(name), damping
        self.order = 1 if self.scheme.beta is None else 2
        self.state = exact(0.0, c=damping)
        self.trial = self.state

    def save(self):
        return self.state.copy()

    def restore(self, state):
        self.state = state.copy()

    def solve_step(self, dt: float) -> int:
        self.dt = dt
        self.trial = oscillator_step(self.scheme, OMEGA, self.damping, dt, self.state)
        return 1

    def local_error(self) -> float:
        return local_error_estimate(self.scheme, self.dt, self.state[2], self.trial[2])

    def advance(self) -> None:
        self.state = self.trial


@pytest.mark.parametrize("name, damping, tolerance", CASES)
def test_march_steps_meets_its_tolerance(name, damping, tolerance):
    """``march_steps`` (the controller on a model's own step loop, as the lens release uses
    it) on the exact oscillator: the estimate and the true error at the end stay below the
    tolerance, as ``march_dynamics``' do."""
    stepper = _OscillatorStepper(name, damping)
    control = TimeErrorControl(tolerance=tolerance, time_scale=2.0, first_dt=0.01)
    summary = march_steps(stepper, 2.0, control)
    assert summary.time_error_estimate <= tolerance
    assert abs(stepper.state[0] - exact(2.0, c=damping)[0]) <= tolerance


def test_steps_at_the_floor_are_accepted_and_the_step_never_goes_below_it():
    control = TimeErrorControl(tolerance=1e-3, time_scale=1.0, first_dt=1e-2, min_dt=1e-4)
    accepted, next_dt = control.judge(1e-4, 1.0, 1)  # far over the allowed 1e-7
    assert accepted and next_dt == pytest.approx(1e-4)
    accepted, next_dt = control.judge(1e-2, 1.0, 1)
    assert not accepted and next_dt == pytest.approx(2e-3)  # shrink limit 0.2
