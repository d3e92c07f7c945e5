"""``cook-membrane``: the incompressible Cook's membrane in plane strain — a tapered
neo-Hookean panel clamped on its left edge and sheared on its right edge, the
standard bending-plus-incompressibility benchmark for mixed elements.

Set-up of de Souza Neto, Perić, Dutko & Owen (1996, IJSS 33:3277) and Elguedj,
Bazilevs, Calo & Hughes (2008, CMAME 197:2732): μ = 80.1938 MPa, total shear load
100 N per mm of thickness as a dead traction on the right edge; reported tip
(48, 60) vertical displacement ≈ 6.9 mm. Here the material is exactly
incompressible (mixed u–p; the references use κ = 400942 MPa, κ/μ = 5000).
A slab one element thick with w = 0 everywhere gives the plane strain state.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import ClassVar

import dolfinx
import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms import NeoHooke
from eyemech.meshes.cook import TIP, cook_membrane
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.error_estimate import Refinement, error_estimate_field, estimate_errors
from eyemech.problems.run.output import gather_grid, render_png
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, SceneParameters, field
from eyemech.problems.run.scene import Scene
from eyemech.problems.solid.residual import solid_residual
from eyemech.problems.solid.spaces import (
    ELEMENTS,
    ElementName,
    check_element,
    global_dofs,
    point_value,
    solid_fields,
)
from eyemech.problems.solve.driver import NonlinearSolver, Stepping, follow_path

REFERENCE_TIP_DISPLACEMENT = 6.9  # mm, converged value of the references above


@dataclasses.dataclass(frozen=True)
class Parameters(SceneParameters):
    shear_modulus: float = field(80.1938, "shear modulus μ = 2 c10 (neo-Hooke)", "MPa", group=PHYSICS)
    load: float = field(100.0, "total shear force on the right edge per unit thickness", "N/mm",
                        group=PHYSICS)
    elements_per_side: int = field(8, "structured elements along each edge of the panel", group=GEOMETRY)
    element: ElementName = field("Q2P1", "element family: " + ", ".join(ELEMENTS), group=GEOMETRY)
    bulk_modulus: float = field(400942.0, "bulk modulus of the displacement-only P1 family", "MPa",
                                group=PHYSICS)
    load_steps: int = field(1, "initial number of load steps; 1 = the whole load at once (a smooth problem: "
                               "Newton converges from the unloaded state, a failed step is cut)",
                            group=SOLVER)
    error_estimate: bool = error_estimate_field()

    RESOLUTION_KEY: ClassVar[str] = "elements_per_side"

    @property
    def estimated_cells(self) -> int:
        """n² hexahedra, or the tetrahedra of n² × 2 extruded triangles (3 each): an
        upper bound, the transfinite grid's (meshes/cook.py)."""
        hexahedral = ELEMENTS[self.element].hexahedral if self.element in ELEMENTS else True
        return self.elements_per_side ** 2 * (1 if hexahedral else 6)

    def validate(self) -> None:
        self.require_positive("shear_modulus", "elements_per_side", "load_steps", "bulk_modulus")
        check_element(self.element)


def auto_factorisation(element: str) -> str:
    """The factorisation ``--factorisation auto`` uses: MUMPS LDLᵀ where it was measured to
    halve LU's factor (the Jacobian is symmetric, ‖A−Aᵀ‖/‖A‖ = 6e-17; default mesh: Q2P1 0.38 M
    against 0.72 M entries, P2P1 0.51 M against 0.96 M, the same tip displacement to 15 digits:
    docs/atlas/peer-comparison.md, "Symmetric factorisation"), LU elsewhere."""
    return "ldlt" if element in ("Q2P1", "P2P1") else "lu"


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        family = ELEMENTS[params.element]
        with ctx.timings("mesh"):
            panel = cook_membrane(params.elements_per_side, family.hexahedral, family.geometry_order,
                                  comm=ctx.comm)
        fields, tests = solid_fields(panel.mesh, family)
        u, v = fields[0], tests[0]
        metadata = {"quadrature_degree": family.quadrature_degree}
        ds, dx = panel.ds(metadata), panel.dx(metadata)
        traction = dolfinx.fem.Constant(panel.mesh, np.zeros(3))
        residual = (solid_residual(NeoHooke(0.5 * params.shear_modulus), family, fields, tests, dx,
                                   params.bulk_modulus)
                    - ufl.dot(traction, v) * ds(panel.tag("loaded")))
        bcs = _boundary_conditions(u.function_space, panel)
        # a step-size test as well: with κ = 400942 MPa (P1) the residual's round-off
        # floor (~1e-8 N at 32×32) lies above the default absolute tolerance
        newton = dataclasses.replace(ctx.options.newton, stol=max(ctx.options.newton.stol, 1e-12))
        solver = NonlinearSolver(list(ufl.extract_blocks(residual)), fields, bcs,
                                 options=newton, timings=ctx.timings,
                                 auto_factorisation=auto_factorisation(params.element))

        def apply(load: float, _increment: float) -> None:
            traction.value = np.array([0.0, load * params.load / 16.0, 0.0])  # edge length 16 mm

        def converged(record) -> None:
            ctx.record_step(step=record.step, load_factor=record.load,
                            newton_iterations=record.iterations, cuts=record.cuts, **record.counts(),
                            tip_displacement=point_value(u, (*TIP, 0.0))[1])

        follow_path(solver, apply, Stepping(initial_step=1.0 / params.load_steps),
                    on_converged=converged, label=SCENE.name, quiet=ctx.options.quiet)
        q = ctx.result.quantities
        q["tip_displacement"] = point_value(u, (*TIP, 0.0))[1]
        q["tip_displacement_reference"] = REFERENCE_TIP_DISPLACEMENT
        q["dofs"] = global_dofs(*fields)
        q["jacobian_nonzeros"] = solver.jacobian_nonzeros()
        if params.error_estimate:
            estimate_errors(ctx, run, params, ESTIMATE)
        if ctx.pictures and len(fields) > 1:
            with ctx.timings("output"):
                path = pressure_picture(u, fields[1], ctx.out / "pressure.png",
                                        f"cook-membrane {params.element}, {params.elements_per_side}"
                                        f"×{params.elements_per_side}: mean stress p (MPa)")
                corner = pressure_picture(u, fields[1], ctx.out / "pressure_corner.png",
                                          f"{params.element}: clamped top corner", bounds=CORNER)
                for picture in (path, corner):
                    if picture is not None:
                        ctx.result.pictures.append(picture.name)
    return ctx.result


def _boundary_conditions(V, panel):
    fdim = panel.mesh.topology.dim - 1
    clamped = dolfinx.fem.locate_dofs_topological(V, fdim, panel.facets("clamped"))
    bcs = [dolfinx.fem.dirichletbc(np.zeros(3), clamped, V)]
    # plane strain: w = 0 at every node (the slab is one element thick)
    tdim = panel.mesh.topology.dim
    all_cells = np.arange(panel.mesh.topology.index_map(tdim).size_local
                          + panel.mesh.topology.index_map(tdim).num_ghosts, dtype=np.int32)
    out_of_plane = dolfinx.fem.locate_dofs_topological(V.sub(2), tdim, all_cells)
    bcs.append(dolfinx.fem.dirichletbc(0.0, out_of_plane, V.sub(2)))
    return bcs


# half the elements per side; the clamped re-entrant corners are singular and the tip
# converges at h^0.6–1.1 (docs/atlas/hyperelastic-range.md): the lowest measured order
ESTIMATE = Refinement(keys=("elements_per_side",), order=0.6, quantities=("tip_displacement",),
                      size=lambda params: 1.0 / params.elements_per_side)


CORNER = (0.0, 12.0, 34.0, 46.0, -1.0, 2.0)  # the clamped top corner: steepest pressure


PRESSURE = "pressure p (MPa)"  # the colour bar's title


def pressure_picture(u, p, path: Path, title: str, clim=None, bounds=None) -> Path | None:
    """The pressure on the deformed panel seen from +z (rank 0 writes it), or on the
    part of it inside the reference ``bounds`` box. Constant pressures are drawn per
    cell; higher ones on a discontinuous Lagrange grid."""
    mesh = u.function_space.mesh
    degree = p.function_space.element.basix_element.degree
    if degree == 0:
        P1 = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
        shown = dolfinx.fem.Function(P1, name="displacement")
        shown.interpolate(u)
        n_cells = mesh.topology.index_map(3).size_local
        grid = gather_grid(shown, cell_data={PRESSURE: p.x.array[:n_cells]})
    else:
        DG = dolfinx.fem.functionspace(mesh, ("DG", 1, (3,)))
        shown = dolfinx.fem.Function(DG, name="displacement")
        shown.interpolate(u)
        scalar = dolfinx.fem.Function(dolfinx.fem.functionspace(mesh, ("DG", 1)), name=PRESSURE)
        scalar.interpolate(dolfinx.fem.Expression(p, scalar.function_space.element.interpolation_points))
        grid = gather_grid(shown, point_data={PRESSURE: scalar})
    if grid is None:
        return None
    if bounds is not None:
        grid = grid.clip_box(bounds, invert=False)
    render_png(grid, path, scalars=PRESSURE, warp="displacement", title=title, camera="xy",
               clim=clim, show_undeformed=False, cmap="coolwarm")
    return path


SCENE = Scene(name="cook-membrane", kind="benchmark", parameters=Parameters, run=run,
              summary="incompressible neo-Hookean Cook's membrane, plane strain (tip displacement)")
