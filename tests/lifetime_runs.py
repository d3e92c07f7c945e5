"""Runs a scene several times in one process and prints (rank 0) one JSON line: the MPI
communicators still free after each run.

    mpiexec -n N python tests/lifetime_runs.py SCENE RUNS

MPICH has 2,048 context ids a process; what a run leaves alive (a mesh, a PETSc object
on a parallel communicator parked in petsc4py's garbage) keeps some, so the count falls
from run to run when something leaks (tests/test_solver_lifetime.py).
"""

from __future__ import annotations

import gc
import json
import sys

# isort: off
from mpi4py import MPI  # first: it loads the libmpi DOLFINx's extension links against
# isort: on

from eyemech.problems import scenes
from eyemech.problems.run.context import RunOptions


def free_communicators(limit: int = 4096) -> int:
    """How many more communicators this process can make (up to ``limit``)."""
    made = []
    try:
        while len(made) < limit:
            made.append(MPI.COMM_SELF.Dup())
    except MPI.Exception:
        pass
    for comm in made:
        comm.Free()
    return len(made)


def main(scene_name: str, runs: int) -> list[int]:
    scene = scenes()[scene_name]
    free = []
    for _ in range(runs):
        scene.run(scene.parameters(), options=RunOptions(fields=False, pictures=False))
        gc.collect()
        free.append(MPI.COMM_WORLD.allreduce(free_communicators(), op=MPI.MIN))
    return free


if __name__ == "__main__":
    counts = main(sys.argv[1], int(sys.argv[2]))
    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps({"free_communicators": counts}))
