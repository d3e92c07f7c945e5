"""``sls-creep``: a viscoelastic bar under a constant axial (true, Cauchy) stress applied at
t = 0 — creep, the seed's standard-linear-solid check (§2.3.1) for the finite-strain
model of :mod:`eyemech.forms.viscoelastic`.

At t = 0 the bar responds glassily (Cv = I, stiffness μ∞ + μv); it then creeps to the
relaxed strain of μ∞ alone with the retardation time τ (μ∞ + μv)/μ∞. The load is a
follower traction σ0 cof(F) N on x = L, so the Cauchy stress stays σ0 while the section
shrinks; at small strain it is the standard linear solid in uniaxial form.
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
from eyemech.problems.run.parameters import PHYSICS, SOLVER, ParameterError, field
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
    stress: float = field(0.003, "axial Cauchy stress applied at t = 0 and held", "MPa", group=PHYSICS)
    t_end: float = field(800.0, "end time (4 retardation times at the defaults)", "s", group=PHYSICS)
    dt: float = field(2.0, "time step (fixed mode; the first step in adaptive mode)", "s", group=SOLVER)

    def validate(self) -> None:
        super().validate()
        if not np.isfinite(self.stress) or self.stress == 0:
            raise ParameterError("stress", f"must be finite and nonzero, got {self.stress!r}")
        # incompressible neo-Hooke in uniaxial tension has no limit point, but a glassy
        # stretch beyond ~3 or a compression below ~0.5 is outside what this bar is for
        glassy = self.stress / self.material.glassy_shear_modulus
        if not -1.0 < glassy < 8.0:
            raise ParameterError("stress", f"{self.stress} MPa gives σ/(μ∞+μv) = {glassy:.3g}: "
                                 "outside (−1, 8), the range this benchmark is meant for")


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        with ctx.timings("mesh"):
            bar = ViscousBar(params, ctx.comm)
        stress = dolfinx.fem.Constant(bar.mesh, 0.0)
        residual = bar.residual + bar.axial_cauchy_traction(stress)
        solver = NonlinearSolver(list(ufl.extract_blocks(residual)), [bar.u, bar.p],
                                 bar.symmetry_bcs(), options=ctx.options.newton,
                                 timings=ctx.timings)
        times: list[float] = []
        strains: list[float] = []
        stresses: list[float] = []

        def record(t: float) -> None:
            times.append(t)
            strains.append(bar.axial_stretch() - 1.0)
            stresses.append(bar.axial_cauchy_stress())

        def set_stress(factor: float) -> None:
            stress.value = factor * params.stress

        load_instantly(ctx, bar, solver, set_stress, SCENE.name)
        record(0.0)
        try:
            timing = march(ctx, bar, solver, params, lambda _t: set_stress(1.0), record, SCENE.name)
        finally:
            ctx.result.quantities.update(times=times, axial_strain=strains, cauchy_stress=stresses)
        ctx.result.quantities.update(timing, time_tolerance=params.time_tolerance,
                                     time_stepping=params.time_stepping)
        ctx.result.quantities["glassy_strain"] = strains[0]
        ctx.result.quantities["final_strain"] = strains[-1]
        ctx.result.quantities["retardation_time"] = params.material.retardation_time
        sls = reference.sls_creep_strain(times, params.stress, params.mu_inf, params.mu_v, params.tau)
        ctx.result.quantities["max_relative_error_sls"] = float(np.max(np.abs(np.array(strains) / sls - 1)))
        if ctx.pictures and ctx.rank0:
            with ctx.timings("output"):
                _picture(ctx, params, times, strains)
    return ctx.result


def _picture(ctx: RunContext, params: Parameters, times, strains) -> None:
    path = ctx.out / "axial_strain.png"
    sls = reference.sls_creep_strain(times, params.stress, params.mu_inf, params.mu_v, params.tau)
    title = (f"creep at σ = {params.stress:g} MPa, τc = {params.material.retardation_time:g} s, "
             f"{_steps(params)}")
    plot_history(path, times, strains, sls, "axial strain λ − 1 (1)", title,
                 reference_label="standard linear solid (small strain)",
                 metadata=picture_metadata(ctx.result.scene, ctx.result.parameters, title))
    ctx.result.pictures.append(path.name)


def _steps(params) -> str:
    if params.time_stepping == "fixed":
        return f"dt = {params.dt:g} s"
    return f"adaptive, tol {params.time_tolerance:g}"


SCENE = Scene(name="sls-creep", kind="benchmark", parameters=Parameters, run=run,
              summary="viscoelastic bar under constant axial stress: creep vs the standard "
                      "linear solid")
