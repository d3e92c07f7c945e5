"""How the buckle's indentation and the band's width drive the outcome of scleral
buckling (issue 5, item 5): axial length change after buckling and after suturing,
the remaining retina–choroid gap and whether the tear closed.

The cases run through :func:`eyemech.problems.run.sweep.run_sweep`, so under
``mpiexec -n N`` they run side by side (one rank each) and a failed case is recorded,
not fatal. The full study uses the coarse eye (it is a trend chart, not a converged
number); ``quick`` runs two cases.
"""

from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from eyemech.problems import scleral_buckling
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.sweep import run_sweep
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import save_chart, write_csv

# an encircling band alone (no tire), so that its width is what touches the sclera:
# the clinical comparison (myopic shift for band widths 1–2.5 mm) is for bands
BASE = {"resolution": "coarse", "tire_height": "0", "suture_width": "4.0"}
# a band narrower than about two elements is not resolved by the coarse eye (1 mm bands
# needed hundreds of cut steps and failed at 1 mm indentation): widths from 2.5 mm
GRID = {"indentation": ["0.5", "1.0", "1.5"], "band_width": ["2.5", "4.0"]}
QUICK_GRID = {"indentation": ["0.5", "1.0"], "band_width": ["2.5"]}


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    grid = QUICK_GRID if quick else GRID
    rows = run_sweep(scleral_buckling.SCENE, BASE, grid,
                     out / "buckling_sweep_cases", options=RunOptions(fields=False, pictures=False),
                     comm=comm)
    if comm.rank != 0:
        return []
    # a failed case's row has an ``error`` column and no quantities: union of the keys
    table = write_csv(out / "buckling_sweep.csv", rows)
    chart = out / "buckling_sweep.png"
    _chart(rows, grid, chart)
    return [table, chart]


def _chart(rows: list[dict], grid: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for width in grid["band_width"]:
        cases = [r for r in rows if str(r["band_width"]) == width and r.get("status") == "ok"]
        depth = [float(r["indentation"]) for r in cases]
        axes[0].plot(depth, [float(r["axial_length_change_mm"]) for r in cases], "o-",
                     label=f"band {width} mm")
        axes[1].plot(depth, [float(r["retina_choroid_gap_mean_mm"]) for r in cases], "o-",
                     label=f"band {width} mm")
        for r in cases:
            if str(r.get("tear_closed")) == "True":
                axes[1].annotate("tear closed", (float(r["indentation"]),
                                                 float(r["retina_choroid_gap_mean_mm"])))
    failed = [r for r in rows if r.get("status") != "ok"]
    for r in failed:  # where the method failed: marked on the x axis
        axes[0].plot(float(r["indentation"]), 0.0, "rx", ms=10, mew=2)
    if failed:
        widths = sorted({str(r["band_width"]) for r in failed})
        axes[0].plot([], [], "rx", label=f"Newton failed (band {', '.join(widths)} mm)")
    axes[0].set(xlabel="buckle indentation (mm)", ylabel="axial length change after suturing (mm)")
    axes[1].set(xlabel="buckle indentation (mm)", ylabel="mean retina–choroid gap (mm)")
    for ax in axes:
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle("scleral-buckling: encircling band alone, coarse eye, Q1P0")
    save_chart(fig, path, dpi=110, rect=(0, 0.04, 1, 0.95))


STUDY = Study("buckling-sweep", "axial length and retina gap vs buckle indentation and band width",
              run)
