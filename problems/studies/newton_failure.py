"""Where Newton fails: load-step size against convergence, with and without a line
search, on ``sphere-inflation`` (issue 9, stability map).

Each case inflates the sphere to ``p = f · p_limit`` in ONE initial load step
(``load_steps = 1``), so the first Newton solve starts from the unloaded sphere and
must take the whole increment. Outcomes:

- ``direct``: that first solve converged (the iterations are charted);
- ``cut``: it did not; the driver halved the step (the cuts are charted) and got there;
- ``failed``: cutting was exhausted — beyond the limit point p_limit (the exact
  pressure maximum, :func:`analytic.sphere_limit_point`) no inflated equilibrium
  exists under pressure control, so every method must fail there.

SNES settings are the scenes' defaults (newtonls, max 15 iterations, rtol 1e-9) with
``snes_linesearch_type`` = basic (plain Newton), bt (backtracking) or l2.
"""

from __future__ import annotations

import math
from pathlib import Path

from mpi4py import MPI

from eyemech.problems import sphere_inflation
from eyemech.problems.reference import analytic
from eyemech.problems.run.context import RunOptions
from eyemech.problems.solve.driver import NewtonOptions, SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import save_chart, with_units, write_csv

FRACTIONS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.98, 0.995, 1.05)
QUICK_FRACTIONS = (0.3, 0.9, 1.05)
LINE_SEARCHES = ("basic", "bt", "l2")
QUICK_LINE_SEARCHES = ("basic", "bt")
BASE = dict(element="P2P1", mesh_size=2.0, load_steps=1)
QUICK_BASE = dict(element="Q1P0", mesh_size=2.0, load_steps=1)


def one_case(fraction: float, line_search: str, base: dict, p_limit: float, comm) -> dict:
    params = sphere_inflation.Parameters(pressure=fraction * p_limit, **base)
    options = RunOptions(fields=False, pictures=False,
                         newton=NewtonOptions(line_search=line_search))
    row = {"line_search": line_search, "pressure_over_limit": fraction,
           "pressure_MPa": params.pressure, "element": base["element"],
           "mesh_size": base["mesh_size"]}
    try:
        result = sphere_inflation.run(params, comm=comm, options=options)
    except SolveFailure as failure:
        return row | {"outcome": "failed", "first_step_iterations": math.nan, "first_step_cuts":
                      math.nan, "total_newton_iterations": math.nan, "steps": math.nan,
                      "reached_over_limit": failure.last_converged * fraction,
                      "wall_time_s": math.nan}
    steps = result.steps
    first = steps[0]
    return row | {"outcome": "direct" if first["cuts"] == 0 else "cut",
                  "first_step_iterations": first["newton_iterations"],
                  "first_step_cuts": first["cuts"],
                  "total_newton_iterations": sum(s["newton_iterations"] for s in steps),
                  "steps": len(steps), "reached_over_limit": fraction,
                  "wall_time_s": result.timings.get("assembly", 0.0) + result.timings.get("solve", 0.0)}


def run(out: Path, quick: bool = False, comm: MPI.Comm | None = None) -> list[Path]:
    comm = comm or MPI.COMM_WORLD
    out = Path(out)
    base = QUICK_BASE if quick else BASE
    defaults = sphere_inflation.Parameters()
    _, p_limit = analytic.sphere_limit_point(defaults.inner_radius, defaults.outer_radius,
                                             defaults.c10)
    rows = [one_case(f, ls, base, p_limit, comm)
            for ls in (QUICK_LINE_SEARCHES if quick else LINE_SEARCHES)
            for f in (QUICK_FRACTIONS if quick else FRACTIONS)]
    if comm.rank != 0:
        return []
    table = write_csv(out / "newton_failure.csv", with_units(rows, sphere_inflation.Parameters),
                      f"sphere-inflation {base['element']} h = {base['mesh_size']} mm, one initial "
                      f"load step to p = f * p_limit (p_limit = {p_limit:.6g} MPa, exact)",
                      "outcome: direct = first Newton solve converged; cut = the driver halved "
                      "the step; failed = cutting exhausted")
    return [table, _chart(out / "newton_failure.png", rows, base)]


def _chart(path: Path, rows: list[dict], base: dict) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    searches = list(dict.fromkeys(r["line_search"] for r in rows))
    fig, (ax_map, ax_cost) = plt.subplots(1, 2, figsize=(11.5, 4.2))
    style = {"direct": ("o", "tab:green"), "cut": ("s", "tab:orange"), "failed": ("X", "tab:red")}
    for y, search in enumerate(searches):
        for r in (r for r in rows if r["line_search"] == search):
            marker, colour = style[r["outcome"]]
            ax_map.scatter(r["pressure_over_limit"], y, marker=marker, color=colour, s=90)
            label = {"direct": f"{r['first_step_iterations']}", "cut": f"{r['first_step_cuts']}✂",
                     "failed": ""}[r["outcome"]]
            crowded = r["pressure_over_limit"] > 0.955  # stagger labels near the limit point
            ax_map.annotate(label, (r["pressure_over_limit"], y), textcoords="offset points",
                            xytext=(0, -14 if crowded and r["pressure_over_limit"] < 0.99 else 9),
                            ha="center", fontsize=7)
        first_cut = [r["pressure_over_limit"] for r in rows
                     if r["line_search"] == search and r["outcome"] != "direct"]
        if first_cut:
            ax_map.plot([min(first_cut)] * 2, [y - 0.3, y + 0.3], "k-", lw=2)
    ax_map.axvline(1.0, color="grey", ls="--", lw=1)
    ax_map.text(1.0, len(searches) - 0.45, " limit point", fontsize=8, color="grey")
    for outcome, (marker, colour) in style.items():
        ax_map.scatter([], [], marker=marker, color=colour, label=outcome)
    ax_map.set(yticks=range(len(searches)), yticklabels=searches, ylim=(-0.6, len(searches) + 0.3),
               xlabel="single load step Δp / p_limit (from the unloaded sphere)",
               ylabel="SNES line search",
               title="first Newton solve: iterations (number) or cuts (✂); bar = first failure")
    ax_map.title.set_fontsize(9)
    ax_map.legend(fontsize=8, loc="upper left", ncol=3)
    for search in searches:
        ok = [r for r in rows if r["line_search"] == search and r["outcome"] != "failed"]
        ax_cost.plot([r["pressure_over_limit"] for r in ok],
                     [r["total_newton_iterations"] for r in ok], "o-", label=search)
    ax_cost.axvline(1.0, color="grey", ls="--", lw=1)
    ax_cost.set(xlabel="target p / p_limit", ylabel="Newton iterations to reach p (all steps)",
                title="cost of getting there (with the driver's cut-back)")
    ax_cost.title.set_fontsize(9)
    ax_cost.legend(fontsize=8)
    ax_cost.grid(alpha=0.3)
    fig.suptitle(f"sphere-inflation {base['element']}, h = {base['mesh_size']} mm: Newton "
                 "convergence against load-step size", fontsize=10)
    save_chart(fig, path, dpi=100, rect=(0, 0.03, 1, 1))
    return path


STUDY = Study(name="newton-failure",
              summary="sphere-inflation: Newton convergence vs load-step size, with and without "
                      "line search (limit point marked)",
              run=run)
