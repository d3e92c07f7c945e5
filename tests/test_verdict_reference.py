"""The tear's verdict at the scene's defaults on the coarse eye against its reference
discretisation, Q2P1, which resolves the retina's bending that one Q1P0 cell through it
locks. After suturing Q1P0 closes the tear (−0.000 mm) and Q2P1 leaves it open (0.123 mm,
the rim's lateral side; docs/scleral_buckling.md, "Q2P1 on the coarse eye, the rim node by
node"): the verdict does not yet survive the element, so the test is a strict expected
failure that passes once an operation closes the tear with both. It took 127 s on this VM
idle (both runs to the end of suturing), 4–5 min beside other runs: it runs only with
``EYEMECH_VERDICT_REFERENCE=1``."""

from __future__ import annotations

import os

import pytest

from eyemech.problems import scleral_buckling as sb
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import build
from eyemech.problems.scleral_buckling.measures import rim_verdict

pytestmark = [pytest.mark.slow, pytest.mark.skipif(
    not os.environ.get("EYEMECH_VERDICT_REFERENCE"),
    reason="two runs to the end of suturing, 2-5 min: EYEMECH_VERDICT_REFERENCE=1 runs it")]

QUIET = RunOptions(fields=False, pictures=False)


def _after_suturing(element: str) -> dict:
    params = build(sb.Parameters, {"resolution": "coarse", "settle": "false", "element": element})
    result = sb.run(params, options=QUIET)
    if result.status != "ok":  # not the expected failure: an error, not an xfail
        raise RuntimeError(f"{element}: {result.status}: {result.message}")
    return result.quantities["after_suturing"]


@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="Q1P0 closes the tear after suturing, Q2P1 leaves it 0.123 mm open "
                   "(docs/scleral_buckling.md, Q2P1 on the coarse eye)")
def test_the_defaults_verdict_after_suturing_is_the_reference_elements():
    verdicts = {element: rim_verdict(_after_suturing(element)["tear_rim_margin_mm"])
                for element in ("Q1P0", "Q2P1")}
    assert verdicts["Q1P0"] == verdicts["Q2P1"] == "closed", verdicts
