"""SIGINT and SIGTERM: a run stops with exit code 128 + the signal number, also when it
is stuck in C.

Python runs a signal handler only when the main thread executes Python code again; a
rank waiting in an MPI collective call (or in one long MUMPS factorisation) never does,
so a handler alone cannot end a hung job. The command line therefore installs, for the
duration of a command (:func:`stop_signals`):

- a Python handler. Where a run can save its state (a stepped scene that passes
  ``ctx.checkpoints`` to ``follow_path``: it has called :func:`listen`) the first signal
  is recorded and the run stops at the end of its step, after a checkpoint
  (:meth:`~eyemech.problems.run.checkpoint.Checkpoints.step_done`); elsewhere (meshing,
  a scene without checkpoints) there is nothing to save and the process ends at once.
  A second signal ends it at once in any case.
- a watchdog thread woken by ``signal.set_wakeup_fd`` (CPython's C-level handler writes
  the signal's number there at once, whatever the main thread does): when the Python
  handler has not run :data:`GRACE_SECONDS` after a signal, the main thread is stuck in
  C, and the watchdog ends the process; a second signal ends it at once.

The watchdog is a Python thread: it runs while the main thread waits in a call that
releases the GIL (an mpi4py collective call, a sleep, file I/O, gmsh), not while it sits
in one that holds it (petsc4py's solves, DOLFINx's assembly). A divergence between ranks
leaves at least one rank in the first kind -- an mpi4py collective call or the lock-step
check's wait (problems/run/lockstep.py) -- and when that rank ends, mpiexec ends the
others. A process whose main thread holds the GIL takes the signal when the C call
returns (a linear solve: seconds).

Every way out uses ``os._exit(128 + signum)`` after flushing stdout and stderr: under
``mpiexec`` (MPICH hydra forwards SIGINT and SIGTERM to every rank) each rank exits with
that code and so does ``mpiexec`` (tests/test_faults.py). Outside the command line
(the Python API, notebooks) only the graceful stop of :func:`listen` is installed, as a
plain handler for the run's duration.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import sys
import threading
import time
from typing import Iterator

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
EXIT_BASE = 128
GRACE_ENV = "EYEMECH_SIGNAL_GRACE_SECONDS"
# the longest the main thread may stay in C after a signal before the watchdog ends the
# process: longer than one linear solve of the meshes this project runs (a MUMPS
# factorisation of the paper eye takes about a second here, docs/scleral_buckling.md),
# short enough that a hung job ends in seconds
GRACE_SECONDS = 10.0


class _State:
    def __init__(self) -> None:
        self.lock = threading.Condition()
        self.received = 0        # the first stop signal's number (0: none)
        self.taken = 0           # signals the Python handler ran for
        self.listeners = 0       # runs that stop at a step's end (listen/unlisten)
        self.managed = False     # stop_signals() is active (the command line)
        self.rank = 0            # who prints the message
        self.previous: dict[int, object] = {}   # handlers before ours
        self.previous_fd = -1
        self.pipe: tuple[int, int] | None = None
        self.watchdog: threading.Thread | None = None


_state = _State()


def requested() -> int:
    """The stop signal received since the current run listened (0: none)."""
    return _state.received


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def listen() -> None:
    """A run that can stop at a step's end (after a checkpoint) is running: the first
    signal is recorded (:func:`requested`) instead of ending the process."""
    if not _main_thread():
        return
    if _state.listeners == 0:
        _state.received = 0
        if not _state.managed:  # the Python API: a plain handler for the run's duration
            _state.previous = {s: signal.signal(s, _on_signal) for s in STOP_SIGNALS}
        else:  # set again at the C level (gmsh may have reset it, see _rearm)
            for signum in STOP_SIGNALS:
                signal.signal(signum, _on_signal)
    _state.listeners += 1


def unlisten() -> None:
    if not _main_thread() or _state.listeners == 0:
        return
    _state.listeners -= 1
    if _state.listeners == 0 and not _state.managed:
        for signum, handler in _state.previous.items():
            signal.signal(signum, handler)
        _state.previous = {}


def _on_signal(signum: int, _frame) -> None:
    with _state.lock:
        _state.taken += 1
        _state.lock.notify_all()
    if _state.received:  # asked twice: at once
        if not _state.managed:  # the Python API: the previous handler's action
            for stop, handler in _state.previous.items():
                signal.signal(stop, handler)
            _state.previous, _state.listeners = {}, 0
            os.kill(os.getpid(), signum)
            return
        _end(signum, "a second time")
    _state.received = signum
    if not _state.listeners:
        _end(signum, "with nothing to save (this scene writes no checkpoints, or it has "
                     "not reached its first step)")


def _end(signum: int, why: str, every_rank: bool = False) -> None:
    """End the process now with 128 + ``signum`` (no clean-up: other ranks may be waiting
    in a collective call that this one will never join). Rank 0 says why; with
    ``every_rank`` (a rank stuck in C: its own state) every rank does."""
    name = signal.Signals(signum).name
    with contextlib.suppress(Exception):
        sys.stdout.flush()
    if _state.rank == 0 or every_rank:
        who = f"rank {_state.rank}: " if every_rank else ""
        with contextlib.suppress(Exception):
            sys.stderr.write(f"eyemech: {who}stopped by {name} {why}\n")
            sys.stderr.flush()
    os._exit(EXIT_BASE + signum)


def grace_seconds() -> float:
    text = os.environ.get(GRACE_ENV, "").strip()
    try:
        return float(text) if text else GRACE_SECONDS
    except ValueError:
        return GRACE_SECONDS


# -- the C-level handlers --------------------------------------------------------------
# gmsh's initialisation resets SIGTERM (and SIGSEGV, SIGFPE, SIGHUP) to the default action
# at the C level, behind Python's back: the PETSc that libgmsh bundles pushes and pops its
# signal handlers. A SIGTERM then kills the process by the signal (mpiexec exits with 15).
# PETSc reads PETSC_OPTIONS when it initialises, so ``-no_signal_handler`` there, set after
# our own PETSc has started (its options database does not see it), keeps gmsh's PETSc off
# the handlers; the watchdog also puts them back within REARM_SECONDS should anything
# else replace them.
REARM_SECONDS = 0.1
GMSH_PETSC_OPTION = "-no_signal_handler"
_SIGACTION_BYTES = 256  # more than any libc's struct sigaction


def _libc():
    import ctypes

    return ctypes.CDLL(None, use_errno=True)


def _sigaction(signum: int) -> bytes | None:
    """The signal's current ``struct sigaction`` (opaque bytes), None where unavailable."""
    import ctypes

    try:
        buffer = ctypes.create_string_buffer(_SIGACTION_BYTES)
        if _libc().sigaction(signum, None, buffer) != 0:
            return None
        return buffer.raw
    except (OSError, AttributeError):
        return None


def _rearm(saved: dict[int, bytes]) -> None:
    """Put back each saved handler that something replaced (its first field, the handler,
    differs)."""
    import ctypes

    size = ctypes.sizeof(ctypes.c_void_p)
    for signum, action in saved.items():
        if signal.getsignal(signum) is not _on_signal:  # Python code chose another handler
            continue
        now = _sigaction(signum)
        if now is not None and now[:size] != action[:size]:
            _libc().sigaction(signum, ctypes.create_string_buffer(action, len(action)), None)


def _watch(read_fd: int, grace: float, saved: dict[int, bytes]) -> None:
    """The watchdog: reads the signal numbers CPython writes to the wakeup pipe, and keeps
    the handlers in place."""
    received, deadline = 0, None
    while True:
        _rearm(saved)
        timeout = REARM_SECONDS if deadline is None \
            else min(REARM_SECONDS, max(0.0, deadline - time.monotonic()))
        ready, _, _ = select.select([read_fd], [], [], timeout)
        if ready:
            try:
                data = os.read(read_fd, 64)
            except OSError:
                return
            if not data:
                return
            for signum in data:
                if signum == 0:  # the stop sentinel of stop_signals()
                    return
                if signum not in STOP_SIGNALS:
                    continue
                received += 1
                if received >= 2:
                    _end(signum, "a second time")
                deadline, last = time.monotonic() + grace, signum
        if deadline is not None:
            with _state.lock:
                taken = _state.taken >= received
            if taken:
                deadline = None
            elif time.monotonic() >= deadline:
                _end(last, f"while stuck in a call to C for {grace:g} s (a collective call "
                           "other ranks do not make, or a long linear solve; "
                           f"{GRACE_ENV} sets the wait)", every_rank=True)


@contextlib.contextmanager
def stop_signals(rank: int = 0) -> Iterator[None]:
    """SIGINT/SIGTERM handling of a command (see the module's text); restores the
    previous handlers and wakeup fd when it ends. Main thread only."""
    if not _main_thread() or _state.managed:
        yield
        return
    petsc_options = os.environ.get("PETSC_OPTIONS")
    os.environ["PETSC_OPTIONS"] = f"{petsc_options or ''} {GMSH_PETSC_OPTION}".strip()
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)
    _state.rank, _state.received, _state.taken = rank, 0, 0
    _state.previous = {s: signal.signal(s, _on_signal) for s in STOP_SIGNALS}
    saved = {s: a for s in STOP_SIGNALS if (a := _sigaction(s)) is not None}
    _state.previous_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    _state.managed, _state.pipe = True, (read_fd, write_fd)
    watchdog = threading.Thread(target=_watch, args=(read_fd, grace_seconds(), saved),
                                name="eyemech-signal-watchdog", daemon=True)
    watchdog.start()
    try:
        yield
    finally:
        if petsc_options is None:
            os.environ.pop("PETSC_OPTIONS", None)
        else:
            os.environ["PETSC_OPTIONS"] = petsc_options
        signal.set_wakeup_fd(_state.previous_fd)
        for signum, handler in _state.previous.items():
            signal.signal(signum, handler)
        _state.previous, _state.managed = {}, False
        with contextlib.suppress(OSError):
            os.write(write_fd, b"\0")
        watchdog.join(timeout=1.0)
        for fd in (read_fd, write_fd):
            with contextlib.suppress(OSError):
                os.close(fd)
        _state.pipe = None
