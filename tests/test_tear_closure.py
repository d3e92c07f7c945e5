"""The force-driven tire on the coarse eye: a suture's loop over the tire pushes it in
until the sclera's contact force balances the pull, and its travel grows with the pull.
Tear closure after suturing at the defaults is checked by
``test_scleral_buckling.test_the_tear_is_closed_after_suturing_on_the_coarse_eye`` and
``::test_the_tear_closes_after_suturing_on_the_default_mesh``; drainage's refusal by
``test_drainage``."""

from __future__ import annotations

import pytest

from eyemech.problems import scleral_buckling as sb
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import build

QUIET = RunOptions(fields=False, pictures=False)

# a tire alone with one suture over it, pressed 0.2 mm in step 2 (0.15 mm past the
# clearance): the sutures' 0.3 N then carry it deeper, with no band to lean on. The
# reference stepping (no predictor, full Newton, load steps sized by iterations) gives
# step 3 ten load steps to follow the travel by; the budget's stepping takes two there
REFERENCE_STEPPING = dict(predictor="none", jacobian_reuse="0", buckle_step="0.25",
                          step_effort="iterations", hard_step_effort="0")
# the paper's operation (Table 1's clamped eye), where the numbers below were measured
PAPER = sb.PAPER_SETTINGS
SEWN = dict(resolution="coarse", buckle="segmental", suture_azimuths="0", indentation="0.2",
            suture_force="0.3", settle="false", buckle_position="12.5", **REFERENCE_STEPPING,
            **PAPER)


@pytest.fixture(scope="module")
def sewn():
    return sb.run(build(sb.Parameters, SEWN), options=QUIET)


def test_sutures_drive_the_tire_until_the_sclera_balances_them(sewn):
    steps = [s for s in sewn.steps if s["stage"] == 3]
    force = [s["suture_force_N"] for s in steps]
    travel = [s["tire_travel_mm"] for s in steps]
    assert len(steps) >= 2
    # the tire goes deeper with the pull: measured 0.319, 0.370, 0.413, 0.425, 0.434, 0.437,
    # 0.443, 0.450, 0.461, 0.468 mm at 0.056 ... 0.3 N (the buckle 12.5 mm behind the
    # limbus). With the lagged suture directions (seed 002 §2.2: from the last converged
    # state) the loop's legs turn tangential as the tire sinks and the radial pull per
    # newton drops, which has made the travel dip between neighbouring steps (0.483 ->
    # 0.474 mm at 0.28 -> 0.3 N, the buckle at 11.5 mm). So the check is across forces at
    # least twice apart
    pairs = [(i, j) for i in range(len(steps)) for j in range(len(steps))
             if force[j] >= 2 * force[i] > 0]
    assert len(pairs) >= 2
    for i, j in pairs:
        assert travel[j] > travel[i], (force[i], travel[i], force[j], travel[j])
    after = sewn.quantities["after_suturing"]
    assert after["tire_travel_mm"] > sewn.quantities["after_buckling"]["tire_travel_mm"] + 0.1
    # at the end of step 3 the holding force is released and there is no band: the
    # tire's row is the balance ∂Π_c/∂δ = F_sutures itself (Newton's tolerance)
    assert after["tire_contact_force_N"] == pytest.approx(after["tire_suture_pull_N"], rel=1e-6)
    # the pull is the opposite of the bite loads' radial part: between 0 and 2 legs of
    # 0.3 N on the one (whole) suture over the tire
    assert 0.0 < after["tire_suture_pull_N"] < 2 * 0.3


def test_sutures_lift_the_tire_off_a_shallow_band():
    # band and tire pressed only 0.3 mm (0.25 mm past the clearance): the sclera's push on
    # the tire is weaker than the 0.25 N suture's loop, so the band lets the tire go
    # deeper than itself in step 3, and with the band's stop inactive the tire's row is
    # the balance contact force = pull. Measured (coarse eye, the tear's rim on its
    # circle): held by the band at 0.094 N (pull and contact 0.161 N); the pull 0.305 N
    # above the contact's 0.259 N at 0.188 N; freed, 0.387 mm at 0.25 N (0.389 N of
    # contact and pull), band at 0.3 mm.
    # The release is checked after each converged step of step 3 and acts from the next
    # one (lagged, as the suture directions): with the budget's stepping step 3 is two load
    # steps and the tire is freed only at its end, too late to move (docs/scleral_buckling.md,
    # "Known limits"); the reference stepping takes three here, which this test pins. With
    # 0.3 N the reference stepping's first step of step 3 goes to 0.225 N at once, and the
    # suture directions updated after it turn the loop's pull outward (-0.14 N): the tire
    # stays on the band (docs/scleral_buckling.md, "Known limits").
    result = sb.run(build(sb.Parameters, dict(resolution="coarse", suture_azimuths="0",
                                              indentation="0.3", suture_force="0.25",
                                              buckle_position="12.5", settle="false",
                                              **REFERENCE_STEPPING, **PAPER)),
                    options=QUIET)
    after = result.quantities["after_suturing"]
    assert result.quantities["after_buckling"]["tire_free"] is False
    assert after["tire_free"] is True
    assert after["tire_travel_mm"] > after["buckle_travel_mm"] + 0.05
    assert after["tire_contact_force_N"] == pytest.approx(after["tire_suture_pull_N"], rel=1e-6)
