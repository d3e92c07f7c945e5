"""Geometrically nonlinear Kirchhoff–Love shell against published large-deflection
references.

References
- Pinched hemisphere with an 18° hole (R 10, h 0.04, E 6.825e7, ν 0.3), four
  alternating radial point loads P on the whole shell (P/2 on the quarter model),
  P_max = 400: Sze, Liu & Lo, "Popular benchmark problems for geometric nonlinear
  analysis of shells", Finite Elem. Anal. Des. 40 (2004) 1551–1569, problem 3.4; the
  load–deflection table as copied in ElmerCSC/elmerfem
  fem/tests/Shell_OpenHemisphere_High_Order/runhemisphere.m. At P = 100: 2.596
  (pulled point, outward) and 3.833 (pushed point, inward).

- Clamped square plate at large deflection, edges sliding in-plane (normal in-plane
  displacement zero), ν = 0.316: S. Levy, "Square plate with clamped edges under
  normal pressure producing large deflections", NACA TN 847 (1942), Table 5; at
  Q = q L⁴/(E h⁴) = 95 the centre deflection is 0.912 h.

Tolerances (from the refinement measured on the team VM, P2 crossed)
- Hemisphere at 8 divisions, P = 100 (25 % of P_max, 5 load steps): measured
  2.214 / 3.089, i.e. −14.7 % / −19.4 % against the table; on 16 divisions the same
  load gives −2.1 % / −3.3 %, and at P = 400 −3.2 % / −5.4 % (study
  ``shell-hemisphere``, docs/studies/shell_hemisphere_nonlinear.csv): the error falls
  about 6–7× per halving of h, from below at every load level. The coarse-mesh error
  is P2 membrane locking of the faceted shell — the LINEAR hemisphere on this mesh is
  23 % too stiff (0.0713 against 0.093, docs/shell.md). The test therefore requires the
  coarse displacements below the table (convergence from below) and within 25 % of it
  (the linear locking error at this mesh plus 2 %), and that the test's run is exactly
  the study's 8-division row (so the study's 16-division row, within 5.5 % of the table
  at every load, is the convergence evidence for this computation). 8 divisions is the
  only mesh fast enough here (~40 Newton iterations of 7 920 dofs, ~20 s on the VM).
- Levy's plate at Q = 95: centre deflection error −2.48 / −1.31 / −0.94 % on
  8 / 16 / 32 divisions, converging from below towards ≈ −0.7 % (the difference of the
  Koiter shell from Levy's von Kármán series, truncated); the clamped edges' penalty is
  the coercive one on the cells' normal height (forms/shell.py ``normal_height``). The
  test uses 8 divisions and 3 %: the measured −2.48 % plus margin; a linear plate would
  be +42 % (1.298 h).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from eyemech.problems import hemisphere_nonlinear, plate_clamped
from eyemech.problems.run.context import RunOptions
from eyemech.problems.shell import model as shells
from eyemech.problems.studies._common import read_csv

QUIET = RunOptions(fields=False, pictures=False)
STUDY_CSV = Path(__file__).resolve().parents[1] / "docs" / "studies" / "shell_hemisphere_nonlinear.csv"
LEVY_DIVISIONS = 8
LEVY_TOLERANCE = 0.03  # measured -2.48 % at 8 divisions, -1.31 % at 16, -0.94 % at 32
HEMISPHERE_TOLERANCE = 0.25  # linear locking error at 8 divisions (23 %) + 2 % (docstring)


def _run(module, **overrides):
    return module.run(module.Parameters(**overrides), options=QUIET)


@pytest.fixture(scope="module")
def hemisphere_coarse():
    return _run(hemisphere_nonlinear, divisions=8, force=100.0, load_steps=5)


def test_hemisphere_reference_is_the_sze_table():
    assert hemisphere_nonlinear.sze_reference(400.0) == (4.067, 8.178)
    assert hemisphere_nonlinear.sze_reference(100.0) == pytest.approx((2.596, 3.833))


def test_nonlinear_hemisphere_follows_sze_at_p100(hemisphere_coarse):
    q = hemisphere_coarse.quantities
    assert q["radial_displacement_x_sze"] == pytest.approx(2.596)
    assert q["radial_displacement_y_sze"] == pytest.approx(3.833)
    # converging from below (P2 membrane locking), within the coarse mesh's locking error
    for key in ("radial_displacement_x_error", "radial_displacement_y_error"):
        assert -HEMISPHERE_TOLERANCE < q[key] < 0.0
    # the pushed point moves more than the pulled one, both far less than linear (0.0465 P)
    assert q["radial_displacement_y"] > 1.2 * q["radial_displacement_x"]
    assert q["radial_displacement_y"] < 0.75 * 0.0465 * 100.0
    # the path landed on the table's load levels 20, 40, ..., 100
    assert [s["force"] for s in hemisphere_coarse.steps] == pytest.approx([20, 40, 60, 80, 100])


def test_nonlinear_hemisphere_is_the_studys_coarse_row_and_the_study_converges(hemisphere_coarse):
    """The study's 8-division rows are this computation; its 16-division rows are
    within 5.5 % of Sze's table at every load and closer than the 8-division ones."""
    rows = read_csv(STUDY_CSV)
    coarse = {float(r["force_N"]): r for r in rows if r["divisions"] == "8"}
    for step in hemisphere_coarse.steps:
        row = _row_at(coarse, step["force"])
        assert step["radial_displacement_x"] == pytest.approx(float(row["outward"]), rel=1e-6)
        assert step["radial_displacement_y"] == pytest.approx(float(row["inward"]), rel=1e-6)
    for row in rows:
        errors = [float(row["outward"]) / float(row["outward_sze"]) - 1.0,
                  float(row["inward"]) / float(row["inward_sze"]) - 1.0]
        if row["divisions"] == "16":
            assert all(-0.055 < e < 0.0 for e in errors)
            coarse_row = _row_at(coarse, float(row["force_N"]))
            assert float(coarse_row["outward"]) < float(row["outward"]) < float(row["outward_sze"])
            assert float(coarse_row["inward"]) < float(row["inward"]) < float(row["inward_sze"])


def _row_at(rows: dict[float, dict], force: float) -> dict:
    return rows[min(rows, key=lambda f: abs(f - force))]


def test_nonlinear_hemisphere_two_ranks_give_the_serial_numbers(tmp_path):
    bin_dir = Path(sys.executable).parent
    settings = dict(divisions=4, force=40.0, load_steps=2)
    serial = _run(hemisphere_nonlinear, **settings).quantities
    args = ["run", "hemisphere-nonlinear", "--json", "--out", str(tmp_path)]
    for key, value in settings.items():
        args += ["--set", f"{key}={value}"]
    run = subprocess.run([str(bin_dir / "mpiexec"), "-n", "2", str(bin_dir / "eyemech"), *args],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    parallel = json.loads(run.stdout.strip().splitlines()[-1])
    assert parallel["mpi_size"] == 2
    for key in ("radial_displacement_x", "radial_displacement_y"):
        assert parallel["quantities"][key] == pytest.approx(serial[key], rel=1e-6)


def test_levy_table_interpolation():
    assert shells.levy_center_deflection(95.0) == pytest.approx(0.912)
    assert shells.levy_center_deflection(0.0) == 0.0
    assert np.isnan(shells.levy_center_deflection(500.0))


def test_clamped_plate_at_large_deflection_matches_levy():
    """Levy's plate (sliding clamped edges, ν = 0.316) at Q = q L⁴/(E h⁴) = 95, where
    the centre deflection is 0.912 h (1.42 × less than linear)."""
    base = plate_clamped.Parameters()
    q = 95.0 * base.youngs_modulus * base.thickness ** 4 / base.length ** 4
    result = _run(plate_clamped, divisions=LEVY_DIVISIONS, q=q, kinematics="nonlinear", in_plane="sliding",
                  poisson_ratio=shells.LEVY_POISSON_RATIO, load_steps=1)
    quantities = result.quantities
    assert quantities["center_deflection_levy"] == pytest.approx(0.912 * base.thickness)
    assert abs(quantities["center_deflection_levy_error"]) < LEVY_TOLERANCE
    # the path landed on Levy's load levels 17.79, 38.3, 63.4, 95
    assert [s["load_parameter"] for s in result.steps] == pytest.approx([17.79, 38.3, 63.4, 95.0])


def test_slit_annular_plate_follows_sze_at_a_tenth_of_the_load():
    """Slit annular plate (Sze, Liu & Lo 2004, problem 3.3, table 4 as copied in
    projectchrono/chrono src/demos/python/fea/demo_FEA_shells.py; A inner, B outer as in
    hanzhao2020/PENGoLINS' docs): at q = 0.08 = 0.1 q_max, W_A = 4.277, W_B = 5.876.
    Measured (P2 crossed): 16 × 2 squares −8.9 % / −9.0 %, 32 × 4 −1.6 % / −1.5 %
    (from below, ~5.7× smaller per halving); the test takes the coarse mesh, from
    below and within 12 % (its error plus 3 %). A linear plate would lift 5.2 / 7.2."""
    from eyemech.problems import slit_annular_plate

    result = _run(slit_annular_plate, divisions=16, radial_divisions=2, line_load=0.08, load_steps=4)
    q = result.quantities
    assert (q["deflection_a_sze"], q["deflection_b_sze"]) == pytest.approx((4.277, 5.876))
    for key in ("deflection_a_error", "deflection_b_error"):
        assert -0.12 < q[key] < 0.0
    assert q["deflection_b"] > 1.3 * q["deflection_a"]  # the outer edge lifts more (twist)
    assert slit_annular_plate.sze_reference(0.8) == (13.891, 17.528)


# -- off the defaults: the slit plate's default mesh at every load level; a second thickness and load
THICK_CSV = STUDY_CSV.with_name("shell_hemisphere_thick.csv")
SLIT_CSV = STUDY_CSV.with_name("shell_slit_plate.csv")
SLIT_THICK_CSV = STUDY_CSV.with_name("shell_slit_plate_thick.csv")
NONLINEAR_TOLERANCE = 0.02


def test_nonlinear_hemisphere_second_thickness_and_load():
    """h = 0.2 (R/h = 50) at P = 12,500 (Sze's P = 100 × (0.2/0.04)³), default resolution
    (15 divisions), against the same model's mesh-converged answer: Richardson's value of
    three resolutions × 1.5 (study shell-hemisphere, shell_hemisphere_thick.csv; no
    published curve exists for this thickness). Measured −0.38 % / −0.30 %."""
    reference = read_csv(THICK_CSV)[0]
    params = hemisphere_nonlinear.Parameters(thickness=0.2, force=12_500.0, load_steps=4)
    q = _run(hemisphere_nonlinear, thickness=0.2, force=12_500.0, load_steps=4).quantities
    assert q["divisions"] == params.meridian_divisions == 15
    assert "radial_displacement_x_sze" not in q  # Sze's table is for h = 0.04 alone
    assert q["radial_displacement_x"] == pytest.approx(float(reference["outward_reference"]),
                                                       rel=NONLINEAR_TOLERANCE)
    assert q["radial_displacement_y"] == pytest.approx(float(reference["inward_reference"]),
                                                       rel=NONLINEAR_TOLERANCE)


def test_slit_plate_default_mesh_follows_sze_within_two_percent():
    """The study's rows on the default 48 × 6 mesh at Sze's 11 load levels q = 0.02 … 0.8
    (measured −0.52 … −1.60 % at W_A). Between the levels the table's linear interpolation
    of a curved path is no reference (+3.8 % at q = 0.06)."""
    from eyemech.problems import slit_annular_plate

    levels = [f * slit_annular_plate.SZE_MAX_LINE_LOAD for f in slit_annular_plate.SZE_LOAD_FRACTION]
    rows = [r for r in read_csv(SLIT_CSV) if r["divisions"] == "48"
            and np.isclose(float(r["line_load_N/mm"]), levels, rtol=1e-6).any()]
    assert len(rows) == 11
    for row in rows:
        assert float(row["deflection_a"]) == pytest.approx(float(row["deflection_a_sze"]),
                                                           rel=NONLINEAR_TOLERANCE)
        assert float(row["deflection_b"]) == pytest.approx(float(row["deflection_b_sze"]),
                                                           rel=NONLINEAR_TOLERANCE)


def test_slit_plate_second_thickness_and_load():
    """h = 0.06 at q = 3.2 (Sze's 0.4 × (0.06/0.03)³: half the path, bending-scaled) on the
    default 48 × 6 mesh against the same model's mesh-converged answer (Richardson of 32 × 4,
    48 × 6, 72 × 9: study shell-slit-plate; no published curve for this thickness)."""
    from eyemech.problems import slit_annular_plate

    reference = read_csv(SLIT_THICK_CSV)[0]
    q = _run(slit_annular_plate, thickness=0.06, line_load=3.2, load_steps=8).quantities
    assert "deflection_a_sze" not in q
    assert q["deflection_a"] == pytest.approx(float(reference["deflection_a_reference"]),
                                              rel=NONLINEAR_TOLERANCE)
    assert q["deflection_b"] == pytest.approx(float(reference["deflection_b_reference"]),
                                              rel=NONLINEAR_TOLERANCE)
