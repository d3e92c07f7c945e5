"""The surgeon's controls of the buckle on the coarse eye: the elastic band tightened by
shortening (``buckle_control = shortening``), its tension and its hoop equilibrium with
the eye; the bad inputs of the controls refused before any solve (exit 2, naming the key).
docs/scleral_buckling.md, "The elastic band"."""

from __future__ import annotations

import math

import pytest
from conftest import run_cli

from eyemech.problems import scleral_buckling as sb
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError, build

QUIET = RunOptions(fields=False, pictures=False)
# the band alone (no tire under it: its length is 2π (ρ_c − δ)), no settling, on Table 1's
# clamped eye (the band's law does not depend on the wall; the measured numbers below are
# this eye's): ≈ 35 s each
BAND = dict(resolution="coarse", buckle="encircling", buckle_control="shortening", settle="false",
            material="table-1", optic_nerve_end_spring="0")
TEN_PERCENT = {"band_shortening_percent": "10"}


@pytest.fixture(scope="module")
def band():
    return sb.run(build(sb.Parameters, {**BAND, **TEN_PERCENT}), options=QUIET)


def test_the_band_tension_follows_its_shortening(band):
    """Over the buckling stage the surgeon takes up to 10 % out of the band's loop. At every
    converged step the band's tension is Hooke's law on its centreline, T = E A (L − L_set)/
    L_set with L = L_laid − 2π δ (δ its travel) and L_set = L_laid − ΔL (E A = 3 MPa × 2.5 mm
    × 0.6 mm = 4.5 N); and its inward resultant 2π T is the sclera's contact force on the
    band (the hoop equilibrium, the row of δ: to Newton's tolerance, measured 7e-13
    relative). Tension and travel rise with the shortening, the travel stays below the slack
    band's ΔL/2π (the eye holds the band out)."""
    ea = 3.0 * 2.5 * 0.6
    steps = [s for s in band.steps if s["stage"] == 2]
    assert len(steps) >= 3
    for s in steps:
        laid, taken = s["band_laid_circumference_mm"], s["band_shortening_mm"]
        length = laid - 2 * math.pi * s["band_travel_mm"]
        assert s["band_circumference_mm"] == pytest.approx(length, rel=1e-12)
        tension = ea * (length - (laid - taken)) / (laid - taken)
        assert s["band_tension_N"] == pytest.approx(tension, rel=1e-9)
        assert s["tire_contact_force_N"] == pytest.approx(2 * math.pi * s["band_tension_N"], rel=1e-6)
        assert 0 < s["band_travel_mm"] < taken / (2 * math.pi)
    shortening = [s["band_shortening_percent"] for s in steps]
    tension = [s["band_tension_N"] for s in steps]
    travel = [s["band_travel_mm"] for s in steps]
    assert shortening == sorted(shortening) and shortening[-1] == pytest.approx(10.0)
    assert all(b > a for a, b in zip(tension, tension[1:])), tension
    assert all(b > a for a, b in zip(travel, travel[1:])), travel
    after = band.quantities["after_buckling"]
    # measured 0.764 mm and 0.183 N: the eye takes back 36 % of the slack band's 1.20 mm
    assert 0.5 < after["band_travel_mm"] < 1.0
    assert 0.1 < after["band_tension_N"] < 0.3


def test_a_stiff_band_shortened_by_2pi_mm_indents_1_mm():
    """The surgeon's rule for a flush band (Read & Hahn, Retina Specialist 2021: "tightening
    the circumference of a flush buckle by 6.28 mm", C = 2π r, gives 1 mm of indentation):
    an inextensible band's radius drops by ΔL/2π whatever the eye pushes. A band 1000 times
    stiffer (E = 3 GPa, E A = 4500 N) shortened by 2π mm travels 1 mm less its own stretch,
    T L/(2π E A) ≈ 1e-3 mm at the measured T ≈ 0.5 N; and the shortening given in
    millimetres is what the band loses."""
    params = build(sb.Parameters, {**BAND, "band_shortening_mm": f"{2 * math.pi}",
                                   "band_modulus_MPa": "3000"})
    after = sb.run(params, options=QUIET).quantities["after_buckling"]
    assert after["band_shortening_mm"] == pytest.approx(2 * math.pi, rel=1e-12)
    assert after["band_travel_mm"] == pytest.approx(1.0, abs=2e-3)  # measured 0.99934
    # what it lacks is the band's stretch at its tension, T L_set/(2π E A)
    set_length = after["band_laid_circumference_mm"] - 2 * math.pi
    stretch = after["band_tension_N"] * set_length / (2 * math.pi * 4500.0)
    assert after["band_travel_mm"] == pytest.approx(1.0 - stretch, abs=1e-9)
    assert 1e-4 < stretch < 2e-3
    assert after["tire_contact_force_N"] == pytest.approx(2 * math.pi * after["band_tension_N"], rel=1e-6)


def test_the_band_carries_the_tire_and_the_sutures_pull(band, tmp_path):
    """The scene's operation (band over a 90° tire, sutures at 0, 90 and 180°, the loop
    model, settling, fields and pictures) on Table 1's clamped eye, the band tightened by
    10 %: the band's laid length includes its rise over the tire, h_t φ_t = 1 mm × π/2 beyond the band alone's
    (same eye, same placement: measured to 5e-14 mm); after suturing and settled, the
    sclera's contact force on band and tire balances the band's 2π T plus the sutures'
    pull on the tire (its row; Newton's tolerance): measured 1.577 = 1.348 + 0.229 N sewn,
    1.356 = 1.127 + 0.229 N settled. As the IOP falls back the band settles deeper (0.702 →
    0.788 mm) and its tension drops (0.215 → 0.179 N). The sibling with settling and
    output of the other tests here (≈ 60 s)."""
    params = build(sb.Parameters, {**BAND, **TEN_PERCENT, "buckle": "encircling+segmental",
                                   "settle": "true", "tire_height": "1.0"})  # as measured
    result = sb.run(params, out=tmp_path)
    sewn, settled = result.quantities["after_suturing"], result.quantities["after_settling"]
    for after in (sewn, settled):
        assert after["tire_contact_force_N"] == pytest.approx(
            after["band_hoop_force_N"] + after["tire_suture_pull_N"], rel=1e-6)
        assert after["tire_suture_pull_N"] > 0.1
        assert after["tire_travel_mm"] == after["band_travel_mm"] == after["buckle_travel_mm"]
    assert settled["band_travel_mm"] > sewn["band_travel_mm"] + 0.05
    assert settled["band_tension_N"] < sewn["band_tension_N"] - 0.01
    assert result.pictures and result.fields
    alone = band.quantities["after_iop"]
    placed = result.quantities["after_iop"]
    assert placed["band_laid_circumference_mm"] - alone["band_laid_circumference_mm"] \
        == pytest.approx(0.5 * math.pi, abs=1e-9)


@pytest.mark.parametrize("settings, key", [
    # the whole loop, or more, taken out of the band
    ({"band_shortening_percent": "100"}, "band_shortening_percent"),
    ({"band_shortening_mm": "80"}, "band_shortening_mm"),
    ({"band_modulus_MPa": "-3"}, "band_modulus_MPa"),
    # nothing to shorten without a band
    ({"buckle": "segmental", "band_shortening_percent": "12"}, "band_shortening_percent"),
    # the rigid buckle's travel has no meaning for an elastic band
    ({"indentation": "1.5"}, "indentation"),
    ({"band_shortening_mm": "7", "band_shortening_percent": "8"}, "band_shortening_mm"),
])
def test_bad_shortening_is_refused(settings, key):
    """(Also for the defaults: buckle_control=shortening is the default.)"""
    with pytest.raises(ParameterError) as info:
        build(sb.Parameters, {"buckle_control": "shortening", **settings})
    assert info.value.key == key
    assert "unknown key" not in str(info.value)


@pytest.mark.parametrize("settings, key", [
    (["buckle_control=shortening", "band_shortening_percent=120"], "band_shortening_percent"),
    (["buckle_control=shortening", "band_shortening_mm=100"], "band_shortening_mm"),
    # the bites of a suture narrower than the 7 mm tire it holds
    (["suture_width=6.5"], "suture_width"),
    # the band's numbers without the band's control
    (["buckle_control=travel", "band_shortening_percent=12"],
     "'band_shortening_percent': is used only with"),
    (["iop_limit_mmHg=10"], "iop_limit_mmHg"),
])
def test_bad_controls_exit_2_before_any_solve(tmp_path, settings, key):
    arguments = [a for s in settings for a in ("--set", s)]
    code, out, err = run_cli("run", "scleral-buckling", *arguments, "--out", str(tmp_path))
    assert code == 2, (out, err)
    assert key in err
    assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "results.json").exists()


def test_a_tire_alone_moves_in_by_indentation_under_the_default_control():
    """buckle_control=shortening (the default) shortens a band; a tire without one
    (buckle=segmental) has nothing to shorten and moves in by ``indentation``, so that
    ``--set buckle=segmental`` alone is a valid operation (and so is its indentation)."""
    tire = build(sb.Parameters, {"buckle": "segmental", "indentation": "1.5"})
    assert tire.buckle_control == "shortening" and not tire.elastic_band()
    assert build(sb.Parameters, {}).elastic_band()
    assert not build(sb.Parameters, {"buckle_control": "travel"}).elastic_band()
