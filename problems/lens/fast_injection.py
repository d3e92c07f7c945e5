r"""The fold and the injection on the rotation-free P1 lens (``model=p1-rotation-free`` of
``iol-fold`` and ``iol-injection``; the model: :mod:`eyemech.problems.lens.rotation_free`).

The same scene as the P2 one (:mod:`eyemech.problems.lens.fold`,
:mod:`eyemech.problems.iol_injection`), acting on the P1 vertices:

- **fold**: the optic's vertices follow the isometric roll about the injector axis
  (κ(t) = (t/T)/``fold_radius``, prescribed dofs of ``Dynamics``); the loading chamber
  (``InjectorLayout.cartridge`` with a shrinking ``opening``) pushes the haptics in through the
  smoothed nodal penalty (``surface_contact.NodalObstacles``, the optic excluded); backward
  Euler with ``fold_damping``.
- **injection**: the cartridge bore with its rounded lip, the capsule and the plunger head
  (on the optic's vertices only, unless ``plunger_engages=lens``) as nodal penalty walls; the
  fluid's drag on the lens' velocity relative to the fluid (``FluidDrag``'s plug flow and
  jet, lagged per step) as the external force c M v_f of the backward-Euler residual
  R = ∇Π − c M v_f + M[(1/Δt² + c/Δt)(u − u_n) − v_n/Δt].
- **self-contact** (both): ipctk's barrier on the P1 triangles with CCD-limited Newton
  updates and lagged smoothed Coulomb friction μ = ``friction`` (``surface_contact.SurfaceSelfContact``),
  and ipctk's exact intersection test after every converged step.
- **wall friction**: ``capsule_friction`` and ``cartridge_friction``, lagged smoothed Coulomb
  on the nodal walls (``NodalObstacles.begin_step``); with ``injector_twist`` the cartridge's
  anchors turn with it, as in the P2 scene.

Steps that Newton does not converge (or whose prescribed motion would cross the surface) are
halved and retried; Δt grows back ×2 after steps of ≤ ``EASY_ITERATIONS`` iterations, as in
the P2 scenes. Newton: ‖R‖ ≤ max(10⁻⁶ ‖R(start)‖, 10⁻⁹ N), the P2 scenes' ``lens_newton``
tolerances.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from eyemech.problems.lens.fast_frames import FrameWriter
from eyemech.problems.lens.fold import EASY_ITERATIONS, blocked_dofs
from eyemech.problems.lens.history import InjectionHistory
from eyemech.problems.lens.injector import Plunger, turn_about_x
from eyemech.problems.lens.model import InjectorLayout, require_ipctk, rolled
from eyemech.problems.lens.push import PlungerMotion, axial_fluid_speed
from eyemech.problems.lens.rotation_free import Dynamics, FastLens, MeshInputError
from eyemech.problems.lens.surface_contact import NodalObstacles, SurfaceSelfContact
from eyemech.problems.lens.time_error import TimeErrorTally, rotation_free_step_error
from eyemech.problems.run.parameters import ParameterError
from eyemech.problems.solve.stepping import StepController

RTOL, ATOL = 1e-6, 1e-9  # lens_newton's: relative, and N (shell forces ~1e-4 N)
MAX_ITERATIONS = 25


class StepFailure(RuntimeError):
    """Δt was cut below ``min_fraction`` of the scene's time step."""


@dataclasses.dataclass
class StepRecord:
    time: float
    dt: float
    iterations: int
    cuts: int


def march(dyn: Dynamics, apply: Callable[[float, float], None], end: float, time_step: float,
          on_converged: Callable[[StepRecord], None], stops: tuple[float, ...] = (),
          min_fraction: float = 1e-3, time_error: TimeErrorTally | None = None) -> None:
    """Backward-Euler steps from t = 0 to ``end`` (landing on each of ``stops``): ``apply(t, Δt)``
    sets the step ending at t, then ``dyn.step()``; a step that fails is undone and halved (down
    to ``min_fraction`` of ``time_step``), an easy one's successor doubled (up to ``time_step``)."""
    t = 0.0
    steps = StepController(time_step, largest=time_step, smallest=min_fraction * time_step,
                           cut_factor=0.5, max_cuts=None, grow_factor=2.0,
                           easy_effort=EASY_ITERATIONS, grow_after_cut=True)
    while t < end - 1e-9 * time_step:
        target = min(t + steps.step, end)
        for stop in stops:
            if t + 1e-9 * time_step < stop < target - 1e-9 * time_step:
                target = stop
        h = target - t
        saved = dyn.save_state()
        apply(target, h)
        dyn.dt = h
        try:
            iterations = dyn.step()
        except RuntimeError as err:
            dyn.restore_state(saved)
            if not steps.cut(attempted=h):
                raise StepFailure(f"Δt cut to {steps.step:.3g} s at t = {t:.4g} s ({err})") from err
            continue
        t = target
        if time_error is not None:
            time_error.add(rotation_free_step_error(dyn))
        on_converged(StepRecord(t, h, iterations, steps.cuts))
        steps.accept(iterations)


def fast_lens(ctx, params) -> FastLens:
    """The rotation-free P1 lens of these parameters (one ParameterError for a mesh it cannot use)."""
    if ctx.comm.size != 1:
        raise ParameterError("model", "model=p1-rotation-free runs on one rank")
    with ctx.timings("mesh"):
        try:
            return FastLens.build(params)
        except (MeshInputError, ValueError) as err:
            raise ParameterError("mesh_size", f"the rotation-free lens cannot use this mesh: {err}") from err


# -- measurements on the P1 lens -----------------------------------------------------------------
def surface_strain(lens: FastLens, u: np.ndarray, triangles: np.ndarray) -> float:
    """Largest surface strain over ``triangles`` (``cell_surface_strain``)."""
    return float(cell_surface_strain(lens, u, triangles).max(initial=0.0))


def cell_surface_strain(lens: FastLens, u: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Largest surface strain of each of ``triangles``: max over both faces of |eig(E ± h/2 κ)|,
    E the CST Green strain, κ = K(x) − K(X) the element's change of curvature (``StrainProbe``'s
    measure on the P2 lens)."""
    shell = lens.shell
    if not len(triangles):
        return np.zeros(0)
    x = shell.X + u.reshape(-1, 3)
    tri = shell.tri[triangles]
    a = np.einsum("tic,tia->tac", x[tri], shell.d[triangles])
    E = 0.5 * (np.einsum("tac,tbc->tab", a, a) - np.eye(2))
    H = np.einsum("tki,tic->tkc", shell.B[triangles], x[shell.nodes[triangles]]) + shell.b[triangles]
    c = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
    K = np.einsum("tkc,tc->tk", H, c / np.linalg.norm(c, axis=1)[:, None]) - shell.K0[triangles]
    kappa = np.stack([np.stack([K[:, 0], K[:, 2]], -1), np.stack([K[:, 2], K[:, 1]], -1)], -1)
    half = 0.5 * shell.thickness[triangles][:, None, None]
    return np.maximum(np.abs(np.linalg.eigvalsh(E + half * kappa)).max(axis=1),
                      np.abs(np.linalg.eigvalsh(E - half * kappa)).max(axis=1))


def optic_measures(lens: FastLens, u: np.ndarray) -> dict:
    """The optic's mean normal (area weighted; +z in the reference), flatness |∫n dA|/∫dA
    (``model.optic_flatness``) and centre (mean of its vertices)."""
    x = lens.shell.X + u.reshape(-1, 3)
    tri = lens.shell.tri[lens.optic_triangles]
    c = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
    total = c.sum(axis=0)
    return {"normal": total / max(np.linalg.norm(total), 1e-300),
            "flatness": float(np.linalg.norm(total) / np.linalg.norm(c, axis=1).sum()),
            "center": x[lens.optic_nodes].mean(axis=0)}


def self_contact(lens: FastLens, params) -> SurfaceSelfContact | None:
    if not params.self_contact:
        return None
    require_ipctk()
    return SurfaceSelfContact(lens.shell.X, lens.shell.tri, params.self_contact_distance,
                              params.self_contact_stiffness, friction=params.friction,
                              slip=params.friction_slip)


def save_state(path: Path, lens: FastLens, u: np.ndarray) -> None:
    """The P1 vertices' displacement as ``model.save_state`` writes it (coordinates, displacement)."""
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, coordinates=lens.shell.X, displacement=u.reshape(-1, 3))
    tmp.replace(path)


def load_state(path: Path, lens: FastLens) -> np.ndarray:
    """The displacement of the P1 vertices from a saved state of either model (the P2 state's
    nodes include the vertices), matched by coordinates."""
    from scipy.spatial import cKDTree

    data = np.load(path)
    distance, index = cKDTree(data["coordinates"]).query(lens.shell.X)
    if np.max(distance, initial=0.0) > 1e-8:
        raise ParameterError("folded_state", f"{path} was saved for another lens mesh "
                             f"(vertices {np.max(distance):.3g} mm apart)")
    return np.asarray(data["displacement"])[index].ravel()


def p2_displacement(lens: FastLens, u: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """The P1 lens' displacement ``u`` (3 per vertex) at the P2 lens' nodes ``nodes`` (n, 3
    reference coordinates, the same gmsh mesh: its vertices and its edge midpoints), (n, 3).
    A vertex takes its own value. An edge midpoint m takes the mean, over the edge's triangles T
    with a full patch (no boundary edge), of the bending model's quadratic patch fit
    (``patch_operators``: the quadratic through T's vertices and the three across its edges),
    q_T(m) = [1 ξ η ξ² ξη η²](m) · F_T⁻¹ u_patch, exact for a quadratic displacement; an edge
    of no such triangle takes the chord's midpoint. So the P2 lens starts on a curved midsurface
    through the P1 fold's vertices rather than on its chords (a chord on a fold of radius R lies
    ℓ²/(8R) inside it: 0.05 mm for ℓ = 0.6 mm on R = 1 mm). Nodes that are neither raise
    ParameterError."""
    from scipy.spatial import cKDTree

    from eyemech.problems.lens.rotation_free import patch_operators

    shell = lens.shell
    U = np.asarray(u, dtype=float).reshape(-1, 3)
    patch_nodes, _, _, _, _, _, fits = patch_operators(shell.X, shell.tri, shell.opposite,
                                                       shell.boundary_kind, shell.material.poisson_ratio)
    n_tri = len(shell.tri)
    patch = U[patch_nodes]  # (triangles, 6, 3); a boundary slot's row is a condition with 0 right side
    patch[:, 3:][shell.opposite < 0] = 0.0
    coefficients = np.einsum("tij,tjc->tic", fits["inverse"], patch)
    # edge k of triangle t joins vertices k+1 and k+2 (the slot 3 + k is across it)
    first, second = (np.arange(3) + 1) % 3, (np.arange(3) + 2) % 3
    xi = fits["xi"]
    midpoint_xi = 0.5 * (xi[:, first] + xi[:, second])  # (triangles, 3, 2)
    basis = np.stack([np.ones((n_tri, 3)), midpoint_xi[..., 0], midpoint_xi[..., 1], midpoint_xi[..., 0] ** 2,
                      midpoint_xi[..., 0] * midpoint_xi[..., 1], midpoint_xi[..., 1] ** 2], axis=-1)
    value = np.einsum("tkj,tjc->tkc", basis, coefficients).reshape(-1, 3)
    ends = np.sort(np.stack([shell.tri[:, first], shell.tri[:, second]], axis=-1).reshape(-1, 2), axis=1)
    edges, inverse = np.unique(ends, axis=0, return_inverse=True)
    # only full patches: a boundary slot's M_νν = 0 bends the fit away from a fold that curves
    # across the free edge (rolled lens, R = 1 mm: 0.19 mm off at a boundary midpoint)
    full = np.repeat(np.all(shell.opposite >= 0, axis=1), 3).astype(float)
    total = 0.5 * (U[edges[:, 0]] + U[edges[:, 1]])  # the chord where no full patch holds the edge
    count = np.zeros(len(edges))
    np.add.at(count, inverse.ravel(), full)
    fitted = np.zeros((len(edges), 3))
    np.add.at(fitted, inverse.ravel(), full[:, None] * value)
    total[count > 0] = fitted[count > 0] / count[count > 0, None]
    points = np.vstack([shell.X, 0.5 * (shell.X[edges[:, 0]] + shell.X[edges[:, 1]])])
    values = np.vstack([U, total])
    distance, index = cKDTree(points).query(np.asarray(nodes, dtype=float))
    if np.max(distance, initial=0.0) > 1e-8:
        raise ParameterError("fold_seed", f"the P2 lens' nodes are not the P1 lens' vertices and edge "
                             f"midpoints ({np.max(distance):.3g} mm apart)")
    return values[index]


def record_converged(history: InjectionHistory, step: StepRecord, lens: FastLens, u: np.ndarray,
           walls: NodalObstacles | None, contact: SurfaceSelfContact | None) -> None:
    """The converged ``step`` of the P1 lens into ``history``."""
    x = lens.shell.X + u.reshape(-1, 3)
    history.add(step.time, step.dt, step.iterations, step.cuts,
                walls.max_penetration(x) if walls is not None else 0.0,
                surface_strain(lens, u, lens.haptic_triangles))
    if contact is not None:
        history.self_distance.append(contact.min_distance(x))
        history.intersecting.append(contact.intersecting(x))


def quantities(history: InjectionHistory, params) -> dict:
    """``InjectionHistory.quantities`` and the P1 solver's: CPU time, factorisations, CCD limits."""
    steps = len(history.time)
    return dict(
        history.quantities(), steps_per_second_cpu=steps / max(history.cpu, 1e-12), cpu_seconds=history.cpu,
        self_contact_forces=(f"ipctk barrier on the P1 triangles (d̂ = {params.self_contact_distance} mm), "
                             f"CCD-limited updates, friction μ = {params.friction}" if params.self_contact
                             else "not applied"),
        factorisations=history.counts.get("factorisations", 0),
        pattern_growths=history.counts.get("pattern_growths", 0),
        ccd_limited_updates=history.counts.get("step_limits", 0))


def _run(dyn: Dynamics, history: InjectionHistory, *args, **kwargs) -> None:
    wall, cpu = time.perf_counter(), time.process_time()
    march(dyn, *args, **kwargs, time_error=history.time_error)
    history.wall, history.cpu = time.perf_counter() - wall, time.process_time() - cpu
    history.counts = dict(dyn.counts)


def _dynamics(lens: FastLens, params, damping: float, fixed=None) -> Dynamics:
    return Dynamics(lens.shell, params.time_step, damping, fixed=fixed, rtol=RTOL, atol=ATOL,
                    max_iterations=MAX_ITERATIONS)


# -- the fold -------------------------------------------------------------------------------------
def fold(params, lens: FastLens, record_step: Callable[..., None] | None = None,
         frames: FrameWriter | None = None) -> tuple[np.ndarray, InjectionHistory]:
    """The fold of ``lens.fold`` on the P1 lens from the flat state: (displacement, history);
    ``frames``: ``params.frames`` of them, evenly in steps and the last, as the P2 fold."""
    shell = lens.shell
    optic = lens.optic_nodes
    X_optic = shell.X[optic]
    axis = params.axis_point()
    chamber = InjectorLayout().cartridge(params)
    reach = np.max(np.hypot(shell.X[:, 1] - axis[1], shell.X[:, 2] - axis[2]))
    opening = reach + 0.3 - params.bore_radius
    walls = NodalObstacles({"chamber": chamber}, params.contact_stiffness, excluded={"chamber": optic})
    dyn = _dynamics(lens, params, params.fold_damping, fixed=blocked_dofs(optic))
    dyn.set_obstacles(walls)
    contact = self_contact(lens, params)
    if contact is not None:
        dyn.set_contact(contact)
    dyn.reset(np.zeros(shell.n_dofs))
    history = InjectionHistory()
    every = max(1, int(round(params.fold_time / params.time_step)) // params.frames)

    def apply(t: float, _dt: float) -> None:
        fraction = t / params.fold_time
        dyn.prescribed = (rolled(X_optic, fraction / params.fold_radius) - X_optic).ravel()
        chamber.opening = (1.0 - fraction) * opening
        if contact is not None:
            contact.begin_step(shell.X + dyn.u.reshape(-1, 3))

    def converged(record: StepRecord) -> None:
        record_converged(history, record, lens, dyn.u, walls, contact)
        if record_step is not None:
            record_step(step=len(history.time), time=record.time, newton_iterations=record.iterations,
                        cuts=record.cuts, max_penetration_mm=history.penetration[-1])
        if frames is not None and (len(history.time) % every == 0 or record.time >= params.fold_time - 1e-9):
            frames.write(record.time, dyn.u, f"iol-fold (P1)  t = {record.time:.2f} s", {"chamber": chamber})

    try:
        _run(dyn, history, apply, params.fold_time, params.time_step, converged)
    except StepFailure as err:
        raise ParameterError("time_step", f"model=p1-rotation-free: the fold failed ({err}); "
                             "take a smaller time_step") from err
    return dyn.u.copy(), history


# -- the injection --------------------------------------------------------------------------------
class Injection:
    """The injection of the folded P1 lens (``iol_injection.Injection`` on the vertices)."""

    def __init__(self, params, lens: FastLens, folded: np.ndarray,
                 record_step: Callable[..., None] | None = None, frames: FrameWriter | None = None):
        """``frames``: as the P2 injection's, at least ``frames_every`` steps and ``frame_interval``
        seconds apart, and the first and last steps."""
        self.params, self.lens, self.record_step, self.frames = params, lens, record_step, frames
        self.last_frame = (0.0, 0)  # time and step of the last frame
        shell = lens.shell
        layout = InjectorLayout()
        self.layout = layout
        axis = params.axis_point()
        x = shell.X + folded.reshape(-1, 3)
        self.start = float(x[:, 0].min()) - 0.05
        self.plunger = Plunger(self.start, axis, params.bore_radius + 0.5)
        self.capsule = layout.capsule(params)
        self.drawn = {"cartridge": layout.cartridge(params, lip=layout.nozzle_lip), "plunger": self.plunger,
                      "capsule": self.capsule}  # the walls in the pictures
        self.walls = None
        self.dyn = _dynamics(lens, params, params.damping)
        if params.contact:
            excluded = {}
            if params.plunger_engages == "optic":
                haptic_nodes = np.unique(shell.tri[lens.haptic_triangles])
                excluded["plunger"] = np.setdiff1d(haptic_nodes, lens.optic_nodes)
            self.walls = NodalObstacles({"cartridge": layout.cartridge(params, lip=layout.nozzle_lip),
                                         "plunger": self.plunger, "capsule": self.capsule},
                                        params.contact_stiffness, excluded=excluded,
                                        friction={"capsule": params.capsule_friction,
                                                  "cartridge": params.cartridge_friction},
                                        slip=params.friction_slip)
            self.dyn.set_obstacles(self.walls)
        self.contact = self_contact(lens, params) if params.contact else None
        if self.contact is not None:
            if self.contact.intersecting(x):
                raise ParameterError("folded_state", "the folded lens passes through itself: fold it with "
                                     "self_contact=true")
            self.dyn.set_contact(self.contact)
        self.dyn.reset(folded)
        self.bore = layout.cartridge(params)
        stop = layout.tip + params.plunger_overshoot
        self.motion = PlungerMotion(params.plunger_speed, params.start_ramp, stop - self.start)
        self.twist = np.radians(params.injector_twist) / self.motion.travel(self.motion.push_time)  # rad/mm
        self.push_time = self.motion.push_time
        self.end = self.push_time + params.settle_time
        self.history = InjectionHistory()

    def apply(self, t: float, dt: float) -> None:
        """The step ending at t: the plunger's position, the fluid's drag force c M v_f at u_n,
        the lagged friction of the walls (the cartridge turned over the step with a twisted
        injector) and of the lens on itself."""
        self.plunger.position = self.start + self.motion.travel(t)
        x = self.lens.shell.X + self.dyn.u.reshape(-1, 3)
        if self.walls is not None:
            motion = {}
            if self.twist != 0.0:
                angle = self.twist * (self.motion.travel(t) - self.motion.travel(t - dt))
                motion["cartridge"] = turn_about_x(self.params.axis_point(), angle)
            self.walls.begin_step(x, motion)
        if self.contact is not None:
            self.contact.begin_step(x)
        if self.params.fluid_carried:
            x = self.lens.shell.X[:, 0] + self.dyn.u[0::3]
            v_fluid = np.zeros((len(x), 3))
            v_fluid[:, 0] = axial_fluid_speed(x, self.motion.speed_at(t), self.bore, self.params.jet_length)
            self.dyn.force = self.params.damping * (self.dyn.M @ v_fluid.ravel())

    def converged(self, record: StepRecord) -> None:
        record_converged(self.history, record, self.lens, self.dyn.u, self.walls, self.contact)
        step = len(self.history.time)
        if self.record_step is not None:
            self.record_step(step=step, time=record.time, newton_iterations=record.iterations,
                             cuts=record.cuts, plunger=self.plunger.position,
                             max_penetration_mm=self.history.penetration[-1])
        last_time, last_step = self.last_frame
        if self.frames is not None and (
                (step - last_step >= self.params.frames_every
                 and record.time >= last_time + self.params.frame_interval - 1e-9)
                or step == 1 or record.time >= self.end - 1e-9):
            self.last_frame = (record.time, step)
            self.frames.write(record.time, self.dyn.u, f"iol-injection (P1)  t = {record.time:.2f} s",
                              self.drawn)

    def run(self) -> InjectionHistory:
        steps = int(np.ceil(self.end / self.params.time_step - 1e-9))
        try:
            _run(self.dyn, self.history, self.apply, steps * self.params.time_step, self.params.time_step,
                 self.converged, stops=(self.push_time,))
        except StepFailure as err:
            raise ParameterError("time_step", f"model=p1-rotation-free: the injection failed ({err}); "
                                 "take a smaller time_step") from err
        return self.history

    def quantities(self) -> dict:
        """``iol_injection.report``'s quantities of the finished injection."""
        u = self.dyn.u
        x = self.lens.shell.X + u.reshape(-1, 3)
        optic = optic_measures(self.lens, u)
        center = optic["center"]
        q = quantities(self.history, self.params)
        q.update(lens_exited=bool(x[:, 0].min() > self.layout.tip),
                 optic_normal_z=float(optic["normal"][2]), optic_flipped=bool(optic["normal"][2] < 0.0),
                 optic_flatness=optic["flatness"], optic_unrolled=bool(optic["flatness"] > 0.9),
                 final_decentration_mm=float(np.hypot(*(center - self.capsule.center)[:2])),
                 final_optic_center=center.tolist(),
                 end_time_s=self.history.time[-1] if self.history.time else 0.0,
                 triangles=len(self.lens.shell.tri), nodes=len(self.lens.shell.X),
                 dofs=self.lens.shell.n_dofs)
        return q
