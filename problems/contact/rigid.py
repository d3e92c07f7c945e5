"""Assembly-side helpers for contact with analytic rigid obstacles
(:mod:`eyemech.forms.contact`): the penetration at the slave surface's nodes, the
refusal of an obstacle that starts inside the body, and the resultant force."""

from __future__ import annotations

import dolfinx
import dolfinx.fem
import numpy as np
from mpi4py import MPI

from eyemech.forms import contact
from eyemech.forms.kinematics import without_variables
from eyemech.meshes.tagged import TaggedMesh
from eyemech.problems.run.parameters import ParameterError


def slave_nodes(u: dolfinx.fem.Function, tagged: TaggedMesh, slave: str) -> np.ndarray:
    """Local (block) indices of the owned nodes of ``u``'s space on the ``slave`` facets;
    the slave region must exist and be non-empty (MeshError otherwise)."""
    tagged.require_nonempty(slave)
    space = u.function_space
    fdim = tagged.mesh.topology.dim - 1
    nodes = dolfinx.fem.locate_dofs_topological(space, fdim, tagged.facets(slave))
    return nodes[nodes < space.dofmap.index_map.size_local]


class NodalPenetration:
    """max ⟨−g⟩ over the slave nodes of ``u``'s Lagrange space (collective)."""

    def __init__(self, obstacle, u: dolfinx.fem.Function, tagged: TaggedMesh, slave: str):
        self.nodes = slave_nodes(u, tagged, slave)
        element = u.function_space.ufl_element()
        scalar = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", element.embedded_superdegree))
        self.values = dolfinx.fem.Function(scalar)
        self.expression = dolfinx.fem.Expression(without_variables(contact.penetration(obstacle, u)),
                                                 scalar.element.interpolation_points)
        self.comm = tagged.mesh.comm

    def __call__(self) -> float:
        self.values.interpolate(self.expression)
        local = float(np.max(self.values.x.array[self.nodes], initial=0.0))
        return self.comm.allreduce(local, op=MPI.MAX)


def refuse_initial_penetration(penetration: NodalPenetration, key: str, tolerance: float) -> None:
    """ParameterError naming ``key`` when the obstacle starts inside the body."""
    depth = penetration()
    if depth > tolerance:
        raise ParameterError(key, f"the obstacle starts interpenetrating the body by {depth:.4g} mm "
                                  f"at the slave surface (tolerance {tolerance:.2g} mm); move it out")


def surface_integral(integrand, measure) -> callable:
    """A callable returning the global value of ∫ integrand over ``measure``."""
    compiled = dolfinx.fem.form(integrand * measure)
    comm = compiled.mesh.comm

    def evaluate() -> float:
        return comm.allreduce(dolfinx.fem.assemble_scalar(compiled), op=MPI.SUM)

    return evaluate


def resultant_force(obstacle, u, penalty, measure) -> list[callable]:
    """The three components of ∫ α ⟨−g⟩ n dA: the force the obstacle exerts on the body."""
    traction = contact.contact_traction(obstacle, u, penalty)
    return [surface_integral(traction[i], measure) for i in range(len(u))]

