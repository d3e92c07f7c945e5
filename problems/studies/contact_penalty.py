"""Penalty study for ``hertz``: penetration, force error and Newton iterations against
the penalty factor (α = factor · E / h), to justify the default factor."""

from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from eyemech.problems import hertz
from eyemech.problems.run.context import RunOptions
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import save_chart, write_csv

FACTORS = (1.0, 3.0, 10.0, 30.0, 100.0, 300.0)
QUICK_FACTORS = (10.0, 100.0)


def run(out: Path, quick: bool, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    base = dict(resolution=1.6, far_resolution=2.0) if quick else {}
    rows = []
    for factor in (QUICK_FACTORS if quick else FACTORS):
        params = hertz.Parameters(penalty=factor, **base)
        try:
            result = hertz.run(params, comm=comm, options=RunOptions(fields=False, pictures=False))
            q = result.quantities
            rows.append({"penalty_factor": factor, "penalty_stiffness": q["penalty_stiffness"],
                         "max_penetration": q["max_penetration"],
                         "penetration_over_indentation": q["max_penetration"] / params.indentation,
                         "force_error": q["force_error"], "radius_error": q["radius_error"],
                         "newton_iterations": q["newton_iterations"], "load_steps": q["load_steps"],
                         "seconds": result.timings.get("total", float("nan")), "status": "ok"})
        except SolveFailure as failure:
            rows.append({"penalty_factor": factor, "status": f"failed at load {failure.load:.3g}"})
    if comm.rank != 0:
        return []
    out.mkdir(parents=True, exist_ok=True)
    stem = "contact_penalty" + ("_quick" if quick else "")
    table = out / f"{stem}.csv"
    write_csv(table, rows)
    chart = out / f"{stem}.png"
    _chart([r for r in rows if r["status"] == "ok"], chart)
    return [table, chart]


def _chart(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    factor = [r["penalty_factor"] for r in rows]
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    left.loglog(factor, [r["penetration_over_indentation"] for r in rows], "o-",
                label="max penetration / indentation")
    left.set_xlabel("penalty factor (α = factor · E / h)")
    left.set_ylabel("max penetration / indentation")
    errors = left.twinx()
    errors.semilogx(factor, [100 * r["force_error"] for r in rows], "s-", color="tab:orange",
                    label="F / F_Hertz − 1 (%)")
    errors.axhline(3.0, color="grey", ls=":", label="±3 % tolerance")
    errors.axhline(-3.0, color="grey", ls=":")
    errors.set_ylabel("force error (%)")
    lines = left.get_legend_handles_labels()
    more = errors.get_legend_handles_labels()
    left.legend(lines[0] + more[0], lines[1] + more[1], fontsize=8, loc="lower left")
    left.set_title("hertz: accuracy (d/R = 0.001)")
    right.semilogx(factor, [r["newton_iterations"] for r in rows], "o-", label="Newton iterations")
    right.semilogx(factor, [r["load_steps"] for r in rows], "s-", label="load steps (after cuts)")
    right.set_xlabel("penalty factor")
    right.legend(fontsize=8)
    right.set_title("hertz: cost")
    save_chart(fig, path, dpi=110, rect=(0, 0.03, 1, 1))


STUDY = Study(name="contact-penalty", summary="hertz: penetration and Newton iterations vs penalty factor",
              run=run)
