"""io4dolfinx (h5py backend) on DOLFINx 0.11: write on N ranks, read on M (docs/restart.md)."""
# ruff: noqa: I001  (h5py must come before DOLFINx: each loads its own HDF5)
import sys
# run with io4dolfinx, fenicsx-compat and h5py importable (pip install --target DIR ...,
# PYTHONPATH=DIR): python tests/io4dolfinx_trial.py write|read FILE.h5, also under mpiexec -n 2
import h5py  # noqa  (its own HDF5 before DOLFINx loads the wheel's)
import dolfinx_solver  # noqa
from pathlib import Path
import numpy as np
from mpi4py import MPI
import dolfinx
import io4dolfinx

mode, path = sys.argv[1], Path(sys.argv[2])
comm = MPI.COMM_WORLD
def exact(x):
    return np.vstack([x[0] + 2 * x[1], x[1] * x[2], np.sin(x[0])])
try:
    if mode == "write":
        mesh = dolfinx.mesh.create_unit_cube(comm, 4, 4, 4, cell_type=dolfinx.mesh.CellType.hexahedron)
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", 2, (3,)))
        u = dolfinx.fem.Function(V, name="u")
        u.interpolate(exact)
        io4dolfinx.write_mesh(path, mesh, backend="h5py")
        io4dolfinx.write_function(path, u, time=1.0, backend="h5py")
        print(f"rank {comm.rank}/{comm.size}: wrote", flush=True)
    else:
        mesh = io4dolfinx.read_mesh(path, comm, backend="h5py")
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", 2, (3,)))
        u = dolfinx.fem.Function(V, name="u")
        io4dolfinx.read_function(path, u, time=1.0, backend="h5py")
        ref = dolfinx.fem.Function(V)
        ref.interpolate(exact)
        err = comm.allreduce(float(np.max(np.abs(u.x.array - ref.x.array))), op=MPI.MAX)
        print(f"rank {comm.rank}/{comm.size}: read, max error {err:.2e}", flush=True)
except Exception as e:
    print(f"rank {comm.rank}/{comm.size}: {type(e).__name__}: {e}", flush=True)
    comm.Abort(3) if comm.size > 1 else sys.exit(3)
