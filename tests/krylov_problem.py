"""The small nonlinear problem of tests/test_newton_krylov.py, also run on N ranks:

    mpiexec -n N python tests/krylov_problem.py LINEAR_REUSE KRYLOV_MAX_IT

prints (rank 0) one JSON line: ∫u², the residual histories and the solver's counts.

−∇·((1 + u²)∇u) = f on the unit square, u = 0 on its boundary, P1 on 24 × 24 cells, f
raised in four load steps 20, 40, 60, 80 (each a Newton solve from the last): the
conductivity changes by a factor of about 2 across the square, so a factorisation of an
earlier Jacobian is a preconditioner, not an exact inverse, of the current one.
"""

from __future__ import annotations

import json
import sys

# isort: off
from mpi4py import MPI  # first: it loads the libmpi DOLFINx's extension links against
# isort: on
import dolfinx
import dolfinx.fem
import dolfinx.mesh
import numpy as np
import ufl

from eyemech.problems.solve.driver import NewtonOptions, NonlinearSolver

LOADS = (20.0, 40.0, 60.0, 80.0)


def solve(linear_reuse: str = "none", krylov_max_it: int = 20, krylov_predict_after: int = 0,
          reuse_contraction: float = 0.0, comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    mesh = dolfinx.mesh.create_unit_square(comm, 24, 24)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    load = dolfinx.fem.Constant(mesh, 0.0)
    residual = ((1 + u**2) * ufl.inner(ufl.grad(u), ufl.grad(v)) - load * v) * ufl.dx
    facets = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x: np.full(x.shape[1], True))
    bc = dolfinx.fem.dirichletbc(0.0, dolfinx.fem.locate_dofs_topological(V, 1, facets), V)
    options = NewtonOptions(line_search="basic", linear_reuse=linear_reuse,
                            krylov_max_it=krylov_max_it, krylov_predict_after=krylov_predict_after,
                            reuse_contraction=reuse_contraction)
    solver = NonlinearSolver(residual, u, [bc], options=options)
    histories, converged = [], []
    for value in LOADS:
        load.value = value
        ok, _ = solver.solve()
        converged.append(ok)
        histories.append(list(solver.residual_history))
    square = dolfinx.fem.assemble_scalar(dolfinx.fem.form(u * u * ufl.dx))
    stale = solver.stale
    return {"u_squared": comm.allreduce(float(square), op=MPI.SUM), "converged": converged,
            "histories": histories, "counts": solver.counts.as_dict(),
            "refreshes": stale.refreshes if stale else None,
            "refreshes_after_failure": stale.refreshes_after_failure if stale else None,
            "early_refreshes": stale.early_refreshes if stale else None,
            "early_iterations": stale.early_iterations if stale else None,
            "fgmres_iterations": stale.iterations if stale else None}


if __name__ == "__main__":
    result = solve(sys.argv[1], int(sys.argv[2]))
    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps(result))
