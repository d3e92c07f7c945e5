r"""Time steps of :class:`~eyemech.problems.solve.time_integration.ImplicitDynamics` chosen
from the local error estimate against a stated tolerance.

Each step is solved with the step Δt proposed, then judged by
:meth:`ImplicitDynamics.local_error` (the embedded backward-Euler/trapezoidal difference, or
Zienkiewicz–Xie for Newmark): a step whose estimate e exceeds the allowed

    e_allowed = tolerance · Δt / time_scale

is repeated shorter, an accepted one sets the next Δt = Δt · clip(safety · (e_allowed/e)^{1/p},
shrink_limit, grow_limit) (p the scheme's order: e ∝ Δt^{p+1}, e_allowed ∝ Δt). Error per
unit step keeps the sum of the local errors, reported as ``time_error_estimate``, below
``tolerance`` over ``time_scale`` (the run's length). A Newton failure halves the step (at
most 6 times in a row): the step controller (:mod:`~eyemech.problems.solve.stepping`), told
each attempt's outcome. Verified on the damped oscillator, whose exact solution is known:
tests/test_adaptive_dynamics.py.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Protocol

import numpy as np

from eyemech.problems.solve.driver import NonlinearSolver, SolveFailure
from eyemech.problems.solve.stepping import StepController
from eyemech.problems.solve.time_integration import ImplicitDynamics

MAX_CUTS = 6  # Newton failures in a row before the march gives up


@dataclasses.dataclass(frozen=True)
class TimeErrorControl:
    """The tolerance of an adaptive march and how fast its steps may change."""

    tolerance: float        # allowed displacement error (the model's length unit) over time_scale
    time_scale: float       # the interval the tolerance is spread over (usually t_end)
    first_dt: float
    max_dt: float = np.inf
    # steps this short are accepted whatever their estimate (which still joins the sum): a
    # start from rest against a large force (the released lens: a₀ ~ 1e8 mm/s²) would
    # otherwise demand Δt ≲ 2 tolerance/(time_scale a₀) ~ 1e-9 s in its inertial layer
    min_dt: float = 0.0
    max_steps: int = 20_000
    safety: float = 0.9
    shrink_limit: float = 0.2
    grow_limit: float = 2.0

    def __post_init__(self) -> None:
        for key in ("tolerance", "time_scale", "first_dt", "max_dt", "max_steps"):
            if not getattr(self, key) > 0:
                raise ValueError(f"{key} must be > 0, got {getattr(self, key)!r}")

    def allowed(self, dt: float) -> float:
        return self.tolerance * dt / self.time_scale

    def controller(self) -> StepController:
        """The step controller of a march: the first step, halved on a Newton failure at
        most ``MAX_CUTS`` times in a row; the error estimate proposes every other length."""
        return StepController(min(self.first_dt, self.max_dt), cut_factor=0.5, max_cuts=MAX_CUTS,
                              easy_effort=None)

    def judge(self, dt: float, error: float, order: int) -> tuple[bool, float]:
        """(accepted, next Δt) for a step of length ``dt`` with estimate ``error``."""
        allowed = self.allowed(dt)
        if error <= 0.0:
            return True, min(dt * self.grow_limit, self.max_dt)
        factor = self.safety * (allowed / error) ** (1.0 / order)
        next_dt = dt * float(np.clip(factor, self.shrink_limit, self.grow_limit))
        at_floor = dt <= self.min_dt * (1.0 + 1e-9)
        return error <= allowed or at_floor, min(max(next_dt, self.min_dt), self.max_dt)


@dataclasses.dataclass
class MarchSummary:
    """What the march did: the estimated time error and the steps it took."""

    time_error_estimate: float = 0.0  # sum of the accepted steps' local estimates
    time_steps: int = 0
    rejected_steps: int = 0
    cuts: int = 0  # Newton failures (each halved the step)
    min_dt: float = np.inf
    max_dt: float = 0.0

    def count(self, controller: StepController) -> None:
        """The failed and rejected attempts, as the controller counted them."""
        self.cuts, self.rejected_steps = controller.failed_attempts, controller.rejected_attempts


def march_dynamics(solver: NonlinearSolver, dynamics: ImplicitDynamics,
                   apply: Callable[[float, float], None], t_end: float, control: TimeErrorControl,
                   accept: Callable[[int, float, float, int, float], None] | None = None, *,
                   stops: tuple[float, ...] = (), t_start: float = 0.0) -> MarchSummary:
    """From ``t_start`` to ``t_end`` with error-controlled steps, landing on ``stops``.

    ``apply(t, dt)`` sets the step ending at t (loads, lagged contact state);
    ``accept(step, t, dt, iterations, error)`` sees each accepted step before
    ``dynamics.advance()`` is called. Raises :class:`SolveFailure` when Newton fails
    ``MAX_CUTS`` times in a row or ``control.max_steps`` would be exceeded (the last
    accepted state is kept)."""
    summary = MarchSummary()
    order = dynamics.order
    ends = sorted({t for t in stops if t_start < t < t_end} | {t_end})
    t, steps = t_start, control.controller()
    state = solver.save_state()
    while t < t_end * (1 - 1e-12):
        if summary.time_steps >= control.max_steps:
            raise SolveFailure(summary.time_steps + 1, t + steps.step, t, [],
                               f"more than max_steps = {control.max_steps} time steps at the "
                               f"tolerance {control.tolerance:g}", quantity="time", unit="s")
        target = steps.target(t, next(s for s in ends if s > t * (1 + 1e-12)))
        h = target - t
        dynamics.set_step(h)
        apply(target, h)
        converged, iterations = solver.solve()
        if not converged:
            residuals, reason = list(solver.residual_history), solver.reason()
            solver.restore_state(state)
            retry = steps.cut(attempted=h)
            summary.count(steps)
            if not retry:
                raise SolveFailure(summary.time_steps + 1, target, t, residuals, reason,
                                   quantity="time", unit="s")
            continue
        error = dynamics.local_error()
        accepted, next_dt = control.judge(h, error, order)
        if not accepted:
            solver.restore_state(state)
            steps.reject(next_dt)
            summary.count(steps)
            continue
        steps.accept(next_step=next_dt)
        summary.time_steps += 1
        summary.time_error_estimate += error
        summary.min_dt, summary.max_dt = min(summary.min_dt, h), max(summary.max_dt, h)
        if accept is not None:
            accept(summary.time_steps, target, h, iterations, error)
        dynamics.advance()
        t = target
        state = solver.save_state()
    return summary


class Stepper(Protocol):
    """One implicit time step that can be tried, judged and undone (for :func:`march_steps`):
    a model with its own step loop (the lens' ``StepSolver``, the rotation-free P1
    ``Dynamics``)."""

    order: int  # of the scheme: local error ∝ Δt^{order+1}

    def save(self) -> Any: ...

    def restore(self, state: Any) -> None: ...

    def solve_step(self, dt: float) -> int:
        """Solve the step of length dt from the saved state; the Newton iterations. Raises
        RuntimeError when Newton does not converge."""

    def local_error(self) -> float: ...

    def advance(self) -> None: ...


def march_steps(stepper: Stepper, t_end: float, control: TimeErrorControl,
                accept: Callable[[int, float, float, int, float], None] | None = None, *,
                t_start: float = 0.0) -> MarchSummary:
    """:func:`march_dynamics`' controller on a :class:`Stepper`: a step whose
    ``local_error()`` exceeds ``control.allowed(Δt)`` is undone and repeated at the Δt
    ``control.judge`` proposes; a Newton failure halves it (at most ``MAX_CUTS`` in a row,
    then :class:`SolveFailure`). ``accept(step, t, dt, iterations, error)`` sees each
    accepted step after ``advance()``."""
    summary = MarchSummary()
    t, steps = t_start, control.controller()
    state = stepper.save()
    while t < t_end * (1 - 1e-12):
        if summary.time_steps >= control.max_steps:
            raise SolveFailure(summary.time_steps + 1, t + steps.step, t, [],
                               f"more than max_steps = {control.max_steps} time steps at the "
                               f"tolerance {control.tolerance:g}", quantity="time", unit="s")
        target = steps.target(t, t_end)
        h = target - t
        try:
            iterations = stepper.solve_step(h)
        except RuntimeError as err:
            stepper.restore(state)
            retry = steps.cut(attempted=h)
            summary.count(steps)
            if not retry:
                raise SolveFailure(summary.time_steps + 1, target, t, [], str(err),
                                   quantity="time", unit="s") from err
            continue
        error = stepper.local_error()
        accepted, next_dt = control.judge(h, error, stepper.order)
        if not accepted:
            stepper.restore(state)
            steps.reject(next_dt)
            summary.count(steps)
            continue
        steps.accept(next_step=next_dt)
        stepper.advance()
        summary.time_steps += 1
        summary.time_error_estimate += error
        summary.min_dt, summary.max_dt = min(summary.min_dt, h), max(summary.max_dt, h)
        t = target
        state = stepper.save()
        if accept is not None:
            accept(summary.time_steps, t, h, iterations, error)
    return summary
