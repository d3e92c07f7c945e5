"""A liquid-filled cavity coupled to a solid, in the two formulations of seed 002 §2.1.

``real``: the cavity pressure P is one more unknown, in a Real space
(``basix.ufl.real_element``), with the liquid law as its residual row
(:func:`eyemech.forms.liquid_law_residual`). The Jacobian gains one column (the
follower load per unit P) and one row (∂V/∂u): about 2·3k + 1 nonzeros for k wall
nodes.

``substituted`` (the paper's previous formulation): P(u) = P_ini − K (V(u) − V_ini)/V_ini
is substituted into the follower load, so every wall dof couples with every other:
the Jacobian gains the dense rank-one block −(K/V_ini) g ⊗ b (g the load per unit P,
b = ∂V/∂u). DOLFINx's sparsity pattern of the solid does not contain it, so
:class:`SubstitutedCavity` builds a matrix from the form's pattern plus all
wall×wall couplings and hands it to SNES in place of the form's matrix.

Before any solve, :func:`check_closed` refuses a wall that does not enclose a volume.
"""

from __future__ import annotations

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import numpy as np
import ufl
from petsc4py import PETSc

from eyemech.forms import (
    axis_volumes,
    enclosed_volume,
    follower_pressure,
    liquid_pressure,
)
from eyemech.forms.cavity import held_liquid, vented_law_pressure, vented_liquid_law_residual
from eyemech.meshes.tagged import MeshError
from eyemech.problems.solve.scalars import assemble_scalar


def check_closed(u, wall_measure, name: str = "cavity wall", rtol: float = 1e-6,
                 outward_sign: float = -1.0) -> float:
    """The enclosed volume, after checking that the wall closes it (with symmetry
    planes through the origin): the volumes from the fields x_k e_k must agree
    (:func:`eyemech.forms.axis_volumes`). Raises MeshError otherwise."""
    volumes = [assemble_scalar(f) for f in axis_volumes(u, wall_measure, outward_sign)]
    volume = assemble_scalar(enclosed_volume(u, wall_measure, outward_sign))
    spread = max(volumes) - min(volumes)
    if not volume > 0 or spread > rtol * abs(volume):
        raise MeshError(
            f"the {name} does not enclose a volume: computed with x·e_k for k = 0, 1, 2 it is "
            f"{', '.join(f'{v:.6g}' for v in volumes)} (1/3 x·n gives {volume:.6g}); a closed wall "
            f"(or one closed by coordinate symmetry planes through the origin) gives one value")
    return volume


def real_pressure_space(mesh: dolfinx.mesh.Mesh) -> dolfinx.fem.FunctionSpace:
    """One global scalar unknown (a Real space)."""
    return dolfinx.fem.functionspace(mesh, basix_real(mesh))


def basix_real(mesh):
    import basix.ufl

    return basix.ufl.real_element(mesh.basix_cell(), (), dtype=dolfinx.default_scalar_type)


class SubstitutedCavity:
    """The substituted formulation: hooks and the enlarged matrix for a NonlinearSolver
    whose residual contains ``follower_pressure(self.pressure, u, v, wall)``.

    The residual assembled by DOLFINx uses the pressure of the previous evaluation;
    the residual hook computes P(u) at the new state, adds (P(u) − P_old) g and
    stores P(u), so the Jacobian that follows (and its P ∂g/∂u part, inside the form)
    uses the same P. The Jacobian hook adds −(K/V_ini) g ⊗ b on the wall dofs.
    """

    def __init__(self, u, v, wall_measure, bcs, initial_volume: float,
                 initial_pressure: dolfinx.fem.Constant, bulk_modulus: float):
        self.u = u
        self.pressure = dolfinx.fem.Constant(u.function_space.mesh, float(initial_pressure.value))
        self.initial_pressure = initial_pressure
        self.initial_volume, self.bulk_modulus = initial_volume, bulk_modulus
        V = u.function_space
        one = dolfinx.fem.Constant(V.mesh, 1.0)
        self._g_form = dolfinx.fem.form(follower_pressure(one, u, v, wall_measure))
        volume = enclosed_volume(u, wall_measure)
        self._volume_form = dolfinx.fem.form(volume)
        self._b_form = dolfinx.fem.form(ufl.derivative(volume, u, v))
        self.comm = V.mesh.comm
        bs = V.dofmap.index_map_bs
        self._n_owned = V.dofmap.index_map.size_local * bs
        constrained = np.concatenate([bc.dof_indices()[0] for bc in bcs]) if bcs else np.array([], int)
        self._free = np.ones(self._n_owned, dtype=bool)
        self._free[constrained[constrained < self._n_owned]] = False
        wall_blocks = dolfinx.fem.locate_dofs_topological(V, V.mesh.topology.dim - 1,
                                                          _facets_of(wall_measure))
        wall = (wall_blocks[:, None] * bs + np.arange(bs)).ravel()
        wall = np.unique(wall[wall < self._n_owned])
        self.wall_dofs = wall[self._free[wall]]  # owned, unconstrained, local numbering
        self.matrix: PETSc.Mat | None = None
        self.last_volume = initial_volume

    # -- evaluations ------------------------------------------------------------
    def _owned(self, form) -> np.ndarray:
        vector = dolfinx.fem.assemble_vector(form)
        vector.scatter_reverse(dolfinx.la.InsertMode.add)
        values = vector.array[: self._n_owned].copy()
        values[~self._free] = 0.0
        return values

    def current_pressure(self) -> float:
        self.last_volume = assemble_scalar(self._volume_form)
        return liquid_pressure(self.last_volume, self.initial_volume,
                               float(self.initial_pressure.value), self.bulk_modulus)

    def residual_hook(self, _x: PETSc.Vec, vec: PETSc.Vec) -> None:
        new = self.current_pressure()
        change = new - float(self.pressure.value)
        if change != 0.0:
            vec.array[: self._n_owned] += change * self._owned(self._g_form)
        self.pressure.value = new

    def jacobian_hook(self, _x: PETSc.Vec, mat: PETSc.Mat) -> None:
        start = mat.getOwnershipRange()[0]
        g = self._owned(self._g_form)[self.wall_dofs]
        b = self._owned(self._b_form)[self.wall_dofs]
        rows = (start + self.wall_dofs).astype(PETSc.IntType)
        cols = np.concatenate(self.comm.allgather(rows)).astype(PETSc.IntType)
        b_all = np.concatenate(self.comm.allgather(b))
        block = -(self.bulk_modulus / self.initial_volume) * np.outer(g, b_all)
        mat.setValues(rows, cols, block.ravel(), addv=PETSc.InsertMode.ADD_VALUES)
        mat.assemble()

    # -- the enlarged matrix ----------------------------------------------------
    def install(self, solver) -> None:
        """Give ``solver`` (a NonlinearSolver on [u, ...] with u the first block) a
        Jacobian matrix whose pattern is the form's plus every wall×wall pair, and
        register the hooks."""
        form_matrix = solver.problem.A
        # assembled once so that its CSR structure (the form's full pattern) is readable
        dolfinx.fem.petsc.assemble_matrix(form_matrix, solver.problem.J)
        form_matrix.assemble()
        start = form_matrix.getOwnershipRange()[0]
        indptr, indices, _ = form_matrix.getValuesCSR()
        rows = start + self.wall_dofs
        wall_cols = np.concatenate(self.comm.allgather(rows))
        is_wall_row = np.zeros(len(indptr) - 1, dtype=bool)
        is_wall_row[self.wall_dofs] = True
        new_indptr = [0]
        new_indices = []
        for row in range(len(indptr) - 1):
            cols = indices[indptr[row]:indptr[row + 1]]
            if is_wall_row[row]:
                cols = np.union1d(cols, wall_cols)
            new_indices.append(cols)
            new_indptr.append(new_indptr[-1] + len(cols))
        csr = (np.asarray(new_indptr, dtype=PETSc.IntType),
               np.concatenate(new_indices).astype(PETSc.IntType))
        matrix = PETSc.Mat().createAIJ(form_matrix.getSizes(), csr=csr, comm=form_matrix.comm)
        matrix.setLGMap(*form_matrix.getLGMap())
        matrix.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        matrix.assemble()
        _, _, (callback, args, kargs) = solver.snes.getJacobian()
        solver.snes.setJacobian(callback, matrix, matrix, args=args, kargs=kargs)
        solver.residual_hooks.append(self.residual_hook)
        solver.jacobian_hooks.append(self.jacobian_hook)
        self.matrix = matrix

    def nonzeros(self) -> int:
        return int(self.matrix.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_allocated"])


def _facets_of(wall_measure) -> np.ndarray:
    """Facets integrated by ``ds(tag)`` (its subdomain data and id)."""
    tags = wall_measure.subdomain_data()
    return tags.find(wall_measure.subdomain_id())


# a venting cavity holds again once the law's pressure at its volume falls this fraction below
# the limit: after a converged venting step the state sits on the kink (the law's pressure is
# the limit to round-off), and without a margin the next solve's first assembly flipped it
# (docs/hyperelastic.md, "The vented cavity")
HOLD_MARGIN = 1e-3


class VentedCavity:
    """A liquid-filled cavity vented at a pressure limit: the terms and the state of
    :func:`eyemech.forms.cavity.vented_liquid_law_residual`.

    - :meth:`residual` is P's row; ``held`` (a Constant, 0 or 1) switches it on, the
      caller's own row (e.g. P pinned to a ramp) takes the complement;
    - :meth:`choose_branch`, a state hook of the nonlinear solver, sets the row's branch
      before every assembly (semismooth Newton on P = min(P_lim, P_law(V)), at most one
      switch a solve; :meth:`memory`/:meth:`restore_memory`, its memory hook, mark a
      solve's start and undo a failed one);
    - :meth:`accept`, after every converged load step, keeps the liquid that is left
      (:func:`eyemech.forms.cavity.held_liquid`): vented liquid does not come back.

    ``limit`` ≤ 0 is no venting: the branch stays 0 and this is the liquid law of seed
    002 eq. 5. Volumes are those of the modelled part (the half eye's half)."""

    def __init__(self, u, wall_measure, initial_volume, initial_pressure, bulk_modulus,
                 limit: float):
        mesh = u.function_space.mesh
        self.u, self.wall = u, wall_measure
        self.initial_volume, self.initial_pressure = initial_volume, initial_pressure
        self.bulk_modulus = bulk_modulus
        self.liquid_volume = dolfinx.fem.Constant(mesh, float(initial_volume.value))
        self.limit = dolfinx.fem.Constant(mesh, float(limit))
        self.venting = dolfinx.fem.Constant(mesh, 0.0)
        self.held = dolfinx.fem.Constant(mesh, 0.0)  # 1 while the liquid law acts
        self._volume = dolfinx.fem.form(enclosed_volume(u, wall_measure))
        self.branch_switches = 0
        self._switched = False  # this solve's one switch is spent
        # the vent opened in this load step (not carried from an accepted step): its state
        # is not on the kink, and the test for holding again does not apply until accept()
        self._opened_this_step = False

    @property
    def enabled(self) -> bool:
        return float(self.limit.value) > 0.0

    def residual(self, pressure, test, wall_area):
        return vented_liquid_law_residual(pressure, test, self.u, self.wall, wall_area,
                                          self.initial_volume, self.initial_pressure,
                                          self.bulk_modulus, self.liquid_volume, self.limit,
                                          self.venting)

    def volume(self) -> float:
        return assemble_scalar(self._volume)

    def hold(self, volume: float) -> None:
        """The liquid law from here on, holding the cavity's liquid at ``volume`` (the
        state's volume at P_ini: the start of the coupled steps)."""
        self.liquid_volume.value = volume
        self.venting.value = 0.0
        self.held.value = 1.0

    def release(self) -> None:
        self.held.value = 0.0
        self.venting.value = 0.0

    def law_pressure(self, volume: float) -> float:
        return vented_law_pressure(volume, float(self.liquid_volume.value),
                                   float(self.initial_volume.value),
                                   float(self.initial_pressure.value),
                                   float(self.bulk_modulus.value))

    def choose_branch(self, pressure: float) -> None:
        """Before every assembly, at most once a solve: a held cavity vents once the
        iterate's P passes the limit; a venting one holds again once the law's pressure
        at its V falls below the limit (the wall wants more volume than the liquid left).
        Holding reads P, not V: with K = 2083 MPa a Newton iterate's volume error of 1 µL is
        a law pressure of thousands of mmHg. One switch a solve: where the state sits on the
        kink (little liquid leaves per step) the two tests otherwise flip the branch every
        iteration (docs/hyperelastic.md, "The vented cavity"). A vent opened in this load step
        stays open until :meth:`accept` (which holds again if the wall took more than the
        liquid left): the holding test is for a state carried from an accepted step, and a
        vent opened at a predicted start — before the solve's memory hook resets its one
        switch — would otherwise be closed again at once and the solve converge held, far
        above the limit. P and V are values every rank shares."""
        if not (self.enabled and float(self.held.value) == 1.0) or self._switched:
            return
        limit = float(self.limit.value)
        if float(self.venting.value) == 0.0:
            branch = 1.0 if pressure > limit else 0.0
        elif self._opened_this_step:
            return
        else:  # a venting state after accept() sits on the kink: law = limit to round-off
            branch = 1.0 if self.law_pressure(self.volume()) >= (1.0 - HOLD_MARGIN) * limit else 0.0
        if branch != float(self.venting.value):
            self.venting.value = branch
            self.branch_switches += 1
            self._switched = True
            self._opened_this_step = branch == 1.0

    def memory(self) -> tuple[float, float]:
        """At the start of a solve (the solver's memory hook): the branch and the liquid
        held at the load step's start (a vent opened in this step, at a predicted start,
        was closed there), and a new solve's one switch."""
        self._switched = False
        branch = 0.0 if self._opened_this_step else float(self.venting.value)
        return branch, float(self.liquid_volume.value)

    def restore_memory(self, saved: tuple[float, float]) -> None:
        self.venting.value, self.liquid_volume.value = saved
        self._switched = False
        self._opened_this_step = False

    def accept(self, pressure: float) -> float:
        """After a converged load step: the liquid the cavity holds now, V + V_ini (P −
        P_ini)/K. While venting it can only fall (vented liquid does not come back); a
        venting state whose wall took more volume than the liquid left (its one switch
        spent) holds again from the next load step. Returns the volume vented in the step."""
        self._switched = False
        self._opened_this_step = False
        if float(self.held.value) != 1.0 or float(self.venting.value) != 1.0:
            return 0.0
        before = float(self.liquid_volume.value)
        now = held_liquid(self.volume(), pressure, float(self.initial_volume.value),
                          float(self.initial_pressure.value), float(self.bulk_modulus.value))
        if now > before:
            self.venting.value = 0.0
            self.branch_switches += 1
            return 0.0
        self.liquid_volume.value = now
        return before - now

    def vented(self, reference_volume: float) -> float:
        """The liquid vented since the liquid was held at ``reference_volume``."""
        return reference_volume - float(self.liquid_volume.value)
