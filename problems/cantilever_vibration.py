"""``cantilever-vibration``: free vibration of a clamped strip released from its first
bending mode — the check of the shell's mass and of the implicit time integrators.

Strip L × b × h, ν = 0 (a narrow strip bends like an Euler–Bernoulli beam), root
clamped, released at rest from w(x) = A φ₁(x), the first cantilever mode
(Rayleigh, Theory of Sound; e.g. Blevins, Formulas for Natural Frequency, Table 8-1):

    φ₁ = cosh βx − cos βx − σ (sinh βx − sin βx),  σ = (cosh βL + cos βL)/(sinh βL + sin βL),
    β L = 1.8751041,   ω₁ = (β L)² / L² · √(E I / (ρ b h)),   I = b h³/12.

With mass-proportional damping c the mode obeys q̈ + c q̇ + ω₁² q = 0. The tip history
is compared with that single-mode equation integrated by the *same* scheme and Δt
(:func:`~eyemech.problems.solve.time_integration.oscillator_response`), so what is left is
the spatial error of the shell and its mass; ``period_exact`` is the continuous one,
2π/√(ω₁² − c²/4).

The time discretisation: ``time_error_single_mode`` is the largest deviation of that
discrete single mode from the exact one (relative to the amplitude), the time error the
shell's tip carries; ``time_error_estimate`` is the sum of the steps' local error
estimates (:meth:`~eyemech.problems.solve.time_integration.ImplicitDynamics.local_error`)
over the amplitude, which tracks it for backward Euler (0.25 against 0.21 with c = 0.2 ω₁,
tests/test_shell_dynamics.py). None for the other schemes: the trapezoidal rule leaves the
finite-element modes above Δt's resolution (ω Δt ≫ 1) undamped, and they dominate
Zienkiewicz–Xie's estimate (2e4 × the amplitude at the defaults) although their error is
bounded by their tiny amplitude.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import ClassVar

import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms.dynamics import mass_form
from eyemech.forms.shell import Kinematics
from eyemech.meshes.surface import mapped_surface, tag_boundary
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, ParameterError, SceneParameters, field
from eyemech.problems.run.scene import Scene
from eyemech.problems.shell.model import Shell, ShellDiscretisation, check_shell_parameters, newton_options
from eyemech.problems.solve.driver import NonlinearSolver, Stepping, follow_path
from eyemech.problems.solve.time_integration import (
    SCHEMES,
    ImplicitDynamics,
    SchemeName,
    oscillator_exact,
    oscillator_response,
)

BETA_L = 1.8751040687  # first root of cos βL cosh βL = −1


@dataclasses.dataclass(frozen=True)
class Parameters(SceneParameters, ShellDiscretisation):
    youngs_modulus: float = field(1.0, "Young's modulus (the lens acrylic)", "MPa", group=PHYSICS)
    poisson_ratio: float = field(0.0, "Poisson's ratio (0: the strip is a beam)", group=PHYSICS)
    density: float = field(1.2e-9, "mass density (1.2 g/cm³)", "tonne/mm³", group=PHYSICS)
    length: float = field(6.0, "strip length", "mm", group=GEOMETRY)
    width: float = field(1.0, "strip width", "mm", group=GEOMETRY)
    thickness: float = field(0.13, "strip thickness", "mm", group=GEOMETRY)
    divisions: int = field(12, "squares along the length", group=GEOMETRY)
    kinematics: Kinematics = field("linear", "linear (small vibration) or nonlinear", group=PHYSICS)
    amplitude: float = field(0.01, "initial tip deflection as a fraction of the length", group=PHYSICS)
    scheme: SchemeName = field("newmark", "time scheme: " + " | ".join(SCHEMES), group=SOLVER)
    damping: float = field(0.0, "mass-proportional damping c as a fraction of ω₁", "", group=PHYSICS)
    steps_per_period: int = field(40, "time steps per undamped period 2π/ω₁", group=SOLVER)
    periods: float = field(2.0, "simulated time in undamped periods", group=PHYSICS)

    RESOLUTION_KEY: ClassVar[str] = "divisions"

    @property
    def estimated_cells(self) -> int:
        return self.grid_triangles(self.divisions, 1)

    def validate(self) -> None:
        self.require_positive("length", "width", "divisions", "density", "steps_per_period",
                              "periods", "amplitude")
        self.require_nonnegative("damping")
        check_shell_parameters(self, min(self.length, self.width))
        if self.damping >= 2.0:
            raise ParameterError("damping", "c ≥ 2ω₁ is overdamped: no period to measure")


def first_frequency(params: Parameters) -> float:
    """ω₁ of the Euler–Bernoulli cantilever (rad/s)."""
    h = params.thickness
    return BETA_L ** 2 / params.length ** 2 * np.sqrt(params.youngs_modulus * h ** 2
                                                      / (12.0 * params.density))


def mode_shape(x: np.ndarray, length: float) -> np.ndarray:
    """φ₁(x) scaled to 1 at the tip."""
    b = BETA_L / length
    sigma = (np.cosh(BETA_L) + np.cos(BETA_L)) / (np.sinh(BETA_L) + np.sin(BETA_L))

    def phi(s):
        return np.cosh(b * s) - np.cos(b * s) - sigma * (np.sinh(b * s) - np.sin(b * s))

    return phi(x) / phi(length)


def measured_period(times: np.ndarray, values: np.ndarray) -> float:
    """Twice the mean spacing of the zero crossings (linear interpolation)."""
    crossings = []
    for i in range(len(values) - 1):
        if values[i] == 0.0 or values[i] * values[i + 1] < 0.0:
            t0, t1, v0, v1 = times[i], times[i + 1], values[i], values[i + 1]
            crossings.append(t0 - v0 * (t1 - t0) / (v1 - v0))
    if len(crossings) < 2:
        return float("nan")
    return 2.0 * float(np.mean(np.diff(crossings)))


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        L, b = params.length, params.width
        with ctx.timings("mesh"):
            mesh = mapped_surface(lambda s, t: np.column_stack([L * s, b * t, 0.0 * s]),
                                  params.divisions, 1, params.diagonal, ctx.comm)
            tagged = tag_boundary(mesh, {"root": lambda x: np.isclose(x[0], 0.0)})
        shell = Shell(tagged, params, lambda x: np.tile([0.0, 0.0, 1.0], (len(x), 1)),
                      clamped=("root",))
        omega = first_frequency(params)
        damping = params.damping * omega
        dt = 2.0 * np.pi / omega / params.steps_per_period
        steps = int(round(params.periods * params.steps_per_period))
        amplitude = params.amplitude * L
        shell.u.interpolate(lambda x: np.vstack([0.0 * x[0], 0.0 * x[0],
                                                 amplitude * mode_shape(x[0], L)]))
        residual = ufl.derivative(shell.energy(params.kinematics), shell.u, shell.v)
        bcs = shell.fix("root")
        density = shell.constant(params.density)
        dynamics = ImplicitDynamics(shell.u, mass_form(ufl.TrialFunction(shell.V), shell.v, density,
                                                       shell.material.thickness, shell.dx),
                                    bcs, scheme_name=params.scheme, damping=damping)
        dynamics.initial_acceleration(residual)
        solver = NonlinearSolver(residual, shell.u, bcs, options=newton_options(ctx, params.kinematics),
                                 timings=ctx.timings, residual_hooks=[dynamics.residual_hook],
                                 jacobian_hooks=[dynamics.jacobian_hook])
        tip = (L, b / 2, 0.0)
        times, tip_w = [0.0], [float(shell.value_at(tip)[2])]

        def apply(_time: float, increment: float) -> None:
            dynamics.set_step(increment)

        estimated = params.scheme == "backward-euler"
        local_errors: list[float] = []

        def converged(record) -> None:
            if estimated:  # before advance: the estimate reads a_n and the new u
                local_errors.append(dynamics.local_error())
            dynamics.advance()
            times.append(record.load)
            tip_w.append(float(shell.value_at(tip)[2]))

        end = steps * dt
        with ctx.timings("time_stepping"):
            follow_path(solver, apply, Stepping(0.0, end, quantity="time", unit="s", initial_step=1.0 / steps,
                                                max_step=1.0 / steps, grow=1.0, min_step=1e-3 / steps),
                        on_converged=converged, label=SCENE.name, quiet=ctx.options.quiet)
        times, tip_w = np.asarray(times), np.asarray(tip_w)
        reference = amplitude * oscillator_response(omega, damping, dt, steps, params.scheme)
        period = measured_period(times, tip_w)
        period_reference = measured_period(times, reference)
        q = ctx.result.quantities
        q.update(omega_exact=omega, period=period, period_reference=period_reference,
                 period_exact=2.0 * np.pi / np.sqrt(omega ** 2 - damping ** 2 / 4.0),
                 period_error=period / period_reference - 1.0, time_step=dt,
                 final_tip_w=float(tip_w[-1]), final_tip_w_reference=float(reference[-1]),
                 time_error_estimate=float(sum(local_errors)) / amplitude if estimated else None,
                 time_error_single_mode=float(np.max(np.abs(
                     reference - amplitude * oscillator_exact(omega, damping, times)))) / amplitude,
                 history_deviation=float(np.max(np.abs(tip_w - reference)) / amplitude),
                 times=times.tolist(), tip_w=tip_w.tolist(), tip_w_reference=reference.tolist(),
                 dofs=shell.dofs())
    return ctx.result


SCENE = Scene(name="cantilever-vibration", kind="benchmark", parameters=Parameters, run=run,
              summary="clamped strip released from its first mode: shell mass and implicit time "
                      "integration against the Euler–Bernoulli frequency")
