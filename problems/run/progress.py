"""What a run says while it runs, on rank 0, to stderr.

- On a terminal: a tqdm bar over each path (load or time), named by the path's label and
  the stage it is in (``scleral-buckling · buckling``).
- Off a terminal (batch logs, ``nohup``, a notebook's subprocess): one plain line per
  converged step, so a log shows where a long run is::

      scleral-buckling · buckling: step 9, load 1.375 (stage 2/4), 5 Newton iterations,
      residual 3.1e-11, 12.4 s

- With ``-v`` (log level INFO) every Newton iteration is logged too.
- A sweep says which case starts and how it ended: ``case 3/12 …``.

``--quiet`` (``RunOptions.quiet``) silences the bar and the lines, not the log.
The path follower (:func:`eyemech.problems.solve.driver.follow_path`) makes a
:class:`PathProgress` and calls its ``update`` after each converged step.
"""

from __future__ import annotations

import logging
import sys
import time
from typing import Any, Sequence

log = logging.getLogger("eyemech")


class PathProgress:
    """Progress of one path: ``update(fraction_increment)`` after each converged step
    (``records[-1]`` is that step's record), ``close()`` at the end."""

    def __init__(self, label: str, stepping: Any, records: Sequence[Any], *, show: bool,
                 terminal: bool | None = None) -> None:
        self.label = label or "path"
        self.stepping = stepping
        self.records = records  # the path follower's list, appended before each update
        self.n = 0.0
        self.started = time.perf_counter()
        self.show = show
        terminal = sys.stderr.isatty() if terminal is None else terminal
        self.bar = None
        if show and terminal:
            from tqdm import tqdm

            self.bar = tqdm(total=1.0, desc=self.label, unit="", leave=False, file=sys.stderr,
                            bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining}")

    def stage(self, value: float) -> tuple[str, int, int]:
        """(name, number from 1, count) of the named stage a step that ended at ``value``
        is in: the interval between ``stepping.stops`` it lies in, when the stepping names
        its stages (``stage_names``; other stops are output times, not stages). A step
        ending on a stop belongs to the stage it ends. ("", 0, 0) when unnamed."""
        names = tuple(getattr(self.stepping, "stage_names", ()) or ())
        if not names:
            return "", 0, 0
        stops = sorted(getattr(self.stepping, "stops", ()) or ())
        tiny = 1e-12 * max(abs(getattr(self.stepping, "end", 1.0)), 1.0)
        index = min(sum(1 for s in stops if s < value - tiny), len(names) - 1)
        return names[index], index + 1, len(names)

    def title(self, value: float) -> str:
        name = self.stage(value)[0]
        return f"{self.label} · {name}" if name else self.label

    def update(self, increment: float) -> None:
        self.n += increment
        if not self.show or not self.records:
            return
        record = self.records[-1]
        if self.bar is not None:
            self.bar.set_description(self.title(record.load), refresh=False)
            self.bar.update(increment)
            return
        print(self.line(record), file=sys.stderr, flush=True)

    def line(self, record: Any) -> str:
        name, number, count = self.stage(record.load)
        quantity, unit = self.stepping.describe() if hasattr(self.stepping, "describe") \
            else ("load", "")
        quantity = "load" if quantity in ("load factor", "path value") else quantity
        where = f" (stage {number}/{count})" if count else ""
        residual = f"{record.residuals[-1]:.2e}" if record.residuals else "—"
        cuts = f", {record.cuts} cut{'s' if record.cuts != 1 else ''}" if record.cuts else ""
        return (f"{self.title(record.load)}: step {record.step}, {quantity} {record.load:.6g}"
                f"{' ' + unit if unit else ''}{where}, {record.iterations} Newton iterations, "
                f"residual {residual}{cuts}, {time.perf_counter() - self.started:.1f} s")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def path_progress(solver: Any, label: str, quiet: bool, stepping: Any = None,
                  records: Sequence[Any] = ()) -> PathProgress:
    """The path follower's hook: a :class:`PathProgress` shown on rank 0 unless ``quiet``;
    under ``-v`` the solver's Newton iterations are logged (:func:`log_newton_iterations`)."""
    comm = solver.problem.A.comm.tompi4py()
    if comm.rank == 0 and log.isEnabledFor(logging.INFO):
        log_newton_iterations(solver)
    return PathProgress(label, stepping, records, show=not quiet and comm.rank == 0)


def log_newton_iterations(solver: Any) -> None:
    """A SNES monitor that logs each Newton iteration's residual (once per solver). It is a
    module function, holding nothing: a closure over the solver would keep it alive from C
    (problems/solve/callbacks.py)."""
    if getattr(solver, "_newton_logged", False):
        return
    solver.snes.setMonitor(_log_iteration)
    solver._newton_logged = True


def _log_iteration(_snes, iteration: int, norm: float) -> None:
    log.info("  Newton iteration %d: residual %.3e", iteration, norm)


def case_started(index: int, total: int, values: dict[str, Any], quiet: bool) -> float:
    """A sweep's case starts: ``case i/N: key=value, ...`` on stderr (the case group's
    first rank); the start time for :func:`case_ended`."""
    if not quiet:
        settings = ", ".join(f"{k}={v}" for k, v in values.items())
        print(f"case {index + 1}/{total}: {settings}", file=sys.stderr, flush=True)
    return time.perf_counter()


def case_ended(index: int, total: int, status: str, started: float, quiet: bool) -> None:
    if not quiet:
        print(f"case {index + 1}/{total}: {status} in {time.perf_counter() - started:.1f} s",
              file=sys.stderr, flush=True)
