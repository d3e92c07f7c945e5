"""The pigment epithelium's pump in the settling (``subretinal_pump_mmHg``,
docs/scleral_buckling.md, "The pigment epithelium's pump"): the subretinal fluid's pressure
held below the vitreous' once the IOP is back, the load the detached flap has nowhere else.
On the coarse eye with the locking-free retina, whose rim is open after suturing, it
closes the settled rim and leaves the eye's shape as it was."""

from __future__ import annotations

import json
import os
import subprocess

import pytest
from conftest import BIN, run_cli

from eyemech.problems import scleral_buckling as sb
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError, build

PUMP = 1.0  # mmHg
LOCKING_FREE = dict(resolution="coarse", retina_incompatible_modes=True)


@pytest.fixture(scope="module")
def pumped(tmp_path_factory):
    params = sb.Parameters(**LOCKING_FREE, subretinal_pump_mmHg=PUMP)
    return sb.run(params, out=tmp_path_factory.mktemp("pump"),
                  options=RunOptions(pictures=False, fields=False))


def test_the_pump_closes_the_settled_rim_and_leaves_the_eye_as_it_was(pumped):
    """Without the pump this eye's rim is 0.136 / 0.083 / 0.030 mm after buckling /
    suturing / settled and its settled ΔAL / ΔSE +0.66 mm / -2.20 D
    (docs/scleral_buckling.md, "A retina not locked in bending", measured 6 Dec 2026,
    printed to 3 digits). The pump acts from the settling on: the acute rims are those, the
    settled one is on the choroid (measured -0.001 mm: the penalty's penetration), and the
    eye's shape moves by less than the printed digits."""
    q = pumped.quantities
    assert q["after_buckling"]["tear_rim_gap_max_mm"] == pytest.approx(0.136, abs=5e-4)
    assert q["after_suturing"]["tear_rim_gap_max_mm"] == pytest.approx(0.083, abs=5e-4)
    settled = q["after_settling"]
    assert abs(settled["tear_rim_gap_max_mm"]) < 0.005 and settled["tear_closed_nts"]
    assert settled["axial_length_change_mm"] == pytest.approx(0.66, abs=0.01)
    assert settled["refraction_change_D"] == pytest.approx(-2.20, abs=0.01)


def test_the_deficit_follows_the_iops_return(pumped):
    """0 through the operation, then ramped with P from the acute pressure (79 mmHg, the
    vent's limit) to PUMP at 15 mmHg: deficit / PUMP = (79 - IOP) / (79 - 15) at every
    settling step."""
    for step in pumped.steps:
        deficit = step["subretinal_pump_deficit_mmHg"]
        if step["stage"] < 4:
            assert deficit == 0.0
        else:
            assert deficit == pytest.approx(PUMP * (79.0 - step["iop_mmHg"]) / (79.0 - 15.0),
                                            rel=1e-9, abs=1e-12)
    assert pumped.quantities["after_settling"]["subretinal_pump_deficit_mmHg"] == pytest.approx(PUMP)


def test_a_pump_without_a_detachment_or_a_settling_is_bad_input(tmp_path):
    for bad in ({"subretinal_pump_mmHg": 1.0, "detachment_height": 0.0},  # nothing to pump
                {"subretinal_pump_mmHg": 1.0, "settle": False},  # no step 4 to pump in
                {"subretinal_pump_mmHg": -1.0}):  # a negative deficit
        with pytest.raises(ParameterError, match="subretinal_pump_mmHg"):
            build(sb.Parameters, bad)
    code, _out, err = run_cli("run", "scleral-buckling", "--set", "subretinal_pump_mmHg=2",
                              "--set", "settle=false", "--out", str(tmp_path / "run"))
    assert code == 2, err
    assert "subretinal_pump_mmHg" in err.strip().splitlines()[-1] and "Traceback" not in err
    assert not (tmp_path / "run" / "results.json").exists()


def test_a_run_killed_while_the_pump_acts_resumes_to_the_same_numbers(pumped, tmp_path):
    """The pump's deficit and its span are in the checkpoint: killed in Newton of step 36
    (the fourth settling load step) and resumed from step 35's checkpoint, the run takes
    the uninterrupted run's deficits and ends on its settled numbers. Not bitwise: the
    locking-free eye resumed inside the settling differs from the uninterrupted run by
    round-off without the pump too (here at most 3e-12 relative; with the Q1P0 retina,
    killed at the same step, the pump's resumed steps are bitwise the uninterrupted run's
    up to the step where both stall)."""
    settings = [a for k, v in {**LOCKING_FREE, "subretinal_pump_mmHg": PUMP}.items()
                for a in ("--set", f"{k}={v}")]
    quiet = ("--no-fields", "--no-pictures", "--quiet")
    env = dict(os.environ, EYEMECH_TEST_KILL="step:36")
    killed = subprocess.run([str(BIN / "eyemech"), "run",
                             "scleral-buckling", *settings, "--out", str(tmp_path),
                             "--checkpoint-every", "1", *quiet],
                            capture_output=True, text=True, timeout=900, env=env)
    assert killed.returncode != 0 and (tmp_path / "checkpoints" / "ckpt_000035").is_dir()
    code, _, err = run_cli("run", "scleral-buckling", "--resume", str(tmp_path), *quiet)
    assert code == 0, err
    resumed = json.loads((tmp_path / "results.json").read_text())
    assert resumed["checkpoints"]["resumed_from"].endswith("ckpt_000035")
    assert resumed["steps"][34]["stage"] == 4 and resumed["steps"][34]["subretinal_pump_deficit_mmHg"] > 0
    assert [s["subretinal_pump_deficit_mmHg"] for s in resumed["steps"]] == \
        [s["subretinal_pump_deficit_mmHg"] for s in pumped.steps]
    whole = pumped.quantities["after_settling"]
    for key, value in resumed["quantities"]["after_settling"].items():
        assert value == (pytest.approx(whole[key], rel=1e-8, abs=1e-12)
                         if isinstance(value, float) else whole[key]), key
