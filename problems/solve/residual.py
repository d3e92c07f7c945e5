"""The residual F(x) as DOLFINx's SNES callback assembles it, without the lifting of
boundary conditions that x already satisfies.

DOLFINx's ``assemble_residual`` lifts the Dirichlet conditions on every call: it adds
``-J[:, bc] (g - x)[bc]`` by computing the element Jacobians of every cell that holds a
constrained degree of freedom. Newton's iterates keep homogeneous conditions exactly
(every increment is zero on the constrained rows, and so is a secant predictor through two
such states), so ``g - x`` is zero there and the lifting adds exact zeros: on the eye's
default mesh it was 30 % of the residual's assembly (the half eye's symmetry planes touch
many cells; 4 blocks). The lifting is skipped when ``g - x`` is zero on every constrained
degree of freedom of every rank, and done as DOLFINx does otherwise (a prescribed
displacement's first iterate), so the residual is the same to the bit either way
(tests/test_residual_lifting.py).
"""

from __future__ import annotations

from collections.abc import Sequence

import dolfinx
from dolfinx.fem.bcs import bcs_by_block
from dolfinx.fem.forms import extract_function_spaces
from dolfinx.fem.petsc import apply_lifting, assemble_vector, assign, set_bc
from mpi4py import MPI
from petsc4py import PETSc

_ghost_update = dolfinx.la.petsc._ghost_update
_zero_vector = dolfinx.la.petsc._zero_vector


class Residual:
    """``SNES.setFunction``'s callback for the residual ``residual`` at ``x``, in the
    arguments DOLFINx's ``NonlinearProblem`` passes (``kargs``); counts the lifts it
    skipped and did (``skipped``, ``lifted``)."""

    def __init__(self) -> None:
        self._work: PETSc.Vec | None = None  # -(g - x) on the constrained rows
        self.skipped = 0
        self.lifted = 0

    def __call__(self, _snes, x: PETSc.Vec, b: PETSc.Vec, u, residual, jacobian,
                 bcs: Sequence, _blocks=None) -> None:
        _ghost_update(x, PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
        assign(x, u)
        blocked = isinstance(residual, Sequence)
        if blocked and b.getType() != PETSc.Vec.Type.NEST:
            b.setAttr("_blocks", _blocks)
            x.setAttr("_blocks", _blocks)
        bcs0 = bcs_by_block(extract_function_spaces(residual), bcs) if blocked else bcs
        lift = self._needs_lifting(x, b, bcs0)
        _zero_vector(b)
        assemble_vector(b, residual)
        if lift:
            self.lifted += 1
            if blocked:
                bcs1 = bcs_by_block(extract_function_spaces(jacobian, 1), bcs)
                apply_lifting(b, jacobian, bcs=bcs1, x0=x, alpha=-1.0)
            else:
                apply_lifting(b, [jacobian], bcs=[bcs], x0=[x], alpha=-1.0)
        else:
            self.skipped += 1
        _ghost_update(b, PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
        set_bc(b, bcs0, x0=x, alpha=-1.0)
        _ghost_update(b, PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)

    def _needs_lifting(self, x: PETSc.Vec, b: PETSc.Vec, bcs0) -> bool:
        """Whether g - x is non-zero on a constrained row of any rank (collective: the
        ghost rows a rank lifts from are owned, and checked, by another)."""
        nested = len(bcs0) > 0 and isinstance(bcs0[0], Sequence)
        constrained = [bc for block in bcs0 for bc in block] if nested else list(bcs0)
        if not constrained:  # the same lists on every rank: no rank calls the reduction
            return False
        if b.getType() == PETSc.Vec.Type.NEST:  # not checked: lifted as DOLFINx does
            return True
        if self._work is None:
            self._work = b.duplicate()
            if b.getAttr("_blocks") is not None:
                self._work.setAttr("_blocks", b.getAttr("_blocks"))
        _zero_vector(self._work)
        set_bc(self._work, bcs0, x0=x, alpha=-1.0)
        local = self._work.getArray(readonly=True)
        largest = float(abs(local).max()) if local.size else 0.0
        return x.comm.tompi4py().allreduce(largest, op=MPI.MAX) > 0.0

    def destroy(self) -> None:
        if self._work is not None:
            self._work.destroy()
            self._work = None
