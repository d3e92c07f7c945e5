"""The lens' smallest self distance, measured by ipctk on the flat triangles through the
P2 vertex nodes (a probe: it adds no force; the barrier is :mod:`.ipc`)."""

from __future__ import annotations

import time

import dolfinx.fem
import numpy as np


def self_distance_probe(u: dolfinx.fem.Function):
    """A :class:`SelfDistance` when ipctk is installed (on rank 0, which measures), else None."""
    comm = u.function_space.mesh.comm
    available = False
    if comm.rank == 0:
        try:
            import ipctk  # noqa: F401
            available = True
        except ImportError:
            pass
    return SelfDistance(u) if comm.bcast(available, root=0) else None


class SelfDistance:
    """Smallest distance between distant parts of the lens mid-surface, by ipctk, on the
    flat triangles through the P2 vertex nodes.

    The lens is small (hundreds of nodes), so under MPI its triangles and node positions
    are gathered on rank 0, which measures and broadcasts the result: every rank count
    measures the same surface (each rank alone sees only its part, and two parts of the
    lens that meet may sit on different ranks).

    Only pairs of primitives whose vertices all lie more than ``exclusion`` apart in the
    reference (flat) lens count: on a flat mesh, neighbouring elements are a fraction of
    an element apart, which says nothing about self-contact; parts that were apart along
    the lens and come together (a haptic on the optic, the rolled optic's rims) are what
    is measured. ipctk gives the candidates within ``search_radius`` and their distances.
    """

    def __init__(self, u: dolfinx.fem.Function, exclusion: float = 1.0):
        V = u.function_space
        self.u, self.comm = u, V.mesh.comm
        index_map = V.dofmap.index_map
        self.owned = index_map.size_local
        local_count = self.owned + index_map.num_ghosts
        to_global = index_map.local_to_global(np.arange(local_count, dtype=np.int32))
        self.owned_global = to_global[: self.owned]
        owned_cells = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
        cells = to_global[V.dofmap.list[:owned_cells, :3]]  # the vertex nodes of each P2 triangle
        X = V.tabulate_dof_coordinates()[: self.owned]
        gathered = self.comm.gather((cells, self.owned_global, X), root=0)
        self.exclusion = exclusion
        if self.comm.rank != 0:
            return
        import ipctk

        cells = np.vstack([g[0] for g in gathered])
        self.nodes, faces = np.unique(cells, return_inverse=True)
        faces = faces.reshape(-1, 3)
        self.slot = np.full(max(int(g[1].max(initial=-1)) for g in gathered) + 1, -1, np.int64)
        self.slot[self.nodes] = np.arange(len(self.nodes))
        self.X = np.empty((len(self.nodes), 3))
        for _, node, x in gathered:
            keep = self.slot[node] >= 0
            self.X[self.slot[node[keep]]] = x[keep]
        self.faces = np.asfortranarray(faces.astype(np.int32))
        self.edges = np.asfortranarray(ipctk.edges(self.faces))
        self.mesh = ipctk.CollisionMesh(np.asfortranarray(self.X), self.edges, self.faces)
        self._ipctk = ipctk

    def positions(self) -> np.ndarray | None:
        """Deformed positions of the vertex nodes on rank 0 (None elsewhere); collective."""
        x = self.u.x.array[: 3 * self.owned].reshape(-1, 3)
        gathered = self.comm.gather((self.owned_global, x), root=0)
        if self.comm.rank != 0:
            return None
        u = np.empty_like(self.X)
        for node, values in gathered:
            keep = self.slot[node] >= 0
            u[self.slot[node[keep]]] = values[keep]
        return np.asfortranarray(self.X + u)

    def __call__(self, search_radius: float = 0.25, distances: bool = True) -> tuple[float, bool]:
        """(minimum distance in mm — ``inf`` when nothing distant is within
        ``search_radius``, NaN when ``distances`` is False —, whether the surface
        intersects itself); collective, measured on rank 0."""
        x = self.positions()
        found = self._measure(x, search_radius, distances) if self.comm.rank == 0 else None
        return self.comm.bcast(found, root=0)

    def _measure(self, x: np.ndarray, search_radius: float, distances: bool) -> tuple[float, bool]:
        """The measurement on rank 0: ipctk's exact triangle–edge intersection test is
        cheap and always done, the distance search only when ``distances``."""
        ipctk = self._ipctk
        if not distances:
            return float("nan"), bool(ipctk.has_intersections(self.mesh, x, broad_phase=ipctk.BVH()))
        collisions = ipctk.NormalCollisions()
        t0 = time.perf_counter()
        collisions.build(self.mesh, x, search_radius, broad_phase=ipctk.BVH())
        self.timing = [time.perf_counter() - t0, len(collisions)]
        best = np.inf
        for i in range(len(collisions)):
            collision = collisions[i]
            ids = [v for v in collision.vertex_ids(self.edges, self.faces) if v >= 0]
            split = 2 if isinstance(collision, ipctk.EdgeEdgeNormalCollision) else 1
            first, second = self.X[ids[:split]], self.X[ids[split:]]
            if np.min(np.linalg.norm(first[:, None] - second[None], axis=2)) < self.exclusion:
                continue
            best = min(best, float(np.sqrt(collision.compute_distance(collision.dof(x, self.edges,
                                                                                     self.faces)))))
        # An element of NormalCollisions refers into the container: let it go first. Python
        # clears a frame's locals in the order they were bound, so a `collision` left alive
        # outlived `collisions` and its deallocation read freed memory (SIGSEGV once VTK had
        # reused that memory: the lens notebook's run, 2026-11-22).
        collision = None
        del collision, collisions
        t0 = time.perf_counter()
        crossing = bool(ipctk.has_intersections(self.mesh, x, broad_phase=ipctk.BVH()))
        self.timing.append(time.perf_counter() - t0)
        return best, crossing
