"""Faults: the MPI error path and the test hooks that inject faults.

The error path. Under MPI every rank runs the same code, and most library calls are
collective: when one rank raises an exception that the other ranks do not raise, the
others wait for it in some collective call (a vector norm inside SNES, an ADIOS2 close, a
barrier) and the job never ends. Exceptions that every rank raises alike -- a failed
Newton solve (the convergence test is global), a stop on SIGINT/SIGTERM (the ranks agree
by an allreduce), bad input found by the shared validation -- are left to the normal
path. Any other exception on a communicator of more than one rank is *stranding*: the
first shared place that sees it (a collective writer's ``close``, ``RunContext.__exit__``,
the command line) prints the rank's traceback and calls ``MPI_Abort``, so ``mpiexec``
ends the whole job at once. Nothing collective may run between the exception and the
abort: writers skip their collective ``close`` while such an exception propagates.

The test hooks (environment variables, read where the fault is injected):

- ``EYEMECH_TEST_RAISE_ON_RANK=R``: rank R raises inside the residual assembly of each
  Newton solver's second residual evaluation (after Newton's first update), while the
  other ranks are inside collective calls.
- ``EYEMECH_TEST_KILL``: ``step:N`` (SIGKILL inside Newton of the N-th step of the run),
  ``checkpoint:N`` (SIGKILL inside the N-th checkpoint write, before its commit),
  ``sigterm:N[:RANK]`` (SIGTERM to this process -- or only to rank RANK -- inside Newton
  of step N).
- ``EYEMECH_TEST_DIVERGE``: ``collective:N:RANK`` (rank RANK makes one collective call
  more than the others at the end of step N, as a picture drawn on rank 0 that reads a
  distributed unknown would), ``decision:N:RANK`` (rank RANK records another path value at
  the end of step N, as a branch on local data would), ``hang:N:RANK`` (rank RANK waits
  in a collective call no other rank makes, inside Newton of step N: a job stuck in C for
  the signal tests), ``petsc:N:RANK`` (rank RANK's residual raises a PETSc error inside
  Newton of step N: SNES fails on that rank only). The lock-step checks
  (problems/run/lockstep.py) must turn each into an error.
"""

from __future__ import annotations

import errno
import os
import sys
import time
import traceback

RAISE_ENV = "EYEMECH_TEST_RAISE_ON_RANK"
KILL_ENV = "EYEMECH_TEST_KILL"
DIVERGE_ENV = "EYEMECH_TEST_DIVERGE"

# exit code of a job ended by MPI_Abort after an exception on one rank
EXIT_RANK_FAILED = 1
# ... after the output folder could not take a file (disk full, quota, read-only): the
# run contract's code of an unusable --out folder
EXIT_OUTPUT = 2
ABORT_GRACE_SECONDS = 0.5
# the errors of a folder that cannot take the run's files (docs/cli.md, exit code 2)
OUTPUT_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EIO)


def output_error(error: BaseException | None) -> bool:
    """Whether ``error`` says that the output folder cannot take a file."""
    return isinstance(error, OSError) and error.errno in OUTPUT_ERRNOS


def describe_output_error(error: OSError) -> str:
    where = f"cannot write {error.filename}" if error.filename else "cannot write the output"
    return (f"{where}: {error.strerror or error} (the files written before are kept; "
            "free space or choose another --out)")


def test_raise_rank(comm) -> bool:
    """Whether this rank is the one ``EYEMECH_TEST_RAISE_ON_RANK`` names."""
    value = os.environ.get(RAISE_ENV, "").strip()
    return value != "" and int(value) == comm.rank


def raise_test_error(rank: int) -> None:
    raise RuntimeError(f"{RAISE_ENV}: test error on rank {rank} inside the residual")


def parse_kill(spec: str | None = None) -> tuple[str, int, int | None]:
    """``EYEMECH_TEST_KILL`` as (kind, number, rank or None); ("", 0, None) when unset."""
    spec = os.environ.get(KILL_ENV, "") if spec is None else spec
    if not spec:
        return "", 0, None
    parts = spec.split(":")
    return parts[0], int(parts[1]), (int(parts[2]) if len(parts) > 2 else None)


def parse_divergence(spec: str | None = None) -> tuple[str, int, int]:
    """``EYEMECH_TEST_DIVERGE`` as (kind, step, rank); ("", 0, -1) when unset."""
    spec = os.environ.get(DIVERGE_ENV, "") if spec is None else spec
    if not spec:
        return "", 0, -1
    kind, step, rank = spec.split(":")
    if kind not in ("collective", "decision", "hang", "petsc"):
        raise ValueError(f"{DIVERGE_ENV}={spec}: the kind is collective, decision, hang or "
                         "petsc")
    return kind, int(step), int(rank)


def plant_divergence(comm, steps_done: int, decision: list[float]) -> None:
    """Test hook (``EYEMECH_TEST_DIVERGE``): at the end of step ``steps_done`` the named
    rank leaves the others' control flow -- one collective call more, or another path
    value (``decision[4]``) in the step's lock-step record."""
    kind, step, rank = parse_divergence()
    if step != steps_done or comm is None or rank != comm.rank:
        return
    if kind == "collective":
        from mpi4py import MPI

        comm.allreduce(0, op=MPI.SUM)
    elif kind == "decision":
        decision[4] += 1.0


def collective_error(error: BaseException | None) -> bool:
    """Whether ``error`` is raised on every rank alike (or is no error at all)."""
    if error is None:
        return True
    from eyemech.meshes import MeshError
    from eyemech.problems.run.checkpoint import CheckpointError, Interrupted
    from eyemech.problems.run.lockstep import RanksDiverged
    from eyemech.problems.run.newton import SolveFailure
    from eyemech.problems.run.parameters import ParameterError

    return isinstance(error, (SolveFailure, Interrupted, ParameterError, MeshError,
                              CheckpointError, RanksDiverged, KeyboardInterrupt, SystemExit))


def propagating() -> BaseException | None:
    """The exception being handled or propagating through a ``finally`` here, if any."""
    return sys.exc_info()[1]


def stranding(comm, error: BaseException | None) -> bool:
    """Whether ``error`` on this rank may leave the other ranks of ``comm`` waiting."""
    return comm is not None and comm.size > 1 and not collective_error(error)


def abort(comm, error: BaseException | None = None) -> None:
    """Print this rank's traceback and end the whole job with ``MPI_Abort``."""
    from mpi4py import MPI

    world = MPI.COMM_WORLD
    error = error if error is not None else sys.exc_info()[1]
    sys.stdout.flush()
    if output_error(error):
        print(f"eyemech: rank {world.rank} of {world.size}: {describe_output_error(error)}",
              file=sys.stderr, flush=True)
    else:
        text = "".join(traceback.format_exception(error)) if error is not None \
            else traceback.format_exc()
        print(f"eyemech: rank {world.rank} of {world.size} failed:\n{text}", file=sys.stderr,
              flush=True)
    # mpiexec forwards each rank's output through its proxies; MPI_Abort tears them down,
    # and output still in transit is lost (seen: an empty stderr). Give it a moment.
    time.sleep(ABORT_GRACE_SECONDS)
    (comm or world).Abort(EXIT_OUTPUT if output_error(error) else EXIT_RANK_FAILED)


def abort_with_message(text: str) -> None:
    """Print ``text`` as this rank's reason and end the whole job with ``MPI_Abort``."""
    from mpi4py import MPI

    world = MPI.COMM_WORLD
    sys.stdout.flush()
    print(f"eyemech: rank {world.rank} of {world.size}: {text}", file=sys.stderr, flush=True)
    time.sleep(ABORT_GRACE_SECONDS)  # see abort()
    world.Abort(EXIT_RANK_FAILED)


def abort_if_stranding(comm, error: BaseException | None = None) -> None:
    """Abort the job when ``error`` (default: the exception propagating here) would
    leave other ranks of ``comm`` waiting; return otherwise. Call it before any
    collective operation in ``finally`` blocks and ``__exit__`` methods."""
    error = propagating() if error is None else error
    if error is not None and stranding(comm, error):
        abort(comm, error)
