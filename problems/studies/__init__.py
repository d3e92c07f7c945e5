"""Studies: accuracy against cost, and where methods fail.

Each module here exposes ``STUDY`` (a :class:`Study`); ``eyemech study NAME`` runs
it and writes CSV and PNG files into ``docs/studies/`` or ``--out``: each CSV with a
sidecar ``<stem>.meta.json`` (machine, versions, date, notes, and the settings it was made
with: the defaults of the scenes the study runs and the study's own constants, hashed, so
that a committed table made with other settings than the code's is found:
tests/test_study_atlas.py). ``quick=True`` runs coarse settings for the tests.

A row whose ``status`` is ``failed`` or ``error`` (what a sweep case records when its run
failed), or ``stopped`` (a case stopped before its end, by hand for lack of time: iol-flip
keeps such a run and does not rerun it), is a case that should have run and did not give
its result: ``eyemech study`` names it, marks it on the charts and exits 4. A study that
measures where a method fails writes what happened in other words ("blew up", "diverged
(NaN)", "failed at load 0.5"): a finding, not a failure.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import importlib
import pkgutil
from pathlib import Path
from typing import Callable, Iterator


@dataclasses.dataclass(frozen=True)
class Study:
    name: str
    summary: str
    run: Callable[..., list[Path]]  # run(out: Path, quick: bool, comm) -> files written


def studies() -> dict[str, Study]:
    found = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        study = getattr(module, "STUDY", None)
        if study is not None:
            found[study.name] = study
    return found


# a case's row with one of these statuses did not give its result: failed, error (the run
# contract's words) or stopped before its end (by hand, for a time budget)
FAILED = ("failed", "error", "stopped")


@dataclasses.dataclass
class Record:
    """What one study run wrote: its cases (CSV rows with a status) and the failed ones."""

    name: str
    module: str
    quick: bool
    cases: int = 0
    failed: list[str] = dataclasses.field(default_factory=list)


_RUNNING: contextvars.ContextVar[Record | None] = contextvars.ContextVar("study", default=None)


def running() -> Record | None:
    """The study being run (set by :func:`record`), for the CSV writer and the charts."""
    return _RUNNING.get()


@contextlib.contextmanager
def record(study: Study, quick: bool) -> Iterator[Record]:
    """``with record(study, quick) as r: study.run(...)``: ``r`` counts its cases and failures."""
    current = Record(study.name, study.run.__module__, quick)
    token = _RUNNING.set(current)
    try:
        yield current
    finally:
        _RUNNING.reset(token)
