"""What a run makes is freed once nothing references it: its solvers, its meshes and its
PETSc objects, serially and on 2 ranks.

PETSc keeps the Python callbacks of a SNES or a KSP in C, where Python's garbage
collector cannot follow them: a callback bound to the solver that owns the SNES makes a
cycle that is never freed (problems/solve/callbacks.py). On more than one rank petsc4py
parks a PETSc object Python drops in PETSc's garbage until a collective clean-up: the
run contract keeps its solvers to its end and releases its PETSc objects there
(problems/run/petsc_lifetime.py). Whatever is kept holds MPI communicators, and MPICH
has 2,048 a process: a process that runs out aborts (exit status 15 after "Too many
communicators", no pytest summary) or crashes in DOLFINx or MUMPS (docs/parallel.md,
"Long processes").
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


# keratotomy at parallel_cases' coarse size: its two solvers are locals of a function
# that returns before the run ends
KERATOTOMY = ["mesh_size=2.5", "azimuthal_divisions=8", "layers=1", "t_end=1800",
              "first_dt=1800", "dt_growth=1.0", "time_stepping=fixed"]


@pytest.mark.mpi
@pytest.mark.parametrize("scene, runs, sets", [("petsc-objects", 3, []),
                                               ("keratotomy", 2, KERATOTOMY)])
def test_runs_on_two_ranks_give_back_their_communicators(scene, runs, sets):
    """Runs in one 2-rank process (as a sweep runs its cases): after the first (which keeps
    what lasts, e.g. PETSc's communicator of COMM_WORLD), every run gives back every
    communicator it took (tests/lifetime_runs.py). ``petsc-objects`` leaves what scenes
    leave: a solver dropped before the run ends, a matrix held to its end, a vector
    dropped mid-run. Measured without the run contract's release
    (problems/run/petsc_lifetime.py): 8 communicators kept a run, and 14 a coarse
    keratotomy run."""
    script = Path(__file__).parent / "lifetime_runs.py"
    command = [str(Path(sys.executable).parent / "mpiexec"), "-n", "2", sys.executable,
               str(script), scene, str(runs), *sets]
    done = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    free = json.loads([line for line in done.stdout.splitlines() if line.startswith("{")][-1])
    counts = free["free_communicators"]
    assert counts[1:] == [counts[0]] * (runs - 1), counts


@pytest.mark.mpi
def test_a_two_rank_sweep_gives_back_its_communicators(tmp_path):
    """30 cases of a 2-rank sweep in one process (``eyemech sweep --ranks-per-case 2``
    through scripts/sweep_lifetime.py): all end ok and the process can make as many
    communicators after them as before, but for the few the first case keeps for good
    (measured: 1). Without the run contract's release each case kept 2 (the time
    integrator's mass matrices and vectors, parked in PETSc's garbage): 2045 free before
    10 cases, 2023 after. The 1,000-case version is ``make bench-sweep``
    (docs/parallel.md, "Long processes")."""
    command = [str(Path(sys.executable).parent / "mpiexec"), "-n", "2", sys.executable, "-m",
               "eyemech.scripts.sweep_lifetime", "cantilever-vibration", "--cases", "30",
               "--vary", "amplitude=0.005:0.015", "--set", "divisions=2", "--set",
               "periods=0.125", "--set", "steps_per_period=8", "--out", str(tmp_path / "sweep")]
    done = subprocess.run(command, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    row = json.loads([line for line in done.stdout.splitlines() if line.startswith("{")][-1])
    assert row["ok_cases"] == 30
    assert row["free_communicators_before"] - row["free_communicators_after"] <= 3, row
