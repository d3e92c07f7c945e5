"""Two parallel triangle sheets, the self-contact tests' fixture (tests/test_iol_self_contact.py
serially, tests/mpi_self_contact.py on N ranks)."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

try:
    import dolfinx_solver  # noqa: F401  (the wheel's PETSc before dolfinx)
except ImportError:
    pass
import basix.ufl
import dolfinx.mesh

GAP = 0.1  # mm between the two sheets


def two_sheets(comm: MPI.Comm = MPI.COMM_SELF, n: int = 4, gap: float = GAP) -> dolfinx.mesh.Mesh:
    """A unit square (z = 0) and, ``gap`` above it, a smaller one (0.2 … 0.8, so that it
    cannot slip past the lower one's edges), n × n × 2 triangles each, one P1 mesh on
    ``comm``; rank 0 of ``comm`` holds the input."""
    s = np.linspace(0.0, 1.0, n + 1)
    X, Y = np.meshgrid(s, s, indexing="ij")
    square = np.column_stack([X.ravel(), Y.ravel()])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    tris = np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    points = np.vstack([np.column_stack([square, np.zeros(len(square))]),
                        np.column_stack([0.2 + 0.6 * square, np.full(len(square), gap)])])
    cells = np.vstack([tris, tris + len(square)]).astype(np.int64)
    if comm.rank != 0:
        points, cells = np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    element = basix.ufl.element("Lagrange", "triangle", 1, shape=(3,))
    return dolfinx.mesh.create_mesh(comm, cells, element, points)
