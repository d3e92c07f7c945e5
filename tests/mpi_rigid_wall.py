"""The lens' rigid-wall contact when only some ranks touch a wall (no pytest here):

    mpiexec -n N python tests/mpi_rigid_wall.py

A unit cube of vector P1 on N ranks against a plane x = 0.3 that acts on rank 0's nodes
only, as when one part of the lens meets the cartridge. The Jacobian hook adds k n⊗n for
rank 0's pressed nodes and must assemble the matrix on every rank (a collective call): a
rank that skipped it left the others waiting (the fold on 3 ranks hung there). Rank 0
prints one JSON line: the pressed nodes per rank and the trace the hook added.
"""

from __future__ import annotations

import json

import numpy as np
from mpi4py import MPI

try:
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass
import dolfinx
import dolfinx.fem.petsc
import ufl

from eyemech.problems.contact.rigid_wall import NodalContact

STIFFNESS = 10.0


class RankZeroPlane:
    """The plane x = 0.3 (gap x − 0.3, normal e_x), acting on rank 0's nodes only."""

    def gap_normal(self, x: np.ndarray):
        normal = np.tile([1.0, 0.0, 0.0], (len(x), 1))
        acts = np.full(len(x), MPI.COMM_WORLD.rank == 0)
        return x[:, 0] - 0.3, normal, acts


comm = MPI.COMM_WORLD
mesh = dolfinx.mesh.create_unit_cube(comm, 4, 4, 4)
V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
w = ufl.TrialFunction(V)
mass = dolfinx.fem.form(ufl.inner(w, v) * ufl.dx)
J = dolfinx.fem.petsc.assemble_matrix(mass)
J.assemble()
trace_before = J.getDiagonal().sum()
contact = NodalContact(u, {"plane": RankZeroPlane()}, stiffness=STIFFNESS, smoothing=0.0)
pressed = sum(len(nodes) for nodes, *_ in contact._pressed(contact.positions()))
x = u.x.petsc_vec
contact.jacobian_hook(x, J)
added = J.getDiagonal().sum() - trace_before
counts = comm.gather(pressed, root=0)
if comm.rank == 0:
    print(json.dumps({"ranks": comm.size, "pressed_nodes": counts, "trace_added": added,
                      "expected": STIFFNESS * sum(counts)}))
J.destroy()
