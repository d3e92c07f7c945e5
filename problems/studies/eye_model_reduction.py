"""Model no more than the scene needs: the scleral-buckling quantities of interest
against model reductions, with the cost of each (issue 9, item 1).

Every case is the ``scleral-buckling`` scene at its defaults (Q1P0, ``default``
resolution, detached retina with retina–choroid contact, sutures) with ONE reduction,
made through existing parameters only:

- ``coarse mesh``: ``resolution=coarse`` (771 instead of 1,730 hexahedra);
- ``no retina contact``: ``retina_contact=false`` (the gap is measured, not enforced);
- ``no sutures``: ``suture_force=0`` (step 3 applies nothing);
- ``attached retina``: ``detachment_height=0, tear_radius=0`` — no subretinal space, no
  tear, no retina–choroid contact: the eye of a prophylactic buckle, or the question
  whether the detachment changes the eye's response at all;

Q1P0 against Q2P1 is not charted: ``element=Q2P1`` did not finish within 400 s even on
the coarse eye on this machine (measured 2026-11-22, timed out; docs/contact.md saw the
same at the default resolution), more than the whole study's budget.

Reductions the existing parameters cannot make (named in the atlas page): merging the retina and
choroid into one layer (the mesh always has both; equal stiffnesses would not lower the
cost), a deformable buckle (the buckle is rigid only), a solid vitreous (the liquid is
the only model), quarter symmetry (the tear lies on the half model's plane).

Deviations are after suturing, relative to the full model; cost = wall time, unknowns,
Newton iterations. A case whose Newton solve fails is recorded, not fatal.
"""

from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from eyemech.problems import scleral_buckling
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import (
    QUIET,
    reduction_chart,
    relative_deviations,
    write_csv,
)

CASES = {
    "full model": {},
    "coarse mesh": {"resolution": "coarse"},
    "no retina contact": {"retina_contact": False},
    "no sutures": {"suture_force": 0.0},
    "attached retina": {"detachment_height": 0.0, "tear_radius": 0.0},
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
    relative_deviations(rows, QUANTITIES, reference="full model")
    table = write_csv(out / "eye_model_reduction.csv", rows,
                      "scleral-buckling after suturing: one reduction per case; deviation_* = "
                      "case / full model - 1")
    chart = reduction_chart(out / "eye_model_reduction.png", rows, QUANTITIES,
                            xlabel="deviation after suturing (%)",
                            title="scleral-buckling: what each model reduction changes, and what it saves")
    return [table, chart]


STUDY = Study(name="eye-model-reduction",
              summary="scleral-buckling: quantities of interest vs model reduction "
                      "(mesh, retina contact, detachment, sutures, element) with the cost",
              run=run)
