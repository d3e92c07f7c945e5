"""Radial keratotomy against cadaver data (Salz et al. 1985), issue 6 item 5.

- 8 incisions at 90 % depth, optical zones 3 / 4 / 5 / 6 mm (published flattening
  9.06 / 6.44 / 5.23 / 2.29 D);
- 3 and 4 incisions at a 3.5 mm zone (published 4.84 and 6.08 D);

all at 15 mmHg, the `keratotomy` scene's default material (μ∞ = 0.04, μv = 0.03 MPa,
τ = 1 h), power change at t = 0 (glassy) and after 4 h of creep. Coarse mesh
(``mesh_size`` 1 mm, 24 divisions around, 3 layers): the trend is the claim, the magnitude
is reported as is.
"""

from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from eyemech.problems import keratotomy
from eyemech.problems.run.context import RunOptions
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import failed_row, mark_failed, save_chart, write_csv

SALZ_ZONES = {3.0: 9.06, 4.0: 6.44, 5.0: 5.23, 6.0: 2.29}
SALZ_COUNTS = {3: 4.84, 4: 6.08}
QUIET = RunOptions(fields=False, pictures=False)


def _case(incisions: int, zone: float, quick: bool, comm) -> dict:
    """The case's row: status ok with its flattening, or status failed (``eyemech study``
    exits 4) with the solver's message."""
    settings = dict(mesh_size=2.0, t_end=1800.0, first_dt=1800.0) if quick else \
        dict(mesh_size=1.0, t_end=4 * 3600.0, first_dt=1800.0, dt_growth=2.0)
    case = {"incisions": incisions, "optical_zone_mm": zone}
    try:
        # the time grid fixed, as for docs/studies/keratotomy_salz.csv
        result = keratotomy.run(keratotomy.Parameters(incisions=incisions, optical_zone=zone,
                                                      incision_depth=0.9, time_stepping="fixed",
                                                      **settings),
                                comm=comm, options=QUIET)
    except SolveFailure as failure:
        return failed_row(case, failure)
    q = result.quantities
    return case | {"status": "ok", "flattening_t0_D": -q["power_change_initial_D"],
                   "flattening_end_D": -q["power_change_final_D"],
                   "hours": q["times"][-1] / 3600.0, "cells": q["cells"],
                   "wall_time_s": result.timings["total"]}


def _chart(path: Path, zones: list[dict], counts: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    failed_zones = [r["optical_zone_mm"] for r in zones if r["status"] != "ok"]
    failed_counts = [r["incisions"] for r in counts if r["status"] != "ok"]
    zones = [r for r in zones if r["status"] == "ok"]
    counts = [r for r in counts if r["status"] == "ok"]
    hours = next((r["hours"] for r in zones + counts), None)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    ax = axes[0]
    ax.plot(list(SALZ_ZONES), list(SALZ_ZONES.values()), "ks--", label="Salz et al. 1985 (cadaver)")
    ax.plot([r["optical_zone_mm"] for r in zones], [r["flattening_t0_D"] for r in zones], "o-",
            label="model, t = 0")
    ax.plot([r["optical_zone_mm"] for r in zones], [r["flattening_end_D"] for r in zones], "o-",
            label=f"model, t = {hours:g} h" if hours is not None else "model, end")
    mark_failed(ax, failed_zones, "solve failed")
    ax.set_xlabel("optical zone (mm)")
    ax.set_ylabel("flattening (D)")
    ax.set_title("8 incisions, 90 % depth, 15 mmHg", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax = axes[1]
    x = [r["incisions"] for r in counts]
    ax.plot(list(SALZ_COUNTS), list(SALZ_COUNTS.values()), "ks--", label="Salz et al. 1985")
    ax.plot(x, [r["flattening_t0_D"] for r in counts], "o-", label="model, t = 0")
    ax.plot(x, [r["flattening_end_D"] for r in counts], "o-", label="model, end")
    mark_failed(ax, failed_counts, "solve failed")
    ax.set_xlabel("incisions")
    ax.set_xticks(sorted(x + failed_counts))
    ax.set_ylabel("flattening (D)")
    ax.set_title("3.5 mm optical zone, 90 % depth, 15 mmHg", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    save_chart(fig, path, dpi=80, rect=(0, 0.03, 1, 1))
    return path


def run(out: Path, quick: bool = False, comm=None) -> list[Path]:
    comm = comm or MPI.COMM_WORLD
    out = Path(out)
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    zones = [_case(8, z, quick, comm) for z in ((3.0, 5.0) if quick else SALZ_ZONES)]
    counts = [_case(n, 3.5, quick, comm) for n in SALZ_COUNTS]
    if comm.rank != 0:
        return []
    rows = zones + counts
    for row in rows:
        published = SALZ_ZONES.get(row["optical_zone_mm"]) if row["incisions"] == 8 \
            else SALZ_COUNTS.get(row["incisions"])
        row["salz_1985_D"] = published
    path = out / "keratotomy_salz.csv"
    write_csv(path, rows, "keratotomy vs Salz et al. 1985 (flattening = -power change, D)")
    return [path, _chart(out / "keratotomy_salz.png", zones, counts)]


STUDY = Study(name="keratotomy-salz",
              summary="radial keratotomy flattening vs optical zone and incision count "
                      "(Salz et al. 1985)",
              run=run)
