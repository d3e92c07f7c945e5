"""scripts/mumps_options.py: the option sets reach MUMPS and the timed solves are solves."""
import numpy as np
from mpi4py import MPI  # noqa: F401  (loads MPI before petsc4py)
from petsc4py import PETSc

from eyemech.scripts.mumps_options import time_matrices


def _laplacian(n: int) -> PETSc.Mat:
    """The 5-point Laplacian on an n × n grid plus one dense row and column (as the eye's
    Real unknowns), unsymmetric."""
    size = n * n + 1
    A = PETSc.Mat().createAIJ((size, size), nnz=size, comm=PETSc.COMM_SELF)
    for i in range(n):
        for j in range(n):
            k = i * n + j
            A.setValue(k, k, 4.0)
            for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                if 0 <= i + di < n and 0 <= j + dj < n:
                    A.setValue(k, (i + di) * n + j + dj, -1.0)
            A.setValue(k, size - 1, 1e-2)
            A.setValue(size - 1, k, 2e-2)
    A.setValue(size - 1, size - 1, 1.0)
    A.assemble()
    return A


def test_orderings_reach_mumps_and_solve(tmp_path):
    path = tmp_path / "laplacian.bin"
    viewer = PETSc.Viewer().createBinary(str(path), "w", comm=PETSc.COMM_SELF)
    _laplacian(30).view(viewer)
    viewer.destroy()
    timings = {t.option_set: t for t in time_matrices([str(path)], ["scotch", "metis", "blr-1e-8"],
                                                      rounds=1, repeats=1)}
    # INFOG(7), the ordering MUMPS used: 3 SCOTCH, 5 METIS
    assert timings["scotch"].ordering == 3
    assert timings["metis"].ordering == 5
    for name in ("scotch", "metis"):
        # full-rank LU of a 901-unknown Laplacian: measured ≈ 1e-16
        assert timings[name].residual < 1e-12
        assert timings[name].factor_entries > 0 and timings[name].flops > 0
    # block low-rank at 1e-8: measured ≈ 1e-16 here (fronts too small to compress)
    assert timings["blr-1e-8"].residual < 1e-6
    assert np.isfinite(timings["blr-1e-8"].factorisation)
