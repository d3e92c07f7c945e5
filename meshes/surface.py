"""Triangle meshes of surfaces embedded in 3D (tdim 2, gdim 3) for the shell.

A structured grid on a parameter rectangle ``[0, 1]²`` is mapped onto the surface
by ``mapping(s, t) -> (x, y, z)`` and triangulated with flat (affine) triangles;
a curved surface is thus faceted, and the shell form subtracts the reference kinks.

DOLFINx orders the vertices of every simplex by global index, so the normal
``J[:, 0] × J[:, 1]`` of a manifold cell flips from cell to cell. :func:`orientation`
returns the per-cell sign (a DG0 function) that makes the normals point to a
chosen side, which the shell's edge terms need.
"""

from __future__ import annotations

from typing import Callable, Literal

import basix.ufl
import dolfinx
import dolfinx.fem
import dolfinx.mesh
import numpy as np
from mpi4py import MPI

from eyemech.meshes.tagged import MeshError, TaggedMesh

Diagonal = Literal["crossed", "right", "left", "alternating"]
Mapping = Callable[[np.ndarray, np.ndarray], np.ndarray]


def require_surface(mesh: dolfinx.mesh.Mesh) -> None:
    """A shell needs a triangle mesh of a surface in 3D (tdim 2, gdim 3)."""
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    if tdim != 2 or gdim != 3 or mesh.topology.cell_name() != "triangle":
        raise MeshError(f"the shell needs a triangle mesh of a surface in 3D (tdim 2, gdim 3); "
                        f"got {mesh.topology.cell_name()} cells with tdim {tdim}, gdim {gdim}")


def _grid(nx: int, ny: int, diagonal: Diagonal) -> tuple[np.ndarray, np.ndarray]:
    """Points (s, t) in [0, 1]² and triangles of a structured nx × ny grid."""
    s, t = np.meshgrid(np.linspace(0.0, 1.0, nx + 1), np.linspace(0.0, 1.0, ny + 1), indexing="ij")
    points = [np.column_stack([s.ravel(), t.ravel()])]

    def vertex(i, j):
        return i * (ny + 1) + j

    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    i, j = i.ravel(), j.ravel()
    v00, v10, v01, v11 = vertex(i, j), vertex(i + 1, j), vertex(i, j + 1), vertex(i + 1, j + 1)
    if diagonal == "crossed":  # four triangles per square around its centre
        centre = (nx + 1) * (ny + 1) + np.arange(nx * ny)
        points.append(np.column_stack([(i + 0.5) / nx, (j + 0.5) / ny]))
        cells = np.vstack([np.column_stack([v00, v10, centre]), np.column_stack([v10, v11, centre]),
                           np.column_stack([v11, v01, centre]), np.column_stack([v01, v00, centre])])
    else:
        flip = {"right": np.zeros_like(i, bool), "left": np.ones_like(i, bool),
                "alternating": (i + j) % 2 == 1}[diagonal]
        a = np.where(flip[:, None], np.column_stack([v00, v10, v01]), np.column_stack([v00, v10, v11]))
        b = np.where(flip[:, None], np.column_stack([v10, v11, v01]), np.column_stack([v00, v11, v01]))
        cells = np.vstack([a, b])
    return np.vstack(points), cells.astype(np.int64)


def mapped_surface(mapping: Mapping, nx: int, ny: int, diagonal: Diagonal = "crossed",
                   comm: MPI.Comm = MPI.COMM_WORLD, weld: bool = False) -> dolfinx.mesh.Mesh:
    """A flat-triangle mesh of the surface ``mapping([0,1]²)``, ghosted across shared
    facets (the shell integrates over interior edges). ``weld`` merges points that the
    mapping sends to the same place (the seam of a closed ring)."""
    if nx < 1 or ny < 1:
        raise MeshError(f"a surface grid needs at least one division each way, got {nx} × {ny}")
    if comm.rank == 0:
        st, cells = _grid(nx, ny, diagonal)
        points = np.asarray(mapping(st[:, 0], st[:, 1]), dtype=np.float64)
        if points.shape != (len(st), 3):
            raise MeshError(f"the surface mapping must return (n, 3) points, got {points.shape}")
        if weld:
            scale = max(float(np.ptp(points)), 1e-300)
            _, first, inverse = np.unique(np.round(points / scale, 9), axis=0, return_index=True,
                                          return_inverse=True)
            points, cells = points[first], inverse.reshape(-1)[cells]
    else:
        points, cells = np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    element = basix.ufl.element("Lagrange", "triangle", 1, shape=(3,))
    partitioner = dolfinx.mesh.create_cell_partitioner(dolfinx.mesh.GhostMode.shared_facet, 2)
    mesh = dolfinx.mesh.create_mesh(comm, cells, element, points, partitioner=partitioner)
    mesh.topology.create_connectivity(1, 2)
    return mesh


def tag_boundary(mesh: dolfinx.mesh.Mesh,
                 regions: dict[str, Callable[[np.ndarray], np.ndarray]]) -> TaggedMesh:
    """Tag boundary edges by name; each predicate takes coordinates ``x`` (3, n) and
    marks the edges whose vertices (and midpoint) it accepts. Later names win."""
    mesh.topology.create_connectivity(1, 2)
    indices, values, names = [], [], {}
    for tag, (name, inside) in enumerate(regions.items(), start=1):
        facets = dolfinx.mesh.locate_entities_boundary(mesh, 1, inside)
        indices.append(facets)
        values.append(np.full(len(facets), tag, dtype=np.int32))
        names[name] = (1, tag)
    facets = np.concatenate(indices) if indices else np.zeros(0, np.int32)
    tags = np.concatenate(values) if values else np.zeros(0, np.int32)
    facets, first = np.unique(facets[::-1], return_index=True)  # later names win
    tags = tags[::-1][first]
    facet_tags = dolfinx.mesh.meshtags(mesh, 1, facets.astype(np.int32), tags)
    return TaggedMesh(mesh, None, facet_tags, names)


def orientation(mesh: dolfinx.mesh.Mesh, direction: Callable[[np.ndarray], np.ndarray]
                ) -> dolfinx.fem.Function:
    """Per-cell sign s = ±1 (DG0) such that ``s · J[:,0] × J[:,1]`` points along
    ``direction(midpoints)`` ((n, 3) -> (n, 3)), e.g. +z for a plate or away from the
    axis of a cylinder."""
    require_surface(mesh)
    tdim = mesh.topology.dim
    cells = np.arange(mesh.topology.index_map(tdim).size_local
                      + mesh.topology.index_map(tdim).num_ghosts, dtype=np.int32)
    nodes = dolfinx.mesh.entities_to_geometry(mesh, tdim, cells)
    x = mesh.geometry.x[nodes]  # (cells, 3 vertices, 3)
    # the Jacobian columns of an affine triangle are x1 - x0 and x2 - x0 in the
    # cell's (geometry) node order, which is what UFL's Jacobian uses
    normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    wanted = np.asarray(direction(x.mean(axis=1)))
    sign = np.where(np.einsum("ij,ij->i", normal, wanted) >= 0.0, 1.0, -1.0)
    space = dolfinx.fem.functionspace(mesh, ("DG", 0))
    s = dolfinx.fem.Function(space, name="orientation")
    dofs = space.dofmap.list[cells, 0]
    s.x.array[dofs] = sign
    return s
