"""The tonometry scene (issue 6, item 6), coarse meshes: the published trend only.

Readings of Goldmann applanation tonometry rise with central corneal thickness
(Ehlers, Bramsen & Sperling 1975; Doughty & Zaman 2000) and with corneal stiffness
(Liu & Roberts 2005). The accuracy at 520 µm is NOT asserted here (see docs/cornea.md).
"""

from __future__ import annotations

import pytest

from eyemech.problems import tonometry
from eyemech.problems.context import RunOptions
from eyemech.problems.parameters import ParameterError, build

QUIET = RunOptions(fields=False, pictures=False, quiet=True)
COARSE = dict(mesh_size=1.5, azimuthal_divisions=8)


def reading(**changes) -> dict:
    return tonometry.run(tonometry.Parameters(**{**COARSE, **changes}), options=QUIET).quantities


@pytest.fixture(scope="module")
def nominal():
    return reading()


def test_disc_reached_and_reading_rises_with_thickness_and_stiffness(nominal):
    assert nominal["contact_diameter_mm"] == pytest.approx(3.06, rel=1e-4)
    assert reading(central_thickness=0.60, limbal_thickness=0.75)["iop_reading_mmHg"] > nominal["iop_reading_mmHg"]
    assert reading(youngs_modulus=0.42)["iop_reading_mmHg"] > nominal["iop_reading_mmHg"]


@pytest.mark.parametrize("key, value", [("iop_mmHg", "-1"), ("youngs_modulus", "0"),
                                        ("applanation_diameter", "9"), ("tear_film_mmHg", "-1"),
                                        ("support", "glued")])
def test_bad_input_is_one_clear_error(key, value):
    with pytest.raises(ParameterError) as info:
        build(tonometry.Parameters, {key: value})
    assert info.value.key == key
