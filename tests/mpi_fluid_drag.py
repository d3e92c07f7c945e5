"""iol-injection's fluid drag on N ranks against its serial self (no pytest here):

    mpiexec -n N python tests/mpi_fluid_drag.py

``FluidDrag`` (problems/iol_injection.py) writes the fluid's nodal velocity into the mass
matrix's (unghosted) right vector and keeps −c M v_f for the residual. A vector P2 field on a
strip along the injector axis (x from the bore through the taper and past the nozzle tip: plug
flow and jet), displaced, is built on COMM_WORLD (partitioned) and, on every rank, on
COMM_SELF (the serial reference); the drag's owned rows are compared node by node (matched by
coordinates). Before the fix the N-rank drag was zero: the values went to the vector's
localForm(), a null Vec on N > 1 ranks. Rank 0 prints one JSON line.
"""

from __future__ import annotations

import json
import types

import basix.ufl
import numpy as np
from mpi4py import MPI

try:
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass
import dolfinx
import dolfinx.fem.petsc
import ufl
from scipy.spatial import cKDTree

from eyemech.forms.dynamics import mass_form
from eyemech.problems.iol_injection import FluidDrag
from eyemech.problems.lens.model import InjectorLayout, LensParameters
from eyemech.problems.solve.time_integration import ImplicitDynamics

SPEED = 40.0  # mm/s, the plunger's


def drag(comm: MPI.Comm) -> tuple[np.ndarray, np.ndarray, float]:
    """(owned node coordinates, their drag rows, the drag's global x resultant) on ``comm``."""
    mesh = dolfinx.mesh.create_rectangle(comm, [[5.0, -1.0], [13.0, 1.0]], [24, 4])
    V = dolfinx.fem.functionspace(mesh, basix.ufl.element("Lagrange", "triangle", 2, shape=(3,)))
    X = V.tabulate_dof_coordinates()
    u = dolfinx.fem.Function(V)
    u.x.array[:] = np.column_stack([0.2 * np.sin(X[:, 1]), 0.0 * X[:, 0], 0.1 * X[:, 1] ** 2]).ravel()
    u.x.scatter_forward()
    density = dolfinx.fem.Constant(mesh, 1.1e-9)
    thickness = dolfinx.fem.Constant(mesh, 0.2)
    dynamics = ImplicitDynamics(u, mass_form(ufl.TrialFunction(V), ufl.TestFunction(V), density,
                                             thickness, ufl.dx), scheme_name="backward-euler", damping=2e4)
    shell = types.SimpleNamespace(u=u, node_coordinates=V.tabulate_dof_coordinates)
    fluid = FluidDrag(dynamics, shell, InjectorLayout().cartridge(LensParameters()), jet_length=2.0)
    fluid.begin_step(SPEED)
    owned = V.dofmap.index_map.size_local
    rows = fluid.drag.array_r.reshape(-1, 3).copy()
    return X[:owned], rows, comm.allreduce(float(rows[:, 0].sum()), op=MPI.SUM)


comm = MPI.COMM_WORLD
X, rows, resultant = drag(comm)
X_serial, rows_serial, resultant_serial = drag(MPI.COMM_SELF)
distance, index = cKDTree(X_serial).query(X)
assert distance.max(initial=0.0) < 1e-12
scale = np.abs(rows_serial).max()
difference = comm.allreduce(float(np.abs(rows - rows_serial[index]).max(initial=0.0)), op=MPI.MAX)
if comm.rank == 0:
    print(json.dumps({"ranks": comm.size, "resultant": resultant, "resultant_serial": resultant_serial,
                      "max_row_difference": difference / scale}))
