"""A planning map for scleral buckling (issue 21, item 8): the paper's planning factors
(seed 002 §1: buckle shape, buckling strength, suture force) swept on the coarse eye,
with what each setting costs the patient — the axial length change and the refraction
change from the eye before surgery (acute, after suturing; settled, after the IOP has
returned) — and whether it closes the tear (``tear_closed_nts`` after suturing).

Cases: the buckle kind (encircling band with the tire at the tear, band alone, tire
alone) × the band's travel. Sutures at the tear's meridian only (``suture_azimuths=0``),
so that every kind holds them. ``quick``: two cases.
"""

from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from eyemech.problems import scleral_buckling
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.sweep import run_sweep
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import save_chart, write_csv

BASE = {"resolution": "coarse", "suture_azimuths": "0"}
GRID = {"buckle": ["encircling+segmental", "encircling", "segmental"],
        "indentation": ["1.0", "1.5", "2.0"]}
QUICK_GRID = {"buckle": ["encircling+segmental", "segmental"], "indentation": ["1.5"]}


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    grid = QUICK_GRID if quick else GRID
    rows = run_sweep(scleral_buckling.SCENE, BASE, grid, out / "buckling_planning_cases",
                     options=RunOptions(fields=False, pictures=False), comm=comm)
    if comm.rank != 0:
        return []
    rows = [_stages(row, out / "buckling_planning_cases") for row in rows]
    table = write_csv(out / "buckling_planning.csv", rows)
    chart = out / "buckling_planning.png"
    _chart(rows, grid, chart)
    return [table, chart]


def _stages(row: dict, folder: Path) -> dict:
    """The acute (after suturing) and settled values of one case, from its results.json."""
    import json

    path = folder / f"case_{int(row['case']):04d}" / "results.json"
    if row.get("status") != "ok" or not path.exists():
        return row
    quantities = json.loads(path.read_text())["quantities"]
    acute, settled = quantities["after_suturing"], quantities.get("after_settling", {})
    return row | {"acute_axial_mm": acute["axial_length_change_mm"],
                  "acute_refraction_D": acute["refraction_change_D"],
                  "acute_iop_change_mmHg": acute["iop_change_mmHg"],
                  "tear_closed_after_suturing": acute["tear_closed_nts"],
                  "tear_rim_gap_after_suturing_mm": acute["tear_rim_gap_max_mm"],
                  "settled_axial_mm": settled.get("axial_length_change_mm"),
                  "settled_refraction_D": settled.get("refraction_change_D"),
                  "tear_closed_settled": settled.get("tear_closed_nts")}


def _chart(rows: list[dict], grid: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    panels = (("acute_axial_mm", "axial length change, acute (mm)"),
              ("acute_refraction_D", "refraction change, acute (D)"),
              ("settled_refraction_D", "refraction change, settled (D)"))
    for kind in grid["buckle"]:
        cases = [r for r in rows if r.get("buckle") == kind and "acute_axial_mm" in r]
        travel = [float(r["indentation"]) for r in cases]
        for ax, (key, _) in zip(axes, panels):
            values = [r.get(key) for r in cases]
            line, = ax.plot(travel, values, "-", label=kind)
            closed = [bool(r.get("tear_closed_after_suturing")) for r in cases]
            for t, v, c in zip(travel, values, closed):  # filled: the tear closed
                ax.plot(t, v, "o", color=line.get_color(), mfc=line.get_color() if c else "white")
    for r in rows:
        if r.get("status") != "ok":
            axes[0].plot(float(r["indentation"]), 0.0, "rx", ms=10, mew=2)
    for ax, (_, label) in zip(axes, panels):
        ax.set(xlabel="buckle travel (mm)", ylabel=label)
        ax.grid(alpha=0.3)
    axes[0].plot([], [], "ko", label="tear closed after suturing")
    axes[0].plot([], [], "ko", mfc="white", label="tear open")
    axes[0].legend(fontsize=8)
    fig.suptitle("scleral-buckling planning map: coarse eye, Q1P0, 0.2 N sutures at the tear; "
                 "changes from the eye before surgery")
    save_chart(fig, path, dpi=110, rect=(0, 0.04, 1, 0.93))


STUDY = Study("buckling-planning", "which buckles close the tear, and their cost in axial "
              "length, refraction and IOP", run)
