"""The ``hyperelastic-convergence`` study in quick mode writes its CSV and PNG files
with one row per element family (charts are checked by eye in docs/studies)."""

from __future__ import annotations

import csv

from mpi4py import MPI

from eyemech.problems.studies import studies
from eyemech.problems.studies.hyperelastic_convergence import FAMILIES


def test_quick_study_writes_csv_and_png(tmp_path):
    files = studies()["hyperelastic-convergence"].run(tmp_path, quick=True, comm=MPI.COMM_WORLD)
    names = {f.name for f in files}
    assert {"sphere_inflation_convergence.png", "cook_membrane_convergence.png",
            "cook_pressure_Q1P0_vs_Q2P1.png", "cavity_formulations.csv"} <= names
    with open(tmp_path / "sphere_inflation_convergence.csv") as handle:
        rows = list(csv.DictReader(line for line in handle if not line.startswith("#")))
    assert {r["element"] for r in rows} == set(FAMILIES)
    with open(tmp_path / "cavity_formulations.csv") as handle:
        rows = list(csv.DictReader(line for line in handle if not line.startswith("#")))
    by = {r["formulation"]: int(r["jacobian_nonzeros"]) for r in rows}
    assert by["substituted"] > 2 * by["real"]
