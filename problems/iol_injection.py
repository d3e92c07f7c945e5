"""``iol-injection``: the folded lens pushed by the plunger through the tapered cartridge; it
leaves the nozzle and unfolds in the (rigid, ellipsoidal) capsule (seed 000 §3, Fig. 6).

Implicit dynamics (backward Euler by default, Δt = 0.01 s) with mass-proportional
damping standing in for the viscoelastic fluid; contact of the lens' nodes with the
cartridge bore (acting inside the injector, x < nozzle tip), the plunger head and the
capsule (acting outside the injector) by a nodal penalty. The plunger moves at
``plunger_speed`` until its face is ``plunger_overshoot`` past the nozzle tip, then the lens
is left to settle for ``settle_time``. The folded state comes from ``iol-fold`` (run first
when ``folded_state`` is empty).

Self-contact: ipctk's barrier with CCD-limited Newton updates and lagged friction
(:mod:`eyemech.problems.iol_self_contact`); a folded state that already intersects itself
is refused before any solve. Not modelled: a soft capsule.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

try:
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass

from eyemech.problems import iol_fold
from eyemech.problems.context import RunContext, RunOptions
from eyemech.problems.driver import NonlinearSolver, Stepping, follow_path
from eyemech.problems.iol import (InjectorLayout, LensShell, StrainProbe, lens_newton, lens_self_contact,
                                  load_state, optic_center, optic_normal, render_frame, write_animation,
                                  write_frame_grid)
from eyemech.problems.iol_contact import NodalContact, Plunger, self_distance_probe
from eyemech.problems.output import PyvistaSeries
from eyemech.problems.parameters import ParameterError, field
from eyemech.problems.scene import Scene
from eyemech.problems.time_integration import SCHEMES, ImplicitDynamics


@dataclasses.dataclass(frozen=True)
class Parameters(iol_fold.Parameters):
    folded_state: str = field("", "folded_state.npz of an iol-fold run ('' = fold first)")
    plunger_speed: float = field(40.0, "plunger speed", "mm/s")
    plunger_overshoot: float = field(1.0, "how far the plunger face goes past the nozzle tip", "mm")
    settle_time: float = field(0.2, "time after the plunger stops", "s")
    scheme: str = field("backward-euler", "time scheme: " + " | ".join(SCHEMES))
    linearised: bool = field(False, "one linearised implicit solve per step (SOFA style) instead of Newton")
    jacobian_lag: int = field(1, "reuse the Jacobian and its factorisation for this many Newton "
                                 "iterations, across steps (1 = full Newton)")
    contact: bool = field(True, "rigid contact on; false: the folded lens unfolds in free space "
                                "(the deformation-only speed)")
    frames_every: int = field(4, "a PNG frame every this many steps")

    def validate(self) -> None:
        layout = InjectorLayout()
        semi = np.asarray(layout.capsule_semi_axes)
        if min(semi[:2]) < 0.5 * self.optic_diameter:
            raise ParameterError("optic_diameter", f"the capsule (semi-axes {tuple(semi)}) is smaller "
                                 f"than the {self.optic_diameter} mm optic")
        iol_fold.Parameters.validate(self)
        self.require_positive("plunger_speed", "frames_every", "jacobian_lag")
        self.require_nonnegative("settle_time", "plunger_overshoot")
        if self.scheme not in SCHEMES:
            raise ParameterError("scheme", f"must be one of {sorted(SCHEMES)}, got {self.scheme!r}")
        if self.folded_state and not Path(self.folded_state).is_file():
            raise ParameterError("folded_state", f"no such file: {self.folded_state}")
        if self.plunger_speed * self.time_step > 0.5 * self.nozzle_radius:
            raise ParameterError("plunger_speed", f"{self.plunger_speed} mm/s moves the plunger "
                                 f"{self.plunger_speed * self.time_step:.3g} mm per step, more than half "
                                 f"the nozzle radius: the contact would be stepped over")


def _newton(ctx: RunContext, params: Parameters):
    """Newton to a relative residual of 1e-6 (forces in the lens are ~1e-4 N: the default
    1e-9 / 1e-10 N costs iterations that change nothing at the scale of a frame)."""
    options = lens_newton(ctx)
    extra = {}
    if params.linearised:
        extra["snes_type"] = "ksponly"
    if params.jacobian_lag > 1:
        extra.update(snes_lag_jacobian=params.jacobian_lag, snes_lag_jacobian_persists="true")
    return dataclasses.replace(options, petsc={**extra, **options.petsc})


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        with ctx.timings("mesh"):
            shell = LensShell(params, ctx.comm)
        if params.folded_state:
            load_state(Path(params.folded_state), shell)
            _refuse_intersecting(params, shell)
        else:
            with ctx.timings("folding"):
                iol_fold.fold(params, ctx, shell, None)
        history = inject(params, ctx, shell)
        report(params, ctx, shell, history)
    return ctx.result


def _refuse_intersecting(params: Parameters, shell: LensShell) -> None:
    """A saved fold that passes through itself cannot start a barrier (infinite energy)."""
    if not (params.self_contact and params.contact):
        return
    from eyemech.problems.iol_self_contact import SelfContactError

    try:
        lens_self_contact(shell, params).check(what=f"the folded state {params.folded_state}")
    except SelfContactError as err:
        raise ParameterError("folded_state", f"{err} (it was folded without self-contact: rerun "
                             "iol-fold)") from None


def inject(params: Parameters, ctx: RunContext, shell: LensShell) -> dict:
    layout = InjectorLayout()
    axis = params.axis_point()
    x = shell.node_coordinates() + shell.u.x.array.reshape(-1, 3)
    start = ctx.comm.allreduce(float(x[:, 0].min()), op=MPI.MIN) - 0.05
    # the head fills the bore and more: a node sliding along the wall must not leave its reach
    plunger = Plunger(start, axis, params.bore_radius + 0.5)
    obstacles = {"cartridge": layout.cartridge(params), "plunger": plunger,
                 "capsule": layout.capsule(params)} if params.contact else {}
    contact = NodalContact(shell.u, obstacles, params.contact_stiffness)
    dynamics = ImplicitDynamics(shell.u, shell.mass(), [], scheme_name=params.scheme,
                                damping=params.damping)
    solver = NonlinearSolver(shell.residual(), shell.u, [], options=_newton(ctx, params),
                             timings=ctx.timings,
                             residual_hooks=[dynamics.residual_hook, contact.residual_hook],
                             jacobian_hooks=[dynamics.jacobian_hook, contact.jacobian_hook])
    # contact=false is the deformation-only benchmark: no self-contact either
    self_contact = lens_self_contact(shell, params) if params.contact else None
    if self_contact is not None:
        self_contact.check(what="the folded lens")
        self_contact.attach(solver)
    if params.scheme != "backward-euler":
        dynamics.initial_acceleration(shell.residual())
    stop = layout.tip + params.plunger_overshoot
    push_time = (stop - start) / params.plunger_speed
    end = push_time + params.settle_time
    self_distance = self_distance_probe(shell.u) if self_contact is None else None
    strain = StrainProbe(shell)
    frames_dir = ctx.out if (ctx.options.pictures and ctx.out is not None) else None
    h = {"time": [], "penetration": [], "self_distance": [], "intersecting": [], "strain": [],
         "frames": [], "newton": []}
    # the frames as .vtu + injection.pvd for notebooks (with the PNGs, or alone under --no-pictures)
    h["series"] = PyvistaSeries(ctx.out if ctx.options.fields else None, ctx.comm, stem="injection")

    def apply(t: float, dt: float) -> None:
        plunger.position = start + params.plunger_speed * min(t, push_time)
        dynamics.set_step(dt)
        if self_contact is not None:
            self_contact.begin_step()

    def converged(record) -> None:
        dynamics.advance()
        h["time"].append(record.load)
        h["newton"].append(record.iterations)
        depth = contact.max_penetration()
        h["penetration"].append(max(depth.values(), default=0.0))
        frame = record.step % params.frames_every == 1 or record.load >= end - 1e-9
        with ctx.timings("measurements"):
            h["strain"].append(strain.haptic_max())
            if self_contact is not None:  # C++, cheap: every step
                h["self_distance"].append(self_contact.min_distance())
                h["intersecting"].append(self_contact.intersecting())
            elif self_distance is not None:  # the distance search on frames, intersections always
                distance, crossing = self_distance(distances=frame)
                h["self_distance"].append(distance)
                h["intersecting"].append(crossing)
        ctx.record_step(step=record.step, time=record.load, newton_iterations=record.iterations,
                        cuts=record.cuts, plunger=plunger.position, max_penetration_mm=h["penetration"][-1],
                        kinetic_energy=dynamics.kinetic_energy())
        if frame:
            with ctx.timings("output"):
                write_frame_grid(h["series"], shell, record.load, strain)
        if frames_dir is not None and frame:
            path = frames_dir / f"frame_{len(h['frames']):03d}.png"
            with ctx.timings("output"):
                render_frame(shell, path, f"iol-injection  t = {record.load:.2f} s", obstacles)
            h["frames"].append(path)

    dt = params.time_step
    steps = int(np.ceil(end / dt))
    begin = time.perf_counter()
    solver_before = ctx.timings.seconds["assembly"] + ctx.timings.seconds["solve"]
    with ctx.timings("time_stepping"):
        follow_path(solver, apply, Stepping(0.0, steps * dt, initial_step=1.0 / steps, max_step=1.0 / steps,
                                            grow=2.0, min_step=1e-3 / steps, stops=(push_time,),
                                            easy_iterations=iol_fold.EASY_ITERATIONS),
                    on_converged=converged, label=SCENE.name, quiet=ctx.options.quiet)
    h["wall"] = time.perf_counter() - begin
    # assembly + factorisation + solves of the steps, contact hooks included (subtracted later)
    h["solver_seconds"] = ctx.timings.seconds["assembly"] + ctx.timings.seconds["solve"] - solver_before
    h["contact_seconds"] = contact.seconds
    h["contact"] = contact
    h["self_contact"] = self_contact
    return h


def report(params: Parameters, ctx: RunContext, shell: LensShell, h: dict) -> None:
    layout = InjectorLayout()
    capsule = layout.capsule(params)
    x = shell.node_coordinates() + shell.u.x.array.reshape(-1, 3)
    exited = ctx.comm.allreduce(float(x[:, 0].min()), op=MPI.MIN) > layout.tip
    center = optic_center(shell)
    normal = optic_normal(shell)
    steps = len(h["time"])
    deformation = h["solver_seconds"] - h["contact_seconds"]
    distances = [d for d in h["self_distance"] if np.isfinite(d)]
    q = ctx.result.quantities
    q.update(
        steps=steps, newton_iterations_total=int(sum(h["newton"])),
        steps_per_second=steps / h["wall"],
        steps_per_second_deformation=steps / max(deformation, 1e-12),
        max_penetration_mm=float(max(h["penetration"], default=0.0)),
        haptic_max_strain=float(max(h["strain"], default=0.0)),
        min_self_distance_mm=float(min(distances)) if distances else None,
        self_intersecting=bool(any(h["intersecting"])),
        self_contact_forces=iol_fold._self_contact_kind(params),
        self_contact_seconds=getattr(h["self_contact"], "seconds", 0.0),
        ccd_limited_updates=len(getattr(h["self_contact"], "step_limits", [])),
        lens_exited=bool(exited),
        optic_normal_z=float(normal[2]),
        optic_flipped=bool(normal[2] < 0.0),
        final_decentration_mm=float(np.hypot(*(center - capsule.center)[:2])),
        final_optic_center=center.tolist(),
        contact_seconds=h["contact_seconds"],
        time=h["time"], penetration_mm=h["penetration"], self_distance_mm=h["self_distance"],
        triangles=shell.mesh.topology.index_map(2).size_global,
        nodes=shell.mesh.geometry.index_map().size_global, dofs=shell.dofs())
    ctx.result.fields.extend(h["series"].files)
    if h["frames"] and ctx.rank0:
        ctx.result.pictures += [p.name for p in h["frames"]]
        gif = write_animation(h["frames"], ctx.out / "injection.gif")
        if gif:
            ctx.result.pictures.append(gif)


SCENE = Scene(name="iol-injection", kind="scene", parameters=Parameters, run=run,
              summary="folded intra-ocular lens pushed through the tapered cartridge, unfolding in the "
                      "capsule (implicit damped dynamics, rigid contact)")
