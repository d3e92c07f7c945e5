"""``cantilever-rolling``: a clamped strip rolled up by an end moment — the large-
rotation (folding) benchmark of the shell.

Strip L × b × h, ν = 0 (no anticlastic curvature), root clamped, end moment
M = moment_fraction · M_max with M_max = 2π E I / L, I = b h³/12. Pure bending
bends the strip into a circular arc of radius R = E I / M (exact), so with
φ = L/R = 2π · moment_fraction the tip sits at

    u = R sin φ - L,   w = R (1 - cos φ),

and at moment_fraction = 1 it is back at the root (Sze, Liu & Lo 2004, problem 3.1).

The moment is applied as the work conjugate to the end rotation: the energy gets
-(M/b) ∫_end φ ds with φ the angle of the deformed material direction F e_x at the
end in the x–z plane. A moment about the fixed y axis doing work M dφ is exactly the
loading of this benchmark (neither a pair of dead forces, which would turn into a
force couple that does not follow, nor a follower force couple). The angle is
unwrapped about the last converged end angle, so rotations past ±π are continuous.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import ClassVar

import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms.shell import Kinematics, end_rotation
from eyemech.meshes.surface import mapped_surface, tag_boundary
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, ParameterError, SceneParameters, field
from eyemech.problems.run.scene import Scene
from eyemech.problems.shell.model import (
    Shell,
    ShellDiscretisation,
    check_shell_parameters,
    newton_options,
    picture,
)
from eyemech.problems.solve.driver import NonlinearSolver, Stepping, follow_path
from eyemech.problems.solve.scalars import assemble_scalar


@dataclasses.dataclass(frozen=True)
class Parameters(SceneParameters, ShellDiscretisation):
    moment_fraction: float = field(
        1.0, "end moment as a fraction of M_max = 2π E I / L (1 = full circle)", group=PHYSICS)
    youngs_modulus: float = field(1.2e6, "Young's modulus (Sze, Liu & Lo 2004)", "MPa", group=PHYSICS)
    poisson_ratio: float = field(0.0, "Poisson's ratio (0: exact circle, no anticlastic bending)",
                                 group=PHYSICS)
    length: float = field(12.0, "strip length", "mm", group=GEOMETRY)
    width: float = field(1.0, "strip width", "mm", group=GEOMETRY)
    thickness: float = field(0.1, "strip thickness", "mm", group=GEOMETRY)
    divisions: int = field(32, "squares along the length", group=GEOMETRY)
    width_divisions: int = field(1, "squares across the width", group=GEOMETRY)
    kinematics: Kinematics = field("nonlinear", "nonlinear (the benchmark) or linear", group=PHYSICS)
    load_steps: int = field(8, "initial number of load steps (cut and grown as needed)", group=SOLVER)

    RESOLUTION_KEY: ClassVar[str] = "divisions"

    @property
    def estimated_cells(self) -> int:
        return self.grid_triangles(self.divisions, self.width_divisions)

    def validate(self) -> None:
        self.require_positive("length", "width", "divisions", "width_divisions", "load_steps")
        check_shell_parameters(self, min(self.length, self.width))
        if not np.isfinite(self.moment_fraction):
            raise ParameterError("moment_fraction", "must be finite")


def exact_tip(params: Parameters) -> tuple[float, float]:
    """Tip displacement (u, w) of the exact circular arc."""
    angle = 2.0 * np.pi * params.moment_fraction
    if abs(angle) < 1e-12:
        return 0.0, 0.0
    radius = params.length / angle
    return radius * np.sin(angle) - params.length, radius * (1.0 - np.cos(angle))


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        L, b = params.length, params.width
        with ctx.timings("mesh"):
            mesh = mapped_surface(lambda s, t: np.column_stack([L * s, b * t, 0.0 * s]),
                                  params.divisions, params.width_divisions, params.diagonal, ctx.comm)
            tagged = tag_boundary(mesh, {"root": lambda x: np.isclose(x[0], 0.0),
                                         "end": lambda x: np.isclose(x[0], L)})
        shell = Shell(tagged, params, lambda x: np.tile([0.0, 0.0, 1.0], (len(x), 1)),
                      clamped=("root",))
        inertia = b * params.thickness ** 3 / 12.0
        full_moment = 2.0 * np.pi * params.youngs_modulus * inertia / L
        moment = shell.constant(0.0)
        end_angle = shell.constant(0.0)  # last converged end rotation (unwrapping)
        e_x = ufl.as_vector([1.0, 0.0, 0.0])
        rotation = end_rotation(shell.u, e_x, end_angle)
        ds_end = shell.ds(tagged.tag("end"))
        energy = shell.energy(params.kinematics) - moment / b * rotation * ds_end
        residual = ufl.derivative(energy, shell.u, shell.v)
        solver = NonlinearSolver(residual, shell.u, shell.fix("root"),
                                 options=newton_options(ctx, params.kinematics), timings=ctx.timings)
        rotation_form = dolfinx.fem.form(rotation * ds_end)
        tip = (L, b / 2, 0.0)
        writer = ctx.field_writer([shell.u])

        def mean_end_rotation() -> float:
            return assemble_scalar(rotation_form, ctx.comm) / b

        def apply(value: float, _increment: float) -> None:
            moment.value = value * params.moment_fraction * full_moment

        def converged(record) -> None:
            end_angle.value = mean_end_rotation()
            u_tip = shell.value_at(tip)
            ctx.record_step(step=record.step, load_factor=record.load, tip_u=float(u_tip[0]),
                            tip_w=float(u_tip[2]), end_rotation=float(end_angle.value),
                            newton_iterations=record.iterations, cuts=record.cuts, **record.counts())
            with ctx.timings("output"):
                writer.write(record.load)

        try:
            follow_path(solver, apply, Stepping(initial_step=1.0 / params.load_steps, max_step=0.25),
                        on_converged=converged, label=SCENE.name, quiet=ctx.options.quiet)
        finally:
            writer.close()
            ctx.result.fields = writer.files
        u_tip = shell.value_at(tip)
        exact_u, exact_w = exact_tip(params)
        q = ctx.result.quantities
        q.update(tip_u=float(u_tip[0]), tip_w=float(u_tip[2]), tip_u_exact=exact_u, tip_w_exact=exact_w,
                 tip_error=float(np.hypot(u_tip[0] - exact_u, u_tip[2] - exact_w) / L),
                 end_rotation=float(end_angle.value),
                 end_rotation_exact=2.0 * np.pi * params.moment_fraction, dofs=shell.dofs())
        if ctx.pictures:
            with ctx.timings("output"):
                picture(shell.u, ctx, f"cantilever-rolling, M = {params.moment_fraction:g} M_max",
                        "|u| (mm)", lambda d: np.linalg.norm(d, axis=1), camera=(0.3, -1.0, 0.4))
    return ctx.result


SCENE = Scene(name="cantilever-rolling", kind="benchmark", parameters=Parameters, run=run,
              summary="strip rolled into a full circle by an end moment (large rotation, exact arc)")
