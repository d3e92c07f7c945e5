"""The viscoelastic bars over the range a user tries: the state is homogeneous, so the
mesh plays no part (one element is exact) and the resolution is the time stepping's:
``time_tolerance`` bounds the stress error the adaptive steps leave (module
``problems/solid/viscous_bar.py``). Measured against the same law integrated at one
material point to 1e-11 (``uniaxial-relaxation``):

- **range**: the default tolerance over μv/μ∞ 0.1 … 10, stretches 0.8 … 1.5 and a ramped
  or an instantaneous stretch: the largest stress error over the history, the reported
  estimate and the steps taken;
- **tolerance**: the error, the estimate and the steps against ``time_tolerance`` at the
  default case and at the hardest of the range.

``sls-creep`` is compared with the small-strain standard linear solid, exact only as the
strain goes to zero; its rows (σ/μ 0.006 … 0.06) show that model error beside the
estimate of the time stepping's.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from eyemech.problems import sls_creep, uniaxial_relaxation
from eyemech.problems.reference import viscoelastic as reference
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, save_chart, write_csv

VISCOSITY_RATIOS = (0.1, 1.0, 10.0)  # μv / μ∞ at μ∞ = 0.05 MPa
STRETCHES = (0.8, 1.2, 1.5)
RAMPS = (10.0, 0.0)  # s; 0 = the stretch at t = 0
TOLERANCES = (0.1, 0.03, 0.01, 0.003, 0.001)
HARD_CASE = dict(mu_v=0.5, stretch=1.5, ramp_time=0.0)
CREEP_STRESSES = (0.0003, 0.003, -0.003, 0.03)
QUICK_TOLERANCE = 0.1  # the quick cases' (43 steps instead of 337)


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    if comm.rank != 0:  # serial study: rank 0 does the work
        return []
    if quick:
        rows = [_relaxation("range", time_tolerance=QUICK_TOLERANCE),
                _relaxation("tolerance, default case", time_tolerance=QUICK_TOLERANCE)]
        creep = [_creep(CREEP_STRESSES[0], time_tolerance=QUICK_TOLERANCE)]
    else:
        rows = [_relaxation("range", mu_v=0.05 * ratio, stretch=stretch, ramp_time=ramp)
                for ratio in VISCOSITY_RATIOS for stretch in STRETCHES for ramp in RAMPS]
        for tolerance in TOLERANCES:
            rows.append(_relaxation("tolerance, default case", time_tolerance=tolerance))
            rows.append(_relaxation("tolerance, hardest case", time_tolerance=tolerance, **HARD_CASE))
        creep = [_creep(stress) for stress in CREEP_STRESSES]
    files = [write_csv(out / "viscoelastic_range.csv", rows,
                       "error: max over the history of |sigma / sigma_point - 1| (point ODE, rtol 1e-11)"),
             write_csv(out / "viscoelastic_range_creep.csv", creep,
                       "error: max |strain / strain_SLS - 1| against the small-strain standard linear solid")]
    files.append(_chart(out / "viscoelastic_range.png", rows))
    return files


def _relaxation(part: str, **changes) -> dict:
    params = uniaxial_relaxation.Parameters(**changes)
    row = {"part": part, "mu_v_over_mu_inf": params.mu_v / params.mu_inf, "stretch": params.stretch,
           "ramp_time": params.ramp_time, "time_tolerance": params.time_tolerance}
    start = time.perf_counter()
    try:
        q = uniaxial_relaxation.run(params, comm=MPI.COMM_SELF, options=QUIET).quantities
    except SolveFailure as failure:
        return row | {"status": "failed", "error": str(failure)[:200]}
    return row | {"status": "ok", "error": q["max_relative_error_point_ode"],
                  "time_error_estimate": q["time_error_estimate"], "time_steps": q["time_steps"],
                  "rejected_steps": q["rejected_steps"], "seconds": time.perf_counter() - start}


def _creep(stress: float, **more) -> dict:
    params = sls_creep.Parameters(stress=stress, **more)
    row = {"stress": stress, "stress_over_mu": stress / params.mu_inf}
    try:
        q = sls_creep.run(params, comm=MPI.COMM_SELF, options=QUIET).quantities
    except SolveFailure as failure:
        return row | {"status": "failed", "error": str(failure)[:200]}
    sls = reference.sls_creep_strain(q["times"], params.stress, params.mu_inf, params.mu_v, params.tau)
    error = float(np.max(np.abs(np.asarray(q["axial_strain"]) / sls - 1.0)))
    return row | {"status": "ok", "error_vs_sls": error, "time_error_estimate": q["time_error_estimate"],
                  "time_steps": q["time_steps"], "final_strain": q["final_strain"]}


def _chart(path: Path, rows: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.4))
    ranged = [r for r in rows if r["part"] == "range" and r["status"] == "ok"]
    x = np.arange(len(ranged))
    left.bar(x - 0.2, [100 * r["error"] for r in ranged], width=0.4, label="error vs point ODE")
    left.bar(x + 0.2, [100 * r["time_error_estimate"] for r in ranged], width=0.4, label="estimate")
    left.set_xticks(x, [f"{r['mu_v_over_mu_inf']:g}, {r['stretch']:g}, {r['ramp_time']:g}" for r in ranged],
                    rotation=90, fontsize=7)
    left.set(xlabel="μv/μ∞, stretch, ramp (s)", ylabel="%", title="default time_tolerance over the range")
    left.legend(fontsize=7)
    for part, marker in (("tolerance, default case", "o"), ("tolerance, hardest case", "s")):
        mine = [r for r in rows if r["part"] == part and r["status"] == "ok"]
        if not mine:
            continue
        tol = [r["time_tolerance"] for r in mine]
        line, = right.loglog(tol, [r["error"] for r in mine], marker=marker, label=f"{part}: error")
        right.loglog(tol, [r["time_error_estimate"] for r in mine], marker=marker, ls="--",
                     color=line.get_color(), label=f"{part}: estimate")
    right.loglog([1e-3, 0.1], [1e-3, 0.1], ":", color="grey", label="= tolerance")
    right.set(xlabel="time_tolerance", ylabel="max relative stress error", title="error against tolerance")
    right.legend(fontsize=7)
    save_chart(fig, path, dpi=110)
    return path


STUDY = Study(name="viscoelastic-range",
              summary="viscoelastic bars: stress error and its estimate vs time_tolerance over "
                      "μv/μ∞, stretch and ramp", run=run)
