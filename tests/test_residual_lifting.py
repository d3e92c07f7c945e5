"""The residual without the lifting of satisfied conditions (problems/solve/residual.py)
equals DOLFINx's to the bit: blocked (u, p) and single-form, at an iterate that keeps the
homogeneous conditions (lifting skipped) and at one that does not (lifted)."""

from __future__ import annotations

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

from eyemech.problems.solve.residual import Residual


def _problem(blocked: bool):
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 3, 3, 3,
                                         dolfinx.mesh.CellType.hexahedron)
    V = fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    Q = fem.functionspace(mesh, ("DG", 0))
    u, p = fem.Function(V), fem.Function(Q)
    v, q = ufl.TestFunction(V), ufl.TestFunction(Q)
    F = ufl.Identity(3) + ufl.grad(u)
    J = ufl.det(F)
    P = 0.5 * F - 0.5 * ufl.inv(F).T + p * J * ufl.inv(F).T  # neo-Hooke with a pressure
    body = fem.Constant(mesh, (0.0, 0.0, -0.1))
    residual_u = (ufl.inner(P, ufl.grad(v)) - ufl.inner(body, v)) * ufl.dx
    facets = dolfinx.mesh.locate_entities_boundary(mesh, 2, lambda x: np.isclose(x[0], 0.0))
    clamp = fem.dirichletbc(np.zeros(3), fem.locate_dofs_topological(V, 2, facets), V)
    if blocked:
        forms = [residual_u, (J - 1) * q * ufl.dx]
        problem = dolfinx.fem.petsc.NonlinearProblem(
            forms, [u, p], bcs=[clamp], petsc_options_prefix="lift_test_b_", kind="mpi")
    else:
        problem = dolfinx.fem.petsc.NonlinearProblem(residual_u, u, bcs=[clamp],
                                                     petsc_options_prefix="lift_test_s_")
    return problem, clamp


@pytest.mark.parametrize("blocked", [True, False])
@pytest.mark.parametrize("keeps_the_condition", [True, False])
def test_the_residual_equals_dolfinxs(blocked, keeps_the_condition):
    problem, clamp = _problem(blocked)
    snes = problem.solver
    b, (dolfinx_residual, args, kargs) = snes.getFunction()
    assert dolfinx_residual is dolfinx.fem.petsc.assemble_residual
    x = problem.x.copy()
    rng = np.random.default_rng(7)
    x.array[:] = 0.05 * rng.standard_normal(x.array.size)
    if keeps_the_condition:  # the clamped rows zero, as Newton's iterates keep them
        work = x.duplicate()
        work.set(1.0)
        if kargs.get("_blocks") is not None:
            work.setAttr("_blocks", kargs["_blocks"])
        bcs = [[clamp], []] if blocked else [clamp]
        dolfinx.fem.petsc.set_bc(work, bcs, alpha=0.0)  # 0 on the clamped rows, 1 elsewhere
        x.pointwiseMult(x, work)
    x.ghostUpdate()
    expected, ours = b.duplicate(), b.duplicate()
    dolfinx_residual(snes, x, expected, **kargs)
    residual = Residual()
    residual(snes, x, ours, **kargs)
    assert (residual.skipped, residual.lifted) == ((1, 0) if keeps_the_condition else (0, 1))
    assert np.array_equal(ours.array, expected.array)
    assert expected.norm() > 1e-3  # not a comparison of two zero vectors
    residual.destroy()
