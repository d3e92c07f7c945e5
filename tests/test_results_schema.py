"""results.json has a version and a schema (problems/run/results.schema.json) that every
run's file satisfies; a staged scene's per-stage quantities reach the run summary and
sweep.csv, labelled by stage."""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest

from eyemech.problems.run.results import SCHEMA_VERSION, Result, schema

EYEMECH = Path(sys.executable).parent / "eyemech"


def check_results(path: Path) -> dict:
    """Validate a results.json against the schema (the notebooks' runs use it too)."""
    data = json.loads(Path(path).read_text())
    jsonschema.validate(data, schema())
    assert data["schema_version"] == SCHEMA_VERSION
    return data


def test_the_schema_is_a_valid_json_schema():
    jsonschema.Draft202012Validator.check_schema(schema())


def test_a_run_writes_a_versioned_results_json_that_fits_the_schema(tmp_path):
    done = subprocess.run([str(EYEMECH), "run", "sphere-inflation", "--set", "mesh_size=2",
                           "--out", str(tmp_path), "--no-pictures", "--no-fields", "--json"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    data = check_results(tmp_path / "results.json")
    assert json.loads(done.stdout.splitlines()[-1]) == data  # --json prints the same object


def test_the_schema_refuses_a_file_without_version_or_with_a_bad_status():
    result = Result(scene="x", parameters={})
    result.timings = {"total": 0.5}
    data = result.as_json()
    jsonschema.validate(data, schema())
    for broken in ({k: v for k, v in data.items() if k != "schema_version"},
                   {**data, "status": "fine"}, {**data, "mpi_size": 0}):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(broken, schema())


STAGED = {"cells": 802, "axial_length_change_mm": 0.45,
          "after_iop": {"axial_length_change_mm": 0.0, "iop_mmHg": 15.0},
          "after_suturing": {"axial_length_change_mm": 2.48, "iop_mmHg": 57.6},
          "after_settling": {"axial_length_change_mm": 0.45, "iop_mmHg": 15.0}}


def test_the_summary_labels_each_stage():
    from eyemech.scripts.cli import _summary

    result = Result(scene="staged", parameters={}, quantities=STAGED)
    result.timings = {"total": 1.0}
    lines: list[str] = []
    _summary(result, Path("out"), lambda *a, **_: lines.append(" ".join(map(str, a))))
    header = next(line for line in lines if "by stage" in line)
    assert header.split()[2:] == ["after", "iop", "after", "suturing", "after", "settling"]
    row = next(line for line in lines if line.split()[0] == "axial_length_change_mm")
    assert row.split()[1:] == ["0", "2.48", "0.45"]
    assert any("at the end of the run (after settling)" in line for line in lines)
    assert any(line.split() == ["cells", "802"] for line in lines)


def test_sweep_csv_has_a_column_group_per_stage():
    from eyemech.problems.run.sweep import _csv, _scalars

    table = _csv([{"case": 0, "status": "ok", **_scalars(STAGED)}])
    row = next(csv.DictReader(io.StringIO(table)))
    assert row["after_suturing.axial_length_change_mm"] == "2.48"  # acute
    assert row["after_settling.iop_mmHg"] == "15.0"  # settled
    assert row["after_iop.iop_mmHg"] == "15.0" and row["axial_length_change_mm"] == "0.45"
