"""Buckles as surgeons place them, on the coarse eye: the sutured buckle
does not slide, a segmental tire lengthens the eye less than an encircling band, deep
buckles and wide bands run to the end, bad buckles are refused."""

from __future__ import annotations

import pytest
from conftest import run_cli

from eyemech.problems import scleral_buckling as sb
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError, build

QUIET = RunOptions(fields=False, pictures=False)


# the buckle kinds compared on the paper's operation (Table 1's clamped eye, rigid travel)
PAPER = sb.PAPER_SETTINGS


def _run(**overrides):
    return sb.run(build(sb.Parameters, {"resolution": "coarse", **PAPER, **overrides}), options=QUIET)


# 1 mm of travel and 0.05 N: the frictionless buckle stalls beyond ~1.4 mm (the slide
# accelerates), so the comparison is made where both converge: centred on the tear
# (11.5 mm). 12.5 mm behind the limbus one of the two stalled at the start of step 3
# (residual flat at 4.9e-4)
SLIDE = dict(tire_arc_deg="360", indentation="1.0", suture_force="0.05", buckle_position="11.5")


@pytest.fixture(scope="module")
def frictionless():
    # without the regularising spring: the slide itself, where it converges
    return _run(buckle_attachment="frictionless", frictionless_slip_stiffness="0", **SLIDE)


@pytest.fixture(scope="module")
def sutured():
    return _run(**SLIDE)


def test_sutured_buckle_does_not_slide(frictionless, sutured):
    # Frictionless, the sclera slides forward along the buckle (the eye squeezed out
    # through the band; measured +0.67 mm mean axial slip at 1 mm of travel). Tied, it
    # slips only by the tie penalty's compliance: traction / α with α = 6.6 MPa/mm and
    # tangential tractions of ~0.1 MPa give ~0.02 mm (measured 0.020 mm). Bound: 0.05 mm,
    # under a tenth of the frictionless slide and of the 0.25 mm tangential resolution
    # a surgeon could see.
    loose = frictionless.quantities["after_buckling"]
    tied = sutured.quantities["after_buckling"]
    assert loose["buckle_slip_axial_mean_mm"] > 0.3
    assert loose["buckle_slip_max_mm"] > 0.5
    for stage in ("after_buckling", "after_suturing"):
        q = sutured.quantities[stage]
        assert q["buckle_footprint_nodes"] >= 20
        assert q["buckle_slip_max_mm"] < 0.05, stage
        assert abs(q["buckle_slip_axial_mean_mm"]) < 0.01, stage
    # the slide is what made the frictionless eye long: tied, the axis grows less
    assert tied["axial_length_change_mm"] < loose["axial_length_change_mm"]


def test_frictionless_buckle_runs_to_the_end_and_slides():
    # 12.5 mm behind the limbus, 1 mm of travel, the 90° tire and 0.2 N sutures: without
    # the spring Newton stalls in step 2 at 0.98 mm of travel (residual flat at 3.4e-5, the
    # slide's stiffness near zero: docs/scleral_buckling.md, "The frictionless buckle's
    # spring"). With its default 0.003 MPa/mm the run ends (measured 22 Newton solves,
    # 2 cut back, 79 factorisations) and the sclera still slides forward by +0.14 mm on
    # average (0.23 mm at most) after buckling, 0.45 mm at most settled: above the 0.05 mm
    # the sutured buckle is held to (test_sutured_buckle_does_not_slide, measured 0.020 mm).
    result = _run(buckle_attachment="frictionless", indentation="1.0", buckle_position="12.5")
    assert result.status == "ok"
    buckled = result.quantities["after_buckling"]
    assert buckled["buckle_slip_axial_mean_mm"] > 0.1
    assert buckled["buckle_slip_max_mm"] > 0.15
    assert result.quantities["after_settling"]["buckle_slip_max_mm"] > 0.3


def test_a_failed_frictionless_run_names_the_slide():
    # the note appended to the solver's message (exit 3) when a frictionless run fails; the
    # numbers are those of the spring-free 12.5 mm run stalled in step 2 (measured)
    params = build(sb.Parameters, {"buckle_attachment": "frictionless",
                                   "frictionless_slip_stiffness": "0"})
    note = sb.slide_note({"buckle_slip_axial_mean_mm": 0.635, "buckle_slip_max_mm": 0.806}, params)
    assert "slid +0.635 mm forward" in note and "0.806 mm at most" in note
    assert "frictionless_slip_stiffness = 0 MPa/mm" in note
    assert "near-zero-stiffness" in sb.slide_note({}, params)


def test_segmental_buckle_lengthens_the_eye_less_than_an_encircling_one():
    # clinical series: encircling bands lengthen the eye (~+0.8 mm), segmental buckles
    # change the axial length little; the same 1 mm travel of a 7 mm tire over 90°
    # against a 2.5 mm band all round. The tire keeps that travel through step 3
    # (suture_model = bites): with the loop a tire without a band sinks or rises to the
    # sutures' balance (tests/test_tear_closure.py), and the comparison is of the buckles
    segmental = _run(buckle="segmental", suture_azimuths="0", indentation="1.0",
                     buckle_position="12.5", suture_model="bites",
                     settle="false").quantities["after_suturing"]
    encircling = _run(buckle="encircling", indentation="1.0", buckle_position="12.5",
                      settle="false").quantities["after_suturing"]
    assert segmental["buckle_travel_mm"] == encircling["buckle_travel_mm"] == 1.0
    assert 0 < segmental["axial_length_change_mm"] < 0.5 * encircling["axial_length_change_mm"]
    assert segmental["refraction_change_D"] > encircling["refraction_change_D"]  # less myopic


@pytest.mark.parametrize("overrides", [
    # 2.5 mm: the plain penalty kink leaves Newton cycling at a 4e-6 residual late in
    # step 3 (0.2 N); the kink rounded over 0.02 mm (a stand-off ≤ 0.02 mm) runs through
    {"indentation": "2.5", "settle": "false", "contact_smoothing": "0.02"},
    {"buckle": "encircling", "band_width": "4", "suture_width": "8", "settle": "false"},
])
def test_realistic_buckles_run_to_the_end(overrides):
    result = _run(**overrides)
    assert result.status == "ok"
    q = result.quantities["after_suturing"]
    assert q["buckle_travel_mm"] == pytest.approx(
        float(overrides.get("indentation", sb.Parameters().indentation)))
    assert q["buckle_indentation_mm"] > 0.8 * q["buckle_travel_mm"]
    assert q["buckle_slip_max_mm"] < 0.05


@pytest.mark.parametrize("overrides, key", [
    ({"tire_arc_deg": "0"}, "tire_arc_deg"),
    ({"tire_arc_deg": "400"}, "tire_arc_deg"),
    ({"buckle": "segmental", "suture_azimuths": "0,90"}, "suture_azimuths"),  # 90°: off the tire
    ({"buckle": "encircling", "suture_width": "2"}, "suture_width"),
    ({"buckle": "rubber-band"}, "buckle"),
    ({"buckle_position": "45"}, "buckle_position"),    # the buckle off the eye
    ({"indentation": "12"}, "indentation"),            # deeper than the sclera's radius
    ({"frictionless_slip_stiffness": "0"}, "frictionless_slip_stiffness"),  # sutured: unused
    ({"buckle_attachment": "frictionless", "frictionless_slip_stiffness": "-1"},
     "frictionless_slip_stiffness"),
])
def test_bad_buckles_are_refused(overrides, key):
    with pytest.raises(ParameterError) as info:
        build(sb.Parameters, overrides)
    assert info.value.key == key


@pytest.mark.parametrize("setting, key", [
    ("tire_arc_deg=0", "tire_arc_deg"),
    ("tire_arc_deg=400", "tire_arc_deg"),
    ("buckle_position=45", "buckle_position"),   # the tire off the eye (behind the optic nerve)
    ("indentation=12", "indentation"),           # deeper than the sclera's 11.5 mm radius
])
def test_bad_buckle_exits_2(tmp_path, setting, key):
    # one clear error naming the parameter, before any solve (drainage: tests/test_drainage.py)
    code, _, err = run_cli("run", "scleral-buckling", "--set", setting, "--out", str(tmp_path))
    assert code == 2
    assert key in err


@pytest.mark.parametrize("overrides, meridians", [
    ({}, (0.0, 90.0, 180.0)),                                         # band and tire
    ({"buckle": "encircling"}, (0.0, 90.0, 180.0)),
    ({"buckle": "segmental"}, (0.0, 36.0)),                           # 90° tire: ±45°
    ({"buckle": "segmental", "tire_arc_deg": "60"}, (0.0, 24.0)),
    ({"buckle": "segmental", "tire_orientation": "radial"}, (0.0,)),
    ({"buckle": "segmental", "suture_azimuths": "0,20"}, (0.0, 20.0)),  # as set
])
def test_the_sutures_follow_the_buckle_chosen(overrides, meridians):
    """Without suture_azimuths the sutures go where the chosen buckle is: every meridian
    they are given lies on an element of that buckle (the validation refuses one that
    does not), so `--set buckle=segmental` alone is a valid operation."""
    params = build(sb.Parameters, overrides)
    assert params.suture_meridians() == meridians
    shape = params.buckle_shape()
    assert all(shape.element_at(a) is not None for a in meridians)


def test_a_segmental_tire_alone_runs_with_its_own_sutures():
    """`eyemech run scleral-buckling --set buckle=segmental` (coarse, to the end of
    suturing): two sutures across the 90° tire, 0 and 36° from the tear, each pulling
    0.2 N at the end of step 3."""
    result = _run(buckle="segmental", settle="false")
    after = result.quantities["after_suturing"]
    assert result.status == "ok" and after["suture_force_N"] == pytest.approx(0.2)
    assert after["buckle_travel_mm"] > 0
