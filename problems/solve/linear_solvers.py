"""The linear solver inside Newton: direct (MUMPS LU, the default) or iterative
(Krylov with a block preconditioner that scales to many ranks and large meshes).

A scene offers the choice by adding :class:`SolverChoice` to its parameters
(``solver = direct | iterative``) and passing ``params.linear_solver(μ, dx)`` to
:class:`~eyemech.problems.solve.driver.NonlinearSolver`.

``solver = "iterative"`` on a mixed [u, p, (P)] system (``NonlinearProblem(...,
kind="mpi")``: one monolithic matrix, each rank's owned dofs of every block one after
the other) sets up

    FGMRES( PCFIELDSPLIT Schur, upper factorisation )   splits  u | p (+ Real P)

    ⎡A   Bᵀ⎤       A: displacement block — one GAMG V-cycle (smoothed aggregation,
    ⎣B   C ⎦          Chebyshev/Jacobi smoothing) with the six rigid-body modes as
                      near-nullspace (composed on the split's index set, so
                      PCFIELDSPLIT attaches it to the extracted block)
                   S = C − B A⁻¹ Bᵀ: never formed; preconditioned by the user matrix
                      Ŝ = diag(−M_p/μ, s_P), M_p the pressure mass matrix weighted
                      by 1/μ (μ the local shear modulus, cellwise: the tissues differ
                      by 10⁴), spectrally equivalent to the Schur complement of
                      incompressible elasticity for an inf–sup stable pair (Q2P1,
                      P2P1); applied by Jacobi (exact inverse for DG0, near for DPC1).

The Real unknown (a cavity pressure P, one global dof owned by one rank) sits in the
pressure split: its row and column couple it with every wall dof, which the
displacement multigrid must not see. Its entry of Ŝ is the "selfp" estimate
s_P = C_PP − Σ_k A_Pk A_kP / A_kk over the displacement dofs k, refreshed after every
Jacobian (two mat-vecs). What this misses of the exact S_PP is a rank-one error,
which FGMRES removes in about one extra iteration.

A displacement-only family (no pressure block, no Real) gets GAMG with the rigid-body
modes on the whole matrix (GMRES). Every choice is a PETSc option under the solver's
prefix, so ``--petsc`` overrides it, e.g. ``fieldsplit_u_pc_type=lu``,
``pc_fieldsplit_schur_precondition=selfp``, ``ksp_rtol=1e-8``, ``ksp_monitor=``.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from eyemech.problems.run.parameters import SOLVER, field
from eyemech.problems.solve.scalars import assemble_scalar

LinearSolverName = Literal["direct", "iterative"]

DIRECT_OPTIONS = {
    "ksp_type": "preonly",
    "pc_type": "lu",
    "pc_factor_mat_solver_type": "mumps",
    # MUMPS: more working space for the indefinite saddle-point systems
    "mat_mumps_icntl_14": 100,
}

# Newton stops at ‖F‖ < 1e-9 ‖F₀‖ (or 1e-10 absolute): a linear solve that leaves a
# relative residual η makes Newton converge linearly with rate ≈ η near the solution,
# so η must be well below the Newton tolerance's share per step (measured in
# docs/scaling.md: 1e-8 costs Newton iterations on the eye, 1e-10 does not).
KRYLOV_RTOL = 1e-10

ITERATIVE_OPTIONS = {
    "ksp_type": "fgmres",
    "ksp_rtol": KRYLOV_RTOL,
    "ksp_atol": 1e-14,
    "ksp_max_it": 1000,
    "ksp_gmres_restart": 200,
    "pc_type": "fieldsplit",
    "pc_fieldsplit_type": "schur",
    "pc_fieldsplit_schur_fact_type": "lower",
    "pc_fieldsplit_schur_precondition": "user",
    "fieldsplit_u_ksp_type": "preonly",
    "fieldsplit_u_pc_type": "gamg",
    "fieldsplit_u_pc_gamg_threshold": 0.01,
    "fieldsplit_u_mg_levels_ksp_type": "chebyshev",
    "fieldsplit_u_mg_levels_pc_type": "jacobi",
    "fieldsplit_u_mg_levels_ksp_max_it": 2,
    "fieldsplit_p_ksp_type": "preonly",
    "fieldsplit_p_pc_type": "jacobi",
}

# displacement only: the whole matrix is the elasticity block
ITERATIVE_SINGLE_BLOCK = {
    "ksp_type": "gmres",
    "ksp_rtol": KRYLOV_RTOL,
    "ksp_atol": 1e-14,
    "ksp_max_it": 1000,
    "ksp_gmres_restart": 200,
    "pc_type": "gamg",
    "pc_gamg_threshold": 0.01,
    "mg_levels_ksp_type": "chebyshev",
    "mg_levels_pc_type": "jacobi",
}

SOLVER_HELP = ("linear solver inside Newton: direct (MUMPS LU) or iterative (FGMRES with "
               "fieldsplit Schur + GAMG; docs/scaling.md)")


@dataclasses.dataclass(frozen=True)
class SolverChoice:
    """Parameter mixin of the scenes whose linear systems the iterative solver handles:
    ``class Parameters(SceneParameters, SolverChoice)``. ``solver`` is a Literal, checked on
    construction by :class:`SceneParameters`."""

    solver: LinearSolverName = field("direct", SOLVER_HELP, group=SOLVER)

    def linear_solver(self, shear_modulus=1.0, measure=None) -> "IterativeSolver | None":
        """What ``solver`` selects for NonlinearSolver(..., iterative=...): None (MUMPS
        LU) or the block preconditioner with μ (float or cellwise UFL) and the solid's dx."""
        return IterativeSolver(shear_modulus, measure) if self.solver == "iterative" else None


@dataclasses.dataclass
class IterativeSolver:
    """Fieldsplit–Schur–GAMG for [u, p, ...] (see the module docstring).

    ``shear_modulus``: μ (a float or a UFL expression, e.g. a cellwise field) weighting
    the pressure mass matrix; ``measure``: the cell measure of the solid."""

    shear_modulus: float | ufl.core.expr.Expr = 1.0
    measure: ufl.Measure | None = None

    def options(self, blocks: int) -> dict[str, object]:
        return dict(ITERATIVE_OPTIONS if blocks > 1 else ITERATIVE_SINGLE_BLOCK)

    def install(self, solver) -> None:
        """Index sets, near-nullspace and Schur preconditioning matrix for ``solver``
        (a :class:`~eyemech.problems.solve.driver.NonlinearSolver`), after its options are
        set. Sets up only what PETSc will use (e.g. nothing of the Schur matrix when
        ``pc_fieldsplit_schur_precondition`` was overridden)."""
        spaces = [u.function_space for u in solver.unknowns]
        pc = solver.snes.getKSP().getPC()
        self._nullspace = rigid_body_modes(spaces[0])  # kept alive with the solver
        self._schur = None
        if len(spaces) == 1:
            solver.problem.A.setNearNullSpace(self._nullspace)
            return
        if pc.getType() != PETSc.PC.Type.FIELDSPLIT:
            return
        comm = solver.problem.A.comm
        starts = _block_starts(spaces)
        is_u = PETSc.IS().createStride(_owned(spaces[0]), first=starts[0], step=1, comm=comm)
        is_u.setBlockSize(spaces[0].dofmap.index_map_bs)
        is_u.compose("nearnullspace", self._nullspace)
        pressure_rows = np.concatenate([starts[i] + np.arange(_owned(V))
                                        for i, V in enumerate(spaces) if i > 0])
        is_p = PETSc.IS().createGeneral(pressure_rows.astype(PETSc.IntType), comm=comm)
        pc.setFieldSplitIS(("u", is_u), ("p", is_p))
        self._index_sets = (is_u, is_p)
        prefix = solver.snes.getOptionsPrefix() or ""
        if PETSc.Options().getString(f"{prefix}pc_fieldsplit_schur_precondition", "") != "user":
            return  # overridden (e.g. selfp, a11): PETSc builds its own
        self._schur = SchurPreconditioner(spaces, starts, self.shear_modulus, self.measure)
        pc.setFieldSplitSchurPreType(PETSc.PC.FieldSplitSchurPreType.USER, self._schur.matrix)

    def update(self, x: PETSc.Vec, jacobian: PETSc.Mat) -> None:
        """After each Jacobian (and its hooks: contact, bars): refresh s_P."""
        if self._schur is not None:
            self._schur.update(jacobian)


def _owned(V: dolfinx.fem.FunctionSpace) -> int:
    return V.dofmap.index_map.size_local * V.dofmap.index_map_bs


def _block_starts(spaces) -> list[int]:
    """Global row of each block's first owned dof on this rank (kind="mpi" layout)."""
    comm = spaces[0].mesh.comm
    sizes = [_owned(V) for V in spaces]
    first = comm.exscan(sum(sizes)) or 0
    return [first + sum(sizes[:i]) for i in range(len(sizes))]


def _is_real(V: dolfinx.fem.FunctionSpace) -> bool:
    return V.dofmap.index_map.size_global * V.dofmap.index_map_bs == 1


class SchurPreconditioner:
    """Ŝ = diag(−M_p/μ for a field pressure block, s_P for a Real block), in the
    layout of the pressure split (each rank: its owned p dofs, then its P dof)."""

    def __init__(self, spaces, starts, shear_modulus, measure):
        mesh = spaces[0].mesh
        dx = measure or ufl.dx(domain=mesh)
        self.spaces, self.starts = spaces, starts
        self.real_blocks = [i for i, V in enumerate(spaces) if i > 0 and _is_real(V)]
        self.real_values = {i: dolfinx.fem.Constant(mesh, 1.0) for i in self.real_blocks}
        volume = assemble_scalar(dolfinx.fem.Constant(mesh, 1.0) * dx, mesh.comm)
        pressure_spaces = spaces[1:]
        forms = []
        for row, V in enumerate(pressure_spaces, start=1):
            line = [None] * len(pressure_spaces)
            p, q = ufl.TrialFunction(V), ufl.TestFunction(V)
            if row in self.real_blocks:
                # ∫ s/|Ω| · 1 · 1 dx = s on the Real dof's diagonal
                line[row - 1] = self.real_values[row] / volume * p * q * dx
            else:
                line[row - 1] = -1.0 / shear_modulus * p * q * dx
            forms.append(line)
        self.forms = dolfinx.fem.form(forms)
        self.matrix = dolfinx.fem.petsc.create_matrix(self.forms, kind="mpi")
        self._assemble()

    def _assemble(self) -> None:
        self.matrix.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self.matrix, self.forms)
        self.matrix.assemble()

    def update(self, jacobian: PETSc.Mat) -> None:
        """s_P = C_PP − Σ_k A_Pk A_kP / A_kk (displacement dofs k) from the Jacobian."""
        if not self.real_blocks:
            return
        comm = self.spaces[0].mesh.comm
        n_u = _owned(self.spaces[0])
        diagonal = jacobian.getDiagonal().array_r[:n_u]
        safe = np.where(diagonal != 0, diagonal, 1.0)
        for block in self.real_blocks:
            rows = self.starts[block] + np.arange(_owned(self.spaces[block]))
            unit = jacobian.createVecRight()
            unit.set(0.0)
            if len(rows):
                unit.setValues(rows.astype(PETSc.IntType), np.ones(len(rows)))
            unit.assemble()
            column, row = jacobian.createVecLeft(), jacobian.createVecRight()
            jacobian.mult(unit, column)          # A e_P: the P column
            jacobian.multTranspose(unit, row)    # Aᵀ e_P: the P row
            coupling = float(np.sum(row.array_r[:n_u] * column.array_r[:n_u] / safe))
            local_pp = float(column.array_r[rows - self.starts[0]].sum()) if len(rows) else 0.0
            value = comm.allreduce(local_pp, op=MPI.SUM) - comm.allreduce(coupling, op=MPI.SUM)
            self.real_values[block].value = value if value != 0.0 else 1.0
            for vec in (unit, column, row):
                vec.destroy()
        self._assemble()


def rigid_body_modes(V: dolfinx.fem.FunctionSpace) -> PETSc.NullSpace:
    """Translations and rotations of a vector space's owned dofs (orthonormalised): the
    near-nullspace that makes smoothed aggregation work for elasticity."""
    bs = V.dofmap.index_map_bs
    n = V.dofmap.index_map.size_local
    x = V.tabulate_dof_coordinates()[:n, :bs]
    modes = []
    for k in range(bs):
        mode = np.zeros((n, bs))
        mode[:, k] = 1.0
        modes.append(mode)
    rotations = [(0, 1)] if bs == 2 else [(0, 1), (1, 2), (2, 0)]
    for i, j in rotations:
        mode = np.zeros((n, bs))
        mode[:, i], mode[:, j] = -x[:, j], x[:, i]
        modes.append(mode)
    comm = V.mesh.comm
    vectors = []
    for mode in modes:
        vec = PETSc.Vec().createMPI((n * bs, PETSc.DETERMINE), bsize=bs, comm=comm)
        vec.array[:] = mode.ravel()
        for other in vectors:  # Gram–Schmidt
            vec.axpy(-vec.dot(other), other)
        vec.normalize()
        vectors.append(vec)
    return PETSc.NullSpace().create(vectors=vectors, comm=comm)
