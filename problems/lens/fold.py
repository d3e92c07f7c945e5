"""The lens folded into the cartridge, shared by ``iol-fold`` and ``iol-injection``
(seed 000 §3: "the haptics are folded onto the implant body; the body was then bent while
keeping the haptics inside").

Two rigid actions over the pseudo time [0, fold_time]:
- the optic is rolled isometrically about the injector axis to ``fold_radius``
  (prescribed on its nodes, κ(t) = (t/T)/fold_radius: two rigid fingers wrapping it);
- the loading chamber closes: a tube about the same axis whose radius shrinks from
  beyond the haptic tips to ``bore_radius`` pushes the haptics in (nodal penalty contact).

Solved as heavily damped implicit dynamics (backward Euler, damping ``fold_damping``):
slow enough to be quasi-static, and the damping carries the haptics through the
snap-throughs of a static path. Self-contact (haptics on the optic): ipctk's barrier
with CCD-limited Newton updates and lagged friction
(:mod:`eyemech.problems.contact.ipc`), so the haptics cannot pass through the rolled optic.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import dolfinx.fem
import numpy as np

from eyemech.problems.contact.rigid_wall import NodalContact
from eyemech.problems.contact.self_distance import self_distance_probe
from eyemech.problems.lens.model import (
    InjectorLayout,
    LensParameters,
    LensShell,
    StrainProbe,
    lens_newton,
    lens_self_contact,
    render_frame,
    rolled,
    write_frame_grid,
)
from eyemech.problems.lens.time_error import TimeErrorTally, step_error
from eyemech.problems.run.context import RunContext
from eyemech.problems.run.output import PyvistaSeries
from eyemech.problems.run.parameters import PHYSICS, SOLVER, field
from eyemech.problems.solve.driver import NonlinearSolver, Stepping, follow_path
from eyemech.problems.solve.time_integration import ImplicitDynamics


@dataclasses.dataclass(frozen=True)
class FoldParameters(LensParameters):
    fold_time: float = field(0.4, "pseudo time of the folding", "s", group=PHYSICS)
    time_step: float = field(0.01, "time step", "s", group=SOLVER)
    fold_damping: float = field(2.0e4, "mass-proportional damping while folding", "1/s", group=SOLVER)
    frames: int = field(10, "PNG frames of the folding", group=SOLVER)

    def validate(self) -> None:
        LensParameters.validate(self)
        self.require_positive("fold_time", "time_step", "frames")


# A step counts as easy (Δt may grow back after a cut) up to this many Newton iterations.
# The driver's default, 6, suits near-linear scenes; the lens needs 8–15 iterations at
# Δt = 0.01 s; with 6, Δt did not grow back after one cut (the injection crawled at
# Δt ≈ 0.6 ms on average, 536 steps for 0.32 s).
EASY_ITERATIONS = 12


class Folding:
    """The optic's prescribed roll and the closing chamber, as functions of λ = t/T."""

    def __init__(self, shell: LensShell, params: FoldParameters):
        self.shell, self.params = shell, params
        V = shell.V
        cells = shell.tagged.cells("optic")
        self.optic_dofs = dolfinx.fem.locate_dofs_topological(V, 2, cells)
        self.prescribed = dolfinx.fem.Function(V)
        self.bc = dolfinx.fem.dirichletbc(self.prescribed, self.optic_dofs)
        self.X = shell.node_coordinates()[self.optic_dofs]
        self.chamber = InjectorLayout().cartridge(params)
        x = shell.node_coordinates()
        reach = np.max(np.hypot(x[:, 1] - params.axis_point()[1], x[:, 2] - params.axis_point()[2]))
        self.opening = reach + 0.3 - params.bore_radius

    def apply(self, fraction: float) -> None:
        curvature = fraction / self.params.fold_radius
        values = self.prescribed.x.array.reshape(-1, 3)
        values[self.optic_dofs] = rolled(self.X, curvature) - self.X
        self.prescribed.x.scatter_forward()
        self.chamber.opening = (1.0 - fraction) * self.opening


def fold(params: FoldParameters, ctx: RunContext, shell: LensShell, frames_dir: Path | None):
    """Run the folding on ``shell`` (its u ends folded); returns the per-step records."""
    folding = Folding(shell, params)
    contact = NodalContact(shell.u, {"chamber": folding.chamber}, params.contact_stiffness,
                           excluded=folding.optic_dofs)
    dynamics = ImplicitDynamics(shell.u, shell.mass(), [folding.bc], scheme_name="backward-euler",
                                damping=params.fold_damping)
    solver = NonlinearSolver(shell.residual(), shell.u, [folding.bc], options=lens_newton(ctx),
                             timings=ctx.timings,
                             residual_hooks=[dynamics.residual_hook, contact.residual_hook],
                             jacobian_hooks=[dynamics.jacobian_hook, contact.jacobian_hook])
    # the optic's dofs are prescribed: their rows stay DOLFINx's (the barrier still pushes
    # the haptics off the optic, and the CCD still limits the prescribed update)
    self_contact = lens_self_contact(shell, params, excluded_dofs=blocked_dofs(folding.optic_dofs))
    if self_contact is not None:
        self_contact.attach(solver)
    self_distance = self_distance_probe(shell.u) if self_contact is None else None
    strain = StrainProbe(shell)
    steps = max(1, int(round(params.fold_time / params.time_step)))
    every = max(1, steps // params.frames)
    frames: list[Path] = []
    history = {"time": [], "penetration": [], "self_distance": [], "intersecting": [], "strain": []}
    # the frames as .vtu + fold.pvd for notebooks (only when the scene writes its pictures)
    history["series"] = PyvistaSeries(frames_dir if ctx.options.fields else None, ctx.comm, stem="fold")

    def apply(t: float, dt: float) -> None:
        folding.apply(t / params.fold_time)
        dynamics.set_step(dt)
        if self_contact is not None:
            self_contact.begin_step()

    time_error = TimeErrorTally()

    def converged(record) -> None:
        time_error.add(step_error(dynamics, solver.snes.getKSP()))
        dynamics.advance()
        history["time"].append(record.load)
        history["penetration"].append(max(contact.max_penetration().values(), default=0.0))
        history["strain"].append(strain.haptic_max())
        frame = record.step % every == 0 or record.load >= params.fold_time - 1e-9
        with ctx.timings("measurements"):
            if self_contact is not None:  # cheap (C++): every step
                history["self_distance"].append(self_contact.min_distance())
                history["intersecting"].append(self_contact.intersecting())
            elif self_distance is not None:
                distance, crossing = self_distance(distances=frame)
                history["self_distance"].append(distance)
                history["intersecting"].append(crossing)
        ctx.record_step(step=record.step, time=record.load, newton_iterations=record.iterations,
                        cuts=record.cuts, **record.counts(), max_penetration_mm=history["penetration"][-1])
        if frame:
            with ctx.timings("output"):
                write_frame_grid(history["series"], shell, record.load, strain)
        if frames_dir is not None and frame:
            path = frames_dir / f"fold_{len(frames):03d}.png"
            with ctx.timings("output"):
                render_frame(shell, path, f"iol-fold  t = {record.load:.2f} s",
                             {"chamber": folding.chamber})
            frames.append(path)

    start = time.perf_counter()
    with ctx.timings("time_stepping"):
        follow_path(solver, apply, Stepping(0.0, params.fold_time, quantity="time", unit="s",
                                            initial_step=1.0 / steps, max_step=1.0 / steps, grow=2.0,
                                            min_step=1e-3 / steps,
                                            easy_iterations=EASY_ITERATIONS),
                    on_converged=converged, label="iol-fold", quiet=ctx.options.quiet)
    history["wall"] = time.perf_counter() - start
    history["steps"] = len(history["time"])
    history["contact_seconds"] = contact.seconds
    history["self_contact"] = self_contact
    history["frames"] = frames
    history["time_error"] = time_error.quantities()
    return history


def blocked_dofs(dofs: np.ndarray) -> np.ndarray:
    """Unrolled (scalar) dof indices of blocked node indices, bs = 3."""
    dofs = np.asarray(dofs).ravel()
    return (3 * dofs[:, None] + np.arange(3)).ravel()


def self_contact_kind(params: LensParameters) -> str:
    if not params.self_contact:
        return "not applied"
    return (f"ipctk barrier (d̂ = {params.self_contact_distance} mm), CCD-limited steps, "
            f"friction μ = {params.friction}")
