"""``scordelis-lo``: the Scordelis–Lo roof of the shell obstacle course (MacNeal &
Harder 1985; Belytschko et al. 1985) — a cylindrical panel (radius 25, length 50,
80° opening, h = 0.25, E = 4.32e8, ν = 0) under its own weight (90 per unit area),
supported by rigid diaphragms at both ends (u_y = u_z = 0) with free straight edges.
Reference: vertical displacement 0.3024 at the midpoint of a free edge (linear).

The whole roof is meshed (no symmetry conditions, which a displacement-only shell
would have to impose on the rotation too); u_x = 0 on the mid-span section, which
holds by symmetry, removes the axial rigid motion. The curved roof is faceted by flat
triangles; the shell form subtracts the reference kinks.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import ClassVar

import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms.shell import Kinematics
from eyemech.meshes.surface import mapped_surface, tag_boundary
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.error_estimate import Refinement, error_estimate_field, estimate_errors
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SceneParameters, field
from eyemech.problems.run.scene import Scene
from eyemech.problems.shell.model import (
    Shell,
    ShellDiscretisation,
    check_shell_parameters,
    newton_options,
    picture,
)
from eyemech.problems.solve.driver import NonlinearSolver, Stepping, follow_path

REFERENCE = 0.3024  # MacNeal & Harder, Finite Elem. Anal. Des. 1 (1985) 3-20


@dataclasses.dataclass(frozen=True)
class Parameters(SceneParameters, ShellDiscretisation):
    radius: float = field(25.0, "cylinder radius", "mm", group=GEOMETRY)
    length: float = field(50.0, "roof length (between the diaphragms)", "mm", group=GEOMETRY)
    half_angle: float = field(40.0, "half opening angle", "deg", group=GEOMETRY)
    thickness: float = field(0.25, "shell thickness", "mm", group=GEOMETRY)
    youngs_modulus: float = field(4.32e8, "Young's modulus", "MPa", group=PHYSICS)
    poisson_ratio: float = field(0.0, "Poisson's ratio", group=PHYSICS)
    gravity_load: float = field(90.0, "self weight per unit (reference) area, acting along -z", "MPa",
                                group=PHYSICS)
    divisions: int = field(0, "squares along the length and around the arc; 0 = from "
                              "cells_per_bending_length", group=GEOMETRY)
    cells_per_bending_length: float = field(
        1.2, "elements per bending length √(R h) around the arc (divisions = 0; as many along "
             "the length): the faceted P2 shell's membrane locking is a function of it "
             "(docs/shell.md, Resolution)", group=GEOMETRY)
    kinematics: Kinematics = field("linear", "linear (the benchmark) or nonlinear", group=PHYSICS)
    error_estimate: bool = error_estimate_field()

    RESOLUTION_KEY: ClassVar[str] = "cells_per_bending_length"

    def resolution_key(self) -> str:
        return "divisions" if self.divisions > 0 else self.RESOLUTION_KEY

    @property
    def grid_divisions(self) -> int:
        """``divisions``, or ⌈cells_per_bending_length · arc / √(R h)⌉."""
        if self.divisions > 0:
            return self.divisions
        arc = self.radius * 2.0 * math.radians(self.half_angle)
        bending = math.sqrt(self.radius * self.thickness)
        return max(2, math.ceil(self.cells_per_bending_length * arc / bending - 1e-9))

    @property
    def estimated_cells(self) -> int:
        return self.grid_triangles(self.grid_divisions, self.grid_divisions)

    def validate(self) -> None:
        self.require_positive("radius", "length", "half_angle", "cells_per_bending_length")
        self.require_nonnegative("divisions")
        check_shell_parameters(self, min(self.length, self.radius * np.radians(self.half_angle)))


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        R, L, half = params.radius, params.length, np.radians(params.half_angle)

        def roof(s, t):
            angle = (2.0 * t - 1.0) * half
            return np.column_stack([L * s, R * np.sin(angle), R * np.cos(angle)])

        with ctx.timings("mesh"):
            mesh = mapped_surface(roof, params.grid_divisions, params.grid_divisions, params.diagonal,
                                  ctx.comm)
            ends = lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], L)  # noqa: E731
            tagged = tag_boundary(mesh, {"diaphragm": ends})
        away_from_axis = lambda x: np.column_stack([0.0 * x[:, 0], x[:, 1], x[:, 2]])  # noqa: E731
        shell = Shell(tagged, params, away_from_axis)
        weight = shell.constant(params.gravity_load)
        residual = (ufl.derivative(shell.energy(params.kinematics), shell.u, shell.v)
                    + weight * shell.v[2] * shell.dx)
        bcs = shell.fix("diaphragm", (1, 2)) + shell.fix_where(lambda x: np.isclose(x[0], L / 2), 0)
        solver = NonlinearSolver(residual, shell.u, bcs, options=newton_options(ctx, params.kinematics),
                                 timings=ctx.timings)
        follow_path(solver, lambda *_: None, Stepping(initial_step=1.0), label=SCENE.name,
                    quiet=ctx.options.quiet)
        edge_mid = (L / 2, R * np.sin(half), R * np.cos(half))
        deflection = -float(shell.value_at(edge_mid)[2])
        ctx.result.quantities.update(edge_deflection=deflection, edge_deflection_reference=REFERENCE,
                                     edge_deflection_error=deflection / REFERENCE - 1.0,
                                     dofs=shell.dofs(), divisions=params.grid_divisions)
        if params.error_estimate:
            estimate_errors(ctx, run, params, ESTIMATE)
        if ctx.pictures:
            with ctx.timings("output"):
                picture(shell.u, ctx, "scordelis-lo", "-u_z (mm)", lambda d: -d[:, 2], scale=10.0)
    return ctx.result


# both directions twice as coarse; the edge deflection converges at about h² (measured in
# docs/atlas/shell-resolution.md)
ESTIMATE = Refinement(keys=("cells_per_bending_length",), order=2.0, quantities=("edge_deflection",),
                      overrides=(("cells_per_bending_length", "divisions"),),
                      size=lambda params: 1.0 / params.grid_divisions)


SCENE = Scene(name="scordelis-lo", kind="benchmark", parameters=Parameters, run=run,
              summary="Scordelis-Lo roof under self weight, diaphragm ends (reference 0.3024)")
