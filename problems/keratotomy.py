"""``keratotomy``: radial keratotomy on a viscoelastic cornea under intra-ocular pressure,
creeping over hours (issue 6, item 5 — a first version, see docs/viscoelastic.md).

Two runs on the same mesh (same cells, same output times): the intact cornea and the cornea
with ``incisions`` real cuts (meshes/cornea.py). Both are loaded at t = 0 by the IOP as a
follower pressure on the posterior surface (glassy response, Cv = I), the limbus clamped
(``support`` = clamped) or on distributed springs (``elastic``, ``limbus_stiffness``),
then creep with backward Euler to ``t_end``. The outputs are the geometric grid
(``first_dt`` growing by ``dt_growth``); ``time_stepping`` = adaptive takes the steps
between them from the embedded backward/forward-Euler error estimate against
``time_tolerance`` (the bars' controller, :func:`~eyemech.problems.solid.viscous_bar.march_adaptive`),
fixed steps on the output grid itself. The keratometric power is 337.5 / R with R from a least-
squares sphere through the deformed anterior nodes inside the central ``fit_diameter``;
``power_change_D`` = incised − intact at the same time and IOP (negative = flattening).
``time_error_estimate`` (incised) and ``intact_time_error_estimate`` are the estimated
relative stress error of the time steps (in both modes), with ``time_steps`` and
``rejected_steps``; a run resumed from a checkpoint continues the accumulation (the
per-point estimate G is checkpointed with Cv_n). Measured against fixed steps:
docs/viscoelastic.md.

Mesh sizes follow the physics: the planform's radial size is the cornea's bending length
√(Ra t_c) (the decay length of the limbus's and the cuts' bending disturbances,
:func:`~eyemech.meshes.cornea.bending_length`) over ``resolution``, so a thinner or flatter
cornea gets the same mesh relative to its shell behaviour; ``mesh_size`` sets an absolute
size instead. Through the thickness ``layers`` cells per local thickness, with a level at
the incision bottom and at least one layer in the uncut ligament, whatever
``incision_depth`` is. The hexahedra are counted before meshing
(:func:`~eyemech.meshes.cornea.cell_count`, exact) and a run above ``max_cells`` is refused,
naming ``resolution``.

Simplification: the incisions exist from the start of loading; cutting a cornea that is
already pressurised (the surgical sequence) would need the pre-stressed state carried over
to the cut mesh, which is not done.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import ClassVar, Literal

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms import follower_pressure
from eyemech.forms import viscoelastic as ve
from eyemech.meshes import MeshError
from eyemech.meshes.cornea import CorneaGeometry, bending_length, cell_count, cornea
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.output import displacement_grid, render_png
from eyemech.problems.run.parameters import (
    GEOMETRY,
    MMHG,
    PHYSICS,
    SOLVER,
    ParameterError,
    SceneParameters,
    field,
)
from eyemech.problems.run.scene import Scene
from eyemech.problems.solid.limbus import Support, limbus_support, validate_support
from eyemech.problems.solid.spaces import (
    ELEMENTS,
    global_dofs,
    mixed_displacement_pressure,
    symmetry_bcs,
)
from eyemech.problems.solid.viscous_bar import AdaptiveSteps, ViscousHistory, march_adaptive
from eyemech.problems.solve.driver import NonlinearSolver, Stepping, follow_path
from eyemech.problems.solve.linear_solvers import SolverChoice
from eyemech.problems.solve.scalars import assemble_scalar


@dataclasses.dataclass(frozen=True)
class Parameters(SceneParameters, SolverChoice):
    incisions: int = field(8, "number of radial incisions (0 = intact only)", group=PHYSICS)
    incision_depth: float = field(0.9, "incision depth, fraction of the local thickness", group=PHYSICS)
    optical_zone: float = field(3.0, "clear central zone diameter", "mm", group=PHYSICS)
    incision_end: float = field(5.35, "planform radius where the incisions stop", "mm", group=PHYSICS)
    iop_mmHg: float = field(15.0, "intra-ocular pressure on the posterior surface", "mmHg", group=PHYSICS)
    mu_inf: float = field(0.04, "equilibrium shear modulus μ∞", "MPa", group=PHYSICS)
    mu_v: float = field(0.03, "viscous-branch shear modulus μv", "MPa", group=PHYSICS)
    tau: float = field(3600.0, "relaxation time τ", "s", group=PHYSICS)
    t_end: float = field(4 * 3600.0, "end of the creep period", "s", group=PHYSICS)
    first_dt: float = field(300.0, "first time step (then growing); the output times are the "
                            "grid first_dt, first_dt (1 + dt_growth), ... in both modes", "s", group=SOLVER)
    dt_growth: float = field(1.6, "growth factor of successive time steps (of output intervals "
                             "in adaptive mode)", group=SOLVER)
    time_stepping: Literal["adaptive", "fixed"] = field(
        "adaptive", "adaptive: steps from the embedded BE/FE error estimate (module viscous_bar), "
                    "landing on the output grid; fixed: the output grid is the time grid", group=SOLVER)
    time_tolerance: float = field(1e-2, "adaptive mode: allowed relative stress error from the "
                                        "time steps (embedded BE/FE estimate, module viscous_bar)",
                                  group=SOLVER)
    max_steps: int = field(20000, "most time steps a creep run may take (adaptive or fixed)", group=SOLVER)
    anterior_radius: float = field(7.8, "anterior radius of curvature", "mm", group=GEOMETRY)
    posterior_radius: float = field(6.5, "posterior apical radius of curvature", "mm", group=GEOMETRY)
    central_thickness: float = field(0.52, "central thickness", "mm", group=GEOMETRY)
    limbal_thickness: float = field(0.67, "thickness at the limbus", "mm", group=GEOMETRY)
    diameter: float = field(11.7, "planform diameter at the limbus", "mm", group=GEOMETRY)
    support: Support = field("clamped", "limbus support: clamped, or "
                                                   "elastic (distributed springs standing in for the sclera)",
                             group=PHYSICS)
    limbus_stiffness: float = field(0.4, "spring stiffness per area of the elastic limbus "
                                    "(≈ E_sclera / 5 mm)", "MPa/mm", group=PHYSICS)
    resolution: float = field(2.0, "planform cells per bending length √(anterior_radius · "
                              "central_thickness) (2.0: 1.007 mm on the default cornea); sets the "
                              "radial element size unless mesh_size is given", group=GEOMETRY)
    mesh_size: float = field(0.0, "radial element size in the planform; 0 = √(anterior_radius · "
                             "central_thickness) / resolution", "mm", group=GEOMETRY)
    max_cells: int = field(20_000, "refuse a mesh of more hexahedra than this (counted before "
                           "meshing; 20,000 Q2P1 cells ≈ 0.6 M unknowns)", group=GEOMETRY)
    azimuthal_divisions: int = field(24, "elements around (rounded up to a multiple of lcm(8, incisions))",
                                     group=GEOMETRY)
    layers: int = field(2, "element layers through the thickness (at least)", group=GEOMETRY)
    geometry_degree: int = field(1, "cell geometry: 1 = trilinear (faceted) cells, 2 = 27-node "
                                 "cells on the curved surfaces", group=GEOMETRY)
    fit_diameter: float = field(3.0, "central zone of the anterior sphere fit", "mm", group=GEOMETRY)
    element: Literal["Q2P1"] = field("Q2P1", "element family (hexahedra)", group=GEOMETRY)
    symmetry: Literal["full", "quarter"] = field("full", "mesh the whole cornea, or the quadrant "
                                                 "x, y > 0 with symmetry planes (even incisions)",
                                                 group=GEOMETRY)

    RESOLUTION_KEY: ClassVar[str] = "resolution"

    def validate(self) -> None:
        self.require_positive("mu_inf", "mu_v", "tau", "t_end", "first_dt", "iop_mmHg",
                              "fit_diameter", "time_tolerance", "max_steps", "resolution",
                              "max_cells")
        self.require_nonnegative("mesh_size")
        try:
            self.geometry(self.incisions).validate()
        except MeshError as err:
            raise ParameterError(getattr(err, "key", "geometry"), str(err)) from None
        validate_support(self)
        if not self.dt_growth >= 1.0:
            raise ParameterError("dt_growth", f"must be >= 1, got {self.dt_growth}")
        if self.first_dt > self.t_end:
            raise ParameterError("first_dt", f"is longer than t_end ({self.t_end})")
        if not self.fit_diameter <= self.optical_zone:
            raise ParameterError("fit_diameter", f"must not exceed optical_zone ({self.optical_zone})")

    def geometry(self, incisions: int) -> CorneaGeometry:
        return CorneaGeometry(self.anterior_radius, self.posterior_radius, self.central_thickness,
                              self.limbal_thickness, self.diameter, incisions, self.incision_depth,
                              self.optical_zone, self.incision_end, self.planform_size,
                              self.azimuthal_divisions, self.layers, self.geometry_degree,
                              quarter=self.symmetry == "quarter")

    @property
    def planform_size(self) -> float:
        """``mesh_size``, or the bending length √(Ra t_c) over ``resolution``."""
        if self.mesh_size > 0:
            return self.mesh_size
        return bending_length(self.anterior_radius, self.central_thickness) / self.resolution

    @property
    def estimated_cells(self) -> int | None:
        """The exact hexahedron count of the incised cornea (the intact one has the same
        cells), from the level counts; None while the geometry is invalid (validate names it)."""
        try:
            return cell_count(self.geometry(self.incisions))
        except (MeshError, ValueError, ZeroDivisionError):
            return None

    def time_grid(self) -> tuple[float, ...]:
        times, dt, t = [], self.first_dt, 0.0
        while t < self.t_end * (1 - 1e-12):
            t = min(t + dt, self.t_end)
            times.append(t)
            dt *= self.dt_growth
        return tuple(times)


class Cornea:
    """One cornea (intact or incised): mesh, mixed u–p viscoelastic residual with the IOP
    as a follower load, the limbus support, and the quantities of interest."""

    def __init__(self, params: Parameters, incisions: int, comm: MPI.Comm,
                 azimuths: int):
        geometry = dataclasses.replace(params.geometry(incisions), azimuthal_divisions=azimuths)
        self.tagged = cornea(geometry, comm)
        mesh = self.tagged.mesh
        family = ELEMENTS[params.element]
        (self.u, self.p), (v, q) = mixed_displacement_pressure(mesh, family)
        metadata = {"quadrature_degree": family.quadrature_degree, "quadrature_rule": "default"}
        dx, ds = self.tagged.dx(metadata), self.tagged.ds(metadata)
        # Constants, not literals: a sweep over the moduli or τ compiles the forms once
        material = ve.Viscoelastic(*(dolfinx.fem.Constant(mesh, value)
                                     for value in (params.mu_inf, params.mu_v, params.tau)))
        self.history = ViscousHistory(self.u, material, "backward-euler", family.quadrature_degree)
        self.pressure = dolfinx.fem.Constant(mesh, 0.0)
        residual = (ve.residual(material, self.u, self.p, v, q, self.history.Cv, dx)
                    + follower_pressure(self.pressure, self.u, v, ds(self.tagged.tag("posterior"))))
        V = self.u.function_space
        fdim = mesh.topology.dim - 1
        support, self.bcs = limbus_support(params, self.u, v, self.tagged, ds)
        self.quarter = params.symmetry == "quarter"
        if self.quarter:
            self.bcs += symmetry_bcs(V, self.tagged, {"symmetry_x": 0, "symmetry_y": 1})
        if support is not None:
            residual += support
        self.residual_blocks = list(ufl.extract_blocks(residual))
        # the glassy shear modulus (the load step) scales the pressure Schur complement
        self.iterative = params.linear_solver(material.glassy_shear_modulus, dx)
        self._central_anterior(V, fdim, params.fit_diameter / 2)
        self.has_cuts = incisions > 0
        if self.has_cuts:
            N = ufl.FacetNormal(mesh)
            cut = ds(self.tagged.tag("incision"))
            area = assemble_scalar(1.0 * cut, comm)
            # a Constant: the cut's area follows the mesh (a literal compiles anew per mesh)
            scale = dolfinx.fem.Constant(mesh, -2.0 / area)
            self._gape = dolfinx.fem.form(scale * ufl.dot(self.u, N) * cut)
        self.comm = comm

    def _central_anterior(self, V, fdim: int, radius: float) -> None:
        blocks = dolfinx.fem.locate_dofs_topological(V, fdim, self.tagged.facets("anterior"))
        owned = V.dofmap.index_map.size_local
        blocks = blocks[blocks < owned]
        x = V.tabulate_dof_coordinates()[blocks]
        inside = np.hypot(x[:, 0], x[:, 1]) <= radius * (1 + 1e-9)
        self._fit_blocks, self._fit_x = blocks[inside], x[inside]
        apex = np.linalg.norm(x, axis=1) < 1e-9
        self._apex_block = blocks[apex]

    def solver(self, ctx: RunContext) -> NonlinearSolver:
        return NonlinearSolver(self.residual_blocks, [self.u, self.p], self.bcs,
                               options=ctx.options.newton, timings=ctx.timings,
                               iterative=self.iterative)

    def register_checkpoint(self, checkpoints, label: str, series: dict[str, list]) -> None:
        """The state of this cornea's run for checkpoints (docs/restart.md)."""
        for name, f in (("u", self.u), ("p", self.p), ("Cv_n", self.history.Cv_n),
                        ("Cbar_n", self.history.Cbar_n), ("G", self.history.error_history)):
            checkpoints.function(f"{label}/{name}", f)
        checkpoints.constant(f"{label}/pressure", self.pressure)
        checkpoints.constant(f"{label}/dt", self.history.dt)
        checkpoints.series(f"{label}/series", series)

    # -- quantities ---------------------------------------------------------------------
    def power_D(self) -> float:
        """337.5 / R of the least-squares sphere through the deformed central anterior nodes."""
        displaced = self._fit_x + self.u.x.array.reshape(-1, 3)[self._fit_blocks]
        points = np.vstack(self.comm.allgather(displaced))
        if self.quarter:  # the whole central zone, so the fit is the full model's
            points = _mirrored(points, axis=0)
            points = _mirrored(points, axis=1)
        A = np.hstack([2 * points, np.ones((len(points), 1))])
        b = (points**2).sum(axis=1)
        (cx, cy, cz, d), *_ = np.linalg.lstsq(A, b, rcond=None)
        return 337.5 / np.sqrt(d + cx * cx + cy * cy + cz * cz)

    def apex_displacement(self) -> float:
        local = self.u.x.array.reshape(-1, 3)[self._apex_block, 2]
        return self.comm.allreduce(float(local.sum()))

    def gape(self) -> float:
        """Mean normal opening of the cuts (mm): −∫ u·N dA over both lips / one lip's area."""
        if not self.has_cuts:
            return 0.0
        return assemble_scalar(self._gape, self.comm)


def _mirrored(points: np.ndarray, axis: int) -> np.ndarray:
    """``points`` and their mirror images across the plane x[axis] = 0; points on the
    plane are not doubled, as in the whole model."""
    off_plane = points[abs(points[:, axis]) > 1e-9]
    image = off_plane.copy()
    image[:, axis] *= -1
    return np.vstack([points, image])


def _simulate(ctx: RunContext, body: Cornea, params: Parameters,
              label: str) -> tuple[dict[str, list], dict[str, float]]:
    """IOP at t = 0 (glassy), then creep to t_end, fixed or adaptive steps
    (``params.time_stepping``); quantities at every output time (``params.time_grid()``)
    and the time-discretisation summary (estimate, steps taken, steps rejected)."""
    solver = body.solver(ctx)
    series: dict[str, list] = {"times": [], "power_D": [], "apex_displacement_mm": [],
                               "wound_gape_mm": [], "time_error_estimate": []}
    summary = {"time_error_estimate": 0.0, "time_steps": 0, "rejected_steps": 0}
    body.register_checkpoint(ctx.checkpoints, label, series)
    ctx.checkpoints.value(f"{label}/time_steps", lambda: summary, summary.update)
    outputs = params.time_grid()

    def record(t: float) -> None:
        series["times"].append(t)
        series["power_D"].append(body.power_D())
        series["apex_displacement_mm"].append(body.apex_displacement())
        series["wound_gape_mm"].append(body.gape())
        series["time_error_estimate"].append(summary["time_error_estimate"])

    body.history.dt.value = 0.0
    follow_path(solver, lambda f, _i: setattr(body.pressure, "value", f * params.iop_mmHg * MMHG),
                Stepping(initial_step=1.0), label=f"{label} IOP", quiet=ctx.options.quiet,
                checkpoints=ctx.checkpoints)
    record(0.0)
    # C̄_n of the loaded cornea: the embedded time-error estimate's forward-Euler half
    # starts from it (backward Euler, which the solution uses, does not read C̄_n)
    body.history.store_strain()

    def accept(step: int, t: float, dt: float, iterations: int, cuts: int, _residuals,
               errors: tuple[float, float], counts: dict) -> None:
        # the embedded BE/FE pair of module viscous_bar: errors = (this step's, accumulated)
        body.history.accept_time_error()
        summary["time_error_estimate"] = max(summary["time_error_estimate"], errors[1])
        summary["time_steps"] += 1
        if any(abs(t - s) <= 1e-12 * params.t_end for s in outputs):
            record(t)  # before the update: the outputs read Cv_n of this step
        body.history.update()
        ctx.record_step(run=label, time=t, dt=dt, newton_iterations=iterations, cuts=cuts,
                        **counts, krylov_iterations=solver.linear_iterations,
                        local_time_error=errors[0])

    if params.time_stepping == "adaptive":
        march_adaptive(body.history, solver,
                       AdaptiveSteps(params.t_end, params.first_dt, params.time_tolerance,
                                     params.max_steps, outputs),
                       lambda _t: None, accept, summary, checkpoints=ctx.checkpoints,
                       label=f"{label} creep")
        return series, summary

    def apply(t: float, increment: float) -> None:
        body.history.dt.value = increment

    def converged(step) -> None:
        accept(step.step, step.load, step.increment, step.iterations, step.cuts, step.residuals,
               body.history.time_error(), step.counts())

    follow_path(solver, apply, Stepping(start=0.0, end=params.t_end, quantity="time", unit="s",
                                        initial_step=1.0, max_step=1.0, min_step=1e-6, stops=outputs),
                on_converged=converged, label=f"{label} creep", quiet=ctx.options.quiet,
                checkpoints=ctx.checkpoints)
    return series, summary


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        azimuths = params.geometry(params.incisions).azimuths  # the same cells for both runs
        with ctx.timings("mesh"):
            intact = Cornea(params, 0, ctx.comm, azimuths)
        reference, steps = _simulate(ctx, intact, params, "intact")
        q = ctx.result.quantities
        q["times"] = reference["times"]
        q["intact_power_D"] = reference["power_D"]
        q["intact_apex_displacement_mm"] = reference["apex_displacement_mm"]
        q["unloaded_power_D"] = 337.5 / params.anterior_radius
        q["intact_time_error_estimate"] = steps["time_error_estimate"]
        q["intact_time_steps"] = steps["time_steps"]
        q["intact_rejected_steps"] = steps["rejected_steps"]
        if params.incisions > 0:
            with ctx.timings("mesh"):
                incised = Cornea(params, params.incisions, ctx.comm, azimuths)
            series, steps = _simulate(ctx, incised, params, "incised")
            q["power_D"] = series["power_D"]
            q["power_change_D"] = [a - b for a, b in zip(series["power_D"], reference["power_D"])]
            q["apex_displacement_mm"] = series["apex_displacement_mm"]
            q["wound_gape_mm"] = series["wound_gape_mm"]
            q["time_error_estimate"] = steps["time_error_estimate"]
            q["time_steps"] = steps["time_steps"]
            q["rejected_steps"] = steps["rejected_steps"]
            q["power_change_initial_D"] = q["power_change_D"][0]
            q["power_change_final_D"] = q["power_change_D"][-1]
            q["creep_power_change_D"] = q["power_change_final_D"] - q["power_change_initial_D"]
            shown = incised
        else:
            q["power_D"] = reference["power_D"]
            shown = intact
        q["cells"] = shown.tagged.mesh.topology.index_map(3).size_global
        q["dofs"] = global_dofs(shown.u, shown.p)
        if ctx.pictures:
            with ctx.timings("output"):
                _picture(ctx, shown, params)
    return ctx.result


def _picture(ctx: RunContext, body: Cornea, params: Parameters) -> None:
    grid = displacement_grid(body.u)
    if grid is None:
        return
    path = ctx.out / "cornea.png"
    render_png(grid, path, scalars="displacement (mm)", warp="displacement", camera=(0.3, -1.0, 1.4),
               title=f"{params.incisions} incisions, OZ {params.optical_zone:g} mm, "
                     f"t = {params.t_end / 3600:g} h",
               scene=ctx.result.scene, parameters=ctx.result.parameters)
    ctx.result.pictures.append(path.name)


SCENE = Scene(name="keratotomy", kind="scene", parameters=Parameters, run=run,
              summary="radial keratotomy on a viscoelastic cornea under IOP: power change "
                      "over hours (first version)")
