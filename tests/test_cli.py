"""The run contract of design.md §4 through the real command line."""

from __future__ import annotations

import csv
import json

import pytest
from conftest import last_json, run_cli


def test_list_names_every_scene_on_one_line():
    code, out, _ = run_cli("list")
    assert code == 0
    lines = [line for line in out.splitlines() if line.strip()]
    assert any(line.startswith("sphere-inflation ") for line in lines)


@pytest.mark.parametrize("setting, words", [
    ("presure=0.01", "unknown key"),
    ("pressure=abc", "cannot read"),
    ("c10=-1", "c10"),
    ("outer_radius=5", "outer_radius"),
    ("mesh_size=-1", "mesh_size"),
])
def test_bad_input_exits_2_and_writes_nothing(tmp_path, setting, words):
    out = tmp_path / "never"
    code, stdout, stderr = run_cli("run", "sphere-inflation", "--set", setting, "--out", str(out))
    assert code == 2
    assert words in stderr and "Traceback" not in stderr
    assert len(stderr.strip().splitlines()) == 1  # one clear message
    assert not out.exists()


def test_unknown_scene_exits_2():
    code, _, stderr = run_cli("run", "no-such-scene")
    assert code == 2 and "sphere-inflation" in stderr


def test_run_writes_results_and_prints_the_same_json(tmp_path):
    code, out, err = run_cli("run", "sphere-inflation", "--set", "mesh_size=2", "--out",
                             str(tmp_path), "--json")
    assert code == 0, err
    printed = last_json(out)
    saved = json.loads((tmp_path / "results.json").read_text())
    assert printed == saved
    assert saved["status"] == "ok" and saved["mpi_size"] == 1
    assert set(saved["timings"]) >= {"mesh", "form_compilation", "assembly", "solve", "total"}
    assert {"dolfinx", "petsc", "eyemech"} <= set(saved["versions"])
    assert saved["parameters"]["mesh_size"] == 2.0
    assert (tmp_path / "deformed.png").stat().st_size > 10_000
    assert all((tmp_path / name).exists() for name in saved["fields"])
    # no stray temporary files: results are written atomically
    assert not list(tmp_path.glob(".*.tmp"))


def test_toml_config_and_set_combine(tmp_path):
    config = tmp_path / "case.toml"
    config.write_text("[parameters]\nmesh_size = 2.0\npressure = 0.005\n")
    code, out, err = run_cli("run", "sphere-inflation", "--config", str(config), "--set",
                             "pressure=0.006", "--out", str(tmp_path / "r"), "--json",
                             "--no-pictures", "--no-fields")
    assert code == 0, err
    params = last_json(out)["parameters"]
    assert params["mesh_size"] == 2.0 and params["pressure"] == 0.006


@pytest.mark.mpi
def test_sweep_runs_cases_side_by_side_on_two_ranks(tmp_path):
    code, out, err = run_cli("sweep", "sphere-inflation", "--grid", "pressure=0.005,0.01",
                             "--set", "mesh_size=2", "--out", str(tmp_path), "--no-pictures",
                             ranks=2)
    assert code == 0, err
    rows = list(csv.DictReader((tmp_path / "sweep.csv").open()))
    assert [row["pressure"] for row in rows] == ["0.005", "0.01"]
    assert all(row["status"] == "ok" for row in rows)
    # side by side: each case ran on one rank of the two
    for index in range(2):
        saved = json.loads((tmp_path / f"case_{index:04d}" / "results.json").read_text())
        assert saved["mpi_size"] == 1
    radii = [float(row["inner_radius_deformed"]) for row in rows]
    assert radii[0] < radii[1]


def test_sweep_records_a_failing_case_and_finishes_the_others(tmp_path):
    code, out, err = run_cli("sweep", "sphere-inflation", "--grid", "pressure=0.005,0.05",
                             "--set", "mesh_size=2", "--set", "load_steps=1", "--petsc",
                             "snes_max_it=6", "--out", str(tmp_path), "--no-pictures",
                             "--no-fields")
    assert code == 4, err  # the sweep ran to its end, a case failed: a job script can tell
    assert "1 of 2 cases failed" in err
    rows = list(csv.DictReader((tmp_path / "sweep.csv").open()))
    assert [row["status"] for row in rows] == ["ok", "failed"]
    assert "did not converge" in rows[1]["error"]


def test_sweep_rejects_a_bad_value_before_running_any_case(tmp_path):
    code, _, stderr = run_cli("sweep", "sphere-inflation", "--grid", "c10=0.05,-1",
                              "--out", str(tmp_path / "s"))
    assert code == 2 and "c10" in stderr
    assert not (tmp_path / "s").exists()


def test_parameter_reference_is_current():
    """docs/parameters.md is generated; regenerate it with
    `eyemech list --markdown > docs/parameters.md` when a scene changes."""
    from pathlib import Path

    code, out, _ = run_cli("list", "--markdown")
    assert code == 0
    assert (Path(__file__).parents[1] / "docs" / "parameters.md").read_text() == out
