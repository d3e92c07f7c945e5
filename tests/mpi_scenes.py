"""Run several scenes through the command line in ONE MPI job (no pytest here):

    mpiexec -n N python tests/mpi_scenes.py OUT SCENE [SCENE ...]

Each scene runs as ``eyemech run SCENE --set ... --out OUT/SCENE --json`` would (the same
``main``), with the coarse overrides of :data:`parallel_cases.CASES`. One job for all
scenes pays the interpreter/DOLFINx start-up once per rank count instead of once per
scene. Every rank's stdout and stderr (file descriptors 1 and 2, so C libraries'
output too) go to ``OUT/SCENE/rank<R>.stdout`` / ``.stderr``: the test reads rank 0's
JSON line from there and checks that the other ranks printed nothing.
"""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

from parallel_cases import cli_arguments  # noqa: E402


@contextlib.contextmanager
def redirected(stdout: Path, stderr: Path):
    """fd-level redirection of 1 and 2 (Python, PETSc and MPI writes alike)."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with stdout.open("w") as out, stderr.open("w") as err:
        os.dup2(out.fileno(), 1)
        os.dup2(err.fileno(), 2)
        try:
            yield
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])


def main() -> int:
    from mpi4py import MPI

    from eyemech.scripts.cli import main as eyemech

    comm = MPI.COMM_WORLD
    out = Path(sys.argv[1])
    for name in sys.argv[2:]:
        folder = out / name
        if comm.rank == 0:
            folder.mkdir(parents=True, exist_ok=True)
        comm.Barrier()
        with redirected(folder / f"rank{comm.rank}.stdout", folder / f"rank{comm.rank}.stderr"):
            code = eyemech(cli_arguments(name, folder))
        if comm.rank == 0:
            (folder / "exit_code").write_text(f"{code}\n")
        comm.Barrier()
    return 0


if __name__ == "__main__":
    sys.exit(main())
