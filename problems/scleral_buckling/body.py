"""The half eye as every term sees it (:class:`Body`): the tagged mesh, the unknowns, the
element and its measures, the boundary conditions, and the run's communicator and timings."""

from __future__ import annotations

import dataclasses
import functools
import math

import dolfinx
import dolfinx.fem
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.meshes.eye import EyeGeometry
from eyemech.problems.run.results import Timings
from eyemech.problems.solid.incompatible_modes import IncompatibleModes
from eyemech.problems.solid.probes import facet_nodes
from eyemech.problems.solid.spaces import ElementFamily


@dataclasses.dataclass
class Body:
    """The half eye as every term sees it: the tagged mesh, the unknowns [u, p, P, δ_tire]
    (p only with Q1P0's mixed pressure; P the cavity's pressure and δ_tire the tire's
    radial travel, Real unknowns; with the retina's incompatible modes their amplitudes
    and pressure slopes after p), the element, its measures, the boundary conditions
    of u, and the run's communicator and timings."""

    eye: object  # meshes.eye.TaggedMesh
    geometry: EyeGeometry
    family: ElementFamily
    fields: list
    dx: ufl.Measure
    ds: ufl.Measure
    bcs: list
    comm: MPI.Comm
    timings: Timings
    modes: IncompatibleModes | None = None  # the retina's incompatible modes, when chosen

    @property
    def u(self) -> dolfinx.fem.Function:
        return self.fields[0]

    @property
    def P(self) -> dolfinx.fem.Function:
        return self.fields[-2]

    @property
    def tire_travel(self) -> dolfinx.fem.Function:
        return self.fields[-1]

    @property
    def mesh(self) -> dolfinx.mesh.Mesh:
        return self.eye.mesh

    @property
    def block_spaces(self) -> list:
        return [f.function_space for f in self.fields]

    @property
    def wall(self) -> ufl.Measure:
        """The cavity's wall (vitreous side, subretinal space, tear edges, lens)."""
        return self.ds(self.eye.tag("cavity_wall"))

    @functools.cached_property
    def element_size(self) -> float:
        """The wall's in-plane element size: a quarter meridian over the cube's edge."""
        return 0.5 * math.pi * self.geometry.sclera_radius / self.geometry.cells_per_edge

    @functools.cached_property
    def sclera_nodes(self) -> np.ndarray:
        """The nodes (blocks) of the sclera's outer surface, ghosts included."""
        return facet_nodes(self.u.function_space, self.eye.facets("sclera_outer"))

    @functools.cached_property
    def _outer_owned(self) -> tuple[np.ndarray, np.ndarray]:
        V = self.u.function_space
        blocks = self.sclera_nodes[self.sclera_nodes < V.dofmap.index_map.size_local]
        return blocks, V.tabulate_dof_coordinates()[blocks]

    def sclera_outer_positions(self) -> np.ndarray:
        """Deformed positions of this rank's owned nodes on the sclera's outer surface."""
        blocks, X = self._outer_owned
        return X + self.u.x.array.reshape(-1, 3)[blocks]

    def real_value(self, f: dolfinx.fem.Function) -> float:
        """The value of a Real unknown (collective: its dof lives on one rank)."""
        owned = f.function_space.dofmap.index_map.size_local
        return float(self.comm.allreduce(float(np.sum(f.x.array[:owned])), op=MPI.SUM))


def cell_field(body: Body, name: str, values: dict[str, float]) -> dolfinx.fem.Function:
    """A cellwise-constant coefficient from per-tissue values (0 where none given)."""
    space = dolfinx.fem.functionspace(body.mesh, ("DG", 0))
    c = dolfinx.fem.Function(space, name=name)
    for tissue, value in values.items():
        if tissue in body.eye.names:
            cells = body.eye.cells(tissue)
            c.x.array[space.dofmap.list[cells, 0]] = value
    return c


def retina_modes(eye) -> IncompatibleModes:
    """Incompatible modes on the retina's cells: one cell through its thickness bends
    without Q1's locking (:mod:`eyemech.forms.incompatible_modes`)."""
    tissues = eye.cell_regions()
    return IncompatibleModes(eye.mesh, eye.cells("retina"), eye.tag("retina"),
                             tuple(eye.tag(name) for name in tissues if name != "retina"))
