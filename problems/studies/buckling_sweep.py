"""How the buckle's indentation and the band's width drive the outcome of scleral
buckling: the axial length change and the mean retina–choroid gap after suturing (acute)
and after settling (the IOP back to its value before surgery), and whether the tear closed.

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
from eyemech.problems.studies._common import save_chart, with_units, write_csv

# an encircling band alone (buckle = encircling: no tire; a tire of zero height made the
# settling stall), so that its width is what touches the sclera:
# the band-width comparison (another finite-element model's myopic shift for band widths
# 1–2.5 mm, J Ophthalmol 2016; docs/scleral_buckling.md, "Clinical comparison") is for bands
# on the paper's operation (Table 1's clamped eye, the rigid buckle moved in by its
# indentation, the liquid conserved): the indentation is the swept control
BASE = {"resolution": "coarse", "buckle": "encircling", **scleral_buckling.PAPER_SETTINGS}
# a band narrower than about two elements is not resolved by the coarse eye (1 mm bands
# needed hundreds of cut steps and failed at 1 mm indentation): widths from 2.5 mm
GRID = {"indentation": ["0.5", "1.0", "1.5"], "band_width": ["2.5", "4.0"]}
# one case: the coarse eye's runs take minutes each on a loaded machine
QUICK_GRID = {"indentation": ["1.0"], "band_width": ["2.5"]}


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    grid = QUICK_GRID if quick else GRID
    rows = run_sweep(scleral_buckling.SCENE, BASE, grid,
                     out / "buckling_sweep_cases", options=RunOptions(fields=False, pictures=False),
                     comm=comm)
    if comm.rank != 0:
        return []
    # a failed case's row has an ``error`` column and no quantities: union of the keys;
    # the acute and settled values are the stage columns (after_suturing., after_settling.)
    table = write_csv(out / "buckling_sweep.csv", with_units(rows, scleral_buckling.Parameters),
                      "scleral-buckling: an encircling band alone (buckle encircling), coarse eye, "
                      "Q1P0; acute = after_suturing.*, settled = after_settling.*")
    chart = out / "buckling_sweep.png"
    _chart(rows, grid, chart)
    return [table, chart]


STAGES = (("after_suturing", "acute (after suturing)", "o-"),
          ("after_settling", "settled (IOP back)", "s--"))


def _chart(rows: list[dict], grid: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    quantities = (("axial_length_change_mm", "axial length change (mm)"),
                  ("retina_choroid_gap_mean_mm", "mean retina–choroid gap (mm)"))
    for ax, (key, label) in zip(axes, quantities):
        for width in grid["band_width"]:
            mine = [r for r in rows if str(r["band_width"]) == width]
            for stage, name, style in STAGES:
                done = [r for r in mine if f"{stage}.{key}" in r]
                ax.plot([float(r["indentation"]) for r in done],
                        [float(r[f"{stage}.{key}"]) for r in done], style,
                        label=f"band {width} mm, {name}")
        failed = [r for r in rows if r.get("status") != "ok"]
        for r in failed:  # where the solve failed: a cross on the axis, in both panels
            ax.plot(float(r["indentation"]), 0.0, "rx", ms=10, mew=2)
        if failed:
            ax.plot([], [], "rx", label="solve failed (settled value missing)")
        ax.set(xlabel="buckle indentation (mm)", ylabel=label)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    for r in rows:
        if str(r.get("after_suturing.tear_closed_nts")) == "True":
            axes[1].annotate("tear closed", (float(r["indentation"]),
                                             float(r["after_suturing.retina_choroid_gap_mean_mm"])),
                             fontsize=7)
    fig.suptitle("scleral-buckling: encircling band alone, coarse eye, Q1P0")
    save_chart(fig, path, dpi=110, rect=(0, 0.04, 1, 0.95))


STUDY = Study("buckling-sweep", "axial length and retina gap vs buckle indentation and band width",
              run)
