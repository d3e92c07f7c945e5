"""Assembly-side helpers for contact with analytic rigid obstacles
(:mod:`eyemech.forms.contact`): the penetration at the slave surface's nodes, the
refusal of an obstacle that starts inside the body, and the resultant force."""

from __future__ import annotations

import math

import basix
import dolfinx
import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms import contact
from eyemech.forms.kinematics import without_variables
from eyemech.meshes.tagged import TaggedMesh
from eyemech.problems.run.parameters import ParameterError
from eyemech.problems.solve.augmentation import relative_change
from eyemech.problems.solve.scalars import assemble_scalar


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

    def evaluate() -> float:
        return assemble_scalar(compiled)

    return evaluate


def resultant_force(obstacle, u, penalty, measure, multiplier=None) -> list[callable]:
    """The three components of ∫ α ⟨−g⟩ n dA (∫ ⟨λ − α g⟩ n dA with an augmented Lagrangian
    ``multiplier``): the force the obstacle exerts on the body."""
    traction = contact.contact_traction(obstacle, u, penalty, multiplier)
    return [surface_integral(traction[i], measure) for i in range(len(u))]



class _MultiplierField:
    """What both multiplier layouts share: λ in ``self.function``, the Uzawa update
    prepared in ``self._next`` and committed at once; memory for a cut load step."""

    def commit_multipliers(self) -> None:
        self.function.x.array[:] = self._next
        self.function.x.scatter_forward()

    def memory(self) -> np.ndarray:
        return self.function.x.array.copy()

    def restore(self, saved: np.ndarray) -> None:
        self.function.x.array[:] = saved


class ObstacleMultipliers(_MultiplierField):
    """Augmented Lagrangian multipliers λ of a rigid obstacle's contact, one per node of the
    ``slave`` facets: a scalar Lagrange Function of ``u``'s degree (``function``, zero off
    the slave surface) for :func:`eyemech.forms.contact.smoothed_penalty_energy`'s
    ``multiplier``.

    Nodal rather than at the contact integral's quadrature points: DOLFINx's quadrature
    spaces live at cell points, not at a facet integral's, and a nodal field is Laursen's
    node-based multiplier, checkpointed as any Function. The update λ ← ⟨λ − α g⟩
    (:func:`eyemech.forms.contact.augmented_pressure`) is interpolated at the nodes of the
    cells next to the slave facets, so at Uzawa's fixed point no node lies inside the
    obstacle, while the integrand sees λ interpolated between the nodes plus the penalty
    α⟨−g⟩ of the quadrature points that a face spanning a convex corner puts inside it:
    the converged answer lies between the nodal constraint (α → 0) and the penalty's
    quadrature-point constraint (α → ∞), and depends on α where the mesh does not resolve
    the obstacle's curvature (the buckle's corners: docs/contact.md, "Augmented
    Lagrangian")."""

    def __init__(self, obstacle, u: dolfinx.fem.Function, tagged: TaggedMesh, slave: str,
                 penalty, smoothing=0.0, name: str = "contact_multiplier"):
        tagged.require_nonempty(slave)
        mesh = tagged.mesh
        degree = u.function_space.ufl_element().embedded_superdegree
        space = dolfinx.fem.functionspace(mesh, ("Lagrange", degree))
        self.function = dolfinx.fem.Function(space, name=name)
        self._trial = dolfinx.fem.Function(space)
        fdim = mesh.topology.dim - 1
        facets = tagged.facets(slave)
        self.nodes = dolfinx.fem.locate_dofs_topological(space, fdim, facets)
        self.owned = self.nodes[self.nodes < space.dofmap.index_map.size_local]
        mesh.topology.create_connectivity(fdim, mesh.topology.dim)
        self.cells = dolfinx.mesh.compute_incident_entities(mesh.topology, facets, fdim,
                                                            mesh.topology.dim)
        gap = obstacle.gap(contact.deformed_position(u))
        points = space.element.interpolation_points
        self._update = dolfinx.fem.Expression(without_variables(
            contact.augmented_pressure(gap, self.function, penalty, smoothing)), points)
        self._next = self.function.x.array.copy()
        self.comm = mesh.comm

    def trial_multipliers(self) -> float:
        """λ_new = p(g − λ/α) at the slave nodes at the current ``u``, kept aside; the
        relative change ‖λ_new − λ‖/‖λ_new‖ over the owned slave nodes (collective)."""
        self._trial.interpolate(self._update, cells0=self.cells)
        self._next = np.zeros_like(self.function.x.array)
        self._next[self.nodes] = self._trial.x.array[self.nodes]
        return relative_change(self._next[self.owned], self.function.x.array[self.owned], self.comm)


class FacePoints:
    """The quadrature points of a facet integral over the ``slave`` facets of a hexahedral
    mesh (a tensor Gauss rule of ``degree`` on each quadrilateral face, as the integral's),
    in each owned cell's reference coordinates: ``values(expression)`` evaluates a compiled
    :class:`dolfinx.fem.Expression` made with ``reference_points`` there, one row per
    (cell, local facet) pair of the slave surface."""

    def __init__(self, tagged: TaggedMesh, slave: str, degree: int):
        tagged.require_nonempty(slave)
        mesh = tagged.mesh
        if mesh.topology.cell_type != dolfinx.mesh.CellType.hexahedron:
            raise ValueError("face quadrature points: hexahedral meshes only")
        fdim = mesh.topology.dim - 1
        mesh.topology.create_connectivity(fdim, mesh.topology.dim)
        pairs = dolfinx.fem.compute_integration_domains(
            dolfinx.fem.IntegralType.exterior_facet, mesh.topology,
            tagged.facets(slave)).reshape(-1, 2)
        owned = mesh.topology.index_map(mesh.topology.dim).size_local
        self.cells, self.local_facets = pairs[pairs[:, 0] < owned].T.astype(np.int32)
        face_points, _ = basix.make_quadrature(basix.CellType.quadrilateral, degree)
        self.per_face = len(face_points)
        geometry = basix.geometry(basix.CellType.hexahedron)
        faces = basix.topology(basix.CellType.hexahedron)[2]
        # facet f's points: v0 + s (v1 − v0) + t (v2 − v0), its vertices in basix's order
        self.reference_points = np.vstack([
            geometry[f[0]] + np.outer(face_points[:, 0], geometry[f[1]] - geometry[f[0]])
            + np.outer(face_points[:, 1], geometry[f[2]] - geometry[f[0]]) for f in faces])
        self.mesh = mesh

    def values(self, expression: dolfinx.fem.Expression) -> np.ndarray:
        """(pairs, points per face, components) of ``expression`` at each pair's face."""
        full = expression.eval(self.mesh, self.cells).reshape(len(self.cells), 6, self.per_face, -1)
        return full[np.arange(len(self.cells)), self.local_facets]


class QuadraturePointMultipliers(_MultiplierField):
    """Augmented Lagrangian multipliers λ of a rigid obstacle's contact at the contact
    integral's quadrature points on a hexahedral mesh's ``slave`` faces, so that Uzawa's
    fixed point is the penalty's own constraint (g ≥ 0 at those points) and does not
    depend on α. DOLFINx's quadrature spaces live at cell points, not at a facet
    integral's: λ is carried by a discontinuous Q_k field (k + 1 points per direction of
    the face's tensor Gauss rule), whose restriction to the cell's slave face is the Q_k
    interpolant of the (k + 1)² point values, exact at the points; the other basis
    functions vanish on that face. The update λ ← ⟨λ − α g⟩
    (:func:`eyemech.forms.contact.augmented_pressure`) is evaluated at the points and the
    face's dofs solved from it."""

    def __init__(self, obstacle, u: dolfinx.fem.Function, tagged: TaggedMesh, slave: str,
                 penalty, degree: int, smoothing=0.0, name: str = "contact_multiplier"):
        self.points = FacePoints(tagged, slave, degree)
        order = round(math.sqrt(self.points.per_face)) - 1
        space = dolfinx.fem.functionspace(tagged.mesh, ("DG", order))
        self.function = dolfinx.fem.Function(space, name=name)
        gap = obstacle.gap(contact.deformed_position(u))
        pressure = contact.augmented_pressure(gap, self.function, penalty, smoothing)
        self._expression = dolfinx.fem.Expression(
            without_variables(ufl.as_vector([pressure, self.function, ufl.max_value(-gap, 0.0)])),
            self.points.reference_points)
        # per local facet: the face's dofs and the inverse of their basis at its points
        table = space.ufl_element().tabulate(0, self.points.reference_points)[0]
        self._face_dofs, self._inverse = [], []
        per_face = self.points.per_face
        for f in range(6):
            rows = table[f * per_face:(f + 1) * per_face]
            dofs = np.flatnonzero(np.abs(rows).max(axis=0) > 1e-12)
            if len(dofs) != per_face:
                raise ValueError("the face's points do not determine its Q_k interpolant")
            self._face_dofs.append(dofs)
            self._inverse.append(np.linalg.inv(rows[:, dofs]))
        self._cell_dofs = space.dofmap.list
        self._next = self.function.x.array.copy()
        self.comm = tagged.mesh.comm
        self.penetration = 0.0  # max ⟨−g⟩ at the points at the last trial (collective)

    def trial_multipliers(self) -> float:
        """λ_new = p(g − λ/α) at the points at the current ``u``, kept aside; the relative
        change ‖λ_new − λ‖/‖λ_new‖ over all points (collective)."""
        values = self.points.values(self._expression)
        new, old = values[..., 0], values[..., 1]
        self.penetration = self.comm.allreduce(float(np.max(values[..., 2], initial=0.0)), op=MPI.MAX)
        self._next = np.zeros_like(self.function.x.array)
        for f in range(6):
            here = self.points.local_facets == f
            if not here.any():
                continue
            dofs = self._cell_dofs[self.points.cells[here]][:, self._face_dofs[f]]
            self._next[dofs] = new[here] @ self._inverse[f].T
        return relative_change(new, old, self.comm)

    def max_penetration(self) -> float:
        """max ⟨−g⟩ at the points (collective)."""
        values = self.points.values(self._expression)
        return self.comm.allreduce(float(np.max(values[..., 2], initial=0.0)), op=MPI.MAX)
