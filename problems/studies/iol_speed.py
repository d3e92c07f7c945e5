"""How fast the lens steps, per solution method, against how accurate it stays (issue 8 §4).

Every variant runs the ``iol-speed`` scene (the rolled paper-resolution lens released in the
damped fluid, backward Euler, Δt = 0.01 s) for the same simulated time, ``repeats`` times; the
speed is the best of the repeats in wall time and in CPU (process) time — the machine is
shared, CPU time is what a step costs on a core of its own. The accuracy is the largest
deviation of the haptic-tip and optic-centre displacement histories from a converged
reference: Newton (exact Jacobian, relative residual 1e-9) at Δt/4. Writes
``iol_speed.csv`` (one row per variant, per-phase CPU ms per step), ``iol_speed.png``
(steps/s against deviation) and ``iol_speed_phases.png`` (where a step's time goes) and
``iol_speed_table.md``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from mpi4py import MPI

from eyemech.problems import iol_speed
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, save_chart, with_units, write_csv

# label, overrides (on top of the common settings)
VARIANTS = [
    ("Newton, fresh J", {}),
    ("Newton, lagged J", {"jacobian": "lagged"}),
    ("Newton-Krylov (FD J·v, lagged LU)", {"jacobian": "matrix-free"}),
    ("linearised (SOFA), fresh J", {"method": "linearised"}),
    ("linearised, lagged J (refresh 5)", {"method": "linearised", "jacobian": "lagged", "refresh": 5}),
    ("linearised, FD J·v + lagged LU", {"method": "linearised", "jacobian": "matrix-free"}),
    ("linearised, quadrature 2", {"method": "linearised", "quadrature_degree": 2}),
    ("Newton, quadrature 2", {"quadrature_degree": 2}),
    ("linearised, mesh ×1.5", {"method": "linearised", "mesh_scale": 1.5}),
    ("linearised, mesh ×2", {"method": "linearised", "mesh_scale": 2.0}),
    ("linearised, Δt/2", {"method": "linearised", "time_step": 0.005}),
    ("Newton, fresh J, UFL tangent", {"tangent": "ufl"}),
    ("linearised, fresh J, UFL tangent", {"method": "linearised", "tangent": "ufl"}),
    ("contact: Newton, fresh J", {"contact": True}),
    ("contact: linearised, fresh J", {"method": "linearised", "contact": True}),
    ("contact: linearised, FD J·v", {"method": "linearised", "jacobian": "matrix-free", "contact": True}),
]
QUICK_VARIANTS = [VARIANTS[0], VARIANTS[3], VARIANTS[5], VARIANTS[13]]
PHASES = iol_speed.PHASES


def _measure(common: dict, overrides: dict, repeats: int, duration: float) -> dict:
    settings = {**common, **overrides}
    dt = settings.get("time_step", 0.01)
    settings["steps"] = int(round(duration / dt))
    params = iol_speed.Parameters(**settings, repeats=repeats)
    try:
        q = iol_speed.run(params, comm=MPI.COMM_SELF, options=QUIET).quantities
    except RuntimeError as err:  # a method that does not converge / blows up
        return {"status": f"failed: {err}"[:120], "time_step": dt}
    finite = np.all(np.isfinite(q["tip_history"]))
    return {"status": "ok" if finite else "diverged (NaN)", "q": q, "time_step": dt}


def _deviation(q: dict, reference: dict, key: str) -> float:
    """max over the variant's sample times of |x(t) − x_ref(t)| (mm)."""
    ref_t = np.asarray(reference["time"])
    ref_x = np.asarray(reference[key])
    worst = 0.0
    for t, x in zip(q["time"], q[key]):
        i = int(np.argmin(np.abs(ref_t - t)))
        if abs(ref_t[i] - t) > 1e-9:
            continue
        worst = max(worst, float(np.linalg.norm(np.asarray(x) - ref_x[i])))
    return worst


def _row(label: str, overrides: dict, measured: dict, references: dict) -> dict:
    row = {"variant": label, "method": overrides.get("method", "newton"),
           "jacobian": overrides.get("jacobian", "fresh"), "contact": bool(overrides.get("contact")),
           "time_step": measured["time_step"], "status": measured["status"]}
    q = measured.get("q")
    if q is None:
        return row
    steps = q["steps"]
    reference = references[row["contact"]]
    span = max(np.linalg.norm(np.asarray(reference["tip_history"]) - np.asarray(reference["tip_history"][0]),
                              axis=1))
    row.update(cells=q["cells"], dofs=q["dofs"], quadrature=q["quadrature_degree"], steps=steps,
               steps_per_second_wall=round(q["steps_per_second"], 3),
               steps_per_second_cpu=round(q["steps_per_second_cpu"], 3),
               newton_per_step=round(q["iterations"] / steps, 2),
               jacobians_per_step=round(q["jacobians"] / steps, 2),
               residuals_per_step=round(q["residuals"] / steps, 2),
               krylov_per_step=round(q["krylov_iterations"] / steps, 2),
               **{f"cpu_ms_{p}": round(1e3 * q["cpu_seconds_per_step"][p], 2) for p in PHASES},
               tip_deviation_mm=_deviation(q, reference, "tip_history"),
               optic_deviation_mm=_deviation(q, reference, "optic_history"),
               tip_travel_mm=float(span), max_penetration_mm=q["max_penetration_mm"],
               load_average=round(q["load_average"], 2))
    return row


def run(out: Path, quick: bool = False, comm=MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    common = {"mesh_scale": 3.0} if quick else {}
    duration, repeats = (0.03, 1) if quick else (0.2, 2)
    variants = QUICK_VARIANTS if quick else VARIANTS
    references = {}
    for contact in (False, True):
        dt = 0.01 / 4
        ref = _measure({**common, "rtol": 1e-9, "jacobian": "lagged", "time_step": dt, "contact": contact},
                       {}, 1, duration)
        if "q" not in ref:
            raise RuntimeError(f"the reference run failed: {ref['status']}")
        references[contact] = ref["q"]
    rows = [_row(label, overrides, _measure(common, overrides, repeats, duration), references)
            for label, overrides in variants]
    notes = (f"iol-speed variants, {duration} s of the released rolled lens, best of {repeats} runs; "
             "reference: Newton rtol 1e-9 at dt/4 = 2.5 ms (lagged Jacobian, refreshed on stall)",
             f"machine load average (1 min) at the end: {os.getloadavg()[0]:.2f}")
    files = [write_csv(out / "iol_speed.csv", with_units(rows, iol_speed.Parameters), *notes)]
    files.append(_chart(rows, out / "iol_speed.png"))
    files.append(_phases(rows, out / "iol_speed_phases.png"))
    files.append(_table(rows, out / "iol_speed_table.md"))
    return files


# tip deviations beyond this are a blown-up run, not an accuracy (the lens is 13 mm long)
DIVERGED_MM = 10.0


def _chart(rows: list[dict], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9.5, 6))
    for row in rows:
        if "steps_per_second_cpu" not in row:
            continue
        deviation = max(row["tip_deviation_mm"], 1e-7)
        # a variant that blew up (1e74 mm) would stretch the axis over the rest: drawn at the
        # top, crossed, with its label saying so
        diverged = not np.isfinite(deviation) or deviation > DIVERGED_MM
        deviation = min(deviation, DIVERGED_MM) if np.isfinite(deviation) else DIVERGED_MM
        marker = "x" if diverged else ("s" if row["contact"] else "o")
        ax.scatter(row["steps_per_second_cpu"], deviation, marker=marker, s=40, c="red" if diverged else None)
        if not diverged:
            ax.scatter(row["steps_per_second_wall"], deviation, marker=marker, s=18, facecolors="none",
                       edgecolors="grey")
        ax.annotate(row["variant"] + (" — diverged" if diverged else ""),
                    (row["steps_per_second_cpu"], deviation),
                    fontsize=7, xytext=(4, 3), textcoords="offset points")
    for target, text in ((10, "paper: deformation 10/s"), (5, "paper: with contact 5/s"),
                         (100, "issue aim 100/s"), (30, "issue aim with contact 30/s")):
        ax.axvline(target, color="grey", lw=0.7, ls=":")
        ax.text(target, ax.get_ylim()[1] if False else 1.0, text, rotation=90, fontsize=7, va="top",
                transform=ax.get_xaxis_transform())
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("steps per second, one core (filled: CPU time; open grey: best wall time under load)")
    ax.set_ylabel("max |tip displacement − reference| over the run (mm)")
    ax.set_title("IOL released in fluid (752 triangles, P2, Δt = 0.01 s): speed vs accuracy\n"
                 "circles: deformation only, squares: in a rigid capsule (contact)")
    save_chart(fig, path)
    return path


def _phases(rows: list[dict], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    done = [r for r in rows if "cpu_ms_residual" in r]
    fig, ax = plt.subplots(figsize=(9.5, 0.45 * len(done) + 1.8))
    left = np.zeros(len(done))
    for phase in PHASES:
        values = np.array([max(r[f"cpu_ms_{phase}"], 0.0) for r in done])
        ax.barh(range(len(done)), values, left=left, label=phase)
        left += values
    ax.set_yticks(range(len(done)), [r["variant"] for r in done], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("CPU milliseconds per time step")
    ax.set_title("Where a step's time goes (best run)")
    ax.legend(fontsize=8, loc="lower right")
    save_chart(fig, path)
    return path


def _table(rows: list[dict], path: Path) -> Path:
    columns = ("variant", "steps_per_second_cpu", "steps_per_second_wall", "newton_per_step",
               "jacobians_per_step", "residuals_per_step", "cpu_ms_residual", "cpu_ms_jacobian",
               "cpu_ms_factorisation", "cpu_ms_solve", "cpu_ms_contact", "cpu_ms_other",
               "tip_deviation_mm", "status")
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        cells = []
        for c in columns:
            v = r.get(c, "")
            cells.append(f"{v:.3g}" if isinstance(v, float) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    path.write_text("\n".join(lines) + "\n")
    return path


STUDY = Study(name="iol-speed", summary="steps/s of the paper-resolution lens per solution method "
              "against deviation from a converged reference, with the per-phase time split", run=run)
