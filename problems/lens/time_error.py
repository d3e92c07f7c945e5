r"""The lens scenes' estimated time-discretisation error, and ``iol-speed``'s release with
Δt chosen by it (issue 27, item 2).

Per step, the embedded backward-Euler/trapezoidal difference of the displacement,
e = u_BE − u_TR = Δt/2 (v_{n+1} − v_n) (``ImplicitDynamics.local_error_vector`` for the P2
lens, Zienkiewicz–Xie's for ``newmark``; from the P1 model's own velocities), filtered by the
step's Jacobian: e_f = (K + mM)⁻¹ mM e (Shampine's filter for stiff problems; Hairer & Wanner,
Solving ODEs II, §IV.8). The lens' stiff overdamped modes relax within a step and carry no
time error, while the raw e counts their whole jump; the filter keeps e where K ≪ mM. Cost:
one triangular solve with the factors the step already has. :class:`TimeErrorTally` sums
‖e_f‖∞ into ``time_error_estimate_mm`` (the displacement error the time stepping leaves at
the end) and keeps the largest (``max_local_time_error_mm``) and the raw sum.

The sum bounds the error at the end when errors made early do not grow later: the lens in
its fluid (c = 2e4 /s, ζ ≫ 1) is a damped gradient flow, which contracts them (measured
17–300× above the true error: tests/test_lens_time_error.py, docs/iol.md §1). It is not a strict bound for a
lightly damped oscillation, whose numerical damping accumulates into an amplitude error the
local estimates do not sum to (the oscillator at ζ = 0.08: 1.5 × the tolerance,
tests/test_adaptive_dynamics.py). docs/iol.md §1.

``time_stepping=adaptive`` (:func:`run_adaptive_release`): the deformation-only release
over ``steps × time_step`` with steps from :func:`~eyemech.problems.solve.adaptive_dynamics.march_steps`
(the controller of ``march_dynamics``), the tolerance ``time_tolerance`` spread over that
interval (error per unit step), Δt between 10⁻³ and 10 ``time_step``.
"""

from __future__ import annotations

import dataclasses
import os
import time
from typing import TYPE_CHECKING, Any, Callable

import numpy as np
from petsc4py import PETSc

from eyemech.problems.run.parameters import ParameterError
from eyemech.problems.solve.adaptive_dynamics import TimeErrorControl, march_steps
from eyemech.problems.solve.time_integration import ESTIMATED_SCHEMES, ImplicitDynamics

if TYPE_CHECKING:
    from eyemech.problems.lens.rotation_free import Dynamics
    from eyemech.problems.run.context import RunContext


@dataclasses.dataclass
class TimeErrorTally:
    """The per-step (filtered, raw) estimates of a run: their sums and the largest filtered
    one; ``None`` for a scheme without an estimate (``generalized-alpha``, ``newmark-damped``)."""

    total: float = 0.0
    largest: float = 0.0
    raw_total: float = 0.0
    steps: int = 0
    available: bool = True

    def add(self, errors: tuple[float, float] | None) -> None:
        if errors is None:
            self.available = False
            return
        filtered, raw = errors
        self.total += filtered
        self.raw_total += raw
        self.largest = max(self.largest, filtered)
        self.steps += 1

    def quantities(self) -> dict:
        if not self.available:
            return dict.fromkeys(("time_error_estimate_mm", "max_local_time_error_mm",
                                  "unfiltered_time_error_estimate_mm"))
        return {"time_error_estimate_mm": self.total, "max_local_time_error_mm": self.largest,
                "unfiltered_time_error_estimate_mm": self.raw_total}


def step_error(dynamics: ImplicitDynamics, ksp: Any) -> tuple[float, float] | None:
    """(filtered, raw) local estimates of the P2 step just solved (call before ``advance``),
    ``ksp`` holding the factors of the step's Jacobian K + m M: the raw vector e (Δt²/2
    a_{n+1}, ``ImplicitDynamics.local_error_vector``) and e_f = (K + m M)⁻¹ m M e. None when
    the scheme has no estimate."""
    if dynamics.scheme.name not in ESTIMATED_SCHEMES:
        return None
    raw = dynamics.M.createVecRight()
    dynamics.local_error_vector(raw)
    rhs, filtered = raw.duplicate(), raw.duplicate()
    dynamics.M.mult(raw, rhs)
    rhs.scale(dynamics.mass_factor())
    ksp.solve(rhs, filtered)
    errors = (filtered.norm(PETSc.NormType.NORM_INFINITY), raw.norm(PETSc.NormType.NORM_INFINITY))
    for vec in (raw, rhs, filtered):
        vec.destroy()
    return errors


def rotation_free_step_error(dyn: "Dynamics") -> tuple[float, float]:
    """(filtered, raw) local estimates of the rotation-free P1 step just taken by
    ``Dynamics.step`` (which keeps v_n as ``v_previous``; its solver holds the factors of the
    step's K + m M): e = Δt/2 (v_{n+1} − v_n), backward Euler against the trapezoidal rule,
    and e_f = (K + m M)⁻¹ m M e, m = 1/Δt² + c/Δt."""
    raw = 0.5 * dyn.dt * (dyn.v - dyn.v_previous)
    mass = 1.0 / dyn.dt ** 2 + dyn.c / dyn.dt
    filtered = dyn.solver.solve(mass * (dyn.M @ raw))
    return float(np.max(np.abs(filtered), initial=0.0)), float(np.max(np.abs(raw), initial=0.0))


# -- steppers for march_steps --------------------------------------------------------------
class P2Stepper:
    """``iol-speed``'s ``StepSolver`` (P2 lens, ``ImplicitDynamics``) as a Stepper."""

    def __init__(self, solver: Any, dynamics: ImplicitDynamics):
        self.solver, self.dynamics = solver, dynamics
        self.order = dynamics.order
        self.u = dynamics.u

    def save(self) -> np.ndarray:
        return self.u.x.array.copy()

    def restore(self, state: np.ndarray) -> None:
        self.u.x.array[:] = state
        self.u.x.scatter_forward()

    def solve_step(self, dt: float) -> int:
        self.dynamics.set_step(dt)
        return self.solver.step()

    def local_error(self) -> float:
        return step_error(self.dynamics, self.solver.ksp)[0]

    def advance(self) -> None:
        self.dynamics.advance()


class P1Stepper:
    """The rotation-free P1 ``Dynamics`` (backward Euler) as a Stepper."""

    order = 1

    def __init__(self, dyn: "Dynamics"):
        self.dyn = dyn
        self.iterations: list[int] = []

    def save(self) -> tuple:
        return self.dyn.save_state()

    def restore(self, state: tuple) -> None:
        self.dyn.restore_state(state)

    def solve_step(self, dt: float) -> int:
        self.dyn.dt = dt
        return self.dyn.step()

    def local_error(self) -> float:
        return rotation_free_step_error(self.dyn)[0]

    def advance(self) -> None:
        pass  # Dynamics.step already moved (u, v) on; save() records them


# -- iol-speed, time_stepping=adaptive -------------------------------------------------------
def validate_adaptive(params: Any) -> None:
    """What ``time_stepping=adaptive`` needs: the deformation-only Newton release with an
    estimated scheme."""
    if params.time_stepping == "fixed":
        return
    if params.time_stepping != "adaptive":
        raise ParameterError("time_stepping", f"fixed or adaptive, got {params.time_stepping!r}")
    if not params.time_tolerance > 0:
        raise ParameterError("time_tolerance", f"must be > 0, got {params.time_tolerance!r}")
    if params.contact or params.surface_contact:
        raise ParameterError("time_stepping", "adaptive steps are for the deformation-only release "
                             "(contact=false, surface_contact=false)")
    if params.method != "newton":
        raise ParameterError("time_stepping", "adaptive steps judge converged steps: method=newton")
    if params.scheme not in ESTIMATED_SCHEMES:
        raise ParameterError("scheme", f"time_stepping=adaptive needs an estimated scheme: "
                             f"{' | '.join(ESTIMATED_SCHEMES)}")


@dataclasses.dataclass(frozen=True)
class P2Release:
    """What the scene builds the P2 release from (``iol-speed``'s own functions, passed in:
    a room does not import a scene)."""

    lens: Callable[[Any], Any]                 # params → LensShell
    initial_roll: Callable[[Any, float], np.ndarray]  # (shell, radius) → u0
    step_solver: Callable[..., Any]            # (shell, dynamics, contact, params) → StepSolver
    tip_nodes: Callable[[Any], np.ndarray]     # shell → the tip's nodes


def run_adaptive_release(ctx: "RunContext", params: Any, p2: P2Release) -> None:
    """The release over ``steps × time_step`` with error-controlled steps (first Δt
    ``time_step``, at most 10 × it); reports the accepted steps' histories and the
    estimate against ``time_tolerance``."""
    control = TimeErrorControl(tolerance=params.time_tolerance, time_scale=params.steps * params.time_step,
                               first_dt=params.time_step, max_dt=10.0 * params.time_step,
                               min_dt=1e-3 * params.time_step)
    with ctx.timings("mesh"):
        stepper, tips, optic, size = _release_stepper(params, p2)
    history: dict[str, list] = {"time": [], "dt": [], "tip": [], "optic": [], "iterations": [], "error": []}

    def accept(step: int, t: float, dt: float, iterations: int, error: float) -> None:
        u = stepper_displacement(stepper)
        history["time"].append(t)
        history["dt"].append(dt)
        history["iterations"].append(iterations)
        history["error"].append(error)
        history["tip"].append(u[tips].mean(axis=0).tolist())
        history["optic"].append(u[optic].mean(axis=0).tolist())

    wall, cpu = time.perf_counter(), time.process_time()
    with ctx.timings("time_stepping"):
        summary = march_steps(stepper, control.time_scale, control, accept)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    ctx.result.quantities.update(
        model=params.model, method=params.method, jacobian=params.jacobian, time_stepping="adaptive",
        time_tolerance_mm=params.time_tolerance, time_error_estimate_mm=summary.time_error_estimate,
        max_local_time_error_mm=max(history["error"], default=0.0),
        steps=summary.time_steps, rejected_steps=summary.rejected_steps, step_cuts=summary.cuts,
        min_time_step_s=summary.min_dt, max_time_step_s=summary.max_dt, end_time_s=control.time_scale,
        iterations=int(sum(history["iterations"])), newton_iterations=history["iterations"],
        time=history["time"], time_steps_s=history["dt"], local_time_errors_mm=history["error"],
        tip_history=history["tip"], optic_history=history["optic"],
        steps_per_second=summary.time_steps / wall, steps_per_second_cpu=summary.time_steps / cpu,
        load_average=os.getloadavg()[0], **size)


def stepper_displacement(stepper: P1Stepper | P2Stepper) -> np.ndarray:
    if isinstance(stepper, P1Stepper):
        return stepper.dyn.u.reshape(-1, 3)
    return stepper.u.x.array.reshape(-1, 3)


def _release_stepper(params: Any, p2: P2Release):
    """(stepper at the rolled state, tip nodes, optic nodes, size quantities) of the model."""
    if params.model == "p1-rotation-free":
        from eyemech.problems.lens.rotation_free import Dynamics, FastLens

        lens = FastLens.build(params, params.bending)
        dyn = Dynamics(lens.shell, params.time_step, params.damping, rtol=params.rtol, atol=params.atol,
                       max_iterations=params.max_iterations)
        dyn.stall = params.stall if params.jacobian == "lagged" else None
        dyn.reset(lens.rolled_displacement(params.roll_radius))
        size = {"dofs": lens.shell.n_dofs, "cells": len(lens.shell.tri), "nodes": len(lens.shell.X)}
        return P1Stepper(dyn), lens.tip_nodes, lens.optic_nodes, size
    shell = p2.lens(params)
    u0 = p2.initial_roll(shell, params.roll_radius)
    shell.u.x.array[:] = u0
    shell.u.x.scatter_forward()
    dynamics = ImplicitDynamics(shell.u, shell.mass(), [], scheme_name=params.scheme, damping=params.damping)
    solver = p2.step_solver(shell, dynamics, None, params)
    dynamics.set_step(params.time_step)
    if params.scheme != "backward-euler":
        dynamics.initial_acceleration(shell.residual())
    size = {"dofs": shell.dofs(), "cells": shell.mesh.topology.index_map(2).size_global,
            "nodes": shell.mesh.geometry.index_map().size_global}
    return P2Stepper(solver, dynamics), p2.tip_nodes(shell), shell.nodes_of("optic"), size
