"""A solver that is no longer referenced is freed, with its mesh and its PETSc objects.

PETSc keeps the Python callbacks of a SNES or a KSP in C, where Python's garbage
collector cannot follow them: a callback bound to the solver that owns the SNES makes a
cycle that is never freed. Each leaked mesh keeps its MPI communicators, and MPICH has
about 2,000 a process: a test session (or a notebook running a parameter study) that
leaks a few meshes per run ends with MPI_Abort(MPI_ERR_OTHER), exit status 15, after a
few hundred runs (problems/solve/callbacks.py).
"""

from __future__ import annotations

import gc
import weakref

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
