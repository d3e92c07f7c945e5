r"""``iol-speed``: how fast the lens of seed 000 can be stepped, and where the time goes
(issue 8, item 4).

The scene: the paper-resolution lens (752 triangles, P2: 5085 unknowns) starts rolled
isometrically about the x axis onto a cylinder of radius ``roll_radius`` and is released in
the damped fluid (backward Euler, Δt = ``time_step``, mass-proportional damping): it unrolls.
``contact=true`` puts it in a rigid ellipsoidal capsule (nodal penalty, the same
``NodalContact`` as the injection) that the haptics and optic press against while unrolling —
the "whole scene" cost. It is a stand-in for ``iol-injection``: that scene needs the folded
state of ``iol-fold`` (16 min here), this one starts from a closed-form state.

Each step is solved by our own loop (not SNES) so that every phase is timed on its own —
residual assembly, Jacobian assembly, LU factorisation (MUMPS), triangular solves, contact
hooks and the rest (Python) — in wall and in CPU (process) time, the latter being what the
step costs when the shared machine is busy with other jobs. Methods:

``method``:
- ``newton``: Newton iterations to ``rtol`` (relative residual) every step.
- ``linearised``: one Newton iteration per step from u_n (the implicit step linearised
  about the last state: what SOFA does with its implicit Euler).

``jacobian`` (what the linear solves use):
- ``fresh``: the Jacobian assembled and factorised (MUMPS LU) at every iteration.
- ``lagged``: the LU factors of an older Jacobian, kept across iterations and steps and
  refreshed every ``refresh`` steps or when an iteration reduces the residual by less than
  ``stall`` (modified Newton).
- ``matrix-free``: the exact Jacobian's action by a finite difference of the residual
  (one residual assembly per product), GMRES to ``krylov_rtol`` preconditioned by the lagged
  LU factors (Newton–Krylov; Knoll & Keyes 2004). Exact Newton directions at the price of
  residuals — which cost ~1/200 of a Jacobian assembly for this shell.

``model``:
- ``p2-c0ip`` (default): the P2 C0-IP Kirchhoff–Love lens of ``LensShell`` (UFL/FFCx
  kernels, PETSc, MUMPS LU), every method above.
- ``p1-rotation-free``: the rotation-free P1 triangle of ``problems/lens/rotation_free.py``
  on the same gmsh mesh (its vertices: 1,416 unknowns at the paper's resolution), numba
  kernels with the exact Hessian, CSR pattern and PETSc matrix built once (the values
  written in place), MUMPS LDLᵀ with one symbolic analysis per run (more only where
  self-contact grows the pattern); ``method=newton`` from the start of least incremental
  potential among u_n and two extrapolations of the past positions
  (``Dynamics._predict``) with ``jacobian=fresh`` (a new Hessian and factorisation every
  iteration) or ``lagged`` (fresh factors at each step's start, kept within the step while
  an iteration reduces the residual by ``stall``). ``contact=true``: the same capsule, met
  by the P1 vertices through the same smoothed nodal penalty
  (``surface_contact.NodalObstacles``); ``surface_contact=true``: ipctk self-contact on the
  P1 triangles (``problems/lens/surface_contact.py``) and an intersection check after every
  step. ``bending``: ``edge`` (default, consistent on every mesh) or ``patch`` (faster, too
  soft on alternating-diagonal meshes: docs/iol.md §4b). Phases: ``jacobian`` is residual +
  Hessian assembly (one kernel pass), ``residual`` the gradient-only passes, ``contact``
  the barrier, CCD, obstacles and intersection checks.

Quantities: steps per second (wall, min over ``repeats``; and CPU), the per-phase split, the
history of the tip and optic-centre displacement (``tip_history``, ``optic_history`` at
every step), Newton iterations, Jacobians and factorisations, residual of the last step, the
estimated time error (``time_error_estimate_mm``; ``time_stepping=adaptive``: Δt chosen by it,
problems/lens/time_error.py, docs/iol.md §1).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import time
import weakref
from pathlib import Path
from typing import Literal, get_args

import dolfinx.fem
import dolfinx.fem.petsc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from eyemech.meshes.iol import LensGeometry
from eyemech.problems.contact.rigid_wall import NodalContact
from eyemech.problems.lens.injector import Capsule
from eyemech.problems.lens.model import LensParameters, LensShell, rolled
from eyemech.problems.lens.models import MODELS, Model
from eyemech.problems.lens.time_error import (
    P2Release,
    TimeErrorTally,
    run_adaptive_release,
    step_error,
    validate_adaptive,
)
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, ParameterError, field
from eyemech.problems.run.scene import Scene
from eyemech.problems.solve.time_integration import SCHEMES, ImplicitDynamics, SchemeName

Method = Literal["newton", "linearised"]
JacobianKind = Literal["fresh", "lagged", "matrix-free"]
Tangent = Literal["explicit", "ufl"]
Bending = Literal["edge", "patch"]
METHODS, JACOBIANS, TANGENTS = get_args(Method), get_args(JacobianKind), get_args(Tangent)
PHASES = ("residual", "jacobian", "factorisation", "solve", "contact", "other")


@dataclasses.dataclass(frozen=True)
class Parameters(LensParameters):
    model: Model = field("p2-c0ip", "the lens model: " + " | ".join(MODELS) + " (the rotation-free P1 "
                                    "triangle: numba kernels, method=newton with jacobian=fresh or "
                                    "lagged; contact=true: the capsule by nodal penalty; "
                                    "surface_contact=true: ipctk self-contact on its triangles)",
                         group=GEOMETRY)
    surface_contact: bool = field(False, "p1-rotation-free: ipctk self-contact on the P1 triangles (barrier "
                                         "d̂ = self_contact_distance, κ = self_contact_stiffness, CCD-limited "
                                         "updates, intersection check every step)", group=PHYSICS)
    bending: Bending = field("edge", "p1-rotation-free's curvature: edge (Green formula with one gradient "
                                     "per edge: consistent on every mesh) | patch (6-node quadratic fit: "
                                     "2× faster, too soft on alternating-diagonal meshes)", group=GEOMETRY)
    method: Method = field("newton", "how a step is solved: " + " | ".join(METHODS), group=SOLVER)
    jacobian: JacobianKind = field("fresh", "the Jacobian of the linear solves: " + " | ".join(JACOBIANS),
                                   group=SOLVER)
    refresh: int = field(10, "lagged / matrix-free: a new Jacobian + factorisation every this many steps",
                         group=SOLVER)
    stall: float = field(0.5, "lagged Newton: a new Jacobian when an iteration reduces the residual "
                              "by less than this factor (p1-rotation-free: fresh factors at every "
                              "step's start, kept within the step while this holds)", group=SOLVER)
    krylov_rtol: float = field(1e-3, "matrix-free: GMRES relative tolerance per Newton iteration",
                               group=SOLVER)
    krylov_max_it: int = field(30, "matrix-free: GMRES iterations before the preconditioner is refreshed",
                               group=SOLVER)
    steps: int = field(30, "time steps per run", group=SOLVER)
    time_step: float = field(0.01, "Δt (the paper: 0.01 s)", "s", group=SOLVER)
    scheme: SchemeName = field("backward-euler", "time scheme: " + " | ".join(SCHEMES), group=SOLVER)
    rtol: float = field(1e-6, "Newton: relative residual reduction per step", group=SOLVER)
    atol: float = field(1e-11, "Newton: absolute residual (shell forces are ~1e-4 N; round-off ~1e-13)", "N",
                        group=SOLVER)
    max_iterations: int = field(25, "Newton iterations per step before the run is declared failed",
                                group=SOLVER)
    quadrature_degree: int = field(0, "quadrature degree of the shell integrals (0: 2 × degree)",
                                   group=GEOMETRY)
    mesh_scale: float = field(1.0, "all lens mesh sizes (optic, haptic, junction) times this", group=GEOMETRY)
    roll_radius: float = field(3.0, "the released lens starts rolled onto a cylinder of this radius", "mm",
                               group=PHYSICS)
    contact: bool = field(False, "release it inside a rigid ellipsoidal capsule (penalty contact)",
                          group=PHYSICS)
    capsule_semi_axes: tuple = field((5.6, 5.6, 2.6), "capsule semi-axes (x, y, z)", "mm", group=GEOMETRY)
    tangent: Tangent = field("explicit", "the Jacobian form: " + " | ".join(TANGENTS) + " (UFL's derivative "
                                     "of the residual: the same matrix, twice the compile and assembly time)",
                             group=SOLVER)
    native_kernels: bool = field(False, "compile the shell kernels with -O3 -march=native (≈ 20 % faster "
                                        "Jacobian here; the JIT cache must then not be shared between CPU "
                                        "types)", group=SOLVER)
    repeats: int = field(1, "runs of the same steps (the state is reset); steps/s is the best of them",
                         group=SOLVER)
    time_stepping: Literal["fixed", "adaptive"] = field(
        "fixed", "fixed (Δt = time_step: the paper's step, at which the speed is measured) | "
                 "adaptive (the deformation-only release over steps × time_step with Δt "
                 "chosen by the time-error estimate: docs/iol.md §1)", group=SOLVER)
    time_tolerance: float = field(0.01, "time_stepping=adaptive: allowed estimated displacement error at the "
                                        "end of the release", "mm", group=SOLVER)

    def validate(self) -> None:
        super().validate()
        self.require_positive("refresh", "steps", "time_step", "rtol", "atol", "max_iterations", "mesh_scale",
                              "roll_radius", "repeats")
        self.require_nonnegative("quadrature_degree")
        self.require_positive("stall", "krylov_rtol", "krylov_max_it")
        validate_adaptive(self)
        if self.method == "linearised" and SCHEMES[self.scheme].alpha_f:
            raise ParameterError("scheme", "generalized-alpha needs the residual at the accepted state "
                                 "(R(u_n)); the linearised step does not evaluate it: use method=newton")
        if self.model == "p1-rotation-free":
            if self.method != "newton" or self.jacobian not in ("fresh", "lagged"):
                raise ParameterError("method", "model=p1-rotation-free runs method=newton with "
                                     "jacobian=fresh or lagged (the other methods are the P2 model's)")
            if self.jacobian == "lagged" and not 0.0 < self.stall < 1.0:
                raise ParameterError("stall", "model=p1-rotation-free, jacobian=lagged: a contraction factor "
                                     "between 0 and 1")
            if self.scheme != "backward-euler":
                raise ParameterError("scheme", "model=p1-rotation-free integrates with backward-euler only")
        elif self.surface_contact:
            raise ParameterError("surface_contact", "the P1 surface's self-contact is "
                                 "model=p1-rotation-free's (the P2 lens' is iol-injection's)")
        if len(self.capsule_semi_axes) != 3 or min(self.capsule_semi_axes) <= 0:
            raise ParameterError("capsule_semi_axes", "three positive semi-axes, mm")
        if self.roll_radius < 0.5 * self.overall_length / np.pi:
            raise ParameterError("roll_radius", f"{self.roll_radius} mm would wrap the "
                                 f"{self.overall_length} mm lens onto itself")

    def geometry(self) -> LensGeometry:
        base = LensGeometry()
        s = self.mesh_scale
        return dataclasses.replace(base, optic_diameter=self.optic_diameter,
                                   overall_length=self.overall_length, mesh_size=self.mesh_size * s,
                                   haptic_size=base.haptic_size * s, junction_size=base.junction_size * s)


# the paper's resolution, the default method: `eyemech bench iol-speed`
BENCHMARK = {"steps": 10, "repeats": 2}


class PhaseClock:
    """Wall and CPU seconds per phase; ``other`` is filled in per step as the remainder."""

    def __init__(self):
        self.wall = dict.fromkeys(PHASES, 0.0)
        self.cpu = dict.fromkeys(PHASES, 0.0)

    @contextlib.contextmanager
    def __call__(self, phase: str):
        wall, cpu = time.perf_counter(), time.process_time()
        yield
        self.wall[phase] += time.perf_counter() - wall
        self.cpu[phase] += time.process_time() - cpu


class FiniteDifferenceJacobian:
    """The Jacobian's action J(x) v ≈ (F(x + h v) − F(x))/h (Brown & Saad 1990:
    h = √ε (1 + ‖x‖)/‖v‖) as a PETSc shell matrix: one residual per product."""

    def __init__(self, solver: "StepSolver"):
        # held weakly: the solver's shell matrix holds this context in C, where a cycle
        # back to the solver is never collected (problems/solve/callbacks.py)
        self._solver = weakref.ref(solver)
        self.base = solver.b.duplicate()  # F(x) at the linearisation point
        self.x0 = solver.x.duplicate()
        self.work = solver.b.duplicate()

    @property
    def solver(self) -> "StepSolver":
        return self._solver()

    def set_point(self) -> None:
        self.solver.x.copy(self.x0)
        self.solver.b.copy(self.base)

    def mult(self, _mat, v: PETSc.Vec, y: PETSc.Vec) -> None:
        s = self.solver
        norm_v = v.norm()
        if norm_v == 0.0:
            y.set(0.0)
            return
        h = np.sqrt(np.finfo(float).eps) * (1.0 + self.x0.norm()) / norm_v
        self.x0.copy(s.x)
        s.x.axpy(h, v)
        s.x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        s.assemble_residual(self.work)
        self.work.axpy(-1.0, self.base)
        self.work.copy(y)
        y.scale(1.0 / h)
        self.x0.copy(s.x)
        s.x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)


class _LaggedFactors:
    """GMRES' preconditioner: the triangular solves with the last LU factors (shared with
    the direct solves, so no second factorisation)."""

    def __init__(self, ksp: PETSc.KSP):
        self.ksp = ksp

    def apply(self, _pc, x: PETSc.Vec, y: PETSc.Vec) -> None:
        self.ksp.solve(x, y)


class StepSolver:
    """Backward-Euler/Newmark steps of the lens by a hand-rolled (modified / inexact) Newton
    loop on preallocated PETSc objects: one matrix, one residual vector, one update vector
    and a KSP whose LU factors are kept while the Jacobian is lagged. ``jacobian``:
    ``fresh`` (assembled and factorised every iteration), ``lagged`` (the factors of an
    older Jacobian used as if exact: modified Newton), ``matrix-free`` (the exact Jacobian's
    action by finite differences of the residual, GMRES preconditioned by the lagged
    factors: Newton–Krylov)."""

    def __init__(self, shell: LensShell, dynamics: ImplicitDynamics, contact: NodalContact | None,
                 params: Parameters):
        self.shell, self.dynamics, self.contact, self.params = shell, dynamics, contact, params
        residual = shell.residual()
        jit = {"cffi_extra_compile_args": ["-O3", "-march=native", "-g0"]} if params.native_kernels else None
        self.F = dolfinx.fem.form(residual, jit_options=jit)
        jacobian = shell.jacobian() if params.tangent == "explicit" else ufl.derivative(residual, shell.u)
        self.J = dolfinx.fem.form(jacobian, jit_options=jit)
        self.A = dolfinx.fem.petsc.create_matrix(self.J)
        self.b = dolfinx.fem.petsc.create_vector(shell.V)
        self.du = self.b.duplicate()
        self.x = shell.u.x.petsc_vec
        self.ksp = self._lu(PETSc.KSP().create(shell.mesh.comm))
        self.ksp.setType("preonly")
        self.ksp.setOperators(self.A)
        if params.jacobian == "matrix-free":
            self.fd = FiniteDifferenceJacobian(self)
            n = self.b.getLocalSize()
            self.Jmf = PETSc.Mat().createPython(((n, PETSc.DECIDE), (n, PETSc.DECIDE)), self.fd,
                                                comm=shell.mesh.comm)
            self.Jmf.setUp()
            self.ksp_mf = PETSc.KSP().create(shell.mesh.comm)
            self.ksp_mf.setType("gmres")
            self.ksp_mf.setTolerances(rtol=params.krylov_rtol, max_it=params.krylov_max_it)
            self.ksp_mf.setOperators(self.Jmf, self.Jmf)
            pc = self.ksp_mf.getPC()
            pc.setType("python")
            pc.setPythonContext(_LaggedFactors(self.ksp))
            self.ksp_mf.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        self.clock = PhaseClock()
        self.counts = dict.fromkeys(("iterations", "residuals", "jacobians", "factorisations",
                                     "krylov_iterations"), 0)
        self.factor_age = None  # steps since the last factorisation (None: none yet)
        self.last_residual = np.nan

    @staticmethod
    def _lu(ksp: PETSc.KSP) -> PETSc.KSP:
        pc = ksp.getPC()
        pc.setType("lu")
        pc.setFactorSolverType("mumps")
        return ksp

    def assemble_residual(self, b: PETSc.Vec) -> None:
        with self.clock("residual"):
            with b.localForm() as local:
                local.set(0.0)
            dolfinx.fem.petsc.assemble_vector(b, self.F)
            b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            self.dynamics.residual_hook(self.x, b)
        if self.contact is not None:
            with self.clock("contact"):
                self.contact.residual_hook(self.x, b)
        self.counts["residuals"] += 1

    def residual(self) -> float:
        self.assemble_residual(self.b)
        return self.b.norm()

    def refactor(self) -> None:
        A = self.A
        with self.clock("jacobian"):
            A.zeroEntries()
            dolfinx.fem.petsc.assemble_matrix(A, self.J)
            A.assemble()
            self.dynamics.jacobian_hook(self.x, A)
        if self.contact is not None:
            with self.clock("contact"):
                self.contact.jacobian_hook(self.x, A)
        with self.clock("factorisation"):
            self.ksp.setOperators(A)  # else KSPSetUp skips the PC and the solve factorises
            self.ksp.setUp()
        self.counts["jacobians"] += 1
        self.counts["factorisations"] += 1
        self.factor_age = 0

    def update(self) -> int:
        """x ← x − J⁻¹ b with the current factors (or GMRES on the exact J(x) they
        precondition); returns the Krylov iterations (0 for a direct solve)."""
        krylov = 0
        if self.params.jacobian == "matrix-free":
            self.fd.set_point()
            inside = (self.clock.wall["residual"] + self.clock.wall["contact"],
                      self.clock.cpu["residual"] + self.clock.cpu["contact"])
            with self.clock("solve"):
                self.ksp_mf.solve(self.b, self.du)
            # the residuals inside GMRES were booked as residual/contact: not solve time
            self.clock.wall["solve"] -= self.clock.wall["residual"] + self.clock.wall["contact"] - inside[0]
            self.clock.cpu["solve"] -= self.clock.cpu["residual"] + self.clock.cpu["contact"] - inside[1]
            krylov = self.ksp_mf.getIterationNumber()
            self.counts["krylov_iterations"] += krylov
        else:
            with self.clock("solve"):
                self.ksp.solve(self.b, self.du)
        with self.clock("solve"):
            self.x.axpy(-1.0, self.du)
            self.x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        self.counts["iterations"] += 1
        return krylov

    def step(self) -> int:
        """One time step (the dynamics' Δt set); returns the Newton iterations used."""
        p = self.params
        fresh = p.jacobian == "fresh"
        if fresh or self.factor_age is None or self.factor_age >= p.refresh:
            self.refactor()
        norm0 = self.residual()
        if p.method == "linearised":
            self.update()
            self.last_residual = norm0
            self.factor_age += 1
            return 1
        tolerance = max(p.rtol * norm0, p.atol)
        norm, iterations = norm0, 0
        while norm > tolerance:
            if iterations >= p.max_iterations or not np.isfinite(norm):
                raise RuntimeError(f"{p.method}/{p.jacobian}: no convergence in {iterations} "
                                   f"iterations (residual {norm:.3e} of {norm0:.3e})")
            krylov = self.update()
            iterations += 1
            previous, norm = norm, self.residual()
            if norm <= tolerance:
                break
            if fresh or (p.jacobian == "lagged" and norm > p.stall * previous) \
                    or krylov >= p.krylov_max_it:
                self.refactor()  # a fresh Jacobian: Newton, or the old one has gone stale
        self.last_residual = norm
        self.factor_age += 1
        return iterations


def initial_roll(shell: LensShell, radius: float) -> np.ndarray:
    """Displacement that rolls the flat lens isometrically onto the cylinder of ``radius``."""
    X = shell.node_coordinates()
    return (rolled(X, 1.0 / radius) - X).ravel()


def tip_nodes(shell: LensShell) -> np.ndarray:
    """Nodes of the first haptic's tip edge (their mean displacement is the tip history)."""
    shell.mesh.topology.create_connectivity(1, 2)
    return dolfinx.fem.locate_dofs_topological(shell.V, 1, shell.tagged.facets("tip_1"))


def make_capsule(shell: LensShell, params: Parameters, u0: np.ndarray) -> Capsule:
    """The capsule centred on the rolled lens' bounding box, acting everywhere; its semi-axes
    are ``capsule_semi_axes`` grown uniformly, if needed, until the rolled lens starts 1 %
    inside it (a start in penetration is a violent, unphysical first step). The lens then
    touches it as it unrolls."""
    return capsule_around(shell.node_coordinates() + u0.reshape(-1, 3), params)


def capsule_around(x: np.ndarray, params: Parameters) -> Capsule:
    """``make_capsule``'s capsule about the lens positions x (n, 3)."""
    centre = 0.5 * (x.min(axis=0) + x.max(axis=0))
    semi = np.asarray(params.capsule_semi_axes, float)
    reach = np.sqrt(np.max(np.sum(((x - centre) / semi) ** 2, axis=1)))
    return Capsule(centre, semi * max(1.0, reach / 0.99), -np.inf)


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        if ctx.comm.size != 1:
            raise ParameterError("ranks", "iol-speed measures one core: run it on one rank")
        if params.time_stepping == "adaptive":
            run_adaptive_release(ctx, params, P2Release(_lens, initial_roll, StepSolver, tip_nodes))
            return ctx.result
        if params.model == "p1-rotation-free":
            _run_rotation_free(ctx, params)
            return ctx.result
        with ctx.timings("mesh"):
            shell = _lens(params)
        with ctx.timings("form_compilation"):
            u0 = initial_roll(shell, params.roll_radius)
            contact, capsule = None, None
            if params.contact:
                capsule = make_capsule(shell, params, u0)
                contact = NodalContact(shell.u, {"capsule": capsule}, params.contact_stiffness)
            dynamics = ImplicitDynamics(shell.u, shell.mass(), [], scheme_name=params.scheme,
                                        damping=params.damping)
            solver = StepSolver(shell, dynamics, contact, params)
        runs = [_timed_run(params, shell, dynamics, solver, contact, u0, ctx) for _ in range(params.repeats)]
        _report(ctx, params, shell, runs)
        if capsule is not None:
            ctx.result.quantities["capsule_semi_axes_mm"] = capsule.semi_axes.tolist()
    return ctx.result


def _run_rotation_free(ctx: RunContext, params: Parameters) -> None:
    """The same release on the rotation-free P1 lens; one untimed step first compiles (or
    loads from numba's cache) the kernels."""
    from eyemech.problems.lens.rotation_free import FastLens, MeshInputError, release

    with ctx.timings("mesh"):
        try:
            lens = FastLens.build(params, params.bending)
        except (MeshInputError, ValueError) as err:
            raise ParameterError("mesh_scale", f"the rotation-free lens cannot use this mesh: {err}") from err

    obstacles = None
    if params.contact:
        x = lens.shell.X + lens.rolled_displacement(params.roll_radius).reshape(-1, 3)
        obstacles = {"capsule": capsule_around(x, params)}

    def timed(steps: int) -> dict:
        try:
            return release(params, steps, lens, stall=params.stall if params.jacobian == "lagged" else None,
                           self_contact=params.surface_contact, obstacles=obstacles)
        except RuntimeError as err:  # Newton did not converge within max_iterations
            raise ParameterError("time_step", f"model=p1-rotation-free cannot take Δt = "
                                 f"{params.time_step:g} s from the released roll (Newton: {err}); take a "
                                 "smaller time_step") from err

    with ctx.timings("form_compilation"):
        timed(1)
    runs = [timed(params.steps) for _ in range(params.repeats)]
    for phase, value in runs[-1]["phases_cpu"].items():
        ctx.timings.add(f"step_{phase}", value)
    best = min(runs, key=lambda r: r["wall"])
    steps = params.steps
    history = best["history"]
    ctx.result.quantities.update(
        model=params.model, bending=params.bending, method=params.method, jacobian=params.jacobian,
        steps=steps, repeats=len(runs),
        steps_per_second=steps / best["wall"], steps_per_second_cpu=steps / min(r["cpu"] for r in runs),
        steps_per_second_all=[steps / r["wall"] for r in runs],
        cpu_seconds_per_step={k: v / steps for k, v in best["phases_cpu"].items()},
        **best["counts"], newton_iterations=history["iterations"],
        tip_history=history["tip"], optic_history=history["optic"],
        time=[params.time_step * (i + 1) for i in range(steps)], load_average=os.getloadavg()[0],
        dofs=best["dofs"], cells=best["cells"], nodes=best["nodes"], time_stepping=params.time_stepping,
        **best["time_error"])
    if obstacles:
        ctx.result.quantities.update(max_penetration_mm=max(history["penetration"], default=0.0),
                                     capsule_semi_axes_mm=obstacles["capsule"].semi_axes.tolist())
    if params.surface_contact:
        closest = history["min_distance"] if np.isfinite(history["min_distance"]) \
            else None  # None: no pair came within d̂
        ctx.result.quantities.update(intersecting_steps=history["intersecting"],
                                     min_self_distance_mm=closest)


def _lens(params: Parameters) -> LensShell:
    shell = LensShell(params, MPI.COMM_SELF)
    if params.quadrature_degree:
        metadata = {"quadrature_degree": params.quadrature_degree}
        shell.dx = ufl.Measure("dx", shell.mesh, metadata=metadata)
        shell.dS = ufl.Measure("dS", shell.mesh, metadata=metadata)
    return shell


def _timed_run(params, shell, dynamics, solver: StepSolver, contact, u0, ctx) -> dict:
    """The run from the rolled state, timed; resets everything it measures."""
    shell.u.x.array[:] = u0
    shell.u.x.scatter_forward()
    dynamics.u_n.array[:] = u0[: len(dynamics.u_n.array)]
    dynamics.v_n.set(0.0)
    dynamics.a_n.set(0.0)
    dynamics.set_step(params.time_step)
    if params.scheme != "backward-euler":
        dynamics.initial_acceleration(shell.residual())
    solver.clock = PhaseClock()
    solver.counts = dict.fromkeys(solver.counts, 0)
    solver.factor_age = None
    tips, optic = tip_nodes(shell), shell.nodes_of("optic")
    history = {"tip": [], "optic": [], "iterations": [], "penetration": []}
    time_error = TimeErrorTally()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for _ in range(params.steps):
        history["iterations"].append(solver.step())
        time_error.add(step_error(dynamics, solver.ksp))
        dynamics.advance()
        u = shell.u.x.array.reshape(-1, 3)
        history["tip"].append(u[tips].mean(axis=0).tolist())
        history["optic"].append(u[optic].mean(axis=0).tolist())
        if contact is not None:
            history["penetration"].append(max(contact.max_penetration().values(), default=0.0))
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    clock = solver.clock
    clock.wall["other"] = wall - sum(clock.wall[p] for p in PHASES[:-1])
    clock.cpu["other"] = cpu - sum(clock.cpu[p] for p in PHASES[:-1])
    for phase in PHASES:
        ctx.timings.add(f"step_{phase}", clock.wall[phase])
    # the columns of `eyemech bench` (problems/run/bench.py)
    ctx.timings.add("assembly", clock.wall["residual"] + clock.wall["jacobian"])
    ctx.timings.add("solve", clock.wall["factorisation"] + clock.wall["solve"])
    ctx.timings.add("contact_search", clock.wall["contact"])
    return {"wall": wall, "cpu": cpu, "phases_wall": dict(clock.wall), "phases_cpu": dict(clock.cpu),
            "counts": dict(solver.counts), "history": history, "last_residual": solver.last_residual,
            "time_error": time_error.quantities()}


def _report(ctx: RunContext, params: Parameters, shell: LensShell, runs: list[dict]) -> None:
    best = min(runs, key=lambda r: r["wall"])
    steps = params.steps
    q = ctx.result.quantities
    q.update(method=params.method, jacobian=params.jacobian, steps=steps, repeats=len(runs),
             steps_per_second=steps / best["wall"],
             steps_per_second_cpu=steps / min(r["cpu"] for r in runs),
             steps_per_second_all=[steps / r["wall"] for r in runs],
             seconds_per_step={k: v / steps for k, v in best["phases_wall"].items()},
             cpu_seconds_per_step={k: v / steps for k, v in best["phases_cpu"].items()},
             **{k: v for k, v in best["counts"].items()},
             newton_iterations=best["history"]["iterations"],
             tip_history=best["history"]["tip"], optic_history=best["history"]["optic"],
             time=[params.time_step * (i + 1) for i in range(steps)],
             max_penetration_mm=max(best["history"]["penetration"], default=0.0),
             load_average=os.getloadavg()[0],
             dofs=shell.dofs(), cells=shell.mesh.topology.index_map(2).size_global,
             nodes=shell.mesh.geometry.index_map().size_global,
             quadrature_degree=params.quadrature_degree or 2 * params.degree,
             time_stepping=params.time_stepping, **best["time_error"])


SCENE = Scene(name="iol-speed", kind="benchmark", parameters=Parameters, run=run,
              summary="steps per second of the released rolled lens (deformation only or in a rigid "
                      "capsule), per method, with the time split per phase")
