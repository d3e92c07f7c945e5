"""Ranks in step: a divergence between ranks becomes an error instead of a hang.

Under MPI every rank must make the same collective calls in the same order. A branch
on a value that only one rank holds (a picture drawn on rank 0 that reads a distributed
unknown, a decision taken on local data) breaks that: one rank waits in a collective call
the others never make, or matches it with a different one, and the job hangs with every
rank at 100 % CPU. :class:`Lockstep` checks at the end of every step of a path
(:meth:`~eyemech.problems.run.checkpoint.Checkpoints.step_done`) that every rank
arrived there, with the same step and the same decision (the path, the value reached,
the next increment, the Newton iterations and cuts):

- on a communicator of its own (``comm.Dup()``), so that its messages can never match an
  application's collective call;
- by nonblocking point-to-point messages (each rank sends its record to every other),
  polled with a deadline: a rank that does not arrive within :func:`timeout_seconds` is
  named, which a nonblocking collective could not do, and the job is ended with
  ``MPI_Abort`` (the missing rank is inside some collective call and cannot be reached);
- when all arrived but their records differ, every rank holds the same table and raises
  :class:`RanksDiverged` alike (exit code 1, no hang).

Cost per step: 2 (N − 1) messages of a few doubles per rank, and the wait for the
slowest rank, which the step's next collective call would wait for anyway.

The deadline. Between the step's last collective call and this check the ranks do only
rank-local work, and the longest such work is rank 0 drawing the step's pictures and
writing the gathered ``.vtu`` after the other ranks sent their part: measured on the
paper-resolution eye below 10 s (docs/parallel.md). :data:`DEFAULT_TIMEOUT` leaves a
margin of more than 10 for a loaded machine; ``EYEMECH_LOCKSTEP_SECONDS`` sets it (0 turns
the check off).
"""

from __future__ import annotations

import os
import time
import zlib

import numpy as np
from mpi4py import MPI

TIMEOUT_ENV = "EYEMECH_LOCKSTEP_SECONDS"
DEFAULT_TIMEOUT = 120.0
# MPI guarantees tags up to 32767: the check's number modulo this tells consecutive
# checks apart (a rank is never more than one check ahead of another)
TAG_CYCLE = 32000


# the tag of :func:`all_left_with_an_error`'s messages (above every lock-step check's)
SOLVER_ERROR_TAG = TAG_CYCLE + 1


class RanksDiverged(RuntimeError):
    """Every rank arrived at a check but with different steps or decisions."""


def timeout_seconds() -> float:
    text = os.environ.get(TIMEOUT_ENV, "").strip()
    if not text:
        return DEFAULT_TIMEOUT
    try:
        return max(float(text), 0.0)
    except ValueError:
        return DEFAULT_TIMEOUT


def exchange(comm: MPI.Comm, mine: np.ndarray, tag: int, timeout: float,
             on_missing) -> np.ndarray:
    """Every rank's ``mine`` (one row per rank) by nonblocking point-to-point messages,
    polled with a deadline; ``on_missing(ranks)`` is called (and must not return) when
    some ranks have not sent theirs within ``timeout`` seconds."""
    table = np.empty((comm.size, len(mine)))
    table[comm.rank] = mine
    others = [r for r in range(comm.size) if r != comm.rank]
    receives = [comm.Irecv(table[r], source=r, tag=tag) for r in others]
    sends = [comm.Isend(mine, dest=r, tag=tag) for r in others]
    deadline = time.monotonic() + timeout
    pause = 5e-5
    while not MPI.Request.Testall(receives):
        if time.monotonic() > deadline:
            missing = [r for r, request in zip(others, receives) if not request.Test()]
            if missing:
                on_missing(missing)
        time.sleep(pause)
        pause = min(2 * pause, 0.01)
    MPI.Request.Waitall(sends)
    return table


def all_left_with_an_error(comm: MPI.Comm, where: str, timeout: float | None = None) -> None:
    """Called by a rank that a library error (a PETSc error inside SNES) took out of a
    solve: return when every rank of ``comm`` left it the same way, end the job naming
    the ranks that did not otherwise. Such an error can be raised on one rank only (a
    factorisation, a callback's PETSc call), and the other ranks then wait inside the
    solve's collective calls for a rank that has gone on to cut the step: without this
    check the job hangs or matches unrelated collective calls. Point-to-point messages
    with their own tag never match a collective call."""
    timeout = timeout_seconds() if timeout is None else timeout
    if comm.size == 1 or timeout <= 0:
        return
    from eyemech.problems.run.faults import abort_with_message

    def abort(missing: list[int]) -> None:
        ranks = ", ".join(str(r) for r in missing)
        abort_with_message(
            f"ranks out of step: rank {comm.rank} of {comm.size} left {where} with a PETSc "
            f"error and rank(s) {ranks} did not within {timeout:g} s ({TIMEOUT_ENV}): they "
            "wait in the solve's collective calls (the error was raised on some ranks only; "
            "docs/parallel.md, \"Ranks in step\")")

    exchange(comm, np.ones(1), SOLVER_ERROR_TAG, timeout, abort)


def label_code(label: str) -> float:
    """A path's label as a number (its CRC-32) for the record."""
    return float(zlib.crc32(label.encode()))


class Lockstep:
    """The check of one communicator (collective to create and to :meth:`free`)."""

    FIELDS = ("check", "path", "label", "steps done", "step", "value", "increment",
              "newton iterations", "cuts")

    def __init__(self, comm: MPI.Comm, timeout: float | None = None):
        self.timeout = timeout_seconds() if timeout is None else timeout
        self.comm = comm.Dup() if comm.size > 1 and self.timeout > 0 else None
        self.checks = 0
        self.longest_wait = 0.0  # seconds this rank waited for the others at a check

    def free(self) -> None:
        if self.comm is not None:
            self.comm.Free()
            self.comm = None

    def check(self, where: str, record: tuple[float, ...]) -> None:
        """Every rank at the same ``where`` with the same ``record`` (FIELDS after
        "check"), or an error: the job is aborted naming the ranks that did not arrive,
        or :class:`RanksDiverged` is raised on every rank."""
        comm = self.comm
        if comm is None:
            return
        self.checks += 1
        mine = np.array([self.checks, *record], dtype=np.float64)
        start = time.monotonic()
        table = exchange(comm, mine, self.checks % TAG_CYCLE, self.timeout,
                         lambda missing: self._abort(where, mine, missing))
        self.longest_wait = max(self.longest_wait, time.monotonic() - start)
        differs = np.flatnonzero(np.any(table != table[0], axis=1))
        if len(differs):
            raise RanksDiverged(self._describe(where, table))

    def _describe(self, where: str, table: np.ndarray) -> str:
        columns = [i for i in range(table.shape[1]) if np.any(table[:, i] != table[0, i])]
        rows = "; ".join(f"rank {r}: " + ", ".join(f"{self.FIELDS[i]} {table[r, i]:.17g}"
                                                   for i in columns)
                         for r in range(table.shape[0]))
        return (f"the ranks diverged at {where} (check {int(table[0, 0])}): {rows}. A branch "
                "depends on a value the ranks do not share (docs/parallel.md, \"Ranks in "
                "step\")")

    def _abort(self, where: str, mine: np.ndarray, missing: list[int]) -> None:
        from eyemech.problems.run.faults import abort_with_message

        record = ", ".join(f"{name} {value:.17g}" for name, value in zip(self.FIELDS, mine))
        ranks = ", ".join(str(r) for r in missing)
        abort_with_message(
            f"ranks out of step: rank(s) {ranks} of {self.comm.size} did not arrive at "
            f"{where} within {self.timeout:g} s ({TIMEOUT_ENV}); rank {self.comm.rank} "
            f"arrived with {record}. The missing rank(s) wait in a collective call that "
            "this rank never makes (a branch on a value the ranks do not share, e.g. "
            "inside 'if rank == 0'; docs/parallel.md, \"Ranks in step\")")
