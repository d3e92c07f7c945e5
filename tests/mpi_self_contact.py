"""The lens self-contact's MPI layer against its serial self (no pytest here):

    mpiexec -n N python tests/mpi_self_contact.py

Two P2 sheets 0.1 mm apart (tests/test_iol_self_contact.py), the upper one pushed to within
d̂ of the lower one and slid sideways after the friction was lagged, so that barrier *and*
friction pairs are active. The same mesh is built on COMM_WORLD (partitioned) and, on every
rank, on COMM_SELF (the serial reference). At the same state, compared node by node (matched
by coordinates) on the rows each rank owns:

- the residual hook's rows (barrier + friction gradient; Dirichlet rows left alone);
- the Jacobian hook's rows, as (M + H) w for a smooth field w (M: an L² mass matrix giving
  the finite-element pattern; H couples nodes of different sheets, which may live on
  different ranks, i.e. entries outside the local pattern and in off-process columns);
- the CCD fraction of an update that would push the upper sheet through the lower one,
  the minimum distance and the intersection test.

Rank 0 prints one JSON line: the largest relative differences and the counts.
"""

from __future__ import annotations

import json
import sys

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
from sheets import GAP, two_sheets

from eyemech.problems.contact.ipc import SelfContact

DHAT = 0.05


def p2_sheets(comm: MPI.Comm):
    """tests/sheets.py's two sheets on ``comm``, with the lens' P2 vector space."""
    mesh = two_sheets(comm)
    return dolfinx.fem.functionspace(mesh, basix.ufl.element("Lagrange", "triangle", 2, shape=(3,)))


def pressed(X: np.ndarray, slide: float) -> np.ndarray:
    """The upper sheet 0.075 mm down (0.025 apart: inside d̂), waved, slid by ``slide``.

    The upper sheet is also moved off the lower one's grid lines (0.0137, 0.0071 mm): with a
    node straight above an edge, the closest-point type (face or edge) is a tie that ipctk
    breaks by the order of its candidates, and the squared distance's Hessian jumps across
    that tie (its gradient does not), so a gathered mesh in another order would give another
    Hessian for the same state."""
    upper = X[:, 2] > 0.5 * GAP
    u = np.zeros_like(X)
    u[upper, 2] = -0.075 + 0.004 * np.sin(7 * X[upper, 0]) * np.cos(5 * X[upper, 1])
    u[upper, 0] = 0.0137 + slide * (1 + X[upper, 1])
    u[upper, 1] = 0.0071
    return u


def evaluate(V) -> dict:
    """Everything the hooks give at the test state, per local node (owned first)."""
    X = V.tabulate_dof_coordinates()
    u = dolfinx.fem.Function(V)
    # "Dirichlet" rows (their residual/Jacobian rows stay DOLFINx's): a band of the lower
    # sheet under the upper one, where the barrier pushes
    clamped = np.flatnonzero((np.abs(X[:, 0] - 0.5) < 0.13) & (X[:, 2] < 1e-9))
    contact = SelfContact(u, dhat=DHAT, stiffness=10.0, friction=0.3, slip=1e-3,
                          excluded_dofs=(3 * clamped[:, None] + np.arange(3)).ravel())
    u.x.array[:] = pressed(X, 0.0).ravel()
    u.x.scatter_forward()
    contact.begin_step()  # friction lagged here
    u.x.array[:] = pressed(X, 0.002).ravel()  # slid: friction acts
    u.x.scatter_forward()
    x_vec = u.x.petsc_vec
    F = x_vec.duplicate()
    F.zeroEntries()
    contact.residual_hook(x_vec, F)
    v, w_trial = ufl.TestFunction(V), ufl.TrialFunction(V)
    J = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(ufl.inner(w_trial, v) * ufl.dx))
    J.assemble()
    w = dolfinx.fem.Function(V)
    w.x.array[:] = np.column_stack([np.sin(3 * X[:, 0]), np.cos(2 * X[:, 1]),
                                    X[:, 2] + X[:, 0] * X[:, 1]]).ravel()
    w.x.scatter_forward()
    Mw, Jw = F.duplicate(), F.duplicate()
    J.mult(w.x.petsc_vec, Mw)
    contact.jacobian_hook(x_vec, J)
    J.mult(w.x.petsc_vec, Jw)
    # an update through the lower sheet: x − y with y = +0.2 in z on the upper sheet
    y_vec = x_vec.duplicate()
    n = V.dofmap.index_map.size_local
    y = np.zeros((n, 3))
    y[X[:n, 2] > 0.5 * GAP, 2] = 0.2
    y_vec.array[:] = y.ravel()
    contact.limit_step(x_vec, y_vec)
    return dict(X=X[:n], F=F.array.reshape(-1, 3).copy(), Jw=Jw.array.reshape(-1, 3).copy(),
                Hw=(Jw.array - Mw.array).reshape(-1, 3),
                fraction=contact.step_limits[-1] if contact.step_limits else 1.0,
                min_distance=contact.min_distance(), intersecting=contact.intersecting(),
                clamped=clamped[clamped < n])


def main() -> int:
    comm = MPI.COMM_WORLD
    parallel = evaluate(p2_sheets(comm))
    serial = evaluate(p2_sheets(MPI.COMM_SELF))
    _, match = cKDTree(serial["X"]).query(parallel["X"])

    def worst(key: str) -> float:
        a, b = parallel[key], serial[key][match]
        local = float(np.max(np.abs(a - b), initial=0.0))
        scale = comm.allreduce(float(np.max(np.abs(b), initial=0.0)), op=MPI.MAX)
        return comm.allreduce(local, op=MPI.MAX) / scale

    active = comm.allreduce(int(np.count_nonzero(np.abs(parallel["F"]).sum(axis=1) > 0)), op=MPI.SUM)
    clamped_force = comm.allreduce(float(np.abs(parallel["F"][parallel["clamped"]]).sum()), op=MPI.SUM)
    # how much of (M + H) w is the contact's H w: the comparison is not M's alone
    hessian_share = comm.allreduce(float(np.abs(parallel["Hw"]).max(initial=0.0)), op=MPI.MAX) / \
        comm.allreduce(float(np.abs(parallel["Jw"]).max(initial=0.0)), op=MPI.MAX)
    report = dict(ranks=comm.size, gradient_difference=worst("F"), jacobian_difference=worst("Jw"),
                  hessian_difference=worst("Hw"), hessian_share=hessian_share,
                  nodes_with_contact_force=active, force_on_clamped_rows=clamped_force,
                  ccd_fraction=[serial["fraction"], parallel["fraction"]],
                  min_distance=[serial["min_distance"], parallel["min_distance"]],
                  intersecting=[serial["intersecting"], parallel["intersecting"]],
                  owned_nodes=comm.allgather(len(parallel["X"])))
    if comm.rank == 0:
        print(json.dumps(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
