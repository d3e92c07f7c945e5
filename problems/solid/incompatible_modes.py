"""Incompatible modes on chosen hexahedra: the unknowns, the centre Jacobians and the
conditions that switch the modes off elsewhere (the form: :mod:`eyemech.forms.incompatible_modes`).

The amplitudes α (three modes × three components per cell) are a DG0 (d, d) field and the
pressure's slopes π a DG0 vector, two more blocks of the Newton system: cell-local, so they
couple only to their cell's displacements and pressure. On the cells without modes they are held at zero by a
Dirichlet condition, and the solid's energy there is integrated with the plain gradient
(:func:`~eyemech.problems.solid.residual.solid_residual`), so those cells neither compile
nor assemble the modes' terms."""

from __future__ import annotations

import basix.ufl
import dolfinx
import dolfinx.fem
import numpy as np
import ufl

from eyemech.forms.incompatible_modes import (
    enhanced_deformation_gradient,
    enhanced_incompressible_energy_density,
    incompatible_gradient,
    pressure_slopes,
)


class IncompatibleModes:
    """Wilson–Taylor modes on the cells ``region`` of a hexahedral ``mesh``.

    ``region``: the cell tag (or tuple of tags) of the cells with modes and ``elsewhere``
    those of the others, for a ``dx`` that carries the mesh's cell tags; both None: every
    cell. ``cells``: the local indices of the cells with modes (None: all; ghosts may be
    left out).
    ``taylor``: Taylor's centre-Jacobian correction (off only to show why it is needed:
    the patch test fails without it on distorted cells)."""

    def __init__(self, mesh: dolfinx.mesh.Mesh, cells: np.ndarray | None = None,
                 region: int | tuple[int, ...] | None = None,
                 elsewhere: int | tuple[int, ...] | None = None, taylor: bool = True):
        if mesh.basix_cell().name != "hexahedron":
            raise ValueError(f"incompatible modes are the hexahedron's, not the {mesh.basix_cell().name}'s")
        if (region is None) != (elsewhere is None):
            raise ValueError("give both region and elsewhere (cell tags), or neither")
        dim = mesh.geometry.dim
        self.region, self.elsewhere = region, elsewhere
        self.space = dolfinx.fem.functionspace(
            mesh, basix.ufl.element("DG", mesh.basix_cell(), 0, shape=(dim, dim)))
        self.modes = dolfinx.fem.Function(self.space, name="incompatible_modes")
        self.slope_space = dolfinx.fem.functionspace(
            mesh, basix.ufl.element("DG", mesh.basix_cell(), 0, shape=(dim,)))
        self.slopes = dolfinx.fem.Function(self.slope_space, name="pressure_slopes")
        # X ∈ [0, 1]³ in each cell: discontinuous Q1 nodal values at the reference vertices
        self.reference_coordinates = dolfinx.fem.Function(dolfinx.fem.functionspace(
            mesh, basix.ufl.element("DG", mesh.basix_cell(), 1, shape=(dim,))))
        X = self.reference_coordinates
        X.x.array.reshape(-1, dim)[X.function_space.dofmap.list] = \
            X.function_space.element.interpolation_points
        self.centre_jacobian = None
        if taylor:
            self.centre_jacobian = dolfinx.fem.Function(self.space, name="centre_jacobian")
            self.centre_jacobian.interpolate(dolfinx.fem.Expression(
                ufl.Jacobian(mesh), self.space.element.interpolation_points))
        self.bcs = []
        if cells is not None:
            # held at zero on this rank's owned cells without modes; the ghosts' owners tell them
            tdim = mesh.topology.dim
            mesh.topology.create_connectivity(tdim, tdim)
            owned = np.arange(mesh.topology.index_map(tdim).size_local, dtype=np.int32)
            without = np.setdiff1d(owned, cells).astype(np.int32)
            for space in self.spaces:
                dofs = dolfinx.fem.locate_dofs_topological(space, tdim, without, remote=True)
                self.bcs.append(dolfinx.fem.dirichletbc(dolfinx.fem.Function(space), dofs))

    def deformation_gradient(self, u) -> ufl.core.expr.Expr:
        """F = I + Grad u + G(α) (a ``ufl.variable``)."""
        return enhanced_deformation_gradient(u, self.modes, self.reference_coordinates,
                                             self.centre_jacobian)

    def energy_density(self, material, u, pressure) -> ufl.core.expr.Expr:
        """The mixed energy density with the modes, ``pressure`` the cells' constant one
        (:func:`~eyemech.forms.incompatible_modes.enhanced_incompressible_energy_density`)."""
        return enhanced_incompressible_energy_density(material, u, self.modes, self.slopes,
                                                      self.reference_coordinates,
                                                      self.centre_jacobian, pressure)

    def gradient(self, modes=None) -> ufl.core.expr.Expr:
        """G of the amplitudes ``modes`` (default: the unknown α; a trial or test function
        of :attr:`space` for a linear problem)."""
        return incompatible_gradient(self.modes if modes is None else modes,
                                     self.reference_coordinates, self.centre_jacobian)

    def linear_pressure(self, slopes=None) -> ufl.core.expr.Expr:
        """The linear part of the pressure, Σ π_i ξ_i, of the slopes ``slopes`` (default: the
        unknown π)."""
        return pressure_slopes(self.slopes if slopes is None else slopes, self.reference_coordinates)

    @property
    def spaces(self) -> list:
        """The blocks the modes add to a system: α, then π."""
        return [self.space, self.slope_space]

    @property
    def fields(self) -> list:
        return [self.modes, self.slopes]

    def measures(self, dx: ufl.Measure) -> tuple[ufl.Measure, ufl.Measure | None]:
        """(the cells with modes, the others) as measures of ``dx``'s quadrature."""
        if self.region is None:
            return dx, None
        return dx(self.region), dx(self.elsewhere)

    def blocks(self, fields) -> list[int]:
        """The positions of α and π among a blocked system's unknowns."""
        return [next(i for i, f in enumerate(fields) if f is mine) for mine in self.fields]
