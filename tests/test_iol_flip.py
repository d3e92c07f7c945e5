"""The iol-flip study's measurement (problems/studies/iol_flip.py): the roll φ of the optic
about the injector axis and the final optic normal, read back from the ``.vtu`` frames a run
writes. Checked on frames of the flat coarse lens turned rigidly about the injector axis by
known angles — the turn a twisted injector gives the lens. The frames are written in double
precision, so the angles come back to round-off (1e-9° is far above it, far below any roll
that matters)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mpi4py import MPI

from eyemech.problems import iol_injection
from eyemech.problems.lens.injector import turn_about_x
from eyemech.problems.lens.model import LensShell, write_frame_grid
from eyemech.problems.run.output import PyvistaSeries
from eyemech.problems.studies import iol_flip


def test_roll_and_final_normal_of_a_rigidly_turned_lens(tmp_path):
    params = iol_injection.Parameters(resolution="coarse")
    shell = LensShell(params, MPI.COMM_SELF)
    X = shell.node_coordinates()
    series = PyvistaSeries(tmp_path, MPI.COMM_SELF, stem="injection")
    turns = (0.0, 50.0, 120.0)
    for time, degrees in enumerate(turns):
        shell.u.x.array[:] = (turn_about_x(params.axis_point(), np.radians(degrees))(X) - X).ravel()
        write_frame_grid(series, shell, 0.1 * time)
    roll = iol_flip.roll_history(tmp_path)
    # a right-handed turn θ about +x takes the optic's normal +z to (0, −sin θ, cos θ): φ = −θ
    assert roll[:, 1] == pytest.approx([-t for t in turns], abs=1e-9)
    assert roll[:, 2] == pytest.approx(1.0, abs=1e-12)  # a rigid turn leaves the optic flat
    assert iol_flip.last_optic_normal_z(tmp_path) == pytest.approx(np.cos(np.radians(120.0)), abs=1e-12)


def test_walls_chart_takes_rows_read_back_from_the_csv(tmp_path):
    """The walls chart is redrawn from iol_flip.csv (values as strings, empty where a case
    lacks a column) as well as from fresh runs (numbers)."""
    from PIL import Image

    from eyemech.problems.studies._common import read_csv, stamp, with_units, write_csv

    base = {"haptic_thickness": 0.13, "friction": 0.2, "damping": 2e4, "start_ramp": 0.02}
    rows = [{**base, "cartridge_friction": mu, "injector_twist": 180.0, "optic_normal_z": z}
            for mu, z in ((0.0, 0.99), (0.3, 0.77), (1.0, -0.9))]
    rows.append({**base, "capsule_friction": 1.0, "optic_normal_z": 0.98})
    rows.append({**base, "haptic_thickness": 0.35, "cartridge_friction": 0.3, "injector_twist": 180.0,
                 "friction_slip": 0.003, "finished": False, "last_frame_optic_normal_z": 0.7})
    # named as the study writes them: haptic_thickness_mm, injector_twist_deg, ...
    back = read_csv(write_csv(tmp_path / "walls.csv", with_units(rows, iol_injection.Parameters), "test"))
    history = np.array([[0.0, 0.0, 0.3], [0.5, -100.0, 1.0]])
    path = iol_flip.walls_chart(back, [history] * len(back), tmp_path / "walls.png")
    assert stamp().split(" · ", 1)[1] in Image.open(path).text["Comment"]
    assert [iol_flip._on_the_walls(r) for r in back] == [True] * 5
    assert iol_flip._wall_label(back[0]) == "h_h = 0.13, μ_cartridge = 0, twist = 180°"
    assert iol_flip._wall_label(back[-1]) == "h_h = 0.35, μ_cartridge = 0.3, twist = 180°, slip 3 µm"
    # a run that stopped is charted by its last frame
    assert iol_flip._final_normal_z(back[-1]) == pytest.approx(0.7)


@pytest.mark.parametrize("saved, status, stopped", [
    (("error", "KeyboardInterrupt"), "stopped", "by hand (time budget)"),
    (("failed", "Newton did not converge at step 9"), "failed", "Newton failed")])
def test_a_case_that_did_not_finish_has_a_status_that_counts_as_failed(tmp_path, saved, status, stopped):
    """Issue 39: a case whose Newton gave up, or that was stopped by hand for a time budget
    (kept, not rerun), was only ``finished`` false, which eyemech study does not read. Its
    row's status is failed or stopped now: neither gave the case's result, and eyemech study
    counts both as failed (exit 4)."""
    from eyemech.problems.studies import FAILED

    params = iol_injection.Parameters(resolution="coarse")
    (tmp_path / "results.json").write_text(json.dumps(
        {"status": saved[0], "message": saved[1], "parameters": params.as_dict(), "quantities": {},
         "steps": [{"time": 0.125}], "timings": {"total": 60.0}}, default=str))
    assert iol_flip._same_run(tmp_path / "results.json", params)  # kept: read, not rerun
    row = iol_flip.case_row({"haptic_thickness": 0.13, "friction": 0.2}, tmp_path)
    assert (row["status"], row["finished"], row["stopped"]) == (status, False, stopped)
    assert row["reached_time_s"] == 0.125 and status in FAILED
