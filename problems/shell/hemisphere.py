"""The pinched hemisphere with an 18° hole (MacNeal & Harder 1985), shared by the
``hemisphere`` (linear) and ``hemisphere-nonlinear`` (Sze, Liu & Lo 2004) benchmarks:
its parameters, the four radial point loads on the equator and the run.

The whole hemisphere is meshed. The rigid motions are removed by conditions that the
symmetric loading satisfies anyway: u_x = 0 on the plane x = 0, u_y = 0 on y = 0, and
u_z = 0 at one node of the equator.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable, ClassVar

import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms.shell import Kinematics
from eyemech.meshes.surface import mapped_surface, tag_boundary
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.error_estimate import Refinement, error_estimate_field, estimate_errors
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, SceneParameters, field
from eyemech.problems.shell.model import (
    Shell,
    ShellDiscretisation,
    check_shell_parameters,
    follow_shell_path,
    newton_options,
    picture,
)
from eyemech.problems.solve.driver import NonlinearSolver

REFERENCE = 0.093


@dataclasses.dataclass(frozen=True)
class HemisphereParameters(SceneParameters, ShellDiscretisation):
    radius: float = field(10.0, "sphere radius", "mm", group=GEOMETRY)
    hole_angle: float = field(18.0, "half angle of the hole at the pole", "deg", group=GEOMETRY)
    thickness: float = field(0.04, "shell thickness", "mm", group=GEOMETRY)
    youngs_modulus: float = field(6.825e7, "Young's modulus", "MPa", group=PHYSICS)
    poisson_ratio: float = field(0.3, "Poisson's ratio", group=PHYSICS)
    force: float = field(2.0, "each point load (whole shell)", "N", group=PHYSICS)
    divisions: int = field(0, "divisions from the equator to the hole (5× as many around); "
                              "0 = from cells_per_bending_length", group=GEOMETRY)
    cells_per_bending_length: float = field(
        1.2, "elements per bending length √(R h) along the meridian (divisions = 0): the "
             "faceted P2 shell's membrane locking is a function of it (docs/shell.md, Resolution)",
        group=GEOMETRY)
    kinematics: Kinematics = field("linear", "linear (the benchmark) or nonlinear", group=PHYSICS)
    load_steps: int = field(10, "initial number of load steps (nonlinear; cut and grown as needed)",
                            group=SOLVER)
    error_estimate: bool = error_estimate_field()

    RESOLUTION_KEY: ClassVar[str] = "cells_per_bending_length"

    def resolution_key(self) -> str:
        return "divisions" if self.divisions > 0 else self.RESOLUTION_KEY

    @property
    def meridian_divisions(self) -> int:
        """``divisions``, or ⌈cells_per_bending_length · meridian / √(R h)⌉ (the meridian from
        the equator to the hole)."""
        if self.divisions > 0:
            return self.divisions
        meridian = self.radius * math.radians(90.0 - self.hole_angle)
        return max(2, math.ceil(self.cells_per_bending_length * meridian / bending_length(self) - 1e-9))

    @property
    def around(self) -> int:
        """Divisions around: about 5 × the meridian's, a multiple of 4."""
        return 4 * max(1, round(5 * self.meridian_divisions / 4))

    @property
    def estimated_cells(self) -> int:
        return self.grid_triangles(self.around, self.meridian_divisions)

    def validate(self) -> None:
        self.require_positive("radius", "hole_angle", "cells_per_bending_length", "load_steps")
        self.require_nonnegative("divisions")
        check_shell_parameters(self, self.radius)


def bending_length(params) -> float:
    """√(R h): the length over which a shell of radius R and thickness h bends."""
    return math.sqrt(params.radius * params.thickness)


# the meridian twice as coarse; the radial displacements converge at about h² (P2 on flat
# facets; measured in docs/atlas/shell-resolution.md)
ESTIMATE = Refinement(keys=("cells_per_bending_length",), order=2.0,
                      quantities=("radial_displacement_x", "radial_displacement_y"),
                      overrides=(("cells_per_bending_length", "divisions"),),
                      size=lambda params: 1.0 / params.meridian_divisions)


def run_hemisphere(scene_name: str, params: HemisphereParameters, comm: MPI.Comm | None, out,
                   options: RunOptions | None, stops: tuple[float, ...] = (),
                   on_step: Callable[[dict], None] | None = None, rerun: Callable | None = None):
    """The pinched hemisphere (linear in one step, nonlinear along the load path with
    the path landing on ``stops``). ``on_step(values)`` may add entries to each
    recorded step (e.g. a reference curve); ``rerun(params, comm, out, options)`` is the
    scene's run, for the error estimate's coarse solve. Returns the Result."""
    with RunContext(scene_name, params, comm, out, options) as ctx:
        R, top = params.radius, np.radians(90.0 - params.hole_angle)
        around = params.around

        def sphere(s, t):
            azimuth, elevation = 2 * np.pi * s, top * t
            return R * np.column_stack([np.cos(elevation) * np.cos(azimuth),
                                        np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])

        with ctx.timings("mesh"):
            mesh = mapped_surface(sphere, around, params.meridian_divisions, params.diagonal, ctx.comm,
                                  weld=True)
            tagged = tag_boundary(mesh, {})
        shell = Shell(tagged, params, lambda x: x)  # outward
        residual = ufl.derivative(shell.energy(params.kinematics), shell.u, shell.v)
        tol = 1e-8 * R
        bcs = (shell.fix_where(lambda x: np.abs(x[0]) < tol, 0)
               + shell.fix_where(lambda x: np.abs(x[1]) < tol, 1)
               + shell.fix_where(lambda x: np.isclose(x[0], R) & (np.abs(x[1]) < tol)
                                 & (np.abs(x[2]) < tol), 2))
        loads = [((R, 0, 0), 0, 1.0), ((-R, 0, 0), 0, -1.0), ((0, R, 0), 1, -1.0), ((0, -R, 0), 1, 1.0)]
        load_factor = [0.0]
        hook = point_loads(shell, [(p, c, sign * params.force) for p, c, sign in loads],
                           scale=lambda: load_factor[0])
        options = newton_options(ctx, params.kinematics)
        if params.kinematics == "nonlinear":
            # the residual is in newtons; round-off leaves an out-of-balance force of
            # ~1e-10 of the applied load at large deflection (measured 4e-8 N at 60 N),
            # above the default atol: converge to 1e-9 of the load instead
            options = dataclasses.replace(options, atol=max(options.atol, 1e-9 * abs(params.force)))
        solver = NonlinearSolver(residual, shell.u, bcs, options=options,
                                 timings=ctx.timings, residual_hooks=[hook])

        def radial() -> tuple[float, float]:
            return float(shell.value_at((R, 0, 0))[0]), -float(shell.value_at((0, R, 0))[1])

        def apply(value: float, _increment: float) -> None:
            load_factor[0] = value

        def step_values(record) -> dict:
            outward_x, inward_y = radial()
            return dict(force=record.load * params.force, radial_displacement_x=outward_x,
                        radial_displacement_y=inward_y)

        follow_shell_path(ctx, solver, apply, params.kinematics, params.load_steps, tuple(stops),
                          step_values, scene_name, on_step=on_step)
        outward_x, inward_y = radial()
        quantities = ctx.result.quantities
        quantities.update(radial_displacement_x=outward_x, radial_displacement_y=inward_y,
                          dofs=shell.dofs(), divisions=params.meridian_divisions)
        if params.kinematics == "linear":
            linear_reference = REFERENCE * params.force / 2.0  # 0.093 is for the load 2
            quantities.update(radial_displacement_reference=linear_reference,
                              radial_displacement_error=outward_x / linear_reference - 1.0)
        if params.error_estimate and rerun is not None:
            estimate_errors(ctx, rerun, params, ESTIMATE)
        if ctx.pictures:
            with ctx.timings("output"):
                scale = 1.0 if params.kinematics == "nonlinear" else 10.0
                picture(shell.u, ctx, scene_name, "|u| (mm)", lambda d: np.linalg.norm(d, axis=1),
                        scale=scale)
    return ctx.result


def point_loads(shell: Shell, loads, scale: Callable[[], float] | None = None):
    """A residual hook subtracting point forces [(point, component, value)] at the
    (owned) degrees of freedom of the nodes at those points, times ``scale()`` (the
    load factor; 1 when not given)."""
    V = shell.V
    bs = V.dofmap.index_map_bs
    owned = V.dofmap.index_map.size_local
    x = V.tabulate_dof_coordinates()[:owned]
    entries = []
    for point, component, value in loads:
        distance = np.linalg.norm(x - np.asarray(point, float), axis=1)
        hits = np.flatnonzero(distance < 1e-8 * shell_size(x))
        entries += [(bs * i + component, value) for i in hits]

    def hook(_x, residual):
        factor = 1.0 if scale is None else scale()
        array = residual.getArray()
        for index, value in entries:
            array[index] -= factor * value

    return hook


def shell_size(x: np.ndarray) -> float:
    return max(float(np.ptp(x)) if len(x) else 1.0, 1.0)
