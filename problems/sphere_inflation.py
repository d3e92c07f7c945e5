"""``sphere-inflation``: a thick incompressible neo-Hookean sphere inflated by an
internal follower pressure — the foundation benchmark, with an exact solution
(:mod:`eyemech.problems.reference.analytic`).

One octant is modelled (three symmetry planes). The pressure is ramped by the path
follower; each converged step records the deformed radii and the cavity volume.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import ClassVar, Literal

import dolfinx
import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms import NeoHooke, enclosed_volume, follower_pressure
from eyemech.meshes import spherical_shell
from eyemech.problems.reference import analytic
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.error_estimate import Refinement, error_estimate_field, estimate_errors
from eyemech.problems.run.output import (
    gather_grid,
    render_png,
)
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, ParameterError, SceneParameters, field
from eyemech.problems.run.scene import Scene
from eyemech.problems.solid.mean_dilatation import MeanDilatation
from eyemech.problems.solid.residual import solid_residual
from eyemech.problems.solid.spaces import (
    ELEMENTS,
    ElementName,
    check_element,
    global_dofs,
    lagrange_view,
    solid_fields,
    surface_mean,
    symmetry_bcs,
)
from eyemech.problems.solve.driver import (
    NonlinearSolver,
    SolveFailure,
    Stepping,
    follow_path,
)
from eyemech.problems.solve.linear_solvers import SolverChoice
from eyemech.problems.solve.scalars import assemble_scalar


@dataclasses.dataclass(frozen=True)
class Parameters(SceneParameters, SolverChoice):
    RESOLUTION_KEY: ClassVar[str] = "cells_across_wall"
    inner_radius: float = field(10.0, "inner radius of the unloaded sphere", "mm", group=GEOMETRY)
    outer_radius: float = field(12.0, "outer radius of the unloaded sphere", "mm", group=GEOMETRY)
    c10: float = field(0.05, "neo-Hookean constant, W = c10 (I1 - 3)", "MPa", group=PHYSICS)
    pressure: float = field(0.01, "internal pressure (follower load)", "MPa", group=PHYSICS)
    cells_across_wall: float = field(2.0, "elements across the wall thickness (outer − inner radius); "
                                   "sets the element size unless mesh_size is given", group=GEOMETRY)
    mesh_size: float = field(0.0, "target element size; 0 = wall thickness / cells_across_wall", "mm",
                             group=GEOMETRY)
    element: ElementName = field("P2P1", "element family: " + ", ".join(ELEMENTS), group=GEOMETRY)
    bulk_modulus: float = field(100.0, "bulk modulus of the displacement-only P1 family "
                                "(U = K/4 (J² − 1 − 2 ln J)) and of Q1P0 with dg0_pressure = condensed "
                                "(U = K/2 (J̄ − 1)²); unused by the mixed families", "MPa", group=PHYSICS)
    dg0_pressure: Literal["mixed", "condensed"] = field(
        "mixed", "Q1P0's DG0 pressure: mixed (an unknown per cell, exactly incompressible) or "
                 "condensed (eliminated cell by cell, p = K (J̄ − 1): the mean-dilatation method, "
                 "O(μ/K) from mixed; docs/hyperelastic.md)", group=GEOMETRY)
    load_steps: int = field(1, "initial number of load steps; 1 = the whole load at once (a smooth problem: "
                               "Newton converges from the unloaded state, a failed step is cut)",
                            group=SOLVER)
    error_estimate: bool = error_estimate_field()

    def validate(self) -> None:
        self.require_positive("inner_radius", "c10", "cells_across_wall", "load_steps", "bulk_modulus")
        self.require_nonnegative("mesh_size")
        check_element(self.element)
        if self.dg0_pressure == "condensed" and self.element != "Q1P0":
            raise ParameterError("dg0_pressure", f"condensed needs element Q1P0, not {self.element}")
        if not self.outer_radius > self.inner_radius:
            raise ParameterError("outer_radius", f"must exceed inner_radius ({self.inner_radius}), "
                                 f"got {self.outer_radius}")
        if self.element_size > self.outer_radius:
            raise ParameterError(self.resolution_key(), f"gives an element size of "
                                 f"{self.element_size:.3g} mm, larger than the sphere")
        if not np.isfinite(self.pressure):
            raise ParameterError("pressure", "must be finite")

    @property
    def element_size(self) -> float:
        """mesh_size, or the wall thickness over cells_across_wall."""
        if self.mesh_size > 0:
            return self.mesh_size
        return (self.outer_radius - self.inner_radius) / self.cells_across_wall


def auto_factorisation(element: str) -> str:
    """The factorisation ``--factorisation auto`` uses. The Jacobian is symmetric (the residual
    is the energy's gradient; the follower pressure's stiffness is symmetric on the closed
    cavity: ‖A−Aᵀ‖/‖A‖ = 1.2e-16), and MUMPS LDLᵀ with its [u, p]-pair ordering halves LU's
    factor and flops at both elements (P2P1 4.20 M against 8.31 M entries, Q2P1 5.21 M against
    10.19 M): docs/atlas/peer-comparison.md, "Symmetric factorisation"."""
    return "ldlt" if element in ("P2P1", "Q2P1") else "lu"


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        with ctx.timings("mesh"):
            family = ELEMENTS[params.element]
            shell = spherical_shell(params.inner_radius, params.outer_radius, params.element_size,
                                    order=family.geometry_order, hexahedra=family.hexahedral,
                                    comm=ctx.comm)
        condensed = params.dg0_pressure == "condensed"
        fields, tests = solid_fields(shell.mesh, family, condensed=condensed)
        u, v = fields[0], tests[0]
        metadata = {"quadrature_degree": family.quadrature_degree}
        ds, dx = shell.ds(metadata), shell.dx(metadata)
        pressure = dolfinx.fem.Constant(shell.mesh, 0.0)
        # material numbers as Constants, not literals: a sweep over them compiles the forms once
        c10 = dolfinx.fem.Constant(shell.mesh, params.c10)
        bulk_modulus = dolfinx.fem.Constant(shell.mesh, params.bulk_modulus)
        bcs = symmetry_bcs(u.function_space, shell, {"symmetry_x": 0, "symmetry_y": 1,
                                                     "symmetry_z": 2})
        mean_dilatation = MeanDilatation(u, bulk_modulus, dx, bcs) if condensed else None
        law = NeoHooke(c10)
        residual = (solid_residual(law, family, fields, tests, dx, bulk_modulus,
                                   condensed_pressure=getattr(mean_dilatation, "pressure", None))
                    + follower_pressure(pressure, u, v, ds(shell.tag("cavity_wall"))))
        solver = NonlinearSolver(list(ufl.extract_blocks(residual)), fields, bcs,
                                 options=ctx.options.newton, timings=ctx.timings,
                                 iterative=params.linear_solver(law.shear_modulus, dx),
                                 auto_factorisation=auto_factorisation(params.element))
        if mean_dilatation is not None:
            solver.state_hooks.append(mean_dilatation.update)
            solver.jacobian_hooks.append(mean_dilatation.jacobian_hook)

        volume_form = dolfinx.fem.form(8.0 * enclosed_volume(u, ds(shell.tag("cavity_wall"))))
        x = ufl.SpatialCoordinate(shell.mesh) + u
        radius = ufl.sqrt(ufl.dot(x, x))
        inner_mean = surface_mean(radius, ds(shell.tag("cavity_wall")))
        outer_mean = surface_mean(radius, ds(shell.tag("outer")))

        def quantities() -> dict[str, float]:
            return {"inner_radius_deformed": inner_mean(),
                    "outer_radius_deformed": outer_mean(),
                    "cavity_volume": assemble_scalar(volume_form, ctx.comm)}

        u.name = "displacement"
        pressure_field = mean_dilatation.pressure if condensed else fields[1] if len(fields) > 1 else None
        write_state, close_fields = _field_output(ctx, shell, family, u, pressure_field)
        write_state(0.0)

        def apply(load: float, _increment: float) -> None:
            pressure.value = load * params.pressure

        def converged(record) -> None:
            values = quantities()
            ctx.record_step(step=record.step, load_factor=record.load,
                            pressure=record.load * params.pressure, newton_iterations=record.iterations,
                            krylov_iterations=record.linear_iterations,
                            cuts=record.cuts, **record.counts(), residuals=record.residuals, **values)
            write_state(record.load)

        try:
            follow_path(solver, apply, Stepping(initial_step=1.0 / params.load_steps),
                        on_converged=converged, label=SCENE.name, quiet=ctx.options.quiet)
        except SolveFailure:
            # the driver restored the last converged state: report that one
            ctx.result.quantities.update(quantities())
            raise
        finally:
            ctx.result.fields = close_fields()
        ctx.result.quantities.update(quantities())
        ctx.result.quantities["jacobian_nonzeros"] = solver.jacobian_nonzeros()
        ctx.result.quantities["dofs"] = global_dofs(*fields)
        _compare_with_exact(ctx.result.quantities, u, shell, params)
        if params.error_estimate:
            estimate_errors(ctx, run, params, ESTIMATE)
        if ctx.pictures:
            with ctx.timings("output"):
                _picture(u, ctx, params)
    return ctx.result


def _field_output(ctx: RunContext, shell, family, u, pressure_field):
    """(write_state(load), close() -> files): the displacement and the pressure as VTX
    fields, and both on the displacement's nodes as the pyvista series."""
    writer = ctx.field_writer([u], pvd=False)  # VTX on request; state.pvd below
    pressure_out = [lagrange_view(pressure_field, "pressure")] if pressure_field is not None else []
    writer_p = ctx.field_writer([view for view, _ in pressure_out], pvd=False)
    series = ctx.pyvista_series()
    # pressure on the displacement's nodes, for pyvista (one grid, one space); made only
    # when fields are written (a function space costs ≈ 0.05 s at h = 1)
    nodal_pressure = dolfinx.fem.Function(dolfinx.fem.functionspace(
        shell.mesh, ("Lagrange", family.displacement_degree)), name="pressure") \
        if ctx.field_dir is not None else None

    def write_state(load: float) -> None:
        with ctx.timings("output"):
            for _, update in pressure_out:
                update()
            writer.write(load)
            writer_p.write(load)
            if ctx.field_dir is not None:
                extra = {}
                for view, _ in pressure_out:
                    nodal_pressure.interpolate(view)
                    extra["pressure"] = nodal_pressure
                series.write(load, gather_grid(u, extra))

    def close() -> list:
        writer.close()
        writer_p.close()
        return writer.files + writer_p.files + series.files

    return write_state, close


def _compare_with_exact(quantities: dict, u, shell, params: Parameters) -> None:
    """The exact inner radius, the relative error of the computed one and the displacement's
    L² error (none when the pressure exceeds the exact solution's limit point)."""
    try:
        exact = analytic.sphere_inner_radius(params.pressure, params.inner_radius,
                                             params.outer_radius, params.c10)
        quantities["inner_radius_exact"] = exact
        quantities["inner_radius_error"] = quantities["inner_radius_deformed"] / exact - 1.0
        quantities["displacement_error"] = _displacement_error(u, shell, params, exact)
    except ValueError:
        pass


def _displacement_error(u, shell, params: Parameters, a: float) -> float:
    """‖u − u_exact‖ / ‖u_exact‖ in L² over the wall; u_exact = (r(R)/R − 1) X with
    r³ = R³ − A³ + a³ (incompressible radial map, :mod:`analytic`)."""
    X = ufl.SpatialCoordinate(shell.mesh)
    R = ufl.sqrt(ufl.dot(X, X))
    # A³ − a³ as a Constant: the error functional compiles once for every pressure and modulus
    shift = dolfinx.fem.Constant(shell.mesh, params.inner_radius**3 - a**3)
    r = (R**3 - shift) ** (1.0 / 3.0)
    exact = (r / R - 1.0) * X
    dx = shell.dx({"quadrature_degree": 2 * u.function_space.element.basix_element.degree + 2})
    comm = shell.mesh.comm
    error = assemble_scalar(ufl.dot(u - exact, u - exact) * dx, comm)
    norm = assemble_scalar(ufl.dot(exact, exact) * dx, comm)
    return float(np.sqrt(error / norm))


def _picture(u, ctx: RunContext, params: Parameters) -> None:
    grid = gather_grid(u)
    if grid is None:
        return
    grid.point_data["displacement (mm)"] = np.linalg.norm(grid.point_data["displacement"], axis=1)
    path = ctx.out / "deformed.png"
    # seen from the open side: the symmetry planes show the wall and the cavity
    render_png(grid, path, scalars="displacement (mm)", warp="displacement", camera=(-1.0, -1.3, 0.8),
               title=f"sphere-inflation, p = {params.pressure:g} MPa",
               scene=ctx.result.scene, parameters=ctx.result.parameters)
    ctx.result.pictures.append(path.name)


# half the cells across the wall; the radii converge at h^2.9–3.3 on these unstructured
# meshes (docs/atlas/hyperelastic-range.md): order 2.5 keeps the estimate above the error
ESTIMATE = Refinement(keys=("cells_across_wall",), order=2.5,
                      quantities=("inner_radius_deformed", "outer_radius_deformed", "cavity_volume"),
                      overrides=(("cells_across_wall", "mesh_size"),))


SCENE = Scene(name="sphere-inflation", kind="benchmark", parameters=Parameters, run=run,
              summary="thick incompressible neo-Hookean sphere under internal pressure (exact solution)")
