"""A solver that is no longer referenced is freed, with its mesh and its PETSc objects.

PETSc keeps the Python callbacks of a SNES or a KSP in C, where Python's garbage
collector cannot follow them: a callback bound to the solver that owns the SNES makes a
cycle that is never freed. Each leaked mesh keeps its MPI communicators, and MPICH has
2,048 a process: a test session (or a notebook running a parameter study) that
leaks a few meshes per run aborts ("Too many communicators"; in CI, exit status 15 and
no pytest summary) after a few hundred runs (problems/solve/callbacks.py).
"""

from __future__ import annotations

import gc
import json
import subprocess
import sys
import weakref
from pathlib import Path

# isort: off
from mpi4py import MPI  # first: it loads the libmpi DOLFINx's extension links against
# isort: on
import dolfinx
import dolfinx.fem
import dolfinx.mesh
import numpy as np
import pytest
import ufl

from eyemech.problems.solve.driver import NewtonOptions, NonlinearSolver


def _solve_and_forget(options: NewtonOptions) -> tuple[weakref.ref, weakref.ref]:
    """Weak references to a solver and its mesh after a solve that kept no other."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 6, 6)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    residual = ((1 + u**2) * ufl.inner(ufl.grad(u), ufl.grad(v)) - 10.0 * v) * ufl.dx
    facets = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x: np.full(x.shape[1], True))
    bc = dolfinx.fem.dirichletbc(0.0, dolfinx.fem.locate_dofs_topological(V, 1, facets), V)
    solver = NonlinearSolver(residual, u, [bc], options=options)
    converged, _ = solver.solve()
    assert converged
    return weakref.ref(solver), weakref.ref(mesh)


@pytest.mark.parametrize("linear_reuse", ["none", "krylov"])
def test_a_dropped_solver_frees_its_mesh(linear_reuse):
    solver, mesh = _solve_and_forget(NewtonOptions(linear_reuse=linear_reuse))
    gc.collect()
    assert solver() is None, "the solver outlives its last reference (a cycle through PETSc)"
    assert mesh() is None, "the mesh outlives its solver"


def test_a_run_closes_its_solvers_as_it_ends():
    """The run contract destroys a run's PETSc solvers when it ends, on every rank at the
    same point: destroying a MUMPS factorisation is collective, and Python's collector
    would free a solver kept in a cycle at a different moment on each rank."""
    from eyemech.problems import sphere_inflation
    from eyemech.problems.run import newton
    from eyemech.problems.run.context import RunOptions
    from eyemech.problems.solve import driver

    before = driver.solvers_created()
    sphere_inflation.run(sphere_inflation.Parameters(),
                         options=RunOptions(fields=False, pictures=False))
    assert driver.solvers_created() > before, "the run made no solver"
    assert not [serial for serial in newton._OPEN_SOLVERS if serial > before]


@pytest.mark.mpi
def test_runs_on_two_ranks_give_back_their_communicators():
    """Four sphere-inflation runs in one 2-rank process (as a sweep runs its cases): after
    the first (which keeps what lasts, e.g. PETSc's communicator of COMM_WORLD), every run
    gives back every communicator it took (tests/lifetime_runs.py)."""
    script = Path(__file__).parent / "lifetime_runs.py"
    command = [str(Path(sys.executable).parent / "mpiexec"), "-n", "2", sys.executable,
               str(script), "sphere-inflation", "4"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    free = json.loads([line for line in done.stdout.splitlines() if line.startswith("{")][-1])
    counts = free["free_communicators"]
    assert counts[1:] == [counts[1]] * 3, counts
