"""Point probes and surface pairings on distributed meshes: the measurements a scene
reports (an apex, a pole, suture points, the retina–choroid gap)."""

from __future__ import annotations

import dolfinx
import dolfinx.fem
import numpy as np
from mpi4py import MPI
from scipy.spatial import cKDTree

from eyemech.forms.kinematics import without_variables


class NodeProbe:
    """The displacement dofs of the mesh nodes nearest to given reference points.

    Each point is owned by the one rank whose owned node is nearest (ties go to the
    lower rank); ``positions`` returns deformed positions on every rank."""

    def __init__(self, V: dolfinx.fem.FunctionSpace, points: np.ndarray,
                 candidates: np.ndarray | None = None):
        comm = V.mesh.comm
        owned = V.dofmap.index_map.size_local
        coordinates = V.tabulate_dof_coordinates()[:owned]
        blocks = np.arange(owned) if candidates is None else candidates[candidates < owned]
        self.reference = np.asarray(points, dtype=float).reshape(-1, 3)
        n = len(self.reference)
        if len(blocks):
            distance, index = cKDTree(coordinates[blocks]).query(self.reference)
        else:
            distance, index = np.full(n, np.inf), np.zeros(n, int)
        best = np.array(comm.allgather(distance))           # (ranks, n)
        self.owner = np.argmin(best, axis=0)
        self.mine = self.owner == comm.rank
        # valid where mine (a rank without candidates owns none of the points)
        self.blocks = (blocks[index] if len(blocks) else np.zeros(n, int)).astype(np.int32)
        self.bs = V.dofmap.index_map_bs
        self.comm = comm
        node = np.where(self.mine[:, None], coordinates[self.blocks] if len(blocks) else 0.0, 0.0)
        self.nodes = comm.allreduce(node, op=MPI.SUM)        # reference node positions

    def displacements(self, u: dolfinx.fem.Function) -> np.ndarray:
        values = u.x.array.reshape(-1, self.bs)
        local = np.where(self.mine[:, None], values[self.blocks] if len(values) else 0.0, 0.0)
        return self.comm.allreduce(local, op=MPI.SUM)

    def positions(self, u: dolfinx.fem.Function) -> np.ndarray:
        return self.nodes + self.displacements(u)


def facet_nodes(V: dolfinx.fem.FunctionSpace, facets: np.ndarray) -> np.ndarray:
    """Local dof blocks of the (vertex) nodes on ``facets``."""
    fdim = V.mesh.topology.dim - 1
    return np.unique(dolfinx.fem.locate_dofs_topological(V, fdim, facets))


class SurfacePairing:
    """Pairs each node of a slave surface with the nearest node of a master surface
    by reference direction from the origin (the structured eye puts the detached
    retina's nodes straight above their choroid twins); nodes the two surfaces share
    are left out. Gathered on every rank: these surfaces hold a few hundred nodes."""

    def __init__(self, V, slave_facets: np.ndarray, master_facets: np.ndarray):
        comm = V.mesh.comm
        owned = V.dofmap.index_map.size_local
        coordinates = V.tabulate_dof_coordinates()
        self.bs, self.comm, self.owned = V.dofmap.index_map_bs, comm, owned

        def gather(facets):
            blocks = facet_nodes(V, facets)
            blocks = blocks[blocks < owned]
            global_index = V.dofmap.index_map.local_to_global(blocks.astype(np.int32))
            allx = np.vstack(comm.allgather(coordinates[blocks]))
            allg = np.concatenate(comm.allgather(global_index))
            _, unique = np.unique(allg, return_index=True)
            return blocks, global_index, allx[unique], allg[unique]

        self.slave_blocks, self.slave_global, slave_x, slave_g = gather(slave_facets)
        self.master_blocks, self.master_global, master_x, master_g = gather(master_facets)
        unit = lambda x: x / np.linalg.norm(x, axis=1, keepdims=True)
        _, nearest = cKDTree(unit(master_x)).query(unit(slave_x))
        # nodes both surfaces share (where the retina is still attached) have no gap
        apart = slave_g != master_g[nearest]
        self.slave_x, self.master_x = slave_x[apart], master_x[nearest][apart]
        self.slave_g, self.master_g = slave_g[apart], master_g[nearest][apart]

    def _values(self, u, blocks, global_index, order):
        values = u.x.array.reshape(-1, self.bs)[blocks]
        gathered = np.vstack(self.comm.allgather(values))
        keys = np.concatenate(self.comm.allgather(global_index))
        lookup = dict(zip(keys.tolist(), range(len(keys))))
        return gathered[[lookup[k] for k in order]]

    def gaps(self, u) -> np.ndarray:
        """Normal gap (mm) of each slave node above its master twin: the distance along
        the master's radial direction, negative when the slave has passed through."""
        slave = self.slave_x + self._values(u, self.slave_blocks, self.slave_global, self.slave_g)
        master = self.master_x + self._values(u, self.master_blocks, self.master_global,
                                              self.master_g)
        normal = master / np.linalg.norm(master, axis=1, keepdims=True)
        return np.einsum("ij,ij->i", master - slave, normal)


class CellField:
    """A DG0 field of ``expression`` at cell midpoints (compiled once, updated per step)."""

    def __init__(self, expression, mesh: dolfinx.mesh.Mesh, name: str):
        space = dolfinx.fem.functionspace(mesh, ("DG", 0))
        self.field = dolfinx.fem.Function(space, name=name)
        self._expression = dolfinx.fem.Expression(without_variables(expression),
                                                 space.element.interpolation_points)
        self._owned = space.dofmap.index_map.size_local
        self._comm = mesh.comm

    def update(self) -> float:
        """Re-evaluate; returns the maximum over all cells."""
        self.field.interpolate(self._expression)
        local = float(self.field.x.array[: self._owned].max()) if self._owned else -np.inf
        return self._comm.allreduce(local, op=MPI.MAX)
