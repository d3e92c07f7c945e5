"""The ``hyperelastic-convergence`` study in quick mode writes its CSV and PNG files
with one row per element family (charts are checked by eye in docs/studies)."""

from __future__ import annotations

import csv

from mpi4py import MPI

from eyemech.problems.studies import hyperelastic_convergence as study
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

    assert all(r["status"] == "ok" for r in rows)


def test_a_case_whose_newton_fails_is_a_failed_row_not_a_gap(monkeypatch):
    """A failed solve was printed as "skipped" and left out of the table (the study then
    exited 0); now it is a row with status failed, which ``eyemech study`` counts (exit 4),
    and the reference and charts use the cases that ran."""
    from eyemech.problems.solve.driver import SolveFailure

    real_run = study.cook_membrane.run

    def fails_for_q1p0(params, **kwargs):
        if params.element == "Q1P0":
            raise SolveFailure(3, 0.5, 0.25, [1.0, 0.9], "DIVERGED_PLANTED")
        return real_run(params, **kwargs)

    monkeypatch.setattr(study.cook_membrane, "run", fails_for_q1p0)
    rows, reference = study.cook_rows(quick=True, comm=MPI.COMM_WORLD)
    failed = [r for r in rows if r["status"] == "failed"]
    assert [r["element"] for r in failed] == ["Q1P0"] and "DIVERGED_PLANTED" in failed[0]["error"]
    assert all("tip_error" in r for r in rows if r["status"] == "ok")
    assert len(rows) == len(FAMILIES)
