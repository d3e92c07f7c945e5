"""External drainage of the subretinal fluid is refused: the drained retina pressed on the
choroid reaches no equilibrium in this model, so the settled state could only be reported
with a pseudo-time drag still on the retina (docs/scleral_buckling.md, "Subretinal
drainage", which gives the measurements). Refused as bad input is: one error naming
``drainage``, before anything is meshed or solved, exit 2."""

from __future__ import annotations

import pytest
from conftest import run_cli

from eyemech.problems import scleral_buckling as sb
from eyemech.problems.run.parameters import ParameterError, build


@pytest.mark.parametrize("overrides", [
    {"drainage": "external"},
    {"drainage": "external", "resolution": "coarse", "indentation": "0", "suture_force": "0"},
    {"drainage": "external", "detachment_height": "0"},
    {"drainage": "external", "settle": "false"},
])
def test_drainage_is_refused(overrides):
    with pytest.raises(ParameterError) as info:
        build(sb.Parameters, overrides)
    assert info.value.key == "drainage"
    assert "no equilibrium" in str(info.value)


def test_no_drainage_is_the_default():
    assert sb.Parameters().drainage == "none"


def test_drainage_exits_2_before_any_solve(tmp_path):
    out = tmp_path / "run"
    code, _, err = run_cli("run", "scleral-buckling", "--set", "drainage=external",
                           "--set", "resolution=coarse", "--out", str(out))
    assert code == 2
    last = err.strip().splitlines()[-1]
    assert "drainage" in last and "no equilibrium" in last
    assert "Traceback" not in err
    assert not (out / "results.json").exists()
