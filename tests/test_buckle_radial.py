"""The radial tire (tire_orientation = radial) on the coarse eye: it
indents the sclera under the tear along its meridian, lengthens the eye less than an
encircling band, its sutured footprint does not slide, and bad radial buckles are
refused before any solve (docs/scleral_buckling.md, Radial tire)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import run_cli

from eyemech.forms.buckle import Buckle, BuckleShape
from eyemech.problems import scleral_buckling as sb
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError, build

QUIET = RunOptions(fields=False, pictures=False)
# 1 mm of travel held through step 3 (suture_model = bites: with the loop a tire
# without a band rises to the sutures' balance, docs/scleral_buckling.md), so that the
# comparison with the band is of the buckles at equal travel; centred 12.5 mm behind the
# limbus, where the numbers below were measured
RADIAL = dict(buckle="segmental", tire_orientation="radial", suture_azimuths="0",
              indentation="1.0", suture_model="bites", settle="false", buckle_position="12.5")


# measured on the paper's operation (Table 1's clamped eye, rigid travel)
PAPER = sb.PAPER_SETTINGS


def _run(**overrides):
    return sb.run(build(sb.Parameters, {"resolution": "coarse", **PAPER, **overrides}), options=QUIET)


@pytest.fixture(scope="module")
def radial():
    result = _run(**RADIAL)
    assert result.status == "ok", result.message
    return result.quantities


def test_radial_tire_indents_the_tears_meridian_by_its_travel(radial):
    # the probe on the tear's meridian under the tire's centre moves towards the tire's
    # axis by the travel less the 0.05 mm clearance (measured 0.903 mm after buckling,
    # 0.974 mm after suturing, of 1.0; 1.40 of 1.5 mm of travel); deeper
    # than the travel only by the penalty's penetration, hundredths of a mm. A step that
    # carries the sclera through the tire read 1.095 (Stepping.depth_limit refuses it:
    # test_depth_through_the_radial_tire_reads_past_its_far_face)
    for stage in ("after_buckling", "after_suturing"):
        q = radial[stage]
        assert q["buckle_travel_mm"] == q["tire_travel_mm"] == 1.0
        assert 0.85 < q["buckle_indentation_mm"] < 1.0, stage


def test_radial_tire_lengthens_the_eye_less_than_an_encircling_band(radial):
    # an encircling band squeezes the whole equator and lengthens the eye (clinical
    # series: ~+0.8 mm); a radial element indents one meridian only (measured after
    # suturing at 1 mm travel: radial +0.124 mm, +0.19 D; encircling +0.726 mm, −2.77 D)
    band = _run(buckle="encircling", indentation="1.0", buckle_position="12.5", settle="false")
    assert band.status == "ok", band.message
    encircling = band.quantities["after_suturing"]
    radial_change = radial["after_suturing"]["axial_length_change_mm"]
    assert encircling["axial_length_change_mm"] > 0.3
    assert abs(radial_change) < 0.5 * encircling["axial_length_change_mm"]
    assert radial["after_suturing"]["refraction_change_D"] > encircling["refraction_change_D"]


def test_radial_tires_sutured_footprint_does_not_slide(radial):
    # frictionless (no sutures, to the end of step 2: with the sutures' pull the
    # frictionless slide flips from step to step and step 3 stalls at s = 2.8), the
    # sclera slides forward along the meridian under the tire (measured +0.786 mm mean,
    # 1.139 mm max at 1 mm of travel; ≈ 9 s). Tied, it slips only by the tie penalty's
    # compliance, as under the circumferential tire (tests/test_buckle_types.py: bound
    # 0.05 mm); the slip is measured about the tire's own axis (x), across and along the
    # meridian (measured 0.021 / 0.018 mm max after buckling / suturing, mean forward
    # slip along the meridian −0.0005 / −0.0013 mm; +0.0104 through the tire)
    loose = _run(**{**RADIAL, "buckle_attachment": "frictionless", "suture_force": "0",
                    "frictionless_slip_stiffness": "0"})   # the slide itself, without the spring
    assert loose.status == "ok", loose.message
    slid = loose.quantities["after_buckling"]
    assert slid["buckle_slip_axial_mean_mm"] > 0.3
    assert slid["buckle_slip_max_mm"] > 0.5
    for stage in ("after_buckling", "after_suturing"):
        q = radial[stage]
        assert q["buckle_footprint_nodes"] >= 8   # 3.5 × 12 mm of the half tire (measured 10)
        assert q["buckle_slip_max_mm"] < 0.05, stage
        assert abs(q["buckle_slip_axial_mean_mm"]) < 0.01, stage


@pytest.mark.parametrize("overrides, key", [
    ({"tire_orientation": "radial"}, "tire_orientation"),  # with the band (the default buckle)
    ({"tire_orientation": "radial", "buckle": "encircling"}, "tire_orientation"),
    ({"tire_orientation": "radial", "buckle": "segmental", "suture_azimuths": "0,30"},
     "suture_azimuths"),                                    # sutures off its meridian
    ({**RADIAL, "tire_length": "28"}, "tire_length"),      # the meridian is 27.0 mm
    ({**RADIAL, "tire_length": "0"}, "tire_length"),
    ({**RADIAL, "buckle_position": "5"}, "buckle_position"),    # its front end past the limbus
    ({**RADIAL, "buckle_position": "22"}, "buckle_position"),   # its back end on the nerve
    ({**RADIAL, "tire_arc_deg": "60"}, "tire_arc_deg"),    # an arc means a circumferential tire
    ({"tire_length": "10"}, "tire_length"),                # a length means a radial tire
])
def test_bad_radial_tires_are_refused(overrides, key):
    with pytest.raises(ParameterError) as info:
        build(sb.Parameters, overrides)
    assert info.value.key == key


@pytest.mark.parametrize("settings, key", [
    (["tire_orientation=radial"], "tire_orientation"),
    (["tire_orientation=radial", "buckle=segmental", "suture_azimuths=0", "tire_length=30"],
     "tire_length"),
    (["tire_orientation=radial", "buckle=segmental", "suture_azimuths=0", "buckle_position=25"],
     "buckle_position"),
])
def test_bad_radial_tire_exits_2(tmp_path, settings, key):
    arguments = [a for s in settings for a in ("--set", s)]
    code, _, err = run_cli("run", "scleral-buckling", *arguments, "--out", str(tmp_path))
    assert code == 2
    assert key in err


def test_radial_tire_of_new_sizes_compiles_nothing_after_its_first_case(compilations):
    """A planning sweep over the radial tire: its length, width, height and centre
    (the wedge's half angle, the profile and the polar angle β₀ are Constants) and the
    suture width (the bites' centres) are new in the second case; a literal among them
    would compile the eye's residual and Jacobian blocks again (as
    tests/test_compile_once.py for the circumferential buckle). ≈ 10 s a case."""
    import random

    def case() -> sb.Parameters:
        return build(sb.Parameters, {
            "resolution": "coarse", **RADIAL, "indentation": "0.75",
            "tire_length": str(10.0 + 2.0 * random.random()),
            "tire_width": str(6.0 + random.random()), "tire_height": str(0.8 + 0.4 * random.random()),
            "buckle_position": str(12.0 + random.random()), "suture_width": str(8.0 + random.random())})

    sb.run(case(), options=QUIET)
    first = len(compilations)
    sb.run(case(), options=QUIET)
    assert compilations[first:] == []


def test_depth_through_the_radial_tire_reads_past_its_far_face():
    """Buckle.depth_through, the measure by which a load step that carries the sclera
    through the tire is refused (problems/solve/driver.py, Stepping.depth_limit): beyond
    the contact face over the tire's span as a fraction of its height, also past its far
    face, where the penalty's signed distance is positive again (the coarse eye's node at
    80° converged 1.3 mm beyond the 1 mm tire's far face with the secant's start)."""
    shape = BuckleShape(kind="segmental", orientation="radial", tire_arc_deg=360.0)
    buckle = Buckle(shape, axial_position=0.0, base_radius=12.0, indentation=1.0,
                    polar_angle=math.radians(90.0))
    # the face at 12 − 1 = 11 mm from the x axis; the corners (0.3 mm) raise it at the edges
    points = np.array([[0.0, 11.0, 0.0], [0.0, 11.5, 0.0], [0.0, 13.3, 0.0],
                       [3.5, 11.5, 0.0], [4.0, 11.5, 0.0], [0.0, 10.0, 0.0],
                       [0.0, 0.0, 11.5]])  # the last: 90° from the tire's centre, off its arc
    depth = buckle.depth_through(points, tire_travel=1.0)
    assert depth[:4] == pytest.approx([0.0, 0.5, 2.3, 0.2])
    assert depth[5] == pytest.approx(-1.0)
    assert np.isneginf(depth[[4, 6]]).all()
