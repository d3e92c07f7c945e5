"""Function spaces for the solid models: element families, symmetry conditions,
and small integral helpers for quantities of interest."""

from __future__ import annotations

import dataclasses
from typing import Callable, Literal, get_args

import basix.ufl
import dolfinx
import dolfinx.fem
import numpy as np
import ufl

from eyemech.problems.solve.scalars import assemble_scalar


@dataclasses.dataclass(frozen=True)
class ElementFamily:
    """A displacement/pressure pair for the incompressible mixed formulation."""

    name: str
    cell: str                    # "tetrahedron" | "hexahedron"
    displacement_degree: int
    pressure_family: str | None  # "P" (continuous), "DG", "DPC", or None (displacement only)
    pressure_degree: int = 0
    description: str = ""

    @property
    def hexahedral(self) -> bool:
        return self.cell == "hexahedron"

    @property
    def quadrature_degree(self) -> int:
        """Fixed quadrature for the (non-polynomial) hyperelastic integrands: UFL's
        estimate grows with every power and inverse and makes assembly ~50× slower
        for no accuracy gain at the discretisation error."""
        return 2 * self.displacement_degree

    @property
    def geometry_order(self) -> int:
        """Curved (second-order) geometry for quadratic displacements, so that the
        faceting error of curved walls does not dominate the discretisation error."""
        return 2 if self.displacement_degree >= 2 else 1


ELEMENTS: dict[str, ElementFamily] = {
    "P2P1": ElementFamily("P2P1", "tetrahedron", 2, "P", 1,
                          "Taylor–Hood tetrahedra: continuous P2 displacement, P1 pressure"),
    "P2P0": ElementFamily("P2P0", "tetrahedron", 2, "DG", 0,
                          "P2 displacement, piecewise constant pressure"),
    "Q1P0": ElementFamily("Q1P0", "hexahedron", 1, "DG", 0,
                          "the buckling paper's element: 8 displacement nodes, 1 pressure"),
    "Q2P1": ElementFamily("Q2P1", "hexahedron", 2, "DPC", 1,
                          "Q2 displacement, discontinuous P1 (DPC) pressure: LBB-stable (cornea paper)"),
    "P1": ElementFamily("P1", "tetrahedron", 1, None, 0,
                        "linear tetrahedra, displacement only with a bulk penalty: locks"),
}


ElementName = Literal["P2P1", "P2P0", "Q1P0", "Q2P1", "P1"]
assert set(get_args(ElementName)) == set(ELEMENTS)


def check_element(name: str, key: str = "element") -> None:
    """ParameterError (before anything is built) for a family not in :data:`ELEMENTS`."""
    from eyemech.problems.run.parameters import ParameterError

    if name not in ELEMENTS:
        raise ParameterError(key, f"unknown element family {name!r}; valid: {', '.join(ELEMENTS)}")


def displacement_space(mesh: dolfinx.mesh.Mesh, family: ElementFamily) -> dolfinx.fem.FunctionSpace:
    if mesh.basix_cell().name != family.cell:
        raise ValueError(f"{family.name} needs {family.cell} cells, the mesh has {mesh.basix_cell().name}")
    return dolfinx.fem.functionspace(
        mesh, basix.ufl.element("Lagrange", mesh.basix_cell(), family.displacement_degree,
                                shape=(mesh.geometry.dim,)))


def pressure_space(mesh: dolfinx.mesh.Mesh, family: ElementFamily) -> dolfinx.fem.FunctionSpace:
    if family.pressure_family is None:
        raise ValueError(f"{family.name} has no pressure field")
    cell = mesh.basix_cell()
    discontinuous = family.pressure_family in ("DG", "DPC")
    lagrange = basix.LagrangeVariant.legendre if discontinuous else basix.LagrangeVariant.unset
    element = {
        "P": lambda: basix.ufl.element("Lagrange", cell, family.pressure_degree),
        "DG": lambda: basix.ufl.element("Lagrange", cell, family.pressure_degree,
                                        discontinuous=True, lagrange_variant=lagrange),
        "DPC": lambda: basix.ufl.element("DPC", cell, family.pressure_degree, discontinuous=True,
                                         dpc_variant=basix.DPCVariant.legendre),
    }[family.pressure_family]()
    return dolfinx.fem.functionspace(mesh, element)


def mixed_displacement_pressure(mesh: dolfinx.mesh.Mesh, family: ElementFamily):
    """Functions (u, p) and test functions (v, q) on separate spaces (blocked system)."""
    V, Q = displacement_space(mesh, family), pressure_space(mesh, family)
    u, p = dolfinx.fem.Function(V), dolfinx.fem.Function(Q)
    return (u, p), test_functions(V, Q)


def solid_fields(mesh: dolfinx.mesh.Mesh, family: ElementFamily, *extra: dolfinx.fem.FunctionSpace,
                 condensed: bool = False, modes=None):
    """Unknowns and test functions of a solid of ``family``: [u, p] (mixed families)
    or [u] (displacement only, or ``condensed``: Q1P0's pressure eliminated cell by cell,
    :mod:`~eyemech.problems.solid.mean_dilatation`), then ``modes``' unknowns (its
    :class:`~eyemech.problems.solid.incompatible_modes.IncompatibleModes`' own functions),
    followed by one per ``extra`` space (e.g. a Real space for a cavity pressure), all in
    one blocked system."""
    if condensed and family.name != "Q1P0":
        raise ValueError(f"only Q1P0's DG0 pressure condenses cell by cell, not {family.name}'s")
    spaces = [displacement_space(mesh, family)]
    if family.pressure_family is not None and not condensed:
        spaces.append(pressure_space(mesh, family))
    own = list(modes.fields) if modes is not None else []
    functions = [dolfinx.fem.Function(V) for V in spaces] + own + [dolfinx.fem.Function(V) for V in extra]
    spaces += [f.function_space for f in own] + list(extra)
    return functions, list(test_functions(*spaces))


def test_functions(*spaces: dolfinx.fem.FunctionSpace):
    """Test functions of a blocked system: one per space, split later by
    ``ufl.extract_blocks`` into one residual form per block."""
    return ufl.TestFunctions(ufl.MixedFunctionSpace(*spaces))


def symmetry_bcs(V: dolfinx.fem.FunctionSpace, tagged, planes: dict[str, int]):
    """Zero normal displacement on each named symmetry plane (component index)."""
    fdim = tagged.mesh.topology.dim - 1
    bcs = []
    for name, component in planes.items():
        sub = V.sub(component)
        dofs = dolfinx.fem.locate_dofs_topological(sub, fdim, tagged.facets(name))
        bcs.append(dolfinx.fem.dirichletbc(0.0, dofs, sub))
    return bcs


def surface_mean(integrand, measure) -> Callable[[], float]:
    """A callable returning ∫ f dA / ∫ dA over ``measure`` (reference area)."""
    numerator = dolfinx.fem.form(integrand * measure)
    area_form = dolfinx.fem.form(dolfinx.fem.Constant(measure.ufl_domain(), 1.0) * measure)
    comm = numerator.mesh.comm
    area = assemble_scalar(area_form, comm)

    def evaluate() -> float:
        return assemble_scalar(numerator, comm) / area

    return evaluate


def global_dofs(*functions) -> int:
    return int(sum(f.function_space.dofmap.index_map.size_global * f.function_space.dofmap.index_map_bs
                   for f in functions))


def point_value(function: dolfinx.fem.Function, point) -> np.ndarray:
    """Value of ``function`` at ``point`` on every rank (evaluated where a local cell
    contains it, the lowest such rank wins)."""
    import dolfinx.geometry

    mesh = function.function_space.mesh
    x = np.asarray(point, dtype=mesh.geometry.x.dtype).reshape(1, 3)
    owned = mesh.topology.index_map(mesh.topology.dim).size_local
    tree = dolfinx.geometry.bb_tree(mesh, mesh.topology.dim,
                                    entities=np.arange(owned, dtype=np.int32))
    candidates = dolfinx.geometry.compute_collisions_points(tree, x)
    cells = dolfinx.geometry.compute_colliding_cells(mesh, candidates, x).links(0)
    local = function.eval(x, cells[:1]) if len(cells) else None
    found = mesh.comm.allgather(local)
    value = next((v for v in found if v is not None), None)
    if value is None:
        raise ValueError(f"point {tuple(point)} is outside the mesh")
    return np.asarray(value)


def lagrange_view(function: dolfinx.fem.Function, name: str):
    """(f, update): ``function`` itself when it is (discontinuous) Lagrange, else a
    discontinuous Lagrange copy of the same degree that ``update()`` refreshes —
    VTX writes Lagrange functions only (DPC pressures of Q2P1 are not)."""
    element = function.function_space.element.basix_element
    if element.family == basix.ElementFamily.P:
        function.name = name
        return function, lambda: None
    mesh = function.function_space.mesh
    view = dolfinx.fem.Function(dolfinx.fem.functionspace(mesh, ("DG", element.degree)), name=name)
    expression = dolfinx.fem.Expression(function, view.function_space.element.interpolation_points)

    def update() -> None:
        view.interpolate(expression)

    update()
    return view, update


class PetscNodeLayout:
    """Where the node blocks of a vector field sit in the PETSc vector of a system, for
    hooks that add point terms (contact pairs, bars) straight into the assembled b and A.

    A single field: global index = global node · bs + component. A blocked system
    (``block_spaces`` = the spaces of ``NonlinearProblem(..., kind="mpi")``, the field's
    first): each rank stores its owned dofs of every block one after the other, so a node
    owned by rank r sits at Σ_{s<r} (owned dofs of all blocks on s) + (its number on r) · bs.
    Collective to build."""

    def __init__(self, space: dolfinx.fem.FunctionSpace, block_spaces=None):
        self.comm = space.mesh.comm
        self.imap = space.dofmap.index_map
        self.bs = space.dofmap.index_map_bs
        if block_spaces is None:
            rank_total = self.bs * self.imap.size_local
        else:
            if block_spaces[0] != space:
                raise ValueError("block_spaces must start with the field's own space")
            rank_total = sum(V.dofmap.index_map.size_local * V.dofmap.index_map_bs
                             for V in block_spaces)
        self._starts = np.array(self.comm.allgather(self.imap.local_range[0]), dtype=np.int64)
        self._offsets = np.concatenate([[0], np.cumsum(self.comm.allgather(rank_total))]).astype(np.int64)

    def base(self, global_nodes: np.ndarray) -> np.ndarray:
        """PETSc index of component 0 of the given global node numbers."""
        global_nodes = np.asarray(global_nodes, dtype=np.int64)
        owner = np.searchsorted(self._starts, global_nodes, side="right") - 1
        return self._offsets[owner] + (global_nodes - self._starts[owner]) * self.bs

    def constrained_dofs(self, bcs) -> np.ndarray:
        """Sorted PETSc indices of the field's Dirichlet-constrained dofs, on every rank
        (collective): point terms must not touch the rows the boundary conditions own."""
        mine = []
        for bc in bcs:
            local, _ = bc.dof_indices()
            blocks = self.imap.local_to_global((local // self.bs).astype(np.int32))
            mine.append(self.base(blocks) + local % self.bs)
        mine = np.concatenate(mine) if mine else np.zeros(0, dtype=np.int64)
        return np.unique(np.concatenate(self.comm.allgather(mine)))
