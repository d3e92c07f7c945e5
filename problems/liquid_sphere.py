"""``liquid-sphere``: the thick incompressible neo-Hookean sphere filled with a static
liquid and squeezed by an external follower pressure — the cavity model of seed 002
§2.1 on a problem with an exact answer (:func:`eyemech.problems.reference.analytic.liquid_sphere`).

The liquid pressure is either a Real-space unknown with the liquid law as its row
(``cavity_formulation = real``) or substituted into the wall load (``substituted``,
the paper's previous formulation, a dense wall×wall Jacobian block); see
:mod:`eyemech.problems.solid.cavity`. The reference cavity volume V_ini is the stress-free
one; the initial and external pressures are ramped together from zero.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import ClassVar, Literal

import dolfinx
import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms import (
    NeoHooke,
    enclosed_volume,
    follower_pressure,
    liquid_law_residual,
)
from eyemech.meshes import spherical_shell
from eyemech.problems.reference import analytic
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, ParameterError, SceneParameters, field
from eyemech.problems.run.scene import Scene
from eyemech.problems.solid.cavity import (
    SubstitutedCavity,
    check_closed,
    real_pressure_space,
)
from eyemech.problems.solid.residual import solid_residual
from eyemech.problems.solid.spaces import (
    ELEMENTS,
    ElementName,
    check_element,
    global_dofs,
    solid_fields,
    surface_mean,
    symmetry_bcs,
)
from eyemech.problems.solve.driver import NonlinearSolver, Stepping, follow_path
from eyemech.problems.solve.linear_solvers import SolverChoice
from eyemech.problems.solve.scalars import assemble_scalar

SYMMETRY = {"symmetry_x": 0, "symmetry_y": 1, "symmetry_z": 2}


@dataclasses.dataclass(frozen=True)
class Parameters(SceneParameters, SolverChoice):
    RESOLUTION_KEY: ClassVar[str] = "cells_across_wall"
    inner_radius: float = field(10.0, "inner (cavity) radius of the unloaded sphere", "mm", group=GEOMETRY)
    outer_radius: float = field(12.0, "outer radius of the unloaded sphere", "mm", group=GEOMETRY)
    c10: float = field(0.05, "neo-Hookean constant of the wall, W = c10 (Ī1 - 3)", "MPa", group=PHYSICS)
    bulk_modulus: float = field(0.2, "liquid bulk modulus K (seed 002 uses 2083.3 for the "
                                "vitreous; the default is soft so the wall and liquid share the load)",
                                "MPa", group=PHYSICS)
    initial_pressure: float = field(0.002, "liquid pressure P_ini at the stress-free cavity volume",
                                    "MPa", group=PHYSICS)
    external_pressure: float = field(0.05, "external pressure on the outer surface (follower)", "MPa",
                                     group=PHYSICS)
    cells_across_wall: float = field(1.0, "elements across the wall thickness (outer − inner radius); "
                                   "sets the element size unless mesh_size is given", group=GEOMETRY)
    mesh_size: float = field(0.0, "target element size; 0 = wall thickness / cells_across_wall", "mm",
                             group=GEOMETRY)
    element: ElementName = field("P2P1", "element family: " + ", ".join(ELEMENTS), group=GEOMETRY)
    cavity_formulation: Literal["real", "substituted"] = field(
        "real", "cavity pressure as a Real-space unknown, or substituted (dense wall block)", group=SOLVER)
    load_steps: int = field(1, "initial number of load steps; 1 = the whole load at once (a smooth problem: "
                               "Newton converges from the unloaded state, a failed step is cut)",
                            group=SOLVER)
    cavity_tag: str = field("cavity_wall", "facet tag of the wall enclosing the liquid", group=GEOMETRY)

    def validate(self) -> None:
        self.require_positive("inner_radius", "c10", "cells_across_wall", "load_steps", "bulk_modulus")
        self.require_nonnegative("mesh_size")
        check_element(self.element)
        if self.cavity_formulation not in ("real", "substituted"):
            raise ParameterError("cavity_formulation", f"must be real or substituted, got "
                                 f"{self.cavity_formulation!r}")
        if self.solver == "iterative" and self.cavity_formulation == "substituted":
            raise ParameterError("solver", "iterative needs cavity_formulation = real (the "
                                 "substituted formulation's dense wall block defeats multigrid)")
        if not self.outer_radius > self.inner_radius:
            raise ParameterError("outer_radius", f"must exceed inner_radius ({self.inner_radius})")
        if self.element_size > self.outer_radius:
            raise ParameterError(self.resolution_key(), f"gives an element size of "
                                 f"{self.element_size:.3g} mm, larger than the sphere")
        for key in ("initial_pressure", "external_pressure"):
            if not np.isfinite(getattr(self, key)):
                raise ParameterError(key, "must be finite")

    @property
    def element_size(self) -> float:
        """mesh_size, or the wall thickness over cells_across_wall."""
        if self.mesh_size > 0:
            return self.mesh_size
        return (self.outer_radius - self.inner_radius) / self.cells_across_wall


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        family = ELEMENTS[params.element]
        with ctx.timings("mesh"):
            shell = spherical_shell(params.inner_radius, params.outer_radius, params.element_size,
                                    order=family.geometry_order, hexahedra=family.hexahedral,
                                    comm=ctx.comm)
        real = params.cavity_formulation == "real"
        extra = [real_pressure_space(shell.mesh)] if real else []
        fields, tests = solid_fields(shell.mesh, family, *extra)
        u, v = fields[0], tests[0]
        metadata = {"quadrature_degree": family.quadrature_degree}
        ds, dx = shell.ds(metadata), shell.dx(metadata)
        wall = ds(shell.tag(params.cavity_tag))
        initial_volume = check_closed(u, wall, f"wall '{params.cavity_tag}'")
        wall_area = assemble_scalar(dolfinx.fem.Constant(shell.mesh, 1.0) * wall, ctx.comm)

        initial_pressure = dolfinx.fem.Constant(shell.mesh, 0.0)
        external = dolfinx.fem.Constant(shell.mesh, 0.0)
        # material and mesh-dependent numbers as Constants, not literals: a sweep over moduli
        # or mesh sizes compiles the forms once
        c10 = dolfinx.fem.Constant(shell.mesh, params.c10)
        constant = {name: dolfinx.fem.Constant(shell.mesh, float(value)) for name, value in
                    (("initial_volume", initial_volume), ("wall_area", wall_area),
                     ("bulk_modulus", params.bulk_modulus))}
        bcs = symmetry_bcs(u.function_space, shell, SYMMETRY)
        law = NeoHooke(c10)
        residual = (solid_residual(law, family, fields, tests, dx)
                    + follower_pressure(external, u, v, ds(shell.tag("outer"))))
        if real:
            P, qP = fields[-1], tests[-1]
            residual += (follower_pressure(P, u, v, wall)
                         + liquid_law_residual(P, qP, u, wall, constant["wall_area"],
                                               constant["initial_volume"], initial_pressure,
                                               constant["bulk_modulus"]))
            cavity = None
        else:
            cavity = SubstitutedCavity(u, v, wall, bcs, initial_volume, initial_pressure,
                                       params.bulk_modulus)
            residual += follower_pressure(cavity.pressure, u, v, wall)
        solver = NonlinearSolver(list(ufl.extract_blocks(residual)), fields, bcs,
                                 options=ctx.options.newton, timings=ctx.timings,
                                 iterative=params.linear_solver(law.shear_modulus, dx))
        if cavity is not None:
            cavity.install(solver)

        quantities = _quantities(ctx.comm, u, wall, fields[-1] if real else None, cavity)

        def apply(load: float, _increment: float) -> None:
            initial_pressure.value = load * params.initial_pressure
            external.value = load * params.external_pressure
            if cavity is not None:  # keep P consistent with the state for the next residual
                cavity.pressure.value = cavity.current_pressure()

        newton = {"iterations": 0}

        def converged(record) -> None:
            newton["iterations"] += record.iterations
            ctx.record_step(step=record.step, load_factor=record.load,
                            newton_iterations=record.iterations, cuts=record.cuts, **record.counts(),
                            krylov_iterations=record.linear_iterations,
                            residuals=record.residuals, **quantities())

        if real:
            P.x.array[:] = 0.0
        started = time.perf_counter()
        follow_path(solver, apply, Stepping(initial_step=1.0 / params.load_steps),
                    on_converged=converged, label=SCENE.name, quiet=ctx.options.quiet)
        solve_seconds = time.perf_counter() - started
        q = ctx.result.quantities
        q.update(quantities())
        q["jacobian_nonzeros"] = cavity.nonzeros() if cavity is not None else solver.jacobian_nonzeros()
        q["dofs"] = global_dofs(*fields)
        q["newton_iterations"] = newton["iterations"]
        q["seconds_per_newton_step"] = solve_seconds / max(1, newton["iterations"])
        _exact(q, params)
    return ctx.result


def _quantities(comm: MPI.Comm, u, wall, P, cavity: SubstitutedCavity | None):
    """The measured quantities of the state: cavity pressure (the Real unknown ``P``, or
    the substituted cavity's), mean deformed inner radius, cavity volume (8 octants)."""
    volume_form = dolfinx.fem.form(enclosed_volume(u, wall))
    x = ufl.SpatialCoordinate(u.function_space.mesh) + u
    inner_mean = surface_mean(ufl.sqrt(ufl.dot(x, x)), wall)

    def cavity_pressure() -> float:
        if P is not None:  # the one Real dof is owned by one rank
            owned = P.function_space.dofmap.index_map.size_local
            return float(comm.allreduce(float(np.sum(P.x.array[:owned])), op=MPI.SUM))
        return cavity.current_pressure()

    def quantities() -> dict[str, float]:
        octant = assemble_scalar(volume_form, comm)
        return {"cavity_pressure": cavity_pressure(), "inner_radius_deformed": inner_mean(),
                "cavity_volume": 8.0 * octant}

    return quantities


def _exact(q: dict, params: Parameters) -> None:
    try:
        a, pressure = analytic.liquid_sphere(params.inner_radius, params.outer_radius, params.c10,
                                             params.bulk_modulus, params.initial_pressure,
                                             params.external_pressure)
    except ValueError:
        return
    q["inner_radius_exact"], q["cavity_pressure_exact"] = a, pressure
    q["inner_radius_error"] = q["inner_radius_deformed"] / a - 1.0
    q["cavity_pressure_error"] = q["cavity_pressure"] / pressure - 1.0


SCENE = Scene(name="liquid-sphere", kind="benchmark", parameters=Parameters, run=run,
              summary="thick incompressible sphere around a static liquid, squeezed (exact solution)")
