"""One field format by default, read by pyvista (and ParaView): ``.vtu`` + ``.pvd``; ADIOS2
VTX as well with ``--vtx``; a sweep writes fields and pictures only when asked."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

EYEMECH = Path(sys.executable).parent / "eyemech"
PLATE = ["plate-clamped", "--set", "divisions=4", "--quiet"]


def _run(*args: str) -> None:
    done = subprocess.run([str(EYEMECH), *args], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]


def test_a_run_writes_a_pvd_series_that_pyvista_reads(tmp_path):
    import pyvista as pv

    _run("run", *PLATE, "--out", str(tmp_path))
    assert not list(tmp_path.glob("*.bp"))
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["fields"] == ["fields.pvd"]
    reader = pv.get_reader(str(tmp_path / "fields.pvd"))
    reader.set_active_time_value(reader.time_values[-1])
    grid = reader.read()[0]
    # the loaded plate: its centre deflection is the run's
    deflection = np.abs(grid.point_data["displacement"][:, 2]).max()
    assert np.isclose(deflection, abs(results["quantities"]["center_deflection"]), rtol=1e-6)


def test_vtx_on_request(tmp_path):
    _run("run", *PLATE, "--vtx", "--no-pictures", "--out", str(tmp_path))
    assert [p.name for p in tmp_path.glob("*.bp")] == ["fields_displacement.bp"]
    assert [p.name for p in tmp_path.glob("*.pvd")] == ["fields.pvd"]  # the default, still


def test_a_sweep_writes_fields_and_pictures_only_when_asked(tmp_path):
    _run("sweep", *PLATE, "--grid", "q=1,2", "--out", str(tmp_path / "bare"))
    written = {p.name for p in (tmp_path / "bare").rglob("*") if p.is_file()}
    assert written == {"sweep.csv", "results.json", "run.json"}  # run.json: each case's identity
    _run("sweep", *PLATE, "--grid", "q=1", "--fields", "--pictures", "--out", str(tmp_path / "all"))
    case = tmp_path / "all" / "case_0000"
    assert (case / "fields.pvd").exists() and list(case.glob("*.png"))
