"""PETSc options that reach the objects that read them (issue 22, deliverable 2).

MUMPS reads its ICNTLs when PETSc sets up the factor matrix, during a solve (and again on
a new factor matrix when the matrix pattern changes): the options must still be in PETSc's
options database then. Before the fix ICNTL(14) read back 20 (MUMPS's default) instead of
the 100 the code sets, and ``--petsc mat_mumps_icntl_33=1`` read back 0.
"""

from __future__ import annotations

import numpy as np
import pytest
import ufl
from mpi4py import MPI

import dolfinx
import dolfinx.fem
import dolfinx.mesh
from eyemech.problems.solve import driver
from eyemech.problems.solve.driver import NewtonOptions, NonlinearSolver
from petsc4py import PETSc


@pytest.fixture
def solvers(monkeypatch):
    """Every NonlinearSolver that solves while the test runs (to read its factor matrix)."""
    seen: list[NonlinearSolver] = []
    solve = NonlinearSolver.solve

    def spy(self):
        if all(s is not self for s in seen):
            seen.append(self)
        return solve(self)

    monkeypatch.setattr(NonlinearSolver, "solve", spy)
    return seen


def code_icntl_14() -> int:
    return int(NewtonOptions().as_petsc()["mat_mumps_icntl_14"])


def test_mumps_options_of_the_code_and_of_petsc_reach_the_factor_matrix(solvers, tmp_path):
    """A run through the command line's own entry point (``--petsc`` as a user gives it):
    after the solve the factored matrix holds the code's ICNTL(14) and the user's ICNTL(33)
    (MUMPS's defaults: 20 and 0)."""
    from eyemech.scripts.cli import main

    code = main(["run", "sphere-inflation", "--set", "mesh_size=4.0", "--petsc",
                 "mat_mumps_icntl_33=1", "--out", str(tmp_path), "--no-fields", "--no-pictures",
                 "--quiet"])
    assert code == 0
    assert len(solvers) == 1
    factor = solvers[0].factor_matrix()
    assert factor is not None and factor.getType() == "mumps"
    assert code_icntl_14() == 100
    assert factor.getMumpsIcntl(14) == code_icntl_14()
    assert factor.getMumpsIcntl(33) == 1


def test_options_are_read_by_the_factor_matrix_made_for_a_new_pattern():
    """A Jacobian hook that adds an entry outside the finite-element pattern (as contact
    does when pairs change) makes PETSc analyse the matrix again on a new factor matrix;
    that one reads the options too. Between solves the options are out of the database."""
    problem = _nonlinear_poisson(NewtonOptions(petsc={"mat_mumps_icntl_33": "1"}))
    solver, u = problem["solver"], problem["u"]
    first, last = 0, problem["size"] - 1  # not coupled by a P1 Laplacian on this mesh
    calls = [0]

    def grow_pattern(_x, matrix):
        calls[0] += 1
        if calls[0] == 2:  # from the second Jacobian on
            matrix.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        if calls[0] >= 2:
            matrix.setValue(first, last, 0.0, addv=PETSc.InsertMode.ADD_VALUES)
            matrix.assemble()

    solver.jacobian_hooks.append(grow_pattern)
    problem["load"].value = 1.0
    if not PETSc.Log.isActive():
        PETSc.Log.begin()
    symbolic = PETSc.Log.Event("MatLUFactorSym")
    before = symbolic.getPerfInfo()["count"]
    converged, iterations = solver.solve()
    assert converged and iterations >= 3
    # the first pattern, then the grown one on a new factor matrix
    assert symbolic.getPerfInfo()["count"] - before == 2
    factor = solver.factor_matrix()
    assert factor.getMumpsIcntl(14) == code_icntl_14()
    assert factor.getMumpsIcntl(33) == 1
    assert np.isfinite(u.x.array).all()
    prefix = solver.snes.getOptionsPrefix()
    assert not PETSc.Options().hasName(f"{prefix}mat_mumps_icntl_14")


def _nonlinear_poisson(options: NewtonOptions) -> dict:
    """-div((1 + u²) grad u) = 20·load on the unit square, u = 0 on its boundary (P1, 4×4)."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 4)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    load = dolfinx.fem.Constant(mesh, 0.0)
    residual = ((1 + u**2) * ufl.inner(ufl.grad(u), ufl.grad(v)) - 20.0 * load * v) * ufl.dx
    mesh.topology.create_connectivity(1, 2)
    facets = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    dofs = dolfinx.fem.locate_dofs_topological(V, 1, facets)
    bc = dolfinx.fem.dirichletbc(0.0, dofs, V)
    solver = driver.NonlinearSolver(residual, u, [bc], options=options)
    return {"solver": solver, "u": u, "load": load, "size": V.dofmap.index_map.size_global}
