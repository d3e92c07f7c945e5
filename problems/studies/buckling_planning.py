"""A planning map for scleral buckling (issue 21, item 8): the paper's planning factors
(seed 002 §1: buckle shape, location, buckling strength, suture width and force) swept on
the coarse eye, with what each setting costs the patient — the axial length change and the
refraction change from the eye before surgery (acute, after suturing; settled, after the
IOP has returned) and the acute IOP rise — and whether it closes the tear
(``tear_closed_nts`` after suturing).

Sweeps, each from the scene's defaults (buckle 13.0 mm behind the limbus, travel 2.0 mm,
0.2 N sutures 8.9 mm wide): the buckle kind (encircling band with the tire at the tear,
band alone, tire alone) × the band's travel; then, for the default kind and travel, the
buckle position, the suture force and the suture width, one at a time (the default case
of the kind sweep stands for each sweep's default value). Sutures at the tear's meridian
only (``suture_azimuths=0``), so that every kind holds them. ``quick``: two cases.
"""

from __future__ import annotations

import json
from pathlib import Path

from mpi4py import MPI

from eyemech.problems import scleral_buckling
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.sweep import run_sweep
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import save_chart, write_csv

BASE = {"resolution": "coarse", "suture_azimuths": "0"}
DEFAULTS = {"buckle": "encircling+segmental", "indentation": "2.0", "buckle_position": "13.0",
            "suture_force": "0.2", "suture_width": "8.9"}
# (factor, grid): each sweep varies its grid's keys; the other factors keep DEFAULTS.
SWEEPS = (("kind", {"buckle": ["encircling+segmental", "encircling", "segmental"],
                    "indentation": ["1.0", "1.5", "2.0"]}),
          ("position", {"buckle_position": ["11.0", "11.5", "12.0", "12.5"]}),
          ("suture_force", {"suture_force": ["0.1", "0.3"]}),
          ("suture_width", {"suture_width": ["7.5", "11.0"]}))
QUICK_SWEEPS = (("kind", {"buckle": ["encircling+segmental", "segmental"],
                          "indentation": ["2.0"]}),)
# tear_closed_nts: every node of the tear's rim within this of the choroid
CLOSED_GAP_MM = scleral_buckling.Parameters().tear_closure_tolerance
# one-factor panels of the chart: (factor, parameter, axis label)
ONE_FACTOR = (("position", "buckle_position", "buckle centre behind the limbus (mm); "
               "tear centre at 11.5"),
              ("suture_force", "suture_force", "suture force (N)"),
              ("suture_width", "suture_width", "suture width (mm)"))
COSTS = (("tear_rim_gap_after_suturing_mm", "tear's rim gap after\nsuturing (mm)"),
         ("acute_axial_mm", "ΔAL acute (mm)"), ("acute_refraction_D", "ΔSE acute (D)"),
         ("acute_iop_change_mmHg", "ΔIOP acute (mmHg)"),
         ("settled_refraction_D", "ΔSE settled (D)"))


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    rows: list[dict] = []
    for factor, grid in QUICK_SWEEPS if quick else SWEEPS:
        folder = out / "buckling_planning_cases" / factor
        base = BASE | {k: v for k, v in DEFAULTS.items() if k not in grid}
        swept = run_sweep(scleral_buckling.SCENE, base, grid, folder,
                          options=RunOptions(fields=False, pictures=False), comm=comm)
        rows += [_stages({"factor": factor, **DEFAULTS, **row}, folder) for row in swept]
    if comm.rank != 0:
        return []
    table = write_csv(out / "buckling_planning.csv", rows)
    chart = out / "buckling_planning.png"
    _chart(rows, chart)
    return [table, chart]


def _stages(row: dict, folder: Path) -> dict:
    """The acute (after suturing) and settled values of one case, from its results.json."""
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
                  "acute_indentation_mm": acute["buckle_indentation_mm"],
                  "tire_free_after_suturing": acute.get("tire_free"),
                  "settled_axial_mm": settled.get("axial_length_change_mm"),
                  "settled_refraction_D": settled.get("refraction_change_D"),
                  "tear_closed_settled": settled.get("tear_closed_nts"),
                  "tear_rim_gap_settled_mm": settled.get("tear_rim_gap_max_mm")}


def _is_default_case(row: dict) -> bool:
    return row["factor"] == "kind" and all(str(row[k]) == DEFAULTS[k]
                                           for k in ("buckle", "indentation"))


def _one_factor_rows(rows: list[dict], factor: str) -> list[dict]:
    """A one-factor sweep's cases with the default case (the kind sweep's) in its place."""
    return [r for r in rows if r["factor"] == factor or _is_default_case(r)]


def _plot(ax, xs: list[float], cases: list[dict], key: str, label: str | None) -> None:
    """A line of ``key`` against ``xs``; filled markers where the tear closed after
    suturing, hollow where it stayed open, a red cross at 0 where the case failed."""
    done = [(x, r) for x, r in zip(xs, cases) if r.get(key) is not None]
    line, = ax.plot([x for x, _ in done], [float(r[key]) for _, r in done], "-", label=label)
    for x, r in done:
        closed = bool(r.get("tear_closed_after_suturing"))
        ax.plot(x, float(r[key]), "o", color=line.get_color(),
                mfc=line.get_color() if closed else "white")
    for x, r in zip(xs, cases):
        if r.get("status") != "ok":
            ax.plot(x, 0.0, "rx", ms=10, mew=2)


def _chart(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    factors = [f for f, _, _ in ONE_FACTOR if any(r["factor"] == f for r in rows)]
    fig, axes = plt.subplots(len(COSTS), 1 + len(factors), squeeze=False,
                             sharey="row", figsize=(4.2 * (1 + len(factors)), 2.4 * len(COSTS)))
    kinds = list(dict.fromkeys(r["buckle"] for r in rows if r["factor"] == "kind"))
    for kind in kinds:
        cases = [r for r in rows if r["factor"] == "kind" and r["buckle"] == kind]
        xs = [float(r["indentation"]) for r in cases]
        for ax, (key, _) in zip(axes[:, 0], COSTS):
            _plot(ax, xs, cases, key, kind)
    axes[-1, 0].set_xlabel("buckle travel (mm)")
    axes[0, 0].set_title(f"buckle kind × travel (at {DEFAULTS['buckle_position']} mm)",
                         fontsize=9)
    for column, factor in enumerate(factors, start=1):
        _, parameter, label = next(f for f in ONE_FACTOR if f[0] == factor)
        cases = sorted(_one_factor_rows(rows, factor), key=lambda r: float(r[parameter]))
        xs = [float(r[parameter]) for r in cases]
        for ax, (key, _) in zip(axes[:, column], COSTS):
            _plot(ax, xs, cases, key, None)
            ax.axvline(float(DEFAULTS[parameter]), color="0.6", ls=":", lw=1)
        axes[-1, column].set_xlabel(label)
        axes[0, column].set_title(f"{factor.replace('_', ' ')} (band + tire, "
                                  f"{DEFAULTS['indentation']} mm; dotted: default)", fontsize=9)
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    for ax in axes[0]:  # the closure criterion of tear_closed_nts
        ax.axhline(CLOSED_GAP_MM, color="k", ls="--", lw=0.8)
    for ax, (_, label) in zip(axes[:, 0], COSTS):
        ax.set_ylabel(label)
    legend = axes[1, 0]  # its upper left is empty: small changes at 1 mm of travel
    legend.plot([], [], "ko", label="tear closed after suturing")
    legend.plot([], [], "ko", mfc="white", label="tear open")
    legend.plot([], [], "rx", label="solve failed")
    legend.plot([], [], "k--", lw=0.8, label=f"closed below {CLOSED_GAP_MM:g} mm")
    legend.legend(fontsize=7, loc="upper left")
    fig.suptitle("scleral-buckling planning map: coarse eye, Q1P0, sutures at the tear's "
                 "meridian; changes from the eye before surgery")
    save_chart(fig, path, dpi=100, rect=(0, 0.03, 1, 0.96))


STUDY = Study("buckling-planning", "which buckles close the tear, and their cost in axial "
              "length, refraction and IOP", run)
