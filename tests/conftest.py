"""Shared test helpers: run the command line (serially or under mpiexec) and read
the JSON it prints as its last stdout line."""

from __future__ import annotations

# Test modules import dolfinx beside eyemech; the PyPI DOLFINx wheel needs dolfinx_solver
# imported first (it orders MPI ahead of the compiled bindings), and conftest is imported
# before every test module.
try:
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass

import faulthandler
import gc
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent

# A module may keep this many MPI communicators for good: the first use of PETSc and of
# a scene makes a few that last the process (measured: 2 on 2 ranks, tests/lifetime_runs.py).
# A module that keeps more leaks them, and MPICH has 2,048 a process: a process that runs
# out aborts (exit status 15 after "Too many communicators") or crashes where DOLFINx or
# MUMPS goes on with the failed MPI_Comm_dup's communicator (docs/parallel.md, "Long
# processes").
COMMUNICATORS_A_MODULE_MAY_KEEP = 8

# How closely 1 and 2 ranks agree on node-to-surface contact quantities. A slave node
# keeps its previous master triangle while its projection stays within STICKY = 2 % of
# the triangle's size beyond an edge, so the converged state depends on the path of the
# Newton iterates, and round-off that differs between partitions (or CPUs) can end a
# node on the neighbouring plane. Measured: 3e-5 relative in the maximum penetration
# (2.6e-9 mm). A partition bug -- a contact force lost or counted twice on a shared
# node -- changes these by O(1), so 1e-3 still catches it.
CONTACT_RANKS_RTOL = 1e-3


def run_cli(*args: str, ranks: int = 1, timeout: float = 900) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of ``eyemech args...``."""
    command = [str(BIN / "eyemech"), *args]
    if ranks > 1:
        command = [str(BIN / "mpiexec"), "-n", str(ranks), *command]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.run(command, capture_output=True, text=True, timeout=timeout, env=env)
    return proc.returncode, proc.stdout, proc.stderr


def last_json(stdout: str) -> dict:
    lines = [line for line in stdout.strip().splitlines() if line.startswith("{")]
    assert lines, f"no JSON line in output:\n{stdout}"
    return json.loads(lines[-1])


@pytest.fixture
def cli():
    return run_cli


@pytest.fixture
def compilations(monkeypatch):
    """Calls of FFCx's C compilation (its disk cache is consulted first)."""
    import ffcx.codegeneration.jit as jit

    calls = []
    compile_objects = jit._compile_objects

    def counted(*args, **kwargs):
        calls.extend(str(form)[:300] for form in args[1])
        return compile_objects(*args, **kwargs)

    monkeypatch.setattr(jit, "_compile_objects", counted)
    return calls


def _live_meshes() -> int:
    import dolfinx.mesh

    return sum(1 for obj in gc.get_objects() if isinstance(obj, dolfinx.mesh.Mesh))


def free_communicators() -> int:
    from eyemech.scripts.sweep_lifetime import free_communicators as probe

    return probe()


class ProcessLog:
    """What is left of a test process that ends abruptly, in the file that
    ``EYEMECH_TEST_LOG`` names (``make test`` sets it and prints its end when the suite
    fails): the test that started last and the free communicators then, the free
    communicators and the resident memory after each module, and Python's traceback of
    every thread on a fatal signal (faulthandler; a crash that overwrote Python's memory
    leaves it incomplete, docs/parallel.md, "Long processes"). pytest captures file
    descriptors 1 and 2 while a test runs, and an abrupt end loses what the test printed
    there (an MPI_Abort's message, PETSc's "Caught signal" block)."""

    def __init__(self, path: str | None):
        self.file = open(path, "a", buffering=1) if path else None  # noqa: SIM115

    def write(self, text: str) -> None:
        if self.file is not None:
            self.file.write(f"{time.strftime('%H:%M:%S')} {text}\n")

    def catch_fatal_signals(self) -> None:
        """Python's faulthandler on SIGSEGV, SIGFPE, SIGABRT, SIGBUS and SIGILL, writing to
        the log. PETSc's signal handler, which PETSc installs when petsc4py is first
        imported, would take SIGSEGV first, print into the captured stderr and call
        MPI_Abort (exit status 59): it is removed."""
        if self.file is None:
            return
        from petsc4py import PETSc

        PETSc.Sys.popSignalHandler()
        # enabled already (pytest's faulthandler plugin), enable() would only change the
        # file and leave the signals to the default action PETSc's pop restored
        faulthandler.disable()
        faulthandler.enable(file=self.file, all_threads=True)


_TEST_LOG = ProcessLog(os.environ.get("EYEMECH_TEST_LOG"))


def pytest_sessionstart(session):
    _TEST_LOG.catch_fatal_signals()
    _TEST_LOG.write(f"pid {os.getpid()} started: {' '.join(sys.argv[1:])}")


def pytest_runtest_logstart(nodeid, location):
    # the free communicators as each test starts (20 ms): the last line of a process
    # that ran out says so, even where the crash leaves faulthandler no readable frames
    if _TEST_LOG.file is not None:
        _TEST_LOG.write(f"start {nodeid} ({free_communicators()} communicators free)")


def pytest_sessionfinish(session, exitstatus):
    _TEST_LOG.write(f"pid {os.getpid()} finished: exit status {int(exitstatus)}")


@pytest.fixture(autouse=True, scope="module")
def meshes_are_freed(request):
    """Every mesh a test module makes is freed when the module ends, and the module keeps
    no more than ``COMMUNICATORS_A_MODULE_MAY_KEEP`` MPI communicators: a leaked mesh
    keeps its communicators, and a process that runs out of them aborts or crashes
    (tests/test_solver_lifetime.py)."""
    gc.collect()
    before = _live_meshes()
    free_before = free_communicators()
    yield
    # the module's last test still holds its fixtures' values (pytest drops them after
    # this teardown): a module-scoped fixture's mesh is not a leak
    for item in request.session.items:
        if item.module is request.module and getattr(item, "funcargs", None):
            item.funcargs.clear()
    gc.collect()
    leaked = _live_meshes() - before
    free_after = free_communicators()
    from eyemech.scripts.sweep_lifetime import resident_mb

    _TEST_LOG.write(f"module {request.module.__name__}: {free_after} communicators free "
                    f"({free_before - free_after} kept), {resident_mb():.0f} MB resident")
    assert leaked <= 0, f"{leaked} meshes outlive the test module that made them"
    kept = free_before - free_after
    assert kept <= COMMUNICATORS_A_MODULE_MAY_KEEP, (
        f"the test module keeps {kept} MPI communicators ({free_after} free)")
