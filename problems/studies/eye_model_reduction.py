"""Model no more than the scene needs: the scleral-buckling quantities of interest
against model reductions, with the cost of each (issue 9, item 1).

Every case is the ``scleral-buckling`` scene at its defaults (Q1P0, ``default``
resolution, detached retina with retina–choroid contact, sutures) with ONE reduction,
made through existing parameters only:

- ``coarse mesh``: ``resolution=coarse`` (771 instead of 1,730 hexahedra);
- ``no retina contact``: ``retina_contact=false`` (the gap is measured, not enforced);
- ``no sutures``: ``suture_force=0`` (step 3 applies nothing);

Q1P0 against Q2P1 is not charted: ``element=Q2P1`` did not finish within 400 s even on
the coarse eye on this machine (measured 2026-11-22, timed out; docs/contact.md saw the
same at the default resolution), more than the whole study's budget.

Reductions the existing parameters cannot make (named in the atlas page): an attached
retina (``detachment_height=0`` passes validation but the eye mesh then has no
``retina_detached`` region and the run stops with exit code 2), merging the retina and
choroid into one layer (the mesh always has both; equal stiffnesses would not lower the
cost), a deformable buckle (the buckle is rigid only), a solid vitreous (the liquid is
the only model), quarter symmetry (the tear lies on the half model's plane).

Deviations are after suturing, relative to the full model; cost = wall time, unknowns,
Newton iterations. A case whose Newton solve fails is recorded, not fatal.
"""

from __future__ import annotations

import math
from pathlib import Path

from mpi4py import MPI

from eyemech.problems import scleral_buckling
from eyemech.problems.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, save_chart, write_csv

CASES = {
    "full model": {},
    "coarse mesh": {"resolution": "coarse"},
    "no retina contact": {"retina_contact": False},
    "no sutures": {"suture_force": 0.0},
}
# quick: the coarse eye (11 s a case here), full against one reduction
QUICK_BASE = {"resolution": "coarse"}
QUICK_CASES = {"full model": {}, "no retina contact": {"retina_contact": False}}
QUANTITIES = {"axial_length_change_mm": "axial length change",
              "buckle_indentation_mm": "buckle indentation",
              "iop_mmHg": "IOP",
              "retina_choroid_gap_mean_mm": "mean retina–choroid gap",
              "von_mises_max_MPa": "peak von Mises"}


def one_case(label: str, overrides: dict, comm) -> dict:
    params = scleral_buckling.Parameters(**overrides)
    row = {"case": label, "resolution": params.resolution, "element": params.element,
           "changes": " ".join(f"{k}={v}" for k, v in overrides.items()) or "defaults"}
    try:
        result = scleral_buckling.run(params, comm=comm, options=QUIET)
    except SolveFailure as failure:
        return row | {"status": f"failed at load {failure.load:.3g}"}
    final = result.quantities["after_suturing"]
    return row | {"status": "ok", **{key: final[key] for key in QUANTITIES},
                  "tear_closed_nts": result.quantities.get("tear_closed_nts"),
                  "cells": result.quantities["cells"], "dofs": result.quantities["dofs"],
                  "newton_iterations": sum(s.get("newton_iterations", 0) for s in result.steps),
                  "load_steps": len(result.steps),
                  "wall_time_s": result.timings["total"]}


def run(out: Path, quick: bool = False, comm: MPI.Comm | None = None) -> list[Path]:
    comm = comm or MPI.COMM_WORLD
    out = Path(out)
    if quick:
        cases = {label: QUICK_BASE | o for label, o in QUICK_CASES.items()}
    else:
        cases = CASES
    rows = [one_case(label, overrides, comm) for label, overrides in cases.items()]
    if comm.rank != 0:
        return []
    _deviations(rows)
    table = write_csv(out / "eye_model_reduction.csv", rows,
                      "scleral-buckling after suturing: one reduction per case; deviation_* = "
                      "case / full model - 1")
    return [table, _chart(out / "eye_model_reduction.png", rows)]


def _deviations(rows: list[dict]) -> None:
    by = {r["case"]: r for r in rows if r["status"] == "ok"}
    for row in rows:
        reference = by.get("full model")
        row["reference"] = reference["case"] if reference else ""
        for key in QUANTITIES:
            ok = reference is not None and row["status"] == "ok" and reference[key] != 0
            row[f"deviation_{key}"] = row[key] / reference[key] - 1.0 if ok else math.nan


def _chart(path: Path, rows: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    ok = [r for r in rows if r["status"] == "ok"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 4.6),
                                      gridspec_kw={"width_ratios": [2.2, 1]})
    width = 0.8 / len(QUANTITIES)
    y = np.arange(len(ok))
    for k, (key, label) in enumerate(QUANTITIES.items()):
        values = [100 * r[f"deviation_{key}"] for r in ok]
        left.barh(y + (k - len(QUANTITIES) / 2 + 0.5) * width, values, height=width, label=label)
    left.axvline(0, color="k", lw=0.8)
    left.set_yticks(y, [r["case"] for r in ok], fontsize=8)
    left.invert_yaxis()
    left.set(xlabel="deviation after suturing (%)",
             title="quantities of interest vs the reference case")
    left.legend(fontsize=7, loc="best")
    left.grid(alpha=0.3, axis="x")
    right.barh(y, [r["wall_time_s"] for r in ok], color="tab:grey")
    for yi, r in zip(y, ok):
        right.annotate(f"{r['dofs']} dofs, {r['newton_iterations']} its", (r["wall_time_s"], yi),
                       textcoords="offset points", xytext=(3, -3), fontsize=7)
    right.set_yticks(y, ["" for _ in ok])
    right.invert_yaxis()
    right.set(xlabel="wall time (s)", title="cost")
    right.set_xlim(0, 1.6 * max(r["wall_time_s"] for r in ok))
    failed = [r for r in rows if r["status"] != "ok"]
    if failed:
        right.text(0.02, 0.02, "failed: " + "; ".join(f"{r['case']} ({r['status']})" for r in failed),
                   transform=right.transAxes, fontsize=7, color="tab:red")
    for ax in (left, right):
        ax.title.set_fontsize(9)
    fig.suptitle("scleral-buckling: what each model reduction changes, and what it saves",
                 fontsize=10)
    save_chart(fig, path, dpi=100, rect=(0, 0.03, 1, 1))
    return path


STUDY = Study(name="eye-model-reduction",
              summary="scleral-buckling: quantities of interest vs model reduction "
                      "(mesh, retina contact, detachment, sutures, element) with the cost",
              run=run)
