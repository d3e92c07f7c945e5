"""The keratotomy scene (issue 6, item 5), first version: trends against cadaver data.

Salz et al. (1985), 8 incisions: 9.06 / 6.44 / 5.23 / 2.29 D flattening for optical zones
3 / 4 / 5 / 6 mm; 4 vs 3 incisions (3.5 mm zone, 90 % depth, 15 mmHg): 6.08 vs 4.84 D. The
tests check the trends (signs and orderings) on coarse meshes, not the magnitudes: those
depend on the moduli and the mesh and are reported in docs/viscoelastic.md.
"""

from __future__ import annotations

import pytest

from eyemech.problems import keratotomy
from eyemech.problems.context import RunOptions
from eyemech.problems.parameters import ParameterError, build

QUIET = RunOptions(fields=False, pictures=False)
COARSE = dict(mesh_size=1.5, azimuthal_divisions=8, t_end=3600.0, first_dt=1800.0, dt_growth=1.0)


def solve(**changes):
    return keratotomy.run(keratotomy.Parameters(**{**COARSE, **changes}), options=QUIET).quantities


@pytest.fixture(scope="module")
def eight_at_3mm():
    return solve(incisions=8, optical_zone=3.0)


def test_incisions_flatten_and_creep_adds(eight_at_3mm):
    q = eight_at_3mm
    assert q["intact_power_D"][0] > q["unloaded_power_D"]  # IOP steepens the intact cornea
    assert all(change < -1.0 for change in q["power_change_D"])  # flattening, dioptres
    assert q["power_change_final_D"] < q["power_change_initial_D"]  # creep adds to it
    assert q["wound_gape_mm"][-1] > q["wound_gape_mm"][0] > 0  # the wounds open, and more so
    assert q["apex_displacement_mm"][-1] > q["apex_displacement_mm"][0] > 0


def test_smaller_optical_zone_flattens_more(eight_at_3mm):
    wide = solve(incisions=8, optical_zone=5.0, t_end=1800.0)
    assert eight_at_3mm["power_change_D"][1] < wide["power_change_D"][1] < 0


def test_four_incisions_flatten_more_than_three():
    # 3 cuts need 24 divisions around; one layer above and one below the cut bottom
    common = dict(optical_zone=3.5, incision_depth=0.9, iop_mmHg=15.0, azimuthal_divisions=24,
                  mesh_size=3.0, layers=1, t_end=1800.0)
    three, four = solve(incisions=3, **common), solve(incisions=4, **common)
    assert four["power_change_D"][-1] < three["power_change_D"][-1] < 0


@pytest.mark.parametrize("key, value, words", [
    ("incision_depth", "1.2", "incision_depth"), ("incision_depth", "0", "incision_depth"),
    ("optical_zone", "12", "narrower than the cornea"), ("optical_zone", "0", "cross"),
    ("tau", "0", "> 0"), ("incision_end", "1.0", "incision_end")])
def test_bad_input_is_one_clear_error(key, value, words):
    with pytest.raises(ParameterError, match=words) as info:
        build(keratotomy.Parameters, {key: value})
    assert info.value.key == key


@pytest.mark.mpi
def test_two_ranks_give_the_same_numbers(tmp_path, eight_at_3mm):
    """The coarse 8-incision case on 2 ranks, stopped after the first time step, against
    the first two time levels of the serial run (same time grid)."""
    from conftest import last_json, run_cli

    sets = [f"{k}={v}" for k, v in {**COARSE, "t_end": 1800.0}.items()]
    args = [a for s in sets for a in ("--set", s)]
    code, out, err = run_cli("run", "keratotomy", *args, "--out", str(tmp_path), "--json",
                             "--no-pictures", "--no-fields", ranks=2)
    assert code == 0, err
    parallel = last_json(out)["quantities"]
    for key in ("power_change_D", "intact_power_D", "apex_displacement_mm", "wound_gape_mm"):
        assert parallel[key] == pytest.approx(eight_at_3mm[key][:2], rel=1e-8)
