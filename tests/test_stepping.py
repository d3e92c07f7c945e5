"""The step controller (problems/solve/stepping.py): cut, retry, grow, and its counts. Plain
arithmetic, no solve: every expected length below is the rule applied by hand."""

from __future__ import annotations

import pytest

from eyemech.problems.solve.stepping import StepController


def test_a_failed_attempt_halves_the_step_and_is_counted():
    steps = StepController(0.4)
    assert steps.cut()
    assert steps.step == pytest.approx(0.2)
    assert (steps.cuts, steps.attempts, steps.failed_attempts) == (1, 1, 1)
    # a time loop halves the attempted length, which a stop may have shortened
    assert steps.cut(attempted=0.1)
    assert steps.step == pytest.approx(0.05)
    assert (steps.cuts, steps.failed_attempts) == (2, 2)


def test_cutting_gives_up_after_max_cuts_in_a_row_or_below_the_smallest_step():
    steps = StepController(1.0, max_cuts=2)
    assert steps.cut() and steps.cut()
    assert not steps.cut()  # the third cut in a row
    steps = StepController(1.0, smallest=0.3)
    assert steps.cut()       # 0.5
    assert not steps.cut()   # 0.25 < 0.3
    unlimited = StepController(1.0, max_cuts=None)
    assert all(unlimited.cut() for _ in range(50))


def test_an_easy_step_grows_a_hard_one_shrinks_within_the_bounds():
    steps = StepController(0.4, largest=1.0, smallest=0.05, easy_effort=6, hard_effort=10)
    steps.accept(effort=3)
    assert steps.step == pytest.approx(0.6)
    steps.accept(effort=3)
    assert steps.step == pytest.approx(0.9)
    steps.accept(effort=3)
    assert steps.step == pytest.approx(1.0)    # at most largest
    steps.accept(effort=8)
    assert steps.step == pytest.approx(1.0)    # neither easy nor hard: kept
    steps.accept(effort=12)
    assert steps.step == pytest.approx(0.5)
    for _ in range(10):
        steps.accept(effort=12)
    assert steps.step == pytest.approx(0.05)   # at least smallest
    assert steps.attempts == 15 and steps.failed_attempts == 0


def test_a_step_that_needed_a_cut_does_not_grow_unless_told_to():
    steps = StepController(0.4, largest=1.0)
    steps.cut()
    steps.accept(effort=2)
    assert steps.step == pytest.approx(0.2)
    assert steps.cuts == 0  # the next step starts without cuts
    lenient = StepController(0.4, largest=1.0, grow_after_cut=True)
    lenient.cut()
    lenient.accept(effort=2)
    assert lenient.step == pytest.approx(0.3)


def test_a_proposed_next_step_and_a_rejection():
    steps = StepController(0.1, largest=0.25)
    steps.accept(next_step=0.4)
    assert steps.step == 0.25
    steps.reject(0.05)
    assert steps.step == 0.05
    assert (steps.attempts, steps.rejected_attempts, steps.failed_attempts, steps.cuts) == (2, 1, 0, 0)


def test_targets_land_on_stops_without_slivers():
    steps = StepController(0.3)
    assert steps.target(0.0, 1.0) == pytest.approx(0.3)
    assert steps.target(0.8, 1.0) == 1.0                 # clipped at the stop
    assert steps.target(0.7 - 2e-4, 1.0) == 1.0          # 2e-4 left: less than 1e-3 of a step
    assert steps.target(0.6, 1.0) == pytest.approx(0.9)


def test_stage_limits():
    steps = StepController(0.5)
    steps.limit(0.2)
    assert steps.step == 0.2
    steps.at_least(0.25)
    assert steps.step == 0.25


@pytest.mark.parametrize("settings", [dict(step=0.0), dict(step=1.0, cut_factor=1.0),
                                      dict(step=1.0, grow_factor=0.5),
                                      dict(step=1.0, shrink_factor=0.0)])
def test_nonsense_settings_are_refused(settings):
    with pytest.raises(ValueError):
        StepController(**settings)
