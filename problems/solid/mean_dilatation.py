"""Q1P0's DG0 pressure condensed element by element: the mean-dilatation method.

The DG0 multiplier of the perturbed constraint ∫ (J − 1 − p/κ) q dX = 0 is local to its
cell, p_K = κ (J̄_K − 1) with J̄_K = (1/|K|) ∫_K J dX, and is eliminated cell by cell
(Nagtegaal, Parks & Rice 1974; Simo, Taylor & Pister 1985). What is left is a
displacement system with the energy ∫ W(F) dX + Σ_K |K| U(J̄_K), U = κ/2 (J̄ − 1)²
(:func:`eyemech.forms.mean_dilatation_energy_density`):

- residual ∫ (∂W/∂F + p̄ J F⁻ᵀ) : ∇v dX, a UFL form with the DG0 field p̄ as a coefficient,
  which :meth:`MeanDilatation.update` computes from u before every assembly;
- tangent: UFL's derivative of that residual with p̄ held fixed, plus per cell the rank-one
  (κ/|K|) b_K b_Kᵀ, b_K = ∫_K J F⁻ᵀ : ∇δu dX, added by :meth:`MeanDilatation.jacobian_hook`
  into the u–u block (inside the finite-element pattern: no new nonzeros).

The pressure field ``pressure`` stands where the mixed element's p stood (outputs,
checkpoints). Verified in tests/test_hyperelastic_elements.py (Taylor test of the
tangent, the inflated sphere against its exact radius and against the mixed Q1P0).
"""

from __future__ import annotations

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from eyemech.forms import deformation_gradient, mean_dilatation_pressure
from eyemech.problems.solid.spaces import PetscNodeLayout


class MeanDilatation:
    """The condensed DG0 pressure of a displacement field ``u`` (Q1 on hexahedra).

    ``bulk_modulus``: κ (MPa): a number or a ``dolfinx.fem.Constant`` (read at every
    update), or a cellwise UFL expression (e.g. a multiple of a DG0 shear modulus, read
    once); ``dx``: the solid's
    cell measure (the quadrature of its residual); ``bcs``: the Dirichlet conditions of the
    system, whose rows and columns the cell terms leave alone; ``block_spaces``: the
    spaces of a blocked system (``NonlinearProblem(..., kind="mpi")``, u's first), None for
    u alone. Collective to build."""

    def __init__(self, u: dolfinx.fem.Function, bulk_modulus, dx: ufl.Measure, bcs=(),
                 block_spaces=None):
        V = u.function_space
        mesh = V.mesh
        self.u = u
        self.comm = mesh.comm
        Q0 = dolfinx.fem.functionspace(mesh, ("DG", 0))
        self.bulk_modulus = bulk_modulus
        if not isinstance(bulk_modulus, (int, float, dolfinx.fem.Constant)):
            # a cellwise field: its values on this space's cells, once
            self.bulk_modulus = dolfinx.fem.Function(Q0, name="bulk_modulus")
            self.bulk_modulus.interpolate(dolfinx.fem.Expression(
                bulk_modulus, Q0.element.interpolation_points))
        self.pressure = dolfinx.fem.Function(Q0, name="p")
        self.cells = Q0.dofmap.index_map.size_local  # owned cells = owned DG0 dofs
        q = ufl.TestFunction(Q0)
        J = ufl.det(deformation_gradient(u))
        # |K| and ∫_K J dX per owned cell, in the residual's quadrature
        self.volumes = dolfinx.fem.assemble_vector(dolfinx.fem.form(q * dx)).array[: self.cells].copy()
        self._jacobian_integral = dolfinx.fem.form(J * q * dx)
        # B: one row per cell, b_K = ∫_K J F⁻ᵀ : ∇δu dX
        self._b_form = dolfinx.fem.form(ufl.derivative(J * q * dx, u, ufl.TrialFunction(V)))
        self._b = dolfinx.fem.petsc.create_matrix(self._b_form)
        self._assemble_b()
        dofs = self._cell_columns()  # u's global PETSc numbering: global node · bs + component
        layout = PetscNodeLayout(V, block_spaces)
        bs = V.dofmap.index_map_bs
        self.rows = (layout.base(dofs.ravel() // bs).reshape(dofs.shape) + dofs % bs).astype(PETSc.IntType)
        constrained = layout.constrained_dofs(list(bcs))
        self.free = ~np.isin(self.rows, constrained)
        self.update()

    def _assemble_b(self) -> None:
        self._b.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self._b, self._b_form)
        self._b.assemble()

    def _cell_columns(self) -> np.ndarray:
        """(owned cells, dofs per cell): the global u dofs of B's rows, in B's order."""
        indptr, indices, _ = self._b.getValuesCSR()
        per_row = np.diff(indptr)
        if len(per_row) != self.cells or (len(per_row) and not np.all(per_row == per_row[0])):
            raise ValueError("B's rows are not one per owned cell with the cell's dofs")
        self.width = int(per_row[0]) if len(per_row) else 0
        return indices.reshape(self.cells, self.width).astype(np.int64)

    def _cell_rows_of_b(self) -> np.ndarray:
        """(owned cells, dofs per cell): b_K at the current u."""
        self._assemble_b()
        return self._b.getValuesCSR()[2].reshape(self.cells, self.width)

    def kappa(self) -> np.ndarray | float:
        """κ on the owned cells (an array) or everywhere (a float)."""
        if isinstance(self.bulk_modulus, dolfinx.fem.Function):
            return self.bulk_modulus.x.array[: self.cells]
        return float(getattr(self.bulk_modulus, "value", self.bulk_modulus))

    def mean_jacobian(self) -> np.ndarray:
        """J̄_K on the owned cells at the current u."""
        integral = dolfinx.fem.assemble_vector(self._jacobian_integral).array[: self.cells]
        return integral / self.volumes

    def update(self) -> None:
        """p̄ = κ (J̄ − 1) from the current u (call after u changed, before assembling)."""
        self.pressure.x.array[: self.cells] = mean_dilatation_pressure(self.mean_jacobian(), self.kappa())
        self.pressure.x.scatter_forward()

    def volumetric_energy(self) -> float:
        """Σ_K |K| κ/2 (J̄_K − 1)² (global)."""
        local = float(np.sum(self.volumes * 0.5 * self.kappa() * (self.mean_jacobian() - 1.0) ** 2))
        return self.comm.allreduce(local, op=MPI.SUM)

    def jacobian_hook(self, _x: PETSc.Vec, A: PETSc.Mat) -> None:
        """A += Σ_K (κ/|K|) b_K b_Kᵀ on the free u dofs (u current)."""
        b = self._cell_rows_of_b() * self.free
        blocks = (self.kappa() / self.volumes)[:, None, None] * b[:, :, None] * b[:, None, :]
        ADD = PETSc.InsertMode.ADD
        for rows, block in zip(self.rows, blocks):
            A.setValues(rows, rows, block, addv=ADD)
        A.assemble()
