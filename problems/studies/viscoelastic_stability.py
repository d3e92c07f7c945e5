"""Where the time integration of the viscoelastic evolution law fails: error against
dt/τ for backward and forward Euler (issue 6, item 3).

Case: ``uniaxial-relaxation`` with a step stretch λ = 1.2 at t = 0 (ramp_time = 0), held
to t_end = 10 τ, μ∞ = μv = 0.05 MPa, τ = 1 s, one Q2P1 element (the state is homogeneous,
so every error is the time integration's). Reference: the same law at one material point
(scipy DOP853, rtol 1e-11). Errors:

- ``error_at_t_end`` = |σ(t_end) − σref(t_end)| / σref(t_end);
- ``max_error``       = max over all steps |σ(tn) − σref(tn)| / σref(0+) (the glassy stress).

Forward Euler multiplies the deviation from equilibrium by (1 − dt/τ) per step
(linearised), so it must fail beyond dt/τ = 2; backward Euler's factor 1/(1 + dt/τ) keeps
it bounded at any step, with first-order error. A run in which the explicit update makes
Cv indefinite stops with UnstableIntegration; the study records the time it happened.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from pathlib import Path

import numpy as np
from mpi4py import MPI

from eyemech.problems import uniaxial_relaxation
from eyemech.problems.reference import viscoelastic as reference
from eyemech.problems.run.context import RunOptions
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import save_chart, write_csv

RATIOS = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 1.25, 2.0, 2.5, 5.0, 10.0)
QUICK_RATIOS = (0.1, 0.5, 2.5)
HISTORY_RATIO = 2.5  # the step whose histories the third panel shows
SCHEMES = ("backward-euler", "forward-euler")
CASE = dict(stretch=1.2, ramp_time=0.0, mu_inf=0.05, mu_v=0.05, tau=1.0, t_end=10.0)
QUIET = RunOptions(fields=False, pictures=False)


def one_case(scheme: str, ratio: float, comm) -> tuple[dict, list[float], list[float]]:
    """One run; a failed one is read back from its results.json (the converged steps)."""
    params = uniaxial_relaxation.Parameters(time_scheme=scheme, dt=ratio * CASE["tau"],
                                            time_stepping="fixed", **CASE)
    folder = comm.bcast(tempfile.mkdtemp(prefix="eyemech_visco_") if comm.rank == 0 else None)
    status, failed_at = "ok", math.nan
    try:
        result = uniaxial_relaxation.run(params, comm=comm, out=folder, options=QUIET)
        quantities, seconds = result.quantities, result.timings["total"]
    except SolveFailure as failure:
        status, failed_at = "blew up", failure.last_converged
        saved = comm.bcast(json.loads((Path(folder) / "results.json").read_text())
                           if comm.rank == 0 else None)
        quantities, seconds = saved["quantities"], saved["timings"]["total"]
    finally:
        comm.Barrier()
        if comm.rank == 0:
            shutil.rmtree(folder, ignore_errors=True)
    times = [float(t) for t in quantities["times"]]
    stress = [math.nan if s is None else float(s) for s in quantities["cauchy_stress"]]
    ref = reference.relaxation(times, lambda _t: CASE["stretch"], CASE["mu_inf"], CASE["mu_v"],
                               CASE["tau"])
    glassy = ref[0]
    deviation = np.abs(np.array(stress) - ref)
    finished = status == "ok" and math.isclose(times[-1], CASE["t_end"])
    row = {"scheme": scheme, "dt_over_tau": ratio, "steps": len(times) - 1, "status": status,
           "failed_at_t": failed_at,
           "error_at_t_end": float(deviation[-1] / ref[-1]) if finished else math.inf,
           "max_error": float(np.nanmax(deviation) / glassy) if finished else math.inf,
           "wall_time_s": seconds}
    return row, times, stress


def _chart(path: Path, rows: list[dict], histories: dict) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13.5, 4.0))
    colours = {"backward-euler": "tab:blue", "forward-euler": "tab:red"}
    for ax, key, label in ((axes[0], "error_at_t_end", "relative error of σ at t_end = 10 τ"),
                           (axes[1], "max_error", "max error over [0, t_end] / glassy σ")):
        finite = [r[key] for r in rows if math.isfinite(r[key]) and r[key] > 0]
        ceiling = 10 * max(finite) if finite else 1.0
        for scheme in SCHEMES:
            mine = [r for r in rows if r["scheme"] == scheme]
            ok = [r for r in mine if math.isfinite(r[key]) and r[key] > 0]
            ax.loglog([r["dt_over_tau"] for r in ok], [r[key] for r in ok], "o-",
                      color=colours[scheme], label=scheme)
            bad = [r for r in mine if not math.isfinite(r[key])]
            if bad:
                ax.loglog([r["dt_over_tau"] for r in bad], [ceiling] * len(bad), "x", ms=10,
                          mew=2, color=colours[scheme], label=f"{scheme}: blew up (Cv indefinite)")
        h = np.array([0.01, 0.3])
        first = [r[key] for r in rows if r["scheme"] == "backward-euler" and r["dt_over_tau"] == 0.01]
        if first and math.isfinite(first[0]) and first[0] > 0:
            ax.loglog(h, first[0] * h / h[0], "k:", lw=0.8, label="slope 1")
        ax.axvline(2.0, color="grey", lw=0.8, ls="--")
        ax.text(2.05, ax.get_ylim()[0] * 3, "dt = 2τ", fontsize=7, color="grey")
        ax.set_xlabel("dt / τ")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    ax = axes[2]
    for scheme, (times, stress) in histories.items():
        ax.plot(times, stress, "o-", ms=3, color=colours[scheme], label=f"{scheme}, dt = {HISTORY_RATIO} τ")
    t = np.linspace(0, CASE["t_end"], 200)
    ax.plot(t, reference.relaxation(t, lambda _t: CASE["stretch"], CASE["mu_inf"], CASE["mu_v"],
                                    CASE["tau"]), "k-", lw=1, label="point ODE")
    ax.set_xlabel("t / τ")
    ax.set_ylabel("axial Cauchy stress (MPa)")
    ax.set_ylim(-0.05, 0.2)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.suptitle("Viscoelastic relaxation (λ = 1.2 step, μ∞ = μv): time-step stability", fontsize=10)
    save_chart(fig, path, dpi=80, rect=(0, 0.03, 1, 1))
    return path


def run(out: Path, quick: bool = False, comm=None) -> list[Path]:
    comm = comm or MPI.COMM_WORLD
    out = Path(out)
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    rows, histories = [], {}
    for scheme in SCHEMES:
        for ratio in (QUICK_RATIOS if quick else RATIOS):
            row, times, stress = one_case(scheme, ratio, comm)
            rows.append(row)
            if ratio == HISTORY_RATIO:
                histories[scheme] = (times, stress)
    if comm.rank != 0:
        return []
    csv_path = out / "viscoelastic_stability.csv"
    write_csv(csv_path, rows, "uniaxial-relaxation, step stretch 1.2, tau = 1 s, t_end = 10 tau; "
              "errors against the point ODE")
    return [csv_path, _chart(out / "viscoelastic_stability.png", rows, histories)]


STUDY = Study(name="viscoelastic-stability",
              summary="error vs dt/τ for backward and forward Euler of the viscoelastic law "
                      "(forward fails beyond 2τ)",
              run=run)
