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
(:mod:`eyemech.problems.contact.ipc`); a folded state that already intersects itself
is refused before any solve. Not modelled: a soft capsule.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Literal

import numpy as np
from mpi4py import MPI

from eyemech.problems.contact.rigid_wall import NodalContact
from eyemech.problems.contact.self_distance import self_distance_probe
from eyemech.problems.lens.fold import (
    EASY_ITERATIONS,
    FoldParameters,
    fold,
    self_contact_kind,
)
from eyemech.problems.lens.history import InjectionHistory
from eyemech.problems.lens.injector import Plunger, turn_about_x
from eyemech.problems.lens.model import (
    InjectorLayout,
    LensShell,
    StrainProbe,
    lens_newton,
    lens_self_contact,
    load_state,
    optic_center,
    optic_flatness,
    optic_normal,
    render_frame,
    save_state,
    write_animation,
    write_frame_grid,
)
from eyemech.problems.lens.models import MODELS, Model
from eyemech.problems.lens.push import PlungerMotion, axial_fluid_speed
from eyemech.problems.lens.time_error import step_error
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, ParameterError, field
from eyemech.problems.run.scene import Scene
from eyemech.problems.solve.driver import NonlinearSolver, SolveFailure, Stepping, follow_path
from eyemech.problems.solve.time_integration import SCHEMES, ImplicitDynamics, SchemeName


@dataclasses.dataclass(frozen=True)
class Parameters(FoldParameters):
    model: Model = field("p2-c0ip", "the lens model: " + " | ".join(MODELS) + " (the rotation-free P1 "
                                    "triangle of iol-speed: the same walls, plunger, fluid, friction and "
                                    "ipctk self-contact on its vertices and triangles, the same pictures and "
                                    ".vtu frames)", group=GEOMETRY)
    folded_state: str = field("", "folded_state.npz of an iol-fold run ('' = fold first)", group=SOLVER)
    fold_seed: Literal["p2", "p1"] = field(
        "p2", "model=p2-c0ip with folded_state='': the model that folds the lens (p1: the rotation-free P1 "
              "fold, seconds instead of minutes, its vertices and the patch quadratics at the edge midpoints "
              "as the P2 lens' folded state; docs/iol.md §4b)", group=SOLVER)
    plunger_speed: float = field(40.0, "plunger speed", "mm/s", group=PHYSICS)
    plunger_overshoot: float = field(1.0, "how far the plunger face goes past the nozzle tip", "mm",
                                     group=PHYSICS)
    settle_time: float = field(0.2, "time after the plunger stops", "s", group=PHYSICS)
    scheme: SchemeName = field("backward-euler", "time scheme: " + " | ".join(SCHEMES), group=SOLVER)
    linearised: bool = field(False, "one linearised implicit solve per step (SOFA style) instead of Newton",
                             group=SOLVER)
    jacobian_lag: int = field(1, "reuse the Jacobian and its factorisation for this many Newton "
                                 "iterations, across steps (1 = full Newton)", group=SOLVER)
    contact: bool = field(True, "rigid contact on; false: the folded lens unfolds in free space "
                                "(the deformation-only speed)", group=PHYSICS)
    frames_every: int = field(1, "at least this many steps between two frames (PNG + .vtu)", group=SOLVER)
    frame_interval: float = field(0.01, "a frame (PNG + .vtu) each time the simulated time has advanced this "
                                        "much since the last one (0: every frames_every steps)", "s",
                                  group=SOLVER)
    fluid_carried: bool = field(True, "the damping acts on the lens' velocity relative to the viscoelastic "
                                      "fluid, which the plunger drives through the bore (false: relative to "
                                      "rest: a drag that crushes the trailing haptic, docs/iol.md)",
                                group=PHYSICS)
    plunger_engages: Literal["optic", "lens"] = field(
        "optic", "what the plunger head pushes: 'optic' (the trailing haptic lies beside the plunger tip, "
                 "as loading instructions ask) or 'lens' (every node: the trailing haptic is crushed)",
        group=PHYSICS)
    jet_length: float = field(2.0, "decay length of the fluid's jet beyond the nozzle tip", "mm",
                              group=PHYSICS)
    fold_cache: bool = field(True, "with folded_state='': reuse a fold made earlier with the same lens and "
                                   "fold parameters and the same code, from the user's cache folder "
                                   "($XDG_CACHE_HOME or ~/.cache)/eyemech/iol-fold; false: always fold",
                             group=SOLVER)
    capsule_friction: float = field(0.0, "Coulomb coefficient μ of the lens on the capsular bag (lagged, "
                                         "smoothed over friction_slip; 0 = frictionless)", group=PHYSICS)
    cartridge_friction: float = field(0.0, "Coulomb coefficient μ of the lens on the cartridge bore and "
                                           "nozzle (0: a coated cartridge lubricated by viscoelastic)",
                                      group=PHYSICS)
    injector_twist: float = field(0.0, "the surgeon turns the injector about its axis by this angle during "
                                       "the push, in step with the plunger's travel (right-handed about the "
                                       "push direction); the round bore drags the lens round only through "
                                       "cartridge_friction", "deg", group=PHYSICS)
    start_ramp: float = field(0.0, "the plunger (and the fluid it drives) accelerates from rest to "
                                    "plunger_speed over this time, linearly (0 = a jump to full speed)", "s",
                              group=PHYSICS)

    def validate(self) -> None:
        layout = InjectorLayout()
        semi = np.asarray(layout.capsule_semi_axes)
        if min(semi[:2]) < 0.5 * self.optic_diameter:
            raise ParameterError("optic_diameter", f"the capsule (semi-axes {tuple(semi)}) is smaller "
                                 f"than the {self.optic_diameter} mm optic")
        FoldParameters.validate(self)
        self.require_positive("plunger_speed", "frames_every", "jacobian_lag")
        self.require_nonnegative("settle_time", "plunger_overshoot", "start_ramp", "frame_interval",
                                 "capsule_friction", "cartridge_friction")
        self.require_positive("jet_length")
        if self.folded_state and not Path(self.folded_state).is_file():
            raise ParameterError("folded_state", f"no such file: {self.folded_state}")
        if self.model == "p1-rotation-free":
            refuse_on_p1(self, {"linearised": False, "jacobian_lag": 1, "scheme": "backward-euler",
                                "fold_seed": "p2"})
        if self.fold_seed == "p1" and self.folded_state:
            raise ParameterError("fold_seed", "fold_seed=p1 folds the lens; folded_state gives the fold: "
                                              "set one")
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
        if params.model == "p1-rotation-free":
            _run_rotation_free(ctx, params)
            return ctx.result
        with ctx.timings("mesh"):
            shell = LensShell(params, ctx.comm)
        if params.folded_state:
            load_state(Path(params.folded_state), shell)
            _refuse_intersecting(params, shell)
        elif params.fold_seed == "p1":
            with ctx.timings("folding"):
                seed_from_p1_fold(ctx, params, shell)
            if ctx.out is not None:
                save_state(ctx.out / "folded_state.npz", shell, ctx.comm)
                ctx.result.fields.append("folded_state.npz")
        else:
            cached = fold_cache_path(params) if params.fold_cache else None
            if cached is not None and cached.is_file():
                load_state(cached, shell)
                ctx.result.quantities["fold_cache"] = str(cached)
            else:
                with ctx.timings("folding"):
                    fold(params, ctx, shell, None)
                if cached is not None:
                    _store_fold(cached, shell, ctx)
            if ctx.out is not None:  # reusable: folded_state=<out>/folded_state.npz
                save_state(ctx.out / "folded_state.npz", shell, ctx.comm)
                ctx.result.fields.append("folded_state.npz")
        injection = Injection(params, ctx, shell)
        injection.run()
        report(params, ctx, injection)
    return ctx.result


def seed_from_p1_fold(ctx: RunContext, params: Parameters, shell: LensShell) -> tuple:
    """The fold on the rotation-free P1 lens of the same mesh (``fast_injection.fold``, on
    every rank alike), carried to the P2 nodes (``fast_injection.p2_displacement``: the
    vertices exactly, the edge midpoints on the patch quadratics), then the edge midpoints
    relaxed to the P2 shell's equilibrium with the vertices held (Newton, ``lens_newton``, with
    the lens' self-contact): the interpolated midpoints strain the P2 membrane (coarse lens: P2
    energy 2.7× the P1 fold's before, 1.08× after; tests/test_iol_injection.py). Returns the P1
    lens and its fold."""
    import dolfinx.fem
    from scipy.spatial import cKDTree

    from eyemech.problems.lens import fast_injection
    from eyemech.problems.lens.rotation_free import FastLens, MeshInputError

    try:
        lens = FastLens.build(params)
    except (MeshInputError, ValueError) as err:
        raise ParameterError("fold_seed", f"the rotation-free lens cannot use this mesh: {err}") from err
    folded, history = fast_injection.fold(params, lens)
    nodes = shell.node_coordinates()
    shell.u.x.array[:] = fast_injection.p2_displacement(lens, folded, nodes).ravel()
    shell.u.x.scatter_forward()
    held = dolfinx.fem.Function(shell.V)
    held.x.array[:] = shell.u.x.array
    vertices = np.flatnonzero(cKDTree(lens.shell.X).query(nodes)[0] < 1e-9).astype(np.int32)
    # the injection's bore on the free midpoints: relaxed without it, haptic midpoints on the
    # curved bore bulged through it (coarse: 8 of them, 0.013 mm deep), and the injection's
    # first step released that penalty force (1.3e-2 N, 4× the largest elastic residual)
    hooks: dict[str, list] = {"residual_hooks": [], "jacobian_hooks": []}
    if params.contact:
        bore = NodalContact(shell.u, {"cartridge": InjectorLayout().cartridge(params)},
                            params.contact_stiffness, excluded=vertices)
        hooks = {"residual_hooks": [bore.residual_hook], "jacobian_hooks": [bore.jacobian_hook]}
    relax = NonlinearSolver(shell.residual(), shell.u, [dolfinx.fem.dirichletbc(held, vertices)],
                            jacobian=shell.jacobian(), options=lens_newton(ctx), timings=ctx.timings, **hooks)
    # the fold's layers are ≈ 0.03 mm apart and the midpoints move up to 0.07 mm: without the
    # barrier (and its CCD-limited updates) they relax through the other layer; the held
    # vertices' rows stay Dirichlet rows
    held_dofs = (3 * vertices[:, None] + np.arange(3)).ravel()
    self_contact = lens_self_contact(shell, params, excluded_dofs=held_dofs)
    if self_contact is not None:
        self_contact.check(what="the P2 lens on the P1 fold")
        self_contact.attach(relax)
    converged, iterations = relax.solve()
    if not converged:
        raise SolveFailure(f"fold_seed=p1: the P2 edge midpoints on the P1 fold did not relax in "
                           f"{iterations} Newton iterations")
    ctx.result.quantities.update(fold_seed="p1", fold_steps=len(history.time), fold_wall_seconds=history.wall,
                                 fold_newton_iterations=int(sum(history.newton)),
                                 fold_self_intersecting=bool(any(history.intersecting)),
                                 seed_relax_iterations=iterations,
                                 seed_p1_strain_energy=lens.shell.energy(folded))
    return lens, folded


def refuse_on_p1(params, defaults: dict) -> None:
    """One ParameterError for the first option the P1 scenes do not model, set off its default."""
    for name, default in defaults.items():
        if getattr(params, name) != default:
            raise ParameterError(name, f"model=p1-rotation-free runs with {name}={default} "
                                 "(this option is the p2-c0ip model's)")


def _run_rotation_free(ctx: RunContext, params: Parameters) -> None:
    """The fold (or ``folded_state``) and the injection on the P1 lens; the wall time from the
    start of the fold to the end of the injection, the frames' drawing and writing left out, is
    ``operation_wall_seconds`` (the frames' is ``frames_wall_seconds``: ≈ 0.3–0.7 s a picture
    here, VTK's software rendering, more than a P1 step)."""
    from eyemech.problems.lens import fast_injection
    from eyemech.problems.lens.fast_frames import FrameWriter

    begin = time.perf_counter()
    lens = fast_injection.fast_lens(ctx, params)
    q = ctx.result.quantities
    if params.folded_state:
        folded = fast_injection.load_state(Path(params.folded_state), lens)
    else:
        with ctx.timings("folding"):
            folded, fold_history = fast_injection.fold(params, lens)
        q.update(fold_steps=len(fold_history.time), fold_wall_seconds=fold_history.wall,
                 fold_newton_iterations=int(sum(fold_history.newton)),
                 fold_step_cuts=int(sum(fold_history.cuts)),
                 fold_self_intersecting=bool(any(fold_history.intersecting)))
        if ctx.out is not None and ctx.rank0:
            fast_injection.save_state(ctx.out / "folded_state.npz", lens, folded)
            ctx.result.fields.append("folded_state.npz")
    frames = FrameWriter(ctx, lens, stem="injection", picture_stem="frame")
    injection = fast_injection.Injection(params, lens, folded, ctx.record_step, frames)
    with ctx.timings("time_stepping"):
        injection.run()
    q.update(model=params.model, **injection.quantities(),
             operation_wall_seconds=time.perf_counter() - begin - frames.seconds,
             frames_wall_seconds=frames.seconds)
    if ctx.out is not None and ctx.rank0:
        frames.finish("injection.gif")


FOLD_CODE = ("problems/lens/fold.py", "problems/lens/model.py", "problems/lens/injector.py",
             "problems/contact/rigid_wall.py", "problems/contact/ipc.py",
             "problems/solve/time_integration.py", "problems/solve/driver.py", "forms", "meshes")


def fold_cache_path(params: Parameters) -> Path:
    """Where the fold of these lens and fold parameters is cached: a hash of every
    ``FoldParameters`` value but ``frames``, of the source of the code the fold runs
    (any edit makes a new key) and of the dolfinx version. Why: the default injection folds
    first (≈ 10–20 min at the paper's resolution); a fold is only reused for the same lens."""
    import hashlib
    import json
    import os

    import dolfinx

    values = {f.name: getattr(params, f.name) for f in dataclasses.fields(FoldParameters)
              if f.name != "frames"}
    digest = hashlib.sha256(json.dumps(values, sort_keys=True, default=str).encode())
    digest.update(dolfinx.__version__.encode())
    root = Path(__file__).resolve().parents[1]
    for name in FOLD_CODE:
        path = root / name
        for source in sorted(path.rglob("*.py")) if path.is_dir() else [path]:
            digest.update(source.read_bytes())
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "eyemech" / "iol-fold"
    return cache / f"{params.resolution}-{digest.hexdigest()[:16]}.npz"


def _store_fold(path: Path, shell: LensShell, ctx: RunContext) -> None:
    """Save the fold in the cache; a cache that cannot be written only costs the next run a
    fold. Collective: rank 0 writes, and every rank learns whether it could (the gather in
    ``save_state`` is made by all ranks or by none)."""
    error = None
    if ctx.rank0:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            error = str(err)
    error = ctx.comm.bcast(error, root=0)
    if error is None:
        try:
            save_state(path, shell, ctx.comm)  # the write on rank 0 may fail there alone
        except OSError as err:
            error = str(err)
        error = ctx.comm.bcast(error, root=0)
    if error is None:
        ctx.result.quantities["fold_cache"] = str(path)
    elif ctx.rank0:
        print(f"iol-injection: fold not cached ({error})")


def _refuse_intersecting(params: Parameters, shell: LensShell) -> None:
    """A saved fold that passes through itself cannot start a barrier (infinite energy)."""
    if not (params.self_contact and params.contact):
        return
    from eyemech.problems.contact.ipc import SelfContactError

    try:
        lens_self_contact(shell, params).check(what=f"the folded state {params.folded_state}")
    except SelfContactError as err:
        raise ParameterError("folded_state", f"{err} (it was folded without self-contact: rerun "
                             "iol-fold)") from None


class FluidDrag:
    """The viscoelastic fluid's drag on the lens relative to the fluid's velocity:
    f = −c M (v − v_f), i.e. a residual term −c M v_f next to the scheme's c M v.

    Why: the damping c stands for the fluid (c = μ/(δ ρ h), see ``damping``), and that fluid
    is pushed through the cartridge by the plunger ahead of and around the lens. A drag on the
    absolute velocity resists the lens' rigid translation with c m v ≈ 2e4 /s × 1e-8 t ×
    40 mm/s ≈ 8e-3 N — about a thousand times the Euler load of a haptic (π² EI/(4L²) ≈ 1e-5 N):
    the plunger then crushes the trailing haptic before the lens moves (Δt is cut to
    0.1 ms). Fluid velocity (along the axis, lagged at the start of each step): the plunger's
    speed times the bore's area ratio (R_bore/R(x))² inside the injector (incompressible plug
    flow), then a jet decaying as exp(−(x − tip)/``jet_length``) in the capsule."""

    def __init__(self, dynamics: ImplicitDynamics, shell: LensShell, bore, jet_length: float):
        self.dynamics, self.shell, self.bore, self.jet_length = dynamics, shell, bore, jet_length
        self.X = shell.node_coordinates()
        self.v_fluid = dynamics.M.createVecRight()
        self.drag = dynamics.M.createVecRight()

    def fluid_velocity(self, speed: float) -> np.ndarray:
        """Axial fluid speed (mm/s) at the current node positions."""
        x = (self.X + self.shell.u.x.array.reshape(-1, 3))[:, 0]
        return axial_fluid_speed(x, speed, self.bore, self.jet_length)

    def begin_step(self, speed: float) -> None:
        axial = self.fluid_velocity(speed)
        # v_fluid is M's unghosted right vector: its ``array`` is the owned rows, which are the
        # first owned nodes of u's local array. Not its localForm(): PETSc gives that only for
        # ghosted vectors (a sequential one is its own), on N > 1 ranks a null Vec whose empty
        # array swallowed the values, so the drag was silently zero and the 2-rank path left
        # the serial one at the first step (tests/test_parallel.py::test_fluid_drag_equals_serial)
        values = np.zeros((self.v_fluid.getLocalSize() // 3, 3))
        values[:, 0] = axial[: len(values)]
        self.v_fluid.setArray(values.ravel())
        self.dynamics.M.mult(self.v_fluid, self.drag)
        self.drag.scale(-self.dynamics.damping)

    def residual_hook(self, _x, F) -> None:
        F.axpy(1.0, self.drag)


class Injection:
    """The injection of a folded lens, built once: the plunger pushing the optic through
    the tapered cartridge into the capsule, the walls' nodal contact with friction, the
    fluid drag, the lens' self-contact and the damped implicit dynamics."""

    def __init__(self, params: Parameters, ctx: RunContext, shell: LensShell):
        self.params, self.ctx, self.shell = params, ctx, shell
        layout = InjectorLayout()
        self.axis = params.axis_point()
        x = shell.node_coordinates() + shell.u.x.array.reshape(-1, 3)
        self.start = ctx.comm.allreduce(float(x[:, 0].min()), op=MPI.MIN) - 0.05
        # the head fills the bore and more: a node sliding along the wall must not leave its reach
        self.plunger = Plunger(self.start, self.axis, params.bore_radius + 0.5)
        self.obstacles = {"cartridge": layout.cartridge(params, lip=layout.nozzle_lip),
                          "plunger": self.plunger, "capsule": layout.capsule(params)} \
            if params.contact else {}
        walls = {k: v for k, v in self.obstacles.items() if k != "plunger"}
        self.contact = NodalContact(shell.u, walls, params.contact_stiffness, slip=params.friction_slip,
                                    friction={"capsule": params.capsule_friction,
                                              "cartridge": params.cartridge_friction})
        # the plunger on the optic only: a flat head pressed on the tip of a 0.13 mm haptic strip
        # (Euler load ~1e-5 N against the ~1e-2 N the lens needs to leave the nozzle) crumples
        # it against the optic; Newton then crawls at Δt ≈ 0.1 ms and failed (t = 0.243 s, coarse)
        haptics = shell.nodes_of("haptic") if params.plunger_engages == "optic" else None
        if haptics is not None:
            haptics = np.setdiff1d(haptics, shell.nodes_of("optic"))
        self.pushing = NodalContact(shell.u, {"plunger": self.plunger} if params.contact else {},
                                    params.contact_stiffness, excluded=haptics)
        self.dynamics = ImplicitDynamics(shell.u, shell.mass(), [], scheme_name=params.scheme,
                                         damping=params.damping)
        self.fluid = FluidDrag(self.dynamics, shell, layout.cartridge(params), params.jet_length) \
            if params.fluid_carried else None
        self.solver = self._solver()
        # contact=false is the deformation-only benchmark: no self-contact either
        self.self_contact = lens_self_contact(shell, params) if params.contact else None
        if self.self_contact is not None:
            self.self_contact.check(what="the folded lens")
            self.self_contact.attach(self.solver)
        if params.scheme != "backward-euler":
            self.dynamics.initial_acceleration(shell.residual())
        stop = layout.tip + params.plunger_overshoot
        self.motion = PlungerMotion(params.plunger_speed, params.start_ramp, stop - self.start)
        self.push_time = self.motion.push_time
        self.end = self.push_time + params.settle_time
        self.twist = np.radians(params.injector_twist) / self.motion.travel(self.push_time)  # rad/mm
        self.self_distance = self_distance_probe(shell.u) if self.self_contact is None else None
        self.strain = StrainProbe(shell)
        self.frames_dir = ctx.out if ctx.pictures else None
        # the frames as .vtu + injection.pvd for notebooks (with the PNGs, or alone under --no-pictures)
        self.history = InjectionHistory(
            series=ctx.pyvista_series(stem="injection"))
        self.last_frame = (0.0, 0)  # time and step of the last frame

    def _solver(self) -> NonlinearSolver:
        # the shell's Jacobian written out (equal to UFL's derivative to 2e-16,
        # tests/test_iol_speed.py; about half its assembly time): the same Newton iterates,
        # cheaper iterations
        hooks = [self.dynamics.residual_hook, self.contact.residual_hook, self.pushing.residual_hook]
        if self.fluid is not None:
            hooks.append(self.fluid.residual_hook)
        return NonlinearSolver(self.shell.residual(), self.shell.u, [], jacobian=self.shell.jacobian(),
                               options=_newton(self.ctx, self.params), timings=self.ctx.timings,
                               residual_hooks=hooks,
                               jacobian_hooks=[self.dynamics.jacobian_hook, self.contact.jacobian_hook,
                                               self.pushing.jacobian_hook])

    # -- one step ------------------------------------------------------------------------
    def _twisted(self, t: float, dt: float) -> dict:
        """The cartridge wall's turn over the step (t − dt, t]: the anchor of its friction."""
        if self.twist == 0.0:
            return {}
        angle = self.twist * (self.motion.travel(t) - self.motion.travel(t - dt))
        return {"cartridge": turn_about_x(self.axis, angle)}

    def apply(self, t: float, dt: float) -> None:
        """Set the step ending at t: the plunger's position, Δt, the fluid's velocity and
        the contacts' lagged state (u is still u_n here)."""
        self.plunger.position = self.start + self.motion.travel(t)
        self.dynamics.set_step(dt)
        if self.fluid is not None:
            self.fluid.begin_step(self.motion.speed_at(t))
        if self.self_contact is not None:
            self.self_contact.begin_step()
        self.contact.begin_step(self._twisted(t, dt))

    def _is_frame(self, record) -> bool:
        # frames evenly in simulated time (the animation's speed is the scene's), not in steps:
        # where Δt is cut to 0.2 ms every-n-steps frames bunch up and cost their rendering
        last_time, last_step = self.last_frame
        return (record.step - last_step >= self.params.frames_every
                and record.load >= last_time + self.params.frame_interval - 1e-9) \
            or record.step == 1 or record.load >= self.end - 1e-9

    def converged(self, record) -> None:
        """Advance the dynamics and record, measure and draw the converged step."""
        ctx, h = self.ctx, self.history
        self.history.time_error.add(step_error(self.dynamics, self.solver.snes.getKSP()))
        self.dynamics.advance()
        depth = {**self.contact.max_penetration(), **self.pushing.max_penetration()}
        frame = self._is_frame(record)
        if frame:
            self.last_frame = (record.load, record.step)
        with ctx.timings("measurements"):
            h.add(record.load, record.increment, record.iterations, record.cuts,
                  max(depth.values(), default=0.0), self.strain.haptic_max())
            if self.self_contact is not None:  # C++, cheap: every step
                h.self_distance.append(self.self_contact.min_distance())
                h.intersecting.append(self.self_contact.intersecting())
            elif self.self_distance is not None:  # the distance search on frames, intersections always
                distance, crossing = self.self_distance(distances=frame)
                h.self_distance.append(distance)
                h.intersecting.append(crossing)
        ctx.record_step(step=record.step, time=record.load, newton_iterations=record.iterations,
                        cuts=record.cuts, **record.counts(), plunger=self.plunger.position,
                        max_penetration_mm=h.penetration[-1], kinetic_energy=self.dynamics.kinetic_energy())
        if frame:
            with ctx.timings("output"):
                write_frame_grid(h.series, self.shell, record.load, self.strain)
        if self.frames_dir is not None and frame:
            path = self.frames_dir / f"frame_{len(h.frames):03d}.png"
            with ctx.timings("output"):
                render_frame(self.shell, path, f"iol-injection  t = {record.load:.2f} s", self.obstacles)
            h.frames.append(path)

    # -- the loop ------------------------------------------------------------------------
    def run(self) -> InjectionHistory:
        """Push and let the lens settle; Δt is cut on failure and grows back after easy steps."""
        ctx, h = self.ctx, self.history
        steps = int(np.ceil(self.end / self.params.time_step))
        begin = time.perf_counter()
        solver_before = ctx.timings.seconds["assembly"] + ctx.timings.seconds["solve"]
        with ctx.timings("time_stepping"):
            follow_path(self.solver, self.apply,
                        Stepping(0.0, steps * self.params.time_step, quantity="time", unit="s",
                                 initial_step=1.0 / steps,
                                 max_step=1.0 / steps, grow=2.0, min_step=1e-3 / steps,
                                 stops=(self.push_time,), easy_iterations=EASY_ITERATIONS),
                        on_converged=self.converged, label=SCENE.name, quiet=ctx.options.quiet)
        h.wall = time.perf_counter() - begin
        h.end = steps * self.params.time_step
        h.solver_seconds = ctx.timings.seconds["assembly"] + ctx.timings.seconds["solve"] - solver_before
        h.contact_seconds = self.contact.seconds + self.pushing.seconds
        return h


def report(params: Parameters, ctx: RunContext, injection: Injection) -> None:
    """The quantities of the finished injection: where the lens landed and how, and the cost."""
    shell, h, self_contact = injection.shell, injection.history, injection.self_contact
    layout = InjectorLayout()
    capsule = layout.capsule(params)
    x = shell.node_coordinates() + shell.u.x.array.reshape(-1, 3)
    exited = ctx.comm.allreduce(float(x[:, 0].min()), op=MPI.MIN) > layout.tip
    center = optic_center(shell)
    normal = optic_normal(shell)
    flatness = optic_flatness(shell)
    deformation = h.solver_seconds - h.contact_seconds
    q = ctx.result.quantities
    q.update(h.quantities())
    q.update(
        steps_per_second_deformation=len(h.time) / max(deformation, 1e-12),
        self_contact_forces=(self_contact_kind(params) if params.contact
                             else "not applied (contact=false)"),
        self_contact_seconds=getattr(self_contact, "seconds", 0.0),
        ccd_limited_updates=len(getattr(self_contact, "step_limits", [])),
        lens_exited=bool(exited),
        optic_normal_z=float(normal[2]),
        optic_flipped=bool(normal[2] < 0.0),
        optic_flatness=flatness, optic_unrolled=bool(flatness > 0.9),
        end_time_s=h.end,
        final_decentration_mm=float(np.hypot(*(center - capsule.center)[:2])),
        final_optic_center=center.tolist(),
        contact_seconds=h.contact_seconds,
        triangles=shell.mesh.topology.index_map(2).size_global,
        nodes=shell.mesh.geometry.index_map().size_global, dofs=shell.dofs())
    ctx.result.fields.extend(h.series.files)
    if h.frames and ctx.rank0:
        ctx.result.pictures += [p.name for p in h.frames]
        gif = write_animation(h.frames, ctx.out / "injection.gif")
        if gif:
            ctx.result.pictures.append(gif)


SCENE = Scene(name="iol-injection", kind="scene", parameters=Parameters, run=run,
              summary="folded intra-ocular lens pushed through the tapered cartridge, unfolding in the "
                      "capsule (implicit damped dynamics, rigid contact)")
