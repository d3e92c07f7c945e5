"""The step controller: how long the next step of a path is, what a failed attempt does to
it, and how it grows after an easy one. Every path follower and time loop asks it.

A path (a load factor, a time, a depth) is walked in steps. The caller proposes a target
with :meth:`StepController.target`, solves, and tells the controller what happened:

- :meth:`~StepController.cut`: Newton failed. The step is multiplied by ``cut_factor``
  and tried again from the same start, unless that was more than ``max_cuts`` cuts in a
  row or the step fell below ``smallest``: then ``cut`` returns False and the caller
  gives up (e.g. raises :class:`~eyemech.problems.solve.driver.SolveFailure`).
- :meth:`~StepController.accept`: the step converged. The next one grows by
  ``grow_factor`` after an easy step (its effort, Newton iterations or factorisations, at
  most ``easy_effort``, and no cut), shrinks by ``shrink_factor`` after a hard one (effort
  above ``hard_effort``); it never grows beyond ``largest`` nor shrinks below
  ``smallest``. A caller with its own rule (an error estimate's proposal) passes
  ``next_step``.
- :meth:`~StepController.reject`: the step converged but the caller refuses it (a time
  error above its tolerance); it is repeated with the step the caller proposes.

It counts honestly: the cuts of the step being tried, and over the whole path every
attempt, every failed one and every rejected one.

Verified in tests/test_stepping.py; the path follower's use in
:func:`eyemech.problems.solve.driver.follow_path`.
"""

from __future__ import annotations

import dataclasses
import math


@dataclasses.dataclass
class StepController:
    """Cut, retry, grow. Lengths are in the path's own unit (load factor, s, mm)."""

    step: float                       # the length the next attempt tries
    largest: float = math.inf         # growth stops here
    smallest: float = 0.0             # a cut below this gives up
    cut_factor: float = 0.5           # a failed attempt's step is multiplied by this
    max_cuts: int | None = 10         # cuts in a row before giving up (None: no limit)
    grow_factor: float = 1.5          # an easy step's successor is this much longer
    easy_effort: int | None = 6       # effort at or below which a step is easy (None: never)
    hard_effort: int | None = None    # effort above which a step is hard (None: never)
    shrink_factor: float = 0.5        # a hard step's successor is this much shorter
    grow_after_cut: bool = False      # whether an easy step that needed cuts grows too
    sliver: float = 1e-3              # a remainder before a stop shorter than this share
    #                                   of the step is taken with it
    cuts: int = 0                     # cuts of the step being tried
    attempts: int = 0                 # attempts of the path so far, all outcomes
    failed_attempts: int = 0          # attempts that failed (each one cut the step)
    rejected_attempts: int = 0        # converged attempts the caller rejected

    def __post_init__(self) -> None:
        if not self.step > 0:
            raise ValueError(f"step must be > 0, got {self.step!r}")
        if not 0 < self.cut_factor < 1:
            raise ValueError(f"cut_factor must lie in (0, 1), got {self.cut_factor!r}")
        if not self.grow_factor >= 1:
            raise ValueError(f"grow_factor must be >= 1, got {self.grow_factor!r}")
        if not 0 < self.shrink_factor <= 1:
            raise ValueError(f"shrink_factor must lie in (0, 1], got {self.shrink_factor!r}")

    def target(self, value: float, stop: float) -> float:
        """Where the next attempt from ``value`` ends: one step on, but not beyond ``stop``
        (a stage's end, an output time), and at ``stop`` when less than ``sliver`` of a
        step would be left before it."""
        target = min(value + self.step, stop)
        if stop - target < self.sliver * self.step:
            target = stop
        return target

    def cut(self, attempted: float | None = None) -> bool:
        """The attempt failed: the step becomes ``cut_factor`` times itself, or times the
        ``attempted`` length when given (a step a stop had shortened). Whether to retry:
        False after more than ``max_cuts`` cuts in a row or below ``smallest``."""
        self.attempts += 1
        self.failed_attempts += 1
        self.cuts += 1
        self.step = self.cut_factor * (self.step if attempted is None else attempted)
        too_many = self.max_cuts is not None and self.cuts > self.max_cuts
        return not too_many and self.step >= self.smallest

    def accept(self, effort: float | None = None, next_step: float | None = None) -> None:
        """The attempt converged and is kept. The next step: ``next_step`` (at most
        ``largest``) when given, else from ``effort`` by the growth rule."""
        self.attempts += 1
        if next_step is not None:
            self.step = min(next_step, self.largest)
        elif effort is not None:
            easy = self.easy_effort is not None and effort <= self.easy_effort \
                and (self.cuts == 0 or self.grow_after_cut)
            if easy:
                self.step = min(self.step * self.grow_factor, self.largest)
            elif self.hard_effort is not None and effort > self.hard_effort:
                self.step = max(self.step * self.shrink_factor, self.smallest)
        self.cuts = 0

    def reject(self, next_step: float) -> None:
        """The attempt converged but is refused (e.g. its time error is too large): it is
        repeated from the same start with ``next_step``. Not a cut."""
        self.attempts += 1
        self.rejected_attempts += 1
        self.step = next_step

    def limit(self, largest: float) -> None:
        """The next step at most ``largest`` (a stage's own largest step)."""
        self.step = min(self.step, largest)

    def at_least(self, first: float) -> None:
        """The next step at least ``first`` (a new stage's first step: the last stage's
        difficulty is not this one's)."""
        self.step = max(self.step, first)
