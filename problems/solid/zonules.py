"""Zinn's zonules as elastic bars between node pairs (seed 002, §3.1: 241 linear bars,
E = 100 MPa), added to a (blocked) Newton system by residual and Jacobian hooks.

Why bars and not cells: the zonules are a fan of thin fibres, not a continuum, and the
paper models them as bars. A conforming ring of hexahedra between the lens's equator
and the ciliary body would have to share nodes with the structured eye wall, whose
cubed-sphere nodes lie on no circle of constant z; bars join any two existing nodes
(the lens is its own body, see :mod:`eyemech.meshes.eye`) and cost a 6×6 block per bar.

Each bar is a two-node truss with a linear material (axial force N = E A (l − L)/L)
and exact kinematics (l the deformed length), so a rigid rotation of the eye costs no
energy:

    f_b = −f_a = N d/l,    d = x_b − x_a,
    K = (E A/L) n⊗n + (N/l) (I − n⊗n),    n = d/l,

on the dofs (a, b) with the signs of [[K, −K], [−K, K]]. A bar lying in the symmetry
plane x = 0 is half in the model and gets half its area.

The pairs are found by reference coordinates (the same numpy computation on every
rank); each bar is added by the rank that owns its first node, the positions of all
bar nodes are gathered every evaluation (a few hundred nodes).
"""

from __future__ import annotations

import functools

import dolfinx
import numpy as np
from petsc4py import PETSc

from eyemech.meshes.tagged import MeshError
from eyemech.problems.solid.spaces import PetscNodeLayout


class ZonuleBars:
    """Bars between reference points ``pairs`` (n, 2, 3) of ``u``'s nodes; ``area`` is
    each bar's cross-section (mm²), ``youngs_modulus`` E (MPa); ``block_spaces``
    the spaces of a blocked system with ``u``'s first (as for
    :class:`eyemech.problems.contact.node_to_surface.NodeToSurfaceContact`)."""

    def __init__(self, u: dolfinx.fem.Function, pairs: np.ndarray, youngs_modulus: float,
                 area: float, bcs=(), block_spaces=None, tolerance: float = 1e-8):
        if not (youngs_modulus > 0 and area > 0):
            raise ValueError("zonules need E > 0 and a cross-section > 0")
        self.u = u
        space = u.function_space
        self.comm = space.mesh.comm
        self.bs = space.dofmap.index_map_bs
        self.imap = space.dofmap.index_map
        self.reference_pairs = np.asarray(pairs, dtype=float).reshape(-1, 2, 3)
        self.nodes = self._find_nodes(space, tolerance)        # (n, 2) global node numbers
        d = self.reference_pairs[:, 1] - self.reference_pairs[:, 0]
        self.lengths = np.linalg.norm(d, axis=1)
        in_plane = np.all(np.abs(self.reference_pairs[:, :, 0]) < 1e-9, axis=1)
        self.in_plane = in_plane
        self.axial_stiffness = youngs_modulus * area * np.where(in_plane, 0.5, 1.0)  # E A
        self.layout = PetscNodeLayout(space, block_spaces)
        self._constrained = self.layout.constrained_dofs(bcs)
        owned = self.imap.size_local
        start = self.imap.local_range[0]
        self.mine = (self.nodes[:, 0] >= start) & (self.nodes[:, 0] < start + owned)
        self.unique_nodes = np.unique(self.nodes)

    # -- set-up ---------------------------------------------------------------------------
    def _find_nodes(self, space, tolerance) -> np.ndarray:
        """Global node numbers of the pairs' points (owned nodes searched, then shared)."""
        coords = space.tabulate_dof_coordinates()[: self.imap.size_local]
        points = self.reference_pairs.reshape(-1, 3)
        found = np.full(len(points), -1, dtype=np.int64)
        if len(coords):
            from scipy.spatial import cKDTree

            distance, index = cKDTree(coords).query(points)
            hit = distance < tolerance
            found[hit] = self.imap.local_to_global(index[hit].astype(np.int32))
        from mpi4py import MPI

        result = np.empty_like(found)
        self.comm.Allreduce(found, result, op=MPI.MAX)
        found = result
        if np.any(found < 0):
            raise MeshError(f"{int(np.sum(found < 0))} zonule end points are not mesh nodes")
        return found.reshape(-1, 2)

    def allow_new_nonzeros(self, matrix: PETSc.Mat) -> None:
        """A bar couples two nodes of different bodies: not in the FE pattern. The bars'
        blocks are inserted (as zeros) here, once, so that the matrix's allocation does not
        depend on when they first appear (a run resumed from a checkpoint then allocates
        exactly as the uninterrupted one). Collective."""
        matrix.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        matrix.setOption(PETSc.Mat.Option.NO_OFF_PROC_ENTRIES, False)
        for index, _keep in self._free_dofs:
            matrix.setValues(index, index, np.zeros((len(index), len(index))),
                             addv=PETSc.InsertMode.ADD)
        # a flush, not a final assembly: a final one squeezes out every slot not yet
        # used, i.e. the finite-element pattern DOLFINx preallocated, and the first
        # Jacobian then grows the matrix by mallocs row by row
        matrix.assemblyBegin(PETSc.Mat.AssemblyType.FLUSH)
        matrix.assemblyEnd(PETSc.Mat.AssemblyType.FLUSH)

    def coupling_entries(self) -> int:
        """Matrix entries the bars add to the finite-element pattern (the lens–ciliary
        blocks, both ways; the same on every rank)."""
        base = self.layout.base(self.nodes.ravel()).reshape(-1, 2)
        free = [(~np.isin(base[:, k, None] + np.arange(self.bs), self._constrained)).sum(axis=1)
                for k in (0, 1)]
        return int(2 * np.sum(free[0] * free[1]))

    # -- kinematics -----------------------------------------------------------------------
    def positions(self) -> np.ndarray:
        """(n, 2, 3) deformed positions of the bars' ends (collective)."""
        start, owned = self.imap.local_range[0], self.imap.size_local
        local = self.unique_nodes[(self.unique_nodes >= start) & (self.unique_nodes < start + owned)]
        values = self.u.x.array.reshape(-1, self.bs)[local - start]
        pieces = self.comm.allgather((local, values))
        nodes = np.concatenate([p[0] for p in pieces])
        displacement = np.vstack([p[1] for p in pieces])
        order = np.argsort(nodes)
        u = displacement[order[np.searchsorted(nodes[order], self.nodes.ravel())]]
        return self.reference_pairs + u.reshape(-1, 2, 3)

    def forces(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N, n, l): axial force (N), unit direction a→b and deformed length per bar."""
        x = self.positions()
        d = x[:, 1] - x[:, 0]
        length = np.linalg.norm(d, axis=1)
        force = self.axial_stiffness * (length - self.lengths) / self.lengths
        return force, d / length[:, None], length

    def _dofs(self) -> np.ndarray:
        base = self.layout.base(self.nodes[self.mine].ravel()).reshape(-1, 2)
        return (base[:, :, None] + np.arange(self.bs)).reshape(-1, 2 * self.bs)

    # -- assembly hooks -------------------------------------------------------------------
    def residual_hook(self, _x: PETSc.Vec, b: PETSc.Vec) -> None:
        """F += internal bar forces: −N n on a, +N n on b."""
        force, n, _ = self.forces()
        f = (force[:, None] * n)[self.mine]
        values = np.hstack([-f, f])
        dofs, keep = self._bar_dofs
        b.setValues(dofs[keep].astype(PETSc.IntType), values[keep], addv=PETSc.InsertMode.ADD)
        b.assemblyBegin()
        b.assemblyEnd()

    def jacobian_hook(self, _x: PETSc.Vec, A: PETSc.Mat) -> None:
        force, n, length = self.forces()
        mine = self.mine
        nn = n[mine, :, None] * n[mine, None, :]
        k = ((self.axial_stiffness / self.lengths)[mine, None, None] * nn
             + (force / length)[mine, None, None] * (np.eye(3) - nn))
        blocks = np.block([[k, -k], [-k, k]])  # (bars, 6, 6)
        for block, (index, keep) in zip(blocks, self._free_dofs):
            A.setValues(index, index, block[np.ix_(keep, keep)], addv=PETSc.InsertMode.ADD)
        A.assemble()

    @functools.cached_property
    def _bar_dofs(self) -> tuple[np.ndarray, np.ndarray]:
        """(bars of this rank, 6): their dofs (PETSc numbering) and which are free of
        Dirichlet conditions; fixed for the run, found once."""
        dofs = self._dofs()
        return dofs, ~np.isin(dofs, self._constrained)

    @functools.cached_property
    def _free_dofs(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per bar of this rank: its free dofs and which of its six they are."""
        dofs, free = self._bar_dofs
        return [(bar[keep].astype(PETSc.IntType), keep) for bar, keep in zip(dofs, free)]

    def summary(self) -> dict[str, float]:
        """Whole eye (twice the half model's bars, in-plane bars counted once)."""
        force, _, length = self.forces()
        weight = np.where(self.in_plane, 1.0, 2.0)
        strain = (length - self.lengths) / self.lengths
        return {"zonule_force_total_N": float(np.sum(weight * force)),
                "zonule_strain_max": float(np.abs(strain).max()) if len(strain) else 0.0}

