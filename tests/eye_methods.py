"""The scleral-buckling scene's reference Newton method and how the Newton-budget tests
compare another method's eye with it (tests/test_newton_counts.py, tests/test_newton_krylov.py).

The reference method: penalty contact, full Newton with backtracking (bt) from step 2 on,
MUMPS LU, the stepping without the budget's predictor, factorisation reuse and step-2
limit, no cycle stop or depth limit (docs/scleral_buckling.md, "Newton's budget")."""

from __future__ import annotations

import pytest

REFERENCE_METHOD = {"predictor": "none", "jacobian_reuse": 0.0, "buckle_step": 0.25,
                    "step_effort": "iterations", "hard_step_effort": 0, "line_search": "bt",
                    "suture_line_search": "bt", "settle_line_search": "bt", "settle_retry": "none",
                    "cycle_max_period": 0, "retina_step_depth": 0.0}
QUANTITIES = ("axial_length_change_mm", "iop_mmHg", "refraction_change_D", "corneal_power_change_D")


def assert_same_eye(reference, actual, rim_gap_tolerance: float, relative: float = 0.01,
                    stages: tuple[str, ...] = ("after_buckling", "after_suturing")) -> None:
    """The quantities of interest within ``relative`` of the reference's after each stage
    (1 %: the issue's tolerance), and the tear rim's widest gap within ``rim_gap_tolerance``
    (mm)."""
    for stage in stages:
        expected, measured = reference.quantities[stage], actual.quantities[stage]
        for key in QUANTITIES:
            assert measured[key] == pytest.approx(expected[key], rel=relative), (stage, key)
        assert measured["tear_rim_gap_max_mm"] == pytest.approx(
            expected["tear_rim_gap_max_mm"], abs=rim_gap_tolerance), stage
