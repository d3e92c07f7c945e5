"""What the shell benchmarks share: the space, the energy with its constants, the
supports, point values in parallel, and the plate scenes' parameters and run."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable, ClassVar, Literal

import basix.ufl
import dolfinx
import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms.shell import Kinematics, ShellMaterial, shell_energy
from eyemech.meshes.surface import (
    Diagonal,
    mapped_surface,
    orientation,
    require_surface,
    tag_boundary,
)
from eyemech.meshes.tagged import TaggedMesh
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.error_estimate import Refinement, error_estimate_field, estimate_errors
from eyemech.problems.run.output import gather_grid, render_png
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, ParameterError, SceneParameters, field
from eyemech.problems.solve.driver import (
    NewtonOptions,
    NonlinearSolver,
    Stepping,
    StepRecord,
    follow_path,
)


def newton_options(ctx: RunContext, kinematics: Kinematics) -> NewtonOptions:
    """The linear shell is solved by one linear solve (SNES ``ksponly``): a Newton
    convergence test on an ill-conditioned system (a large penalty) can stall at
    round-off above the absolute tolerance although the solve is exact."""
    options = ctx.options.newton
    if kinematics != "linear":
        # The same stall in the nonlinear shell once Newton has converged: a clamped edge's
        # penalty on stretched cells puts the residual's round-off floor near the absolute
        # tolerance. A Newton update below 1e-8 of the solution (PETSc's default stol)
        # leaves an error of order its square, so it stops there too.
        options = options if options.stol > 0.0 else dataclasses.replace(options, stol=1e-8)
        # The first iterate of a load step on a thin shell carries the membrane forces of
        # its bending predictor: 1e3–1e5 × the step's load residual, after which Newton
        # converges quadratically (slit annular plate: 4.1e-3, 2.4e2, then 6e-6, 7e-10).
        # PETSc's divergence test (‖F‖ > 1e4 ‖F₀‖) stopped those solves and cut the step
        # (1,459 Newton iterations to Sze's q_max); switched off (1e300), a diverging
        # solve still fails by max_it or a NaN.
        petsc = {"snes_divergence_tolerance": "1e300", **options.petsc}
        return dataclasses.replace(options, petsc=petsc)
    return dataclasses.replace(options, petsc={"snes_type": "ksponly", **options.petsc})


def check_shell_parameters(params: SceneParameters, in_plane_size: float) -> None:
    """The checks every shell scene makes (named keys, before any mesh is built)."""
    params.require_positive("youngs_modulus", "thickness", "penalty_factor")
    if not -1.0 < params.poisson_ratio < 0.5:
        raise ParameterError("poisson_ratio", f"must lie in (-1, 0.5), got {params.poisson_ratio!r}")
    if not params.thickness < in_plane_size:
        raise ParameterError("thickness", f"must be smaller than the in-plane size ({in_plane_size:g}) "
                             f"for a shell, got {params.thickness!r}")
    if params.degree not in (2, 3):
        raise ParameterError("degree", f"must be 2 or 3, got {params.degree!r}")


class Shell:
    """A Kirchhoff–Love shell on a tagged surface mesh: displacement space, material
    constants (so one compiled form serves every parameter value) and measures."""

    def __init__(self, tagged: TaggedMesh, params, direction: Callable[[np.ndarray], np.ndarray],
                 clamped: tuple[str, ...] = ()):
        mesh = tagged.mesh
        require_surface(mesh)
        self.tagged, self.mesh, self.degree = tagged, mesh, params.degree
        element = basix.ufl.element("Lagrange", "triangle", params.degree, shape=(3,))
        self.V = dolfinx.fem.functionspace(mesh, element)
        self.u = dolfinx.fem.Function(self.V, name="displacement")
        self.v = ufl.TestFunction(self.V)
        self.orientation = orientation(mesh, direction)

        def constant(value: float):
            return dolfinx.fem.Constant(mesh, dolfinx.default_scalar_type(value))

        self.constant = constant
        self.material = ShellMaterial(constant(params.youngs_modulus), constant(params.poisson_ratio),
                                      constant(params.thickness))
        self.penalty_factor = constant(params.penalty_factor)
        # P2: strains of degree 1 (linear) or 2 (nonlinear, squared in the energy);
        # a fixed degree keeps UFL from estimating ~20 for the rational integrand
        metadata = {"quadrature_degree": 2 * params.degree}
        self.dx = ufl.Measure("dx", mesh, metadata=metadata)
        self.dS = ufl.Measure("dS", mesh, metadata=metadata)
        self.ds = tagged.ds(metadata)
        self.clamped = None
        for name in clamped:
            measure = self.ds(tagged.tag(name))
            self.clamped = measure if self.clamped is None else self.clamped + measure

    def energy(self, kinematics: Kinematics):
        return shell_energy(self.u, self.material, self.orientation, degree=self.degree,
                            penalty_factor=self.penalty_factor, dx=self.dx, dS=self.dS,
                            ds_clamped=self.clamped, kinematics=kinematics)

    def fix(self, name: str, components: tuple[int, ...] = (0, 1, 2)) -> list:
        """Dirichlet u_i = 0 on the tagged edges ``name`` for the given components."""
        facets = self.tagged.facets(name)
        bcs = []
        for i in components:
            sub, _ = self.V.sub(i).collapse()
            dofs = dolfinx.fem.locate_dofs_topological((self.V.sub(i), sub), 1, facets)
            bcs.append(dolfinx.fem.dirichletbc(dolfinx.default_scalar_type(0.0), dofs[0], self.V.sub(i)))
        return bcs

    def fix_where(self, inside: Callable[[np.ndarray], np.ndarray], component: int) -> list:
        """Dirichlet u_i = 0 at the nodes where ``inside(x)`` holds (e.g. a symmetry line)."""
        sub, _ = self.V.sub(component).collapse()
        dofs = dolfinx.fem.locate_dofs_geometrical((self.V.sub(component), sub), inside)
        return [dolfinx.fem.dirichletbc(dolfinx.default_scalar_type(0.0), dofs[0],
                                        self.V.sub(component))]

    def value_at(self, point) -> np.ndarray:
        """Displacement at the degree of freedom nearest to ``point`` (a node of the
        mesh in the benchmarks), the same on every rank."""
        return nodal_value(self.u, np.asarray(point, dtype=float))

    def dofs(self) -> int:
        index_map = self.V.dofmap.index_map
        return index_map.size_global * self.V.dofmap.index_map_bs


def nodal_value(u: dolfinx.fem.Function, point: np.ndarray) -> np.ndarray:
    V = u.function_space
    owned = V.dofmap.index_map.size_local
    x = V.tabulate_dof_coordinates()[:owned]
    bs = V.dofmap.index_map_bs
    if owned:
        i = int(np.argmin(np.linalg.norm(x - point, axis=1)))
        local = (float(np.linalg.norm(x[i] - point)), u.x.array[bs * i: bs * i + bs].copy())
    else:
        local = (np.inf, np.zeros(bs))
    candidates = V.mesh.comm.allgather(local)
    return min(candidates, key=lambda c: c[0])[1]


# -- the plate benchmarks -------------------------------------------------------------

InPlane = Literal["immovable", "sliding"]


@dataclasses.dataclass(frozen=True)
class ShellDiscretisation:
    """Parameter mixin of the shell benchmarks (``class Parameters(SceneParameters,
    ShellDiscretisation)``): the triangulation and the C0 interior-penalty discretisation."""

    diagonal: Diagonal = field("crossed", "triangulation of each square: crossed|right|left|alternating",
                               group=GEOMETRY)
    degree: int = field(2, "Lagrange degree of the displacement (2 or 3)", group=GEOMETRY)
    penalty_factor: float = field(1.0, "α in the edge penalty α p(p+1) D / h", group=GEOMETRY)

    def grid_triangles(self, nx: int, ny: int) -> int:
        """Triangles of the structured nx × ny grid (meshes/surface.py: 4 per square when
        crossed, else 2), the exact cell count before meshing."""
        return (4 if self.diagonal == "crossed" else 2) * nx * ny


@dataclasses.dataclass(frozen=True)
class PlateParameters(SceneParameters, ShellDiscretisation):
    q: float = field(1.0, "uniform transverse load (dead load, per reference area)", "MPa", group=PHYSICS)
    youngs_modulus: float = field(1.092e6, "Young's modulus (the shell paper's test)", "MPa", group=PHYSICS)
    poisson_ratio: float = field(0.3, "Poisson's ratio", group=PHYSICS)
    length: float = field(10.0, "side of the square plate", "mm", group=GEOMETRY)
    thickness: float = field(0.1, "plate thickness", "mm", group=GEOMETRY)
    divisions: int = field(32, "squares per side (each split in 4 triangles when crossed)", group=GEOMETRY)
    kinematics: Kinematics = field("linear", "linear (small displacement) or nonlinear "
                                                        "(total Lagrangian)", group=PHYSICS)
    load_steps: int = field(4, "initial number of load steps (nonlinear; cut and grown as needed)",
                            group=SOLVER)
    in_plane: InPlane = field("immovable", "in-plane edge condition: immovable (u = 0) or sliding "
                                           "(normal in-plane displacement 0, tangential free: Levy 1942)",
                              group=PHYSICS)
    error_estimate: bool = error_estimate_field()

    RESOLUTION_KEY: ClassVar[str] = "divisions"

    @property
    def estimated_cells(self) -> int:
        return self.grid_triangles(self.divisions, self.divisions)

    def validate(self) -> None:
        self.require_positive("length", "divisions", "load_steps")
        check_shell_parameters(self, self.length)
        if not np.isfinite(self.q):
            raise ParameterError("q", "must be finite")


# centre deflection of a uniformly loaded square plate, w = c q L⁴ / D, ν = 0.3:
# Timoshenko & Woinowsky-Krieger, Theory of Plates and Shells (1959), Table 35
# (clamped, c = 0.00126) and Table 8 (simply supported, c = 0.00406); the digits
# 0.00126532 and 0.00406235 are the converged series values.
PLATE_COEFFICIENT = {"clamped": 0.00126532, "simply-supported": 0.00406235}

# Large deflections of the clamped square plate under uniform pressure (von Kármán
# plate): S. Levy, "Square plate with clamped edges under normal pressure producing
# large deflections", NACA Technical Note 847 (1942) = NACA Report 740, Table 5.
# Edges clamped against rotation and against in-plane displacement NORMAL to the
# edge, free to slide along it (no edge shear); ν = 0.316. Load parameter
# Q = q a⁴/(E h⁴), centre deflection w₀/h.
LEVY_LOAD_PARAMETER = (17.79, 38.3, 63.4, 95.0, 134.9, 184.0, 245.0, 318.0, 402.0)
LEVY_CENTER_DEFLECTION = (0.237, 0.471, 0.695, 0.912, 1.121, 1.323, 1.521, 1.714, 1.902)
LEVY_POISSON_RATIO = 0.316


def follow_shell_path(ctx: RunContext, solver: NonlinearSolver, apply: Callable[[float, float], None],
                      kinematics: Kinematics, load_steps: int, stops: tuple[float, ...],
                      step_values: Callable[[StepRecord], dict], label: str,
                      on_step: Callable[[dict], None] | None = None) -> None:
    """The load path of a shell benchmark: one step when linear, ``load_steps`` otherwise,
    landing on ``stops``. Each converged step is recorded (the scene's ``step_values`` and
    the solver's counts) and its displacement written; the field writer is closed whatever
    happens, so an interrupted run leaves readable fields."""
    writer = ctx.field_writer(solver.unknowns)

    def converged(record: StepRecord) -> None:
        values = dict(step=record.step, load_factor=record.load, **step_values(record),
                      newton_iterations=record.iterations, cuts=record.cuts, **record.counts())
        if on_step is not None:
            on_step(values)
        ctx.record_step(**values)
        with ctx.timings("output"):
            writer.write(record.load)

    steps = 1 if kinematics == "linear" else load_steps
    try:
        follow_path(solver, apply, Stepping(initial_step=1.0 / steps, stops=tuple(stops)),
                    on_converged=converged, label=label, quiet=ctx.options.quiet)
    finally:
        writer.close()
        ctx.result.fields = writer.files


def levy_center_deflection(load_parameter: float) -> float:
    """w₀/h of Levy's table at Q = q a⁴/(E h⁴), monotone cubic (PCHIP) through the
    origin and the nine tabulated points; NaN beyond the table (Q > 402)."""
    from scipy.interpolate import PchipInterpolator

    if not 0.0 <= load_parameter <= LEVY_LOAD_PARAMETER[-1] * (1.0 + 1e-9):
        return float("nan")
    curve = PchipInterpolator((0.0,) + LEVY_LOAD_PARAMETER, (0.0,) + LEVY_CENTER_DEFLECTION)
    return float(curve(min(load_parameter, LEVY_LOAD_PARAMETER[-1])))


def levy_conditions(support: str, params: PlateParameters) -> bool:
    """Levy's plate: clamped, large deflection, edges sliding, ν = 0.316."""
    return (support == "clamped" and params.kinematics == "nonlinear" and params.in_plane == "sliding"
            and bool(np.isclose(params.poisson_ratio, LEVY_POISSON_RATIO)))


def plate_supports(shell: Shell, length: float, in_plane: InPlane) -> list:
    """w = 0 on every edge; in-plane u = 0 (immovable) or only the component normal
    to each edge (sliding: u_x = 0 on x = 0, L and u_y = 0 on y = 0, L)."""
    if in_plane == "immovable":
        return shell.fix("edge")
    L = length
    return (shell.fix("edge", (2,))
            + shell.fix_where(lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], L), 0)
            + shell.fix_where(lambda x: np.isclose(x[1], 0.0) | np.isclose(x[1], L), 1))


# half the divisions; the centre deflection converges at h^1.8 or faster (P2 crossed:
# docs/atlas/shell-resolution.md)
PLATE_ESTIMATE = Refinement(keys=("divisions",), order=1.8, quantities=("center_deflection",),
                            size=lambda params: 1.0 / params.divisions)


def run_plate(scene_name: str, support: Literal["clamped", "simply-supported"],
              params: PlateParameters, comm: MPI.Comm | None, out, options: RunOptions | None,
              stops: tuple[float, ...] = (), rerun: Callable | None = None):
    """The plate benchmarks; ``stops`` (load factors in (0, 1]) are values the load
    path must land on exactly (e.g. the loads of a reference table); ``rerun`` is the
    scene's run, for the error estimate's coarse solve."""
    with RunContext(scene_name, params, comm, out, options) as ctx:
        L = params.length
        with ctx.timings("mesh"):
            mesh = mapped_surface(lambda s, t: np.column_stack([L * s, L * t, 0.0 * s]),
                                  params.divisions, params.divisions, params.diagonal, ctx.comm)
            on_edge = (lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], L)
                       | np.isclose(x[1], 0.0) | np.isclose(x[1], L))
            tagged = tag_boundary(mesh, {"edge": on_edge})
        up = lambda x: np.tile([0.0, 0.0, 1.0], (len(x), 1))  # noqa: E731
        shell = Shell(tagged, params, up, clamped=("edge",) if support == "clamped" else ())
        load = shell.constant(0.0)
        residual = (ufl.derivative(shell.energy(params.kinematics), shell.u, shell.v)
                    - load * shell.v[2] * shell.dx)
        # w = 0 and the in-plane condition for both supports; the clamped one also
        # fixes the rotation (weakly, in the energy). The linear plate does not see
        # the in-plane condition (its membrane part is decoupled and unloaded).
        solver = NonlinearSolver(residual, shell.u, plate_supports(shell, L, params.in_plane),
                                 options=newton_options(ctx, params.kinematics),
                                 timings=ctx.timings)
        centre = (L / 2, L / 2, 0.0)

        def apply(value: float, _increment: float) -> None:
            load.value = value * params.q

        load_scale = L ** 4 / (params.youngs_modulus * params.thickness ** 4)
        levy = levy_conditions(support, params)
        if levy:  # land on the load levels of Levy's table that the path passes
            total = abs(params.q) * load_scale
            stops = tuple(stops) + tuple(Q / total for Q in LEVY_LOAD_PARAMETER if Q <= total)

        def step_values(record: StepRecord) -> dict:
            values = dict(q=record.load * params.q, load_parameter=record.load * params.q * load_scale,
                          center_deflection=float(shell.value_at(centre)[2]))
            reference = levy_center_deflection(abs(values["load_parameter"])) if levy else np.nan
            if np.isfinite(reference):
                values["center_deflection_levy"] = float(np.sign(params.q) * reference * params.thickness)
            return values

        follow_shell_path(ctx, solver, apply, params.kinematics, params.load_steps, tuple(stops),
                          step_values, scene_name)
        D = params.youngs_modulus * params.thickness ** 3 / (12 * (1 - params.poisson_ratio ** 2))
        deflection = float(shell.value_at(centre)[2])
        quantities = ctx.result.quantities
        quantities["center_deflection"] = deflection
        quantities["dofs"] = shell.dofs()
        if np.isclose(params.poisson_ratio, 0.3):  # the tabulated coefficients are for ν = 0.3
            linear = PLATE_COEFFICIENT[support] * params.q * L ** 4 / D
            quantities["center_deflection_linear_reference"] = linear
            if params.kinematics == "linear":
                quantities["center_deflection_error"] = deflection / linear - 1.0
        quantities["load_parameter"] = params.q * load_scale
        if levy:
            reference = levy_center_deflection(abs(params.q) * load_scale) * params.thickness
            if np.isfinite(reference):
                quantities["center_deflection_levy"] = float(np.sign(params.q) * reference)
                quantities["center_deflection_levy_error"] = abs(deflection) / reference - 1.0
        if params.error_estimate and rerun is not None:
            estimate_errors(ctx, rerun, params, PLATE_ESTIMATE)
        if ctx.pictures:
            with ctx.timings("output"):
                picture(shell.u, ctx, f"{scene_name}, q = {params.q:g} MPa", "w (mm)",
                        lambda d: d[:, 2], scale=0.2 * L / max(abs(deflection), 1e-30))
    return ctx.result


def picture(u: dolfinx.fem.Function, ctx: RunContext, title: str, label: str,
            scalar: Callable[[np.ndarray], np.ndarray], scale: float = 1.0,
            camera="iso", name: str = "deformed.png") -> None:
    """Deformed surface (displacement times ``scale``) coloured by ``scalar``."""
    grid = gather_grid(u)
    if grid is None:
        return
    displacement = grid.point_data[u.name]
    grid.point_data[label] = scalar(displacement)
    grid.point_data["shown"] = displacement * scale
    path = Path(ctx.out) / name
    suffix = f" (displacement × {scale:.3g})" if not np.isclose(scale, 1.0) else ""
    render_png(grid, path, scalars=label, warp="shown", title=title + suffix, camera=camera,
               scene=ctx.result.scene, parameters=ctx.result.parameters)
    ctx.result.pictures.append(path.name)
