"""The scleral-buckling scene on the coarse eye: the physics the paper and the clinic
report, checked qualitatively and for consistency (issue #5)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import CONTACT_RANKS_RTOL, last_json, run_cli
from eyemech.problems import scleral_buckling as sb
from eyemech.problems.context import RunOptions
from eyemech.problems.parameters import ParameterError, build

COARSE = dict(resolution="coarse")


@pytest.fixture(scope="module")
def coarse():
    return sb.run(sb.Parameters(**COARSE), options=RunOptions(fields=False, pictures=False))


def stage(result, number):
    return [s for s in result.steps if s["stage"] == number]


def test_iop_lengthens_the_axis(coarse):
    after = coarse.quantities["after_iop"]
    assert after["iop_mmHg"] == pytest.approx(15.0, rel=1e-9)
    assert after["axial_length_change_mm"] > 0.05


def test_buckling_closes_the_gap_and_raises_the_pressure(coarse):
    steps = stage(coarse, 2)
    travel = [s["buckle_travel_mm"] for s in steps]
    gap = [s["retina_choroid_gap_mean_mm"] for s in steps]
    pressure = [s["iop_mmHg"] for s in steps]
    assert np.all(np.diff(travel) > 0)
    assert np.all(np.diff(gap) < 0), gap            # the gap shortens monotonically
    assert np.all(np.diff(pressure) > 0), pressure  # the stiff liquid resists
    assert pressure[-1] > 15.0 + 1.0
    # the paper: the buckle elongates the optic axis
    assert steps[-1]["axial_length_change_mm"] > coarse.quantities["after_iop"]["axial_length_change_mm"]


def test_liquid_volume_obeys_its_bulk_modulus(coarse):
    # from step 2 on P = P_ini − K ΔV/V_ini: the volume may change only by ΔP/K
    before = coarse.quantities["after_iop"]
    after = coarse.quantities["after_suturing"]
    pressure_rise = (after["iop_mmHg"] - before["iop_mmHg"]) * sb.MMHG
    relative_change = after["cavity_volume_mm3"] / before["cavity_volume_mm3"] - 1
    assert relative_change == pytest.approx(-pressure_rise / 2083.3, rel=1e-3, abs=1e-9)


def test_sutures_shorten_the_axis_and_concentrate_stress(coarse):
    # seed 002 §3.2: in the sewing step the optic axis decreases and the stress
    # concentrates at the sewing points
    buckled, sutured = coarse.quantities["after_buckling"], coarse.quantities["after_suturing"]
    assert sutured["axial_length_mm"] < buckled["axial_length_mm"]
    assert sutured["von_mises_max_MPa"] > buckled["von_mises_max_MPa"]


def test_results_are_finite_and_complete(coarse):
    q = coarse.quantities
    for key in ("axial_length_change_mm", "buckle_indentation_mm", "iop_mmHg",
                "retina_choroid_gap_min_mm", "retina_contact_area_mm2", "tear_closed",
                "von_mises_max_MPa"):
        assert key in q
    assert q["buckle_indentation_mm"] > 0.5 * q["buckle_travel_mm"]


def test_retina_choroid_contact_is_enforced_and_reported(coarse):
    # node-to-surface penalty contact retina (slave) on choroid (master) in the
    # blocked [u, p, P] system; at the default 1 mm travel the coarse retina does
    # not reach the choroid, so no node may be below it
    q = coarse.quantities
    assert q["retina_contact_penalty"] > 0
    for name in ("after_iop", "after_buckling", "after_suturing"):
        assert q[name]["max_penetration_mm"] == 0.0
        assert q[name]["retina_contact_nodes"] == 0


# a thinner detachment and a deeper buckle: the retina reaches the choroid in step 2
CLOSING = dict(resolution="coarse", detachment_height="0.2", indentation="1.3")


@pytest.fixture(scope="module")
def closing():
    params = build(sb.Parameters, CLOSING)
    return sb.run(params, options=RunOptions(fields=False, pictures=False))


def test_retina_lands_on_the_choroid_without_passing_through(closing):
    # the penalty contact holds the retina on the choroid's surface: pressed nodes,
    # a normal gap no deeper than the penalty allows (p/α with p ≤ a few kPa and
    # α = 0.21 MPa/mm is < 1e-3 mm; measured 2e-5 mm), Newton converged
    q = closing.quantities
    after = q["after_suturing"]
    assert after["retina_penalty_contact_area_mm2"] > 0.0
    assert after["retina_pressed_nodes"] >= 1
    assert after["max_penetration_mm"] < 1e-3
    assert after["retina_choroid_gap_nts_min_mm"] > -1e-3
    assert q["after_iop"]["retina_pressed_nodes"] == 0
    assert max(s["newton_iterations"] for s in closing.steps) <= 15


@pytest.mark.mpi
def test_contact_two_ranks_agree(closing, tmp_path):
    args = [f"{k}={v}" for k, v in CLOSING.items()]
    code, out, err = run_cli("run", "scleral-buckling", *sum((["--set", a] for a in args), []),
                             "--out", str(tmp_path), "--json", "--no-pictures", "--no-fields",
                             ranks=2)
    assert code == 0, err
    parallel = last_json(out)["quantities"]["after_suturing"]
    serial = closing.quantities["after_suturing"]
    for key in ("axial_length_change_mm", "iop_mmHg"):
        assert parallel[key] == pytest.approx(serial[key], rel=1e-6, abs=1e-9), key
    for key in ("retina_penalty_contact_area_mm2", "retina_contact_force_N", "max_penetration_mm",
                "retina_choroid_gap_nts_min_mm"):
        assert parallel[key] == pytest.approx(serial[key], rel=CONTACT_RANKS_RTOL, abs=1e-9), key
    for key in ("retina_pressed_nodes", "tear_closed_nts", "tear_closed"):
        assert parallel[key] == serial[key], key


@pytest.mark.parametrize("overrides, key", [
    ({"buckle_clearance": "-0.5"}, "buckle_clearance"),
    ({"suture_width": "20"}, "suture_width"),
    ({"suture_width": "3"}, "suture_width"),
    ({"c_sclera": "0"}, "c_sclera"),
    ({"buckle_position": "40"}, "buckle_position"),
    ({"detachment_height": "-1"}, "detachment_height"),
])
def test_bad_input_is_refused_before_solving(overrides, key):
    with pytest.raises(ParameterError) as info:
        build(sb.Parameters, overrides)
    assert info.value.key == key


def test_too_coarse_for_the_retina_is_refused():
    # a thinner retina needs smaller elements: at the coarse resolution the cells would
    # be 23 times wider than the layer is thick
    with pytest.raises(ParameterError, match="too coarse") as info:
        build(sb.Parameters, {"resolution": "coarse", "retina_thickness": "0.1"})
    assert info.value.key == "resolution"


@pytest.mark.mpi
def test_two_ranks_agree(coarse, tmp_path):
    code, out, err = run_cli("run", "scleral-buckling", "--set", "resolution=coarse", "--out",
                             str(tmp_path), "--json", "--no-pictures", "--no-fields", ranks=2)
    assert code == 0, err
    parallel = last_json(out)["quantities"]
    for key in ("axial_length_change_mm", "iop_mmHg", "buckle_indentation_mm",
                "retina_choroid_gap_mean_mm", "von_mises_max_MPa", "retina_contact_nodes"):
        assert parallel[key] == pytest.approx(coarse.quantities[key], rel=1e-6, abs=1e-9), key
    for key in ("max_penetration_mm", "retina_penalty_contact_area_mm2"):
        assert parallel[key] == pytest.approx(coarse.quantities[key], rel=CONTACT_RANKS_RTOL,
                                              abs=1e-9), key
