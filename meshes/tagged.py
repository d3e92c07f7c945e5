"""From a gmsh model to a DOLFINx mesh whose tags are known by name.

gmsh runs on rank 0 only; DOLFINx distributes the mesh. Tag names (``cavity_wall``,
``sclera``, ...) are part of each builder's API, and the integer values behind them
are looked up through :class:`TaggedMesh`, never hard-coded by callers.
"""

from __future__ import annotations

import contextlib
import dataclasses
from typing import Callable, Iterator

import dolfinx
import gmsh
import numpy as np
import ufl
from dolfinx.io import gmsh as gmshio
from mpi4py import MPI


class MeshError(ValueError):
    """A mesh that cannot be used: inverted cells, a missing or empty tag, ..."""


@dataclasses.dataclass
class TaggedMesh:
    mesh: dolfinx.mesh.Mesh
    cell_tags: dolfinx.mesh.MeshTags | None
    facet_tags: dolfinx.mesh.MeshTags | None
    names: dict[str, tuple[int, int]]  # physical name -> (dim, tag)
    # named unions of regions, e.g. "cavity_wall" = every face the liquid wets
    unions: dict[str, tuple[str, ...]] = dataclasses.field(default_factory=dict)

    def tag(self, name: str) -> int | tuple[int, ...]:
        """The integer tag of a region (a tuple for a union, usable in ``ds(...)``)."""
        if name in self.unions:
            return tuple(self.names[part][1] for part in self.unions[name])
        if name not in self.names:
            known = sorted(set(self.names) | set(self.unions))
            raise MeshError(f"the mesh has no region '{name}'; it has: {', '.join(known)}")
        return self.names[name][1]

    def _find(self, tags, name: str) -> np.ndarray:
        values = self.tag(name)
        values = values if isinstance(values, tuple) else (values,)
        return np.unique(np.concatenate([tags.find(v) for v in values])).astype(np.int32)

    def facets(self, name: str) -> np.ndarray:
        """Local indices of the facets tagged ``name`` (or any part of a union)."""
        return self._find(self.facet_tags, name)

    def cell_regions(self) -> list[str]:
        """The names of the regions made of cells (the tissues of an eye), in tag order."""
        return [name for name, (dim, _) in self.names.items() if dim == self.mesh.topology.dim]

    def cells(self, name: str) -> np.ndarray:
        return self._find(self.cell_tags, name)

    def ds(self, metadata: dict | None = None) -> ufl.Measure:
        return ufl.Measure("ds", domain=self.mesh, subdomain_data=self.facet_tags, metadata=metadata)

    def dx(self, metadata: dict | None = None) -> ufl.Measure:
        return ufl.Measure("dx", domain=self.mesh, subdomain_data=self.cell_tags, metadata=metadata)

    def count(self, name: str) -> int:
        """Global number of entities tagged ``name`` (owned entities only)."""
        first = self.unions.get(name, (name,))[0]
        self.tag(name)
        dim, _ = self.names[first]
        entities = self.cells(name) if dim == self.mesh.topology.dim else self.facets(name)
        owned = self.mesh.topology.index_map(dim).size_local
        return self.mesh.comm.allreduce(int(np.sum(entities < owned)), op=MPI.SUM)

    def require_nonempty(self, *names: str) -> None:
        for name in names:
            self.tag(name)
            if self.count(name) == 0:
                raise MeshError(f"the mesh region '{name}' is empty")


@contextlib.contextmanager
def gmsh_session(comm: MPI.Comm, root: int = 0) -> Iterator[gmsh.model | None]:
    """A fresh gmsh model on ``root``; other ranks get None."""
    if comm.rank != root:
        yield None
        return
    started = not gmsh.isInitialized()
    if started:
        gmsh.initialize(interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("General.Verbosity", 1)
    gmsh.clear()
    gmsh.model.add("eyemech")
    try:
        yield gmsh.model
    finally:
        gmsh.clear()
        if started:
            gmsh.finalize()


def from_gmsh(build: Callable[[gmsh.model], None], comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    """Run ``build(model)`` on rank 0 (it must create physical groups and mesh),
    then distribute and check the mesh."""
    error = None
    with gmsh_session(comm) as model:
        if model is not None:
            try:
                build(model)
            except Exception as err:  # reported on every rank below, not a deadlock
                error = err
        error = comm.bcast(error, root=0)
        if error is not None:
            raise error
        data = gmshio.model_to_mesh(model, comm, 0, gdim=3)
    tagged = TaggedMesh(data.mesh, data.cell_tags, data.facet_tags,
                        {name: (g.dim, g.tag) for name, g in data.physical_groups.items()})
    check_orientation(tagged.mesh)
    return tagged


def check_orientation(mesh: dolfinx.mesh.Mesh) -> None:
    """Refuse meshes with inverted (or degenerate) cells: det of the reference-to-
    physical Jacobian must be positive at every cell midpoint."""
    if mesh.topology.dim != mesh.geometry.dim:
        return  # manifold meshes have no sign of the Jacobian determinant
    degree0 = dolfinx.fem.functionspace(mesh, ("DG", 0))
    detJ = dolfinx.fem.Function(degree0)
    expr = dolfinx.fem.Expression(ufl.JacobianDeterminant(mesh), degree0.element.interpolation_points)
    detJ.interpolate(expr)
    n_local = mesh.topology.index_map(mesh.topology.dim).size_local
    local_min = float(np.min(detJ.x.array[:n_local])) if n_local else np.inf
    worst = mesh.comm.allreduce(local_min, op=MPI.MIN)
    if not worst > 0:
        raise MeshError(f"the mesh has inverted or degenerate cells (min det J = {worst:.3e})")
