"""``uniaxial-relaxation``: a viscoelastic bar stretched to ``stretch`` over ``ramp_time``
and then held to ``t_end`` — the finite-strain check of the Le Tallec-type model
(:mod:`eyemech.forms.viscoelastic`, issue 6).

The state is homogeneous uniaxial tension (see :mod:`eyemech.problems.solid.viscous_bar`), so
the axial Cauchy stress over time can be compared with the same evolution law integrated
at one material point (:mod:`eyemech.problems.reference.viscoelastic`). ``ramp_time = 0``
applies the stretch at t = 0 (the glassy response, Cv = I), then holds it.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.problems.reference import viscoelastic as reference
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.output import picture_metadata
from eyemech.problems.run.parameters import PHYSICS, ParameterError, field
from eyemech.problems.run.scene import Scene
from eyemech.problems.solid.viscous_bar import (
    BarParameters,
    ViscousBar,
    load_instantly,
    march,
    plot_history,
)
from eyemech.problems.solve.driver import NonlinearSolver


@dataclasses.dataclass(frozen=True)
class Parameters(BarParameters):
    stretch: float = field(1.2, "axial stretch λ reached at ramp_time and then held", group=PHYSICS)
    ramp_time: float = field(10.0, "duration of the linear stretch ramp (0: a step at t = 0)", "s",
                             group=PHYSICS)

    def validate(self) -> None:
        super().validate()
        if not (np.isfinite(self.stretch) and 0.3 < self.stretch < 5.0):
            raise ParameterError("stretch", f"must lie in (0.3, 5), got {self.stretch!r}")
        if not 0 <= self.ramp_time <= self.t_end:
            raise ParameterError("ramp_time", f"must be >= 0 and <= t_end ({self.t_end}), "
                                 f"got {self.ramp_time!r}")

    def stretch_at(self, t: float) -> float:
        """λ(t): linear ramp, then held."""
        if self.ramp_time == 0:
            return self.stretch
        return 1.0 + (self.stretch - 1.0) * min(t / self.ramp_time, 1.0)


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        with ctx.timings("mesh"):
            bar = ViscousBar(params, ctx.comm)
        end_displacement = dolfinx.fem.Constant(bar.mesh, 0.0)
        bcs = bar.symmetry_bcs() + [bar.end_displacement_bc(end_displacement)]
        solver = NonlinearSolver(list(ufl.extract_blocks(bar.residual)), [bar.u, bar.p], bcs,
                                 options=ctx.options.newton, timings=ctx.timings)
        times: list[float] = []
        stresses: list[float] = []
        stretches: list[float] = []

        def record(t: float) -> None:
            times.append(t)
            stresses.append(bar.axial_cauchy_stress())
            stretches.append(bar.axial_stretch())

        def set_stretch(value: float) -> None:
            end_displacement.value = (value - 1.0) * params.length

        if params.ramp_time == 0:
            load_instantly(ctx, bar, solver, lambda f: set_stretch(1 + f * (params.stretch - 1)),
                           SCENE.name)
            record(0.0)
        try:
            timing = march(ctx, bar, solver, params, lambda t: set_stretch(params.stretch_at(t)), record,
                  SCENE.name, extra_stops=(params.ramp_time,))
        finally:
            ctx.result.quantities.update(times=times, cauchy_stress=stresses, axial_stretch=stretches)
        ctx.result.quantities.update(timing, time_tolerance=params.time_tolerance,
                                     time_stepping=params.time_stepping)
        ctx.result.quantities["final_cauchy_stress"] = stresses[-1]
        ctx.result.quantities["max_relative_error_point_ode"] = float(np.max(np.abs(
            np.array(stresses) / point_reference(params, times) - 1.0)))
        ctx.result.quantities["dofs"] = sum(
            f.function_space.dofmap.index_map.size_global * f.function_space.dofmap.index_map_bs
            for f in (bar.u, bar.p))
        if ctx.pictures and ctx.rank0:
            with ctx.timings("output"):
                _picture(ctx, params, times, stresses)
    return ctx.result


def point_reference(params: Parameters, times) -> np.ndarray:
    """The same law at one material point (scipy, rtol 1e-11)."""
    return reference.relaxation(times, params.stretch_at, params.mu_inf, params.mu_v, params.tau,
                                breaks=(params.ramp_time,))


def _picture(ctx: RunContext, params: Parameters, times, stresses) -> None:
    path = ctx.out / "cauchy_stress.png"
    title = (f"uniaxial relaxation, λ = {params.stretch:g}, τ = {params.tau:g} s, "
             f"{_steps(params)} ({params.time_scheme})")
    plot_history(path, times, stresses, point_reference(params, times), "axial Cauchy stress (MPa)",
                 title, reference_label="same law at one point (scipy)",
                 metadata=picture_metadata(ctx.result.scene, ctx.result.parameters, title))
    ctx.result.pictures.append(path.name)


def _steps(params) -> str:
    if params.time_stepping == "fixed":
        return f"dt = {params.dt:g} s"
    return f"adaptive, tol {params.time_tolerance:g}"


SCENE = Scene(name="uniaxial-relaxation", kind="benchmark", parameters=Parameters, run=run,
              summary="finite-strain viscoelastic bar: stretch, hold, stress relaxation "
                      "(vs the point ODE)")
