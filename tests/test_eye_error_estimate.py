"""The eye's estimate of its discretisation error (``error_estimate=true`` on
scleral-buckling, problems/scleral_buckling/error_estimate.py): Roache's grid convergence
index against hand numbers, the ladder of meshes, the rim's verdict, and the coarse eye
run as a user runs it (pictures and fields on), whose second solve is the default mesh.

The module's one run costs a coarse eye and a default one (≈ 60 s on an idle 2-core VM,
more under load): the coarse eye is the smallest mesh that holds the retina, and its
estimate needs the next rung of the ladder. Every test below reads that run."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from conftest import run_cli

from eyemech.problems import scleral_buckling as sb
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.error_estimate import grid_convergence_index
from eyemech.problems.run.parameters import ParameterError, build
from eyemech.problems.scleral_buckling import error_estimate as ee
from eyemech.problems.scleral_buckling.measures import rim_margin, rim_verdict

RECORDED = Path(__file__).parent / "data" / "scleral_buckling_coarse.json"
STAGES = ("after_iop", "after_buckling", "after_suturing", "after_settling")


def test_grid_convergence_index_against_hand_numbers():
    # settled ΔAL 0.41 mm on the finer, 0.45 mm on the coarser mesh, r = 1.5, Fs = 3:
    # p = 1: 3 × 0.04 / 0.5 = 0.24 mm about the finer value, × 1.5 = 0.36 about the coarser;
    # p = 2: 3 × 0.04 / 1.25 = 0.096 mm
    assert grid_convergence_index(0.41, 0.45, 1.5, 1.0) == pytest.approx(0.24)
    assert grid_convergence_index(0.41, 0.45, 1.5, 1.0, of="coarse") == pytest.approx(0.36)
    assert grid_convergence_index(0.45, 0.41, 1.5, 2.0) == pytest.approx(0.096)
    # r = 2, p = 2, Fs = 1.25 (three grids): 1.25 × 0.3 / 3
    assert grid_convergence_index(1.3, 1.0, 2.0, 2.0, safety=1.25) == pytest.approx(0.125)
    with pytest.raises(ValueError):
        grid_convergence_index(1.0, 1.1, 1.0, 1.0)
    with pytest.raises(ValueError):
        grid_convergence_index(1.0, 1.1, 2.0, 1.0, of="middle")


def test_the_ladder_goes_to_the_next_coarser_mesh_or_from_the_coarsest_one_finer():
    cases = {(): ("coarse", False, 1.5), (("resolution", "coarse"),): ("default", True, 1.5),
             (("resolution", "paper"),): ("n20", False, 1.3),
             (("cells_per_bending_length", 2.5),): ("default", False, 20 / 12)}
    for settings, (name, finer, ratio) in cases.items():
        params = sb.Parameters(error_estimate=True, **dict(settings))
        other = ee.companion(params)
        assert (other.mesh.name, other.finer) == (name, finer), settings
        assert other.ratio(params) == pytest.approx(ratio), settings
        assert other.params.error_estimate is False
        assert other.params.cells_per_edge == other.mesh.cells_per_edge
    # the physics is the run's: only the mesh differs
    other = ee.companion(sb.Parameters(error_estimate=True, indentation=1.5, buckle_position=12.5,
                                       buckle_control="travel")).params
    assert (other.indentation, other.buckle_position) == (1.5, 12.5)


def test_the_verdict_reads_the_margin_against_the_estimate():
    tolerance = sb.Parameters().tear_closure_tolerance
    assert rim_margin(0.036, tolerance) == pytest.approx(0.014)  # closed by 0.014 mm
    assert rim_margin(0.324, tolerance) == pytest.approx(-0.274)  # open by 0.274 mm
    assert rim_verdict(0.014) == "closed" and rim_verdict(-0.274) == "open"
    assert rim_verdict(0.0) == "open"  # closed means below the tolerance (tear_closed_nts)
    assert rim_verdict(0.014, 0.05) == "uncertain" and rim_verdict(-0.014, 0.05) == "uncertain"
    assert rim_verdict(0.014, 0.014) == "uncertain"  # |margin| <= estimate
    assert rim_verdict(0.06, 0.05) == "closed" and rim_verdict(-0.06, 0.05) == "open"
    assert rim_verdict(float("nan"), 0.05) is None  # no rim to judge


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("eye_error_estimate")


@pytest.fixture(scope="module")
def estimated(folder):
    """The coarse eye with error_estimate=true as a user runs it: pictures and fields on."""
    return sb.run(sb.Parameters(resolution="coarse", error_estimate=True), out=folder, options=RunOptions())


def test_every_stage_carries_its_estimates_and_verdict(estimated):
    q = estimated.quantities
    assert (q["error_estimate_mesh"], q["error_estimate_cells"]) == ("default", 1762)
    assert q["error_estimate_ratio"] == pytest.approx(1.5)
    assert (q["error_estimate_order"], q["error_estimate_safety_factor"]) == (ee.ORDER, 3.0)
    assert "finer" in q["error_estimate_note"]  # a coarse run says its second mesh is finer
    tolerance = estimated.parameters["tear_closure_tolerance"]
    for group in (q, *(q[stage] for stage in STAGES)):
        for name in ee.QUANTITIES:
            assert math.isfinite(group[f"{name}_error_estimate"]), name
        margin, band = group["tear_rim_margin_mm"], group["tear_rim_gap_max_mm_error_estimate"]
        assert margin == pytest.approx(tolerance - group["tear_rim_gap_max_mm"], abs=1e-15)
        assert group["tear_verdict"] == ("uncertain" if abs(margin) <= band else
                                         "closed" if margin > 0 else "open")
        assert (group["tear_verdict"] == "closed") <= group["tear_closed_nts"]
    for stage in STAGES[1:]:  # the changes are read from the end of step 1, where they are 0
        assert q[stage]["axial_length_change_mm_error_estimate"] > 0.0
        assert q[stage]["refraction_change_D_error_estimate"] > 0.0
        assert q[stage]["tear_rim_gap_max_mm_error_estimate"] > 0.0
    assert q["after_iop"]["tear_verdict"] == "open"  # 0.74 mm wide before surgery
    # the settled top level is the last stage's
    settled = q["after_settling"]
    assert q["axial_length_change_mm_error_estimate"] == settled["axial_length_change_mm_error_estimate"]


def test_the_estimate_is_the_coarse_mesh_band_against_the_default_mesh(estimated):
    """The coarse run's band is r^p/(r^p − 1) Fs |q_coarse − q_default| = 9 |Δ| (r = 1.5,
    p = 1, Fs = 3), with the default mesh's settled ΔAL +0.56000 mm and ΔSE −0.89785 D
    (measured by `eyemech run scleral-buckling --json`, 8 Dec 2026; docs/scleral_buckling.md,
    "The defaults", to two digits; the default mesh's run repeats them to
    1e-4)."""
    settled = estimated.quantities["after_settling"]
    assert settled["axial_length_change_mm_error_estimate"] == pytest.approx(
        9.0 * abs(settled["axial_length_change_mm"] - 0.56000), abs=9e-4)
    assert settled["refraction_change_D_error_estimate"] == pytest.approx(
        9.0 * abs(settled["refraction_change_D"] + 0.89785), abs=9e-4)


def test_the_estimate_leaves_the_runs_own_numbers_and_draws_the_margin(estimated, folder):
    """The second solve changes none of the run's numbers (tests/data/scleral_buckling_coarse.json,
    the coarse eye without the estimate) and writes no fields or pictures of its own; the
    section's title states the margin."""
    recorded = json.loads(RECORDED.read_text())["quantities"]
    for stage in STAGES:
        for key in ("axial_length_change_mm", "refraction_change_D", "tear_rim_gap_max_mm", "iop_mmHg"):
            assert estimated.quantities[stage][key] == pytest.approx(recorded[stage][key], rel=1e-10,
                                                                     abs=1e-12), (stage, key)
    assert len(estimated.pictures) == 2 * len(STAGES) and "state.pvd" in estimated.fields
    assert sorted(p.name for p in folder.glob("*.png")) == sorted(estimated.pictures)
    assert "error_estimate" in estimated.timings
    from eyemech.problems.run.output import picture_record

    sutured = estimated.quantities["after_suturing"]
    caption = picture_record(folder / "step3_suturing_section.png")["caption"]
    gap, margin = sutured["tear_rim_gap_max_mm"], sutured["tear_rim_margin_mm"]
    assert f"rim gap {gap:.3f} mm (closed by {margin:.3f} mm)" in caption


def test_the_headline_reads_the_margin_against_its_band(estimated):
    """With the estimate, the run's first lines (``Scene.headline``) give each verdict
    (closed / open / uncertain) with its margin ± the rim gap's band, and no longer ask
    for the estimate."""
    tear = sb.SCENE.headline(estimated.quantities)[0]
    for stage in ("suturing", "settling"):
        group = estimated.quantities[f"after_{stage}"]
        assert (f"{group['tear_verdict']} after {stage} (margin {group['tear_rim_margin_mm']:+.3f} "
                f"± {group['tear_rim_gap_max_mm_error_estimate']:.3f} mm)") in tear
    assert "error_estimate=true" not in tear


def test_a_second_mesh_the_scene_would_refuse_is_bad_input(tmp_path):
    # the default mesh's companion, the coarse eye, cannot hold a 0.15 mm retina (2.26 mm
    # elements: aspect ratio 15 > 12); the default mesh alone can (10)
    build(sb.Parameters, {"retina_thickness": 0.15})
    with pytest.raises(ParameterError, match="error_estimate.*coarse mesh.*retina"):
        build(sb.Parameters, {"retina_thickness": 0.15, "error_estimate": True})
    # from the command line: exit 2 before anything is meshed (the coarse eye's companion,
    # the default mesh, has 1,762 cells)
    code, _out, err = run_cli("run", "scleral-buckling", "--set", "resolution=coarse", "--set",
                              "error_estimate=true", "--set", "max_cells=1000", "--no-pictures",
                              "--no-fields", "--out", str(tmp_path / "run"))
    assert code == 2, err
    last = err.strip().splitlines()[-1]
    assert "error_estimate" in last and "default mesh" in last and "max_cells" in last
    assert "Traceback" not in err and not (tmp_path / "run" / "results.json").exists()
