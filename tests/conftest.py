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

import gc
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent

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


@pytest.fixture(autouse=True, scope="module")
def meshes_are_freed(request):
    """Every mesh a test module makes is freed when the module ends: a leaked mesh keeps
    its MPI communicators, and a process that runs out of them aborts
    (tests/test_solver_lifetime.py)."""
    gc.collect()
    before = _live_meshes()
    yield
    # the module's last test still holds its fixtures' values (pytest drops them after
    # this teardown): a module-scoped fixture's mesh is not a leak
    for item in request.session.items:
        if item.module is request.module and getattr(item, "funcargs", None):
            item.funcargs.clear()
    gc.collect()
    leaked = _live_meshes() - before
    assert leaked <= 0, f"{leaked} meshes outlive the test module that made them"
