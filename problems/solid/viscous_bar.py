"""What the viscoelastic bar scenes (``uniaxial-relaxation``, ``sls-creep``) share: the
parameters of the material and the time stepping, a box of hexahedra (or tetrahedra)
in homogeneous uniaxial tension, the internal variable Cv_n at the quadrature points
and its update after each converged step.

The bar is [0, L]³ with the symmetry conditions u_x = 0 on x = 0, u_y = 0 on y = 0,
u_z = 0 on z = 0; the load acts on x = L (a prescribed u_x or an axial traction), the
other faces are free. The exact solution is homogeneous uniaxial tension, so a single
element is as accurate as any mesh: these scenes test the constitutive update and the
time stepping, not the spatial discretisation.

Time steps (``time_stepping``): ``fixed`` steps dt; ``adaptive`` (the default) chooses
each step from a local error estimate of the internal variable. Backward Euler (BE) and
forward Euler (FE) from the same Cv_n form an embedded pair: their local errors are
∓dt²/2 C̈v + O(dt³), so E = ½ |Cv_BE − Cv_FE| (Frobenius, per quadrature point)
estimates BE's local error. Its effect on the stress is measured against the stress
scale D = μ∞ |C̄ − I| + μv |C̄ − Cv| (the two branches' strains): μv E/D is a step's
relative stress error. Errors of Cv relax at least at the retardation rate
1/τc = μ∞/((μ∞ + μv) τ), so the global error is tracked per point as
G ← G e^(−dt/τc) + E, and μv max G / max D (largest over the steps) is reported as
``time_error_estimate``, in fixed and adaptive mode alike. A step is accepted when

    μv E/D ≤ max(tol · dt/τc, (tol/10)²),   tol = time_tolerance:

error per unit step, which keeps μv G/D ≤ tol once the decay balances the new errors.
The second bound lets a ramp start from rest, where μv E/D ≈ dt/2τ and the first bound
are both proportional to dt so that no shorter step meets it: the first step is of
order τ (tol/10)² and then doubles. The next step is
dt · min(2, max(0.2, 0.9 √(allowed/(μv E/D)))). ``max_steps`` caps the number of steps
in both modes: an adaptive run that needs more stops with a message naming
``time_tolerance`` and ``max_steps`` (``TooManySteps``, a ``SolveFailure``). The
controller, :func:`march_adaptive`, works on any :class:`ViscousHistory` and is also the
cornea's (``keratotomy``), with checkpoints.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable, ClassVar, Literal

import basix.ufl
import dolfinx
import dolfinx.fem
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms import viscoelastic as ve
from eyemech.forms.kinematics import deformation_gradient, without_variables
from eyemech.problems.run.context import RunContext
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, ParameterError, SceneParameters, field
from eyemech.problems.solid.spaces import ELEMENTS, mixed_displacement_pressure
from eyemech.problems.solve.driver import (
    NonlinearSolver,
    SolveFailure,
    Stepping,
    StepRecord,
    follow_path,
)
from eyemech.problems.solve.scalars import assemble_scalar
from eyemech.problems.solve.stepping import StepController

LOADED_FACE = 1  # facet tag of x = L


@dataclasses.dataclass(frozen=True)
class BarParameters(SceneParameters):
    mu_inf: float = field(0.05, "equilibrium shear modulus μ∞ (Ψ∞ = μ∞/2 (tr C̄ − 3))", "MPa", group=PHYSICS)
    mu_v: float = field(0.05, "viscous-branch shear modulus μv (Ψv = μv/2 (tr(C̄ Cv⁻¹) − 3))", "MPa",
                        group=PHYSICS)
    tau: float = field(100.0, "relaxation time τ of the evolution τ Ċv = C̄ − ⅓ tr(C̄ Cv⁻¹) Cv", "s",
                       group=PHYSICS)
    t_end: float = field(300.0, "end time", "s", group=PHYSICS)
    dt: float = field(1.0, "time step (fixed mode; the first step in adaptive mode)", "s", group=SOLVER)
    time_stepping: Literal["adaptive", "fixed"] = field(
        "adaptive", "adaptive: steps from a local error estimate of Cv; fixed: every step dt", group=SOLVER)
    time_tolerance: float = field(1e-2, "adaptive mode: allowed relative stress error from the time "
                                        "steps (embedded BE/FE estimate, module viscous_bar)", group=SOLVER)
    max_steps: int = field(20000, "most time steps a run may take (adaptive or fixed)", group=SOLVER)
    time_scheme: Literal["backward-euler", "forward-euler"] = field(
        "backward-euler", "integration of the evolution law (forward Euler: stability study only)",
        group=SOLVER)
    element: Literal["Q2P1", "P2P1"] = field("Q2P1", "element family (displacement/pressure)", group=GEOMETRY)
    mesh_divisions: int = field(1, "elements (hexahedra; ×6 tetrahedra) along each edge of the cube",
                                group=GEOMETRY)
    length: float = field(1.0, "edge of the cube", "mm", group=GEOMETRY)

    RESOLUTION_KEY: ClassVar[str] = "mesh_divisions"

    @property
    def estimated_cells(self) -> int:
        """n³ hexahedra, or 6 n³ tetrahedra (dolfinx.mesh.create_box)."""
        hexahedral = ELEMENTS[self.element].hexahedral if self.element in ELEMENTS else True
        return self.mesh_divisions ** 3 * (1 if hexahedral else 6)

    def validate(self) -> None:
        self.require_positive("mu_inf", "mu_v", "tau", "t_end", "dt", "mesh_divisions", "length",
                              "time_tolerance", "max_steps")
        for key in ("mu_inf", "mu_v", "tau", "t_end", "dt", "length"):
            if not np.isfinite(getattr(self, key)):
                raise ParameterError(key, "must be finite")
        if self.time_scheme not in ve.TIME_SCHEMES:
            raise ParameterError("time_scheme", f"unknown scheme {self.time_scheme!r}; choose one of "
                                 f"{', '.join(ve.TIME_SCHEMES)}")
        if self.element not in ("Q2P1", "P2P1"):
            raise ParameterError("element", f"must be Q2P1 or P2P1, got {self.element!r}")
        if self.dt > self.t_end:
            raise ParameterError("dt", f"is longer than t_end ({self.t_end})")
        if self.time_stepping == "fixed" and self.t_end / self.dt > self.max_steps:
            raise ParameterError("dt", f"gives {self.t_end / self.dt:.0f} steps; at most max_steps = "
                                       f"{self.max_steps}")
        if self.time_stepping == "adaptive" and self.time_scheme != "backward-euler":
            raise ParameterError("time_stepping", "adaptive steps need time_scheme = backward-euler "
                                                  "(forward Euler is the stability study's fixed step)")

    @property
    def material(self) -> ve.Viscoelastic:
        return ve.Viscoelastic(self.mu_inf, self.mu_v, self.tau)


class ViscousHistory:
    """The internal variable of :mod:`eyemech.forms.viscoelastic` on a mesh: Cv_n (and C̄_n
    for forward Euler) on a tensor-valued quadrature space whose points are those of the
    residual's rule of ``degree`` (one value per Gauss point, the seed's §3.2.2), the UFL
    expression of Cv_{n+1} for the time scheme, and the update after a converged step."""

    def __init__(self, u, material: ve.Viscoelastic, scheme: str, degree: int):
        mesh = u.function_space.mesh
        self.comm = mesh.comm
        self.dt = dolfinx.fem.Constant(mesh, 0.0)
        Q = dolfinx.fem.functionspace(mesh, basix.ufl.quadrature_element(
            mesh.basix_cell(), value_shape=(3, 3), scheme="default", degree=degree))
        points = Q.element.interpolation_points
        self.Cv_n = self._identity(Q, "Cv_n")
        self.Cbar_n = self._identity(Q, "Cbar_n")  # read by forward Euler only
        F = deformation_gradient(u)
        self.Cv = ve.current_internal_variable(scheme, material, F, self.Cv_n, self.Cbar_n, self.dt)
        self._Cv_next = dolfinx.fem.Expression(without_variables(self.Cv), points)
        self._Cbar_next = dolfinx.fem.Expression(without_variables(ve.isochoric_cauchy_green(F)), points)
        self._scratch = dolfinx.fem.Function(Q)
        # the embedded pair: ½ (Cv_BE − Cv_FE) from the same Cv_n, C̄_n and dt
        pair = 0.5 * (ve.current_internal_variable("backward-euler", material, F, self.Cv_n,
                                                   self.Cbar_n, self.dt)
                      - ve.current_internal_variable("forward-euler", material, F, self.Cv_n,
                                                     self.Cbar_n, self.dt))
        self._difference = dolfinx.fem.Expression(without_variables(pair), points)
        Cbar = ve.isochoric_cauchy_green(F)
        self._distance = dolfinx.fem.Expression(without_variables(Cbar - self.Cv), points)
        self._strain = dolfinx.fem.Expression(without_variables(Cbar - ufl.Identity(3)), points)
        self.material = material
        # G per point, a Function on the same points (one value each, the dof layout of Q
        # without its block of 9) so that checkpoints carry it as they carry Cv_n
        self.error_history = dolfinx.fem.Function(dolfinx.fem.functionspace(
            mesh, basix.ufl.quadrature_element(mesh.basix_cell(), value_shape=(),
                                               scheme="default", degree=degree)), name="G")
        self._last_error = np.zeros_like(self.global_error)

    @property
    def global_error(self) -> np.ndarray:
        """The accumulated error G at every local point (owned and ghost cells)."""
        return self.error_history.x.array

    @global_error.setter
    def global_error(self, values: np.ndarray) -> None:
        self.error_history.x.array[:] = values

    @staticmethod
    def _identity(Q, name: str) -> dolfinx.fem.Function:
        f = dolfinx.fem.Function(Q, name=name)
        f.x.array.reshape(-1, 9)[:] = np.eye(3).ravel()
        return f

    def store_strain(self) -> None:
        """C̄_n ← C̄(u) without touching Cv_n: after the instantaneous loading at t = 0,
        forward Euler's first step must start from the loaded C̄(0+), not from C̄ = I."""
        self._scratch.interpolate(self._Cbar_next)
        self.Cbar_n.x.array[:] = self._scratch.x.array

    def _norms(self, expression) -> np.ndarray:
        self._scratch.interpolate(expression)
        return np.sqrt((self._scratch.x.array.reshape(-1, 9) ** 2).sum(axis=1))

    def time_error(self) -> tuple[float, float]:
        """For the current u and dt, before ``update``: (μv E/D, μv (G e^(−dt/τc) + E)/D),
        numerators and D each the largest over all points (module docstring of viscous_bar). C̄_n must hold
        the strain at the start of the step (``store_strain`` after an instantaneous
        load, ``update`` after each step keep it so)."""
        mu_inf, mu_v, retardation = self._moduli()
        error = self._norms(self._difference)
        scale = mu_inf * self._norms(self._strain) + mu_v * self._norms(self._distance)
        decay = np.exp(-float(self.dt.value) / retardation)
        self._last_error = error
        # against the body's largest stress scale: a point at rest (D → 0) must not
        # dominate; in the homogeneous bar this is the per-point ratio
        values = np.array([(mu_v * error).max(initial=0.0),
                           (mu_v * (self.global_error * decay + error)).max(initial=0.0),
                           scale.max(initial=0.0)])
        if not np.all(np.isfinite(values)):
            values[:2] = np.inf
        largest = np.empty(3)
        self.comm.Allreduce(values, largest, op=MPI.MAX)
        return float(largest[0] / largest[2]), float(largest[1] / largest[2])

    def accept_time_error(self) -> None:
        """G ← G e^(−dt/τc) + E with the E of the last ``time_error``."""
        decay = np.exp(-float(self.dt.value) / self._moduli()[2])
        self.global_error = self.global_error * decay + self._last_error

    def retardation_time(self) -> float:
        """τc = τ (μ∞ + μv)/μ∞: the slowest decay of an error in Cv."""
        return self._moduli()[2]

    def _moduli(self) -> tuple[float, float, float]:
        """μ∞, μv and the retardation time as numbers (the material may hold Constants)."""
        number = lambda x: float(np.asarray(getattr(x, "value", x)))
        numbers = ve.Viscoelastic(*(number(x) for x in (self.material.mu_inf, self.material.mu_v,
                                                        self.material.tau)))
        return numbers.mu_inf, numbers.mu_v, numbers.retardation_time

    def update(self) -> float:
        """Cv_n ← Cv_{n+1}(u) (and C̄_n ← C̄(u) for forward Euler) after a converged step.
        Both new values are evaluated before either is stored (forward Euler's Cv_{n+1}
        reads C̄_n). Returns the smallest eigenvalue of the new Cv over all points: a
        forward-Euler blow-up shows as Cv losing positive definiteness."""
        self._scratch.interpolate(self._Cv_next)
        new_Cv = self._scratch.x.array.copy()
        self.store_strain()
        self.Cv_n.x.array[:] = new_Cv
        tensors = new_Cv.reshape(-1, 3, 3)
        if not np.all(np.isfinite(tensors)):
            local = -np.inf
        else:
            local = np.linalg.eigvalsh(0.5 * (tensors + tensors.transpose(0, 2, 1))).min() \
                if len(tensors) else np.inf
        return self.comm.allreduce(float(local), op=MPI.MIN)


class ViscousBar:
    """The unit cube in uniaxial tension with the viscoelastic mixed u–p residual.

    ``self.residual`` has no load; the scene adds a traction or a Dirichlet condition.
    Cv_n (and C̄_n for forward Euler) are functions on a quadrature space whose points
    are the integration points of ``self.dx``: one value of the internal variable per
    Gauss point, as in the seed's §3.2.2.
    """

    def __init__(self, params: BarParameters, comm: MPI.Comm):
        self.params = params
        self.family = ELEMENTS[params.element]
        cell = dolfinx.mesh.CellType.hexahedron if self.family.hexahedral \
            else dolfinx.mesh.CellType.tetrahedron
        n, L = params.mesh_divisions, params.length
        self.mesh = dolfinx.mesh.create_box(comm, [np.zeros(3), np.full(3, L)], [n, n, n], cell)
        (self.u, self.p), (self.v, self.q) = mixed_displacement_pressure(self.mesh, self.family)
        degree = self.family.quadrature_degree
        metadata = {"quadrature_degree": degree, "quadrature_rule": "default"}
        self.dx = ufl.Measure("dx", domain=self.mesh, metadata=metadata)
        fdim = self.mesh.topology.dim - 1
        self.faces = {axis: dolfinx.mesh.locate_entities_boundary(
            self.mesh, fdim, lambda x, a=axis: np.isclose(x[a], 0.0)) for axis in range(3)}
        self.loaded_facets = dolfinx.mesh.locate_entities_boundary(
            self.mesh, fdim, lambda x: np.isclose(x[0], L))
        tags = dolfinx.mesh.meshtags(self.mesh, fdim, self.loaded_facets,
                                     np.full(len(self.loaded_facets), LOADED_FACE, dtype=np.int32))
        self.ds = ufl.Measure("ds", domain=self.mesh, subdomain_data=tags, metadata=metadata)

        self.material = params.material
        self.history = ViscousHistory(self.u, self.material, params.time_scheme, degree)
        self.dt, self.Cv = self.history.dt, self.history.Cv
        self.update_history, self.store_strain = self.history.update, self.history.store_strain
        self.time_error, self.accept_time_error = self.history.time_error, self.history.accept_time_error
        F = deformation_gradient(self.u)
        self.residual = ve.residual(self.material, self.u, self.p, self.v, self.q, self.Cv, self.dx)

        volume = assemble_scalar(1.0 * self.dx, comm)
        sigma = ve.cauchy_stress(self.material, F, self.p, self.Cv)
        self._stress_form = dolfinx.fem.form(sigma[0, 0] / volume * self.dx)
        self._stretch_form = dolfinx.fem.form(F[0, 0] / volume * self.dx)
        self.comm = comm

    # -- boundary conditions --------------------------------------------------------
    def symmetry_bcs(self) -> list:
        fdim = self.mesh.topology.dim - 1
        V = self.u.function_space
        return [dolfinx.fem.dirichletbc(
            0.0, dolfinx.fem.locate_dofs_topological(V.sub(a), fdim, self.faces[a]), V.sub(a))
            for a in range(3)]

    def end_displacement_bc(self, value: dolfinx.fem.Constant):
        V = self.u.function_space
        dofs = dolfinx.fem.locate_dofs_topological(V.sub(0), self.mesh.topology.dim - 1,
                                                   self.loaded_facets)
        return dolfinx.fem.dirichletbc(value, dofs, V.sub(0))

    def axial_cauchy_traction(self, stress: dolfinx.fem.Constant):
        """−∫ σ0 n da · v on x = L, pulled back with Nanson (cof F N dA): a constant
        true (Cauchy) axial stress σ0 however much the face shrinks."""
        F = deformation_gradient(self.u)
        N = ufl.FacetNormal(self.mesh)
        nanson = ufl.det(F) * ufl.inv(F).T * N
        return -stress * ufl.dot(nanson, self.v) * self.ds(LOADED_FACE)

    # -- quantities -----------------------------------------------------------------
    def axial_cauchy_stress(self) -> float:
        """Volume mean of σ_xx (the state is homogeneous, so this is σ_xx itself)."""
        return assemble_scalar(self._stress_form, self.comm)

    def axial_stretch(self) -> float:
        return assemble_scalar(self._stretch_form, self.comm)


class UnstableIntegration(SolveFailure):
    """The explicit update made Cv lose positive definiteness: the time integration
    blew up (the state of the step that produced it is kept, as for a SolveFailure)."""

    def __init__(self, step: int, time: float, smallest_eigenvalue: float, dt_over_tau: float):
        self.step, self.load, self.last_converged = step, time, time
        self.residuals, self.reason = [], "unstable time integration"
        self.time, self.smallest_eigenvalue = time, smallest_eigenvalue
        RuntimeError.__init__(
            self, f"time integration unstable at step {step}, t = {time:.6g}: the explicit update "
                  f"made Cv lose positive definiteness (smallest eigenvalue {smallest_eigenvalue:.3g}) "
                  f"at dt/tau = {dt_over_tau:.3g}. The state at t = {time:.6g} is kept.")


def time_stops(params: BarParameters, extra: tuple[float, ...] = ()) -> tuple[float, ...]:
    """Every multiple of dt up to t_end, plus ``extra`` (e.g. the end of the ramp)."""
    count = int(np.floor(params.t_end / params.dt * (1 + 1e-12)))
    grid = [k * params.dt for k in range(1, count + 1)]
    return tuple(sorted(set(grid) | {t for t in extra if 0 < t <= params.t_end} | {params.t_end}))


class TooManySteps(SolveFailure):
    """The adaptive steps would exceed ``max_steps`` (the state reached is kept)."""

    def __init__(self, step: int, time: float, dt: float, max_steps: int):
        self.step, self.load, self.last_converged = step, time, time
        self.residuals, self.reason = [], "too many time steps"
        RuntimeError.__init__(
            self, f"adaptive time stepping needs more than max_steps = {max_steps} steps: at "
                  f"t = {time:.6g} the step allowed by time_tolerance is {dt:.3g}; raise "
                  f"time_tolerance or max_steps. The state at t = {time:.6g} is kept.")


def march(ctx: RunContext, bar: ViscousBar, solver: NonlinearSolver, params: BarParameters,
          apply_load: Callable[[float], None], record: Callable[[float], None], label: str,
          extra_stops: tuple[float, ...] = ()) -> dict[str, float]:
    """Time stepping from 0 to t_end, fixed or adaptive (``params.time_stepping``):
    ``apply_load(t)`` sets the load, ``record(t)`` stores outputs of the converged step,
    before the history update. Returns the time-discretisation summary
    (``time_error_estimate``, ``time_steps``, ``rejected_steps``) for the quantities.

    Cv_n is touched only after a step is accepted, so a cut (failed) step leaves it intact.
    For forward Euler no cut is allowed: the step size is the experiment, and halving it
    would hide the instability; a Cv that loses positive definiteness stops the run
    with a SolveFailure naming the time.
    """
    summary = {"time_error_estimate": 0.0, "time_steps": 0, "rejected_steps": 0}

    def accept(step: int, t: float, dt: float, iterations: int, cuts: int, residuals,
               errors: tuple[float, float], counts: dict | None = None):
        # outputs first: the stress expression reads Cv_{n+1}(u, Cv_n) and must see the
        # Cv_n this step was solved with, not the updated one
        record(t)
        error = errors[0]
        if np.isfinite(errors[1]):
            bar.accept_time_error()
            summary["time_error_estimate"] = max(summary["time_error_estimate"], errors[1])
        smallest = bar.update_history()
        summary["time_steps"] += 1
        ctx.record_step(step=step, time=t, dt=dt, newton_iterations=iterations, cuts=cuts,
                        **(counts or {}), residuals=residuals, smallest_cv_eigenvalue=smallest,
                        local_time_error=error)
        if not smallest > 0:
            raise UnstableIntegration(step, t, smallest, dt / params.tau)

    if params.time_stepping == "adaptive":
        march_adaptive(bar.history, solver, AdaptiveSteps(params.t_end, params.dt,
                                                          params.time_tolerance, params.max_steps,
                                                          extra_stops),
                       apply_load, accept, summary)
        return summary

    explicit = params.time_scheme == "forward-euler"
    fraction = params.dt / params.t_end
    stepping = Stepping(start=0.0, end=params.t_end, quantity="time", unit="s", initial_step=fraction,
                        max_step=fraction, min_step=fraction / 64, max_cuts=0 if explicit else 6,
                        stops=time_stops(params, extra_stops))

    def apply(t: float, increment: float) -> None:
        bar.dt.value = increment
        apply_load(t)

    def converged(step: StepRecord) -> None:
        error = bar.time_error() if not explicit else (float("nan"), float("nan"))
        accept(step.step, step.load, step.increment, step.iterations, step.cuts, step.residuals, error,
               step.counts())

    follow_path(solver, apply, stepping, on_converged=converged, label=label,
                quiet=ctx.options.quiet)
    return summary


@dataclasses.dataclass(frozen=True)
class AdaptiveSteps:
    """What the adaptive controller needs to know: the interval, the first step, the
    tolerance on μv E/D per unit step, the step cap and the times to land on."""

    t_end: float
    first_dt: float
    tolerance: float
    max_steps: int
    stops: tuple[float, ...] = ()


def march_adaptive(history: ViscousHistory, solver: NonlinearSolver, steps: AdaptiveSteps,
                   apply_load: Callable[[float], None], accept, summary: dict, *,
                   checkpoints=None, label: str = "") -> None:
    """Backward Euler from the current state (t = 0) to ``steps.t_end`` with steps from the
    embedded BE/FE estimate of ``history`` (module docstring). A step Newton cannot solve
    is halved (at most 6 times in a row); a step whose estimate exceeds the tolerance is
    repeated shorter. ``accept(step, t, dt, iterations, cuts, residuals, errors, counts)``
    takes an accepted step (outputs, ``accept_time_error``, ``update``); ``counts`` is the
    step's whole solver work, its cut and rejected attempts included, and
    ``summary["rejected_steps"]`` counts the rejections.

    With ``checkpoints`` (the run's, collective) the path is ``label``: a checkpoint is due
    after each accepted step as in ``follow_path``, and a resumed run continues from the
    checkpoint's time and step size (the caller registers ``history``'s state, the
    ``dt`` Constant and ``summary``)."""
    t_end, tol = steps.t_end, steps.tolerance
    retardation = history.retardation_time()
    stops = sorted({t for t in steps.stops if 0 < t < t_end} | {t_end})
    t, step = 0.0, 0
    # a failed Newton solve halves the step (at most 6 times in a row); the error
    # estimate proposes every other length
    controller = StepController(min(steps.first_dt, t_end), cut_factor=0.5, max_cuts=6,
                                easy_effort=None)
    resumed = checkpoints.enter_path(label) if checkpoints is not None else None
    if resumed is not None:
        if "skip" in resumed:  # finished before the checkpoint: its state comes later
            checkpoints.leave_path([])
            return
        t, controller.step, step = resumed["value"], resumed["increment"], resumed["step"]
    fresh = True
    while t < t_end * (1 - 1e-12):
        if fresh:  # a new step: its start state and the work counted from here
            if step >= steps.max_steps:
                raise TooManySteps(step, t, controller.step, steps.max_steps)
            state, counts_before = solver.save_state(), solver.counts.copy()
            if checkpoints is not None:
                checkpoints.watch_step(solver)
            fresh = False
        target = controller.target(t, next(s for s in stops if s > t * (1 + 1e-12) + 1e-300))
        h = target - t
        history.dt.value = h
        apply_load(target)
        converged, iterations = solver.solve()
        if not converged:
            residuals, reason = list(solver.residual_history), solver.reason()
            solver.restore_state(state)
            if not controller.cut(attempted=h):
                history.dt.value = 0.0
                apply_load(t)
                raise SolveFailure(step + 1, target, t, residuals, reason)
            continue
        errors = history.time_error()
        relative = errors[0]
        allowed = max(tol * h / retardation, (tol / 10) ** 2)
        ratio = np.sqrt(allowed / relative) if relative > 0 else np.inf
        if ratio < 1.0:
            solver.restore_state(state)
            controller.reject(h * max(0.2, 0.9 * ratio))
            summary["rejected_steps"] += 1  # kept in the checkpoints: a resume continues it
            continue
        step += 1
        work = StepRecord.work(solver.counts - counts_before)
        cuts = controller.cuts
        record = StepRecord(step, target, h, iterations, cuts, list(solver.residual_history),
                            solver.linear_iterations, **work)
        accept(step, target, h, iterations, cuts, record.residuals, errors, record.counts())
        t, fresh = target, True
        controller.accept(next_step=h * min(2.0, max(0.2, 0.9 * ratio)))
        if checkpoints is not None:
            checkpoints.step_done({"label": label, "step": step, "value": t,
                                   "increment": controller.step, "records": []})
    if checkpoints is not None:
        checkpoints.leave_path([])


def load_instantly(ctx: RunContext, bar: ViscousBar, solver: NonlinearSolver,
                   apply_load: Callable[[float], None], label: str) -> None:
    """The glassy response at t = 0: the full load with dt = 0 (Cv stays Cv_0 = I),
    reached by load steps if Newton needs them; Cv_n is not updated, C̄_n is."""
    bar.dt.value = 0.0
    follow_path(solver, lambda factor, _inc: apply_load(factor), Stepping(initial_step=1.0),
                label=f"{label} (t = 0)", quiet=ctx.options.quiet)
    bar.store_strain()


def plot_history(path: Path, times, values, reference, ylabel: str, title: str,
                 reference_label: str = "reference", metadata: dict | None = None) -> None:
    """A small PNG of a quantity over time, with its reference when there is one."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.0, 3.2), dpi=100)
    ax.plot(times, values, "o", ms=2.5, label="FE (DOLFINx)")
    if reference is not None:
        ax.plot(times, reference, "-", lw=1.0, label=reference_label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, metadata=metadata)
    plt.close(fig)
