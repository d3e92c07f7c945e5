"""Runs a scene several times in one process and prints (rank 0) one JSON line: the MPI
communicators still free after each run.

    mpiexec -n N python tests/lifetime_runs.py SCENE RUNS [KEY=VALUE ...]

MPICH has 2,048 context ids a process; what a run leaves alive (a mesh, a PETSc object
on a parallel communicator parked in PETSc's garbage) keeps some, so the count falls
from run to run when something leaks (tests/test_solver_lifetime.py).

``SCENE`` ``petsc-objects`` is not a scene but a run of the run contract that leaves
behind what scenes leave: a solver dropped before the run ends (keratotomy's solvers are
locals of a function that returns), a matrix still held as it ends (a time integrator's
mass matrix) and a vector petsc4py made and Python dropped mid-run (``getDiagonal``).
"""

from __future__ import annotations

import gc
import json
import sys

# isort: off
from mpi4py import MPI  # first: it loads the libmpi DOLFINx's extension links against
# isort: on

from eyemech.problems import scenes
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.parameters import build
from eyemech.scripts.sweep_lifetime import free_communicators

QUIET = RunOptions(fields=False, pictures=False)


def _solve_in_a_function(comm: MPI.Comm) -> None:
    """A Newton solve whose solver and mesh are locals of this function."""
    import dolfinx
    import numpy as np
    import ufl

    from eyemech.problems.solve.driver import NonlinearSolver

    mesh = dolfinx.mesh.create_unit_square(comm, 6, 6)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    residual = ((1 + u**2) * ufl.inner(ufl.grad(u), ufl.grad(v)) - 10.0 * v) * ufl.dx
    facets = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x: np.full(x.shape[1], True))
    bc = dolfinx.fem.dirichletbc(0.0, dolfinx.fem.locate_dofs_topological(V, 1, facets), V)
    converged, _ = NonlinearSolver(residual, u, [bc]).solve()
    assert converged


def petsc_objects_run(comm: MPI.Comm) -> None:
    import dolfinx
    import dolfinx.fem.petsc
    import ufl

    from eyemech.problems import sphere_inflation

    with RunContext("petsc-objects", sphere_inflation.Parameters(), comm, None, QUIET):
        _solve_in_a_function(comm)
        mesh = dolfinx.mesh.create_unit_square(comm, 4, 4)
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
        u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
        kept = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(u * v * ufl.dx))
        kept.assemble()
        assert kept.getDiagonal().sum() > 0  # the diagonal's vector is dropped at once


def main(scene_name: str, runs: int, overrides: dict[str, str]) -> list[int]:
    free = []
    for _ in range(runs):
        if scene_name == "petsc-objects":
            petsc_objects_run(MPI.COMM_WORLD)
        else:
            scene = scenes()[scene_name]
            scene.run(build(scene.parameters, overrides), options=QUIET)
        gc.collect()
        free.append(MPI.COMM_WORLD.allreduce(free_communicators(), op=MPI.MIN))
    return free


if __name__ == "__main__":
    sets = dict(arg.split("=", 1) for arg in sys.argv[3:])
    counts = main(sys.argv[1], int(sys.argv[2]), sets)
    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps({"free_communicators": counts}))
