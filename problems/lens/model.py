"""What the lens scenes (``iol-fold``, ``iol-injection``) share: the lens parameters, the
shell with a thickness field (optic vs haptics), its mass, the rigid injector and capsule,
the saved folded state and the per-frame measurements."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Literal

import basix.ufl
import dolfinx
import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms.dynamics import mass_form
from eyemech.forms.shell import ShellMaterial, shell_energy, shell_jacobian
from eyemech.meshes.iol import LensGeometry, intraocular_lens
from eyemech.meshes.surface import orientation
from eyemech.meshes.tagged import TaggedMesh
from eyemech.problems.lens.injector import Capsule, Plunger, TaperedBore
from eyemech.problems.lens.surface_contact import serial_ipctk
from eyemech.problems.run.context import RunContext
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, ParameterError, SceneParameters, field
from eyemech.problems.solve.driver import NewtonOptions

# every mesh size of the lens (optic, haptics, junctions) times this factor
RESOLUTIONS = {"paper": 1.0, "coarse": 2.0}


@dataclasses.dataclass(frozen=True)
class LensParameters(SceneParameters):
    youngs_modulus: float = field(1.0, "Young's modulus of the acrylic (seed 000, Table 2)", "MPa",
                                  group=PHYSICS)
    poisson_ratio: float = field(0.42, "Poisson's ratio (seed 000, Table 2)", group=PHYSICS)
    density: float = field(1.2e-9, "mass density, 1.2 g/cm³ (seed 000, Table 2)", "tonne/mm³", group=PHYSICS)
    optic_thickness: float = field(0.2, "shell thickness of the optic (assumed)", "mm", group=GEOMETRY)
    haptic_thickness: float = field(0.13, "shell thickness of the haptics (seed 000: 0.13 mm)", "mm",
                                    group=GEOMETRY)
    optic_diameter: float = field(6.0, "optic diameter", "mm", group=GEOMETRY)
    overall_length: float = field(13.0, "diameter of the circle enclosing the haptics", "mm", group=GEOMETRY)
    mesh_size: float = field(0.6, "triangle size in the optic (0.6: 752 triangles, the paper 743)", "mm",
                             group=GEOMETRY)
    resolution: Literal["paper", "coarse"] = field(
        "paper", "lens mesh: 'paper' (the sizes as given: 752 triangles by default) or "
                 "'coarse' (every size × 2: 250 triangles, a quick run)", group=GEOMETRY)
    degree: int = field(2, "Lagrange degree of the displacement (2 or 3)", group=GEOMETRY)
    penalty_factor: float = field(1.0, "α in the shell's edge penalty α p(p+1) D / h", group=GEOMETRY)
    bore_radius: float = field(1.25, "cartridge bore radius (loading chamber)", "mm", group=GEOMETRY)
    nozzle_radius: float = field(1.05, "nozzle bore radius (≈ 2.2 mm outer: a ≈ 2 mm incision)", "mm",
                                 group=GEOMETRY)
    fold_radius: float = field(1.0, "radius the optic is rolled to about the injector axis", "mm",
                               group=GEOMETRY)
    contact_stiffness: float = field(1.0, "nodal penalty stiffness k of rigid contact", "N/mm", group=SOLVER)
    damping: float = field(2.0e4, "mass-proportional damping c standing in for the viscoelastic "
                                  "fluid: c = μ/(δ ρ h), μ ≈ 10 Pa·s over a δ ≈ 2 mm layer", "1/s",
                           group=PHYSICS)
    self_contact: bool = field(True, "lens self-contact by ipctk's barrier with CCD-limited Newton steps "
                                     "(needs ipctk)", group=PHYSICS)
    self_contact_distance: float = field(0.05, "barrier reach d̂: mid-surfaces closer than this repel", "mm",
                                         group=SOLVER)
    self_contact_stiffness: float = field(1.0, "barrier stiffness κ (Π = κ Σ b(d², d̂²); at d = d̂/2 a pair "
                                               "pushes with ≈ 4.3 κ d̂³)", "N/mm³", group=SOLVER)
    friction: float = field(0.2, "Coulomb coefficient μ of lens–lens contact (haptic–optic adhesion; "
                                 "0 = none)", group=PHYSICS)
    friction_slip: float = field(1e-3, "slip per step below which friction is regularised (viscous)", "mm",
                                 group=SOLVER)

    def validate(self) -> None:
        self.require_positive("youngs_modulus", "density", "optic_thickness", "haptic_thickness",
                              "optic_diameter", "overall_length", "mesh_size", "penalty_factor",
                              "bore_radius", "nozzle_radius", "fold_radius", "contact_stiffness")
        self.require_nonnegative("damping", "friction")
        self.require_positive("self_contact_distance", "self_contact_stiffness", "friction_slip")
        if self.self_contact_distance > 0.5 * self.haptic_thickness + 0.5 * self.optic_thickness:
            raise ParameterError("self_contact_distance", f"{self.self_contact_distance} mm is more than the "
                                 "half thicknesses of two touching layers: the barrier would hold parts "
                                 "apart that are not touching")
        if not -1.0 < self.poisson_ratio < 0.5:
            raise ParameterError("poisson_ratio", f"must lie in (-1, 0.5), got {self.poisson_ratio!r}")
        if self.degree not in (2, 3):
            raise ParameterError("degree", f"must be 2 or 3, got {self.degree!r}")
        if self.nozzle_radius > self.bore_radius:
            raise ParameterError("nozzle_radius", "the bore must taper down to the nozzle")
        rolled = 0.5 * self.optic_diameter / np.pi  # the optic closed into a full circle
        if self.fold_radius < rolled:
            raise ParameterError("fold_radius", f"{self.fold_radius} mm would make the {self.optic_diameter}"
                                 f" mm optic overlap itself (a full turn is {rolled:.3g} mm)")
        if self.fold_radius + 0.5 * self.optic_thickness > self.bore_radius:
            raise ParameterError("fold_radius", f"the folded optic (radius {self.fold_radius} mm) does not "
                                 f"fit the cartridge bore (radius {self.bore_radius} mm)")

    def geometry(self) -> LensGeometry:
        scale = RESOLUTIONS[self.resolution]
        reference = LensGeometry()
        return LensGeometry(optic_diameter=self.optic_diameter, overall_length=self.overall_length,
                            mesh_size=scale * self.mesh_size, haptic_size=scale * reference.haptic_size,
                            junction_size=scale * reference.junction_size)

    @property
    def estimated_cells(self) -> int | None:
        """The lens' triangles before meshing (``LensGeometry.estimated_triangles``); None for
        a size that is not positive (refused by ``validate``)."""
        geometry = self.geometry()
        if not min(geometry.mesh_size, geometry.haptic_size, geometry.junction_size) > 0:
            return None
        return geometry.estimated_triangles

    def axis_point(self) -> np.ndarray:
        """The injector axis runs along x through (0, 0, fold_radius): the optic's roll axis."""
        return np.array([0.0, 0.0, self.fold_radius])


class LensShell:
    """The lens as a nonlinear Kirchhoff–Love shell with a DG0 thickness field."""

    def __init__(self, params: LensParameters, comm: MPI.Comm):
        self.tagged: TaggedMesh = intraocular_lens(params.geometry(), comm)
        mesh = self.mesh = self.tagged.mesh
        element = basix.ufl.element("Lagrange", "triangle", params.degree, shape=(3,))
        self.V = dolfinx.fem.functionspace(mesh, element)
        self.u = dolfinx.fem.Function(self.V, name="displacement")
        self.v = ufl.TestFunction(self.V)
        self.orientation = orientation(mesh, lambda x: np.tile([0.0, 0.0, 1.0], (len(x), 1)))
        self.thickness = dolfinx.fem.Function(self.orientation.function_space, name="thickness")
        self.thickness.x.array[:] = params.haptic_thickness
        optic_cells = self.tagged.cells("optic")
        self.thickness.x.array[self.thickness.function_space.dofmap.list[optic_cells, 0]] = \
            params.optic_thickness
        self.thickness.x.scatter_forward()

        def constant(value: float):
            return dolfinx.fem.Constant(mesh, dolfinx.default_scalar_type(value))

        self.constant = constant
        self.material = ShellMaterial(constant(params.youngs_modulus), constant(params.poisson_ratio),
                                      self.thickness)
        metadata = {"quadrature_degree": 2 * params.degree}
        self.dx = ufl.Measure("dx", mesh, metadata=metadata)
        self.dS = ufl.Measure("dS", mesh, metadata=metadata)
        self.degree = params.degree
        self.penalty_factor = constant(params.penalty_factor)
        self.density = constant(params.density)

    def residual(self):
        """f_int(u): the first variation of the nonlinear shell energy (no loads)."""
        energy = shell_energy(self.u, self.material, self.orientation, degree=self.degree,
                              penalty_factor=self.penalty_factor, dx=self.dx, dS=self.dS,
                              kinematics="nonlinear")
        return ufl.derivative(energy, self.u, self.v)

    def jacobian(self):
        """f_int'(u): the residual's Jacobian written out by hand (``shell_jacobian``; equal to
        ``derivative(self.residual(), self.u)`` up to round-off, half its compile and assembly time)."""
        return shell_jacobian(self.u, self.v, ufl.TrialFunction(self.V), self.material, self.orientation,
                              degree=self.degree, penalty_factor=self.penalty_factor, dx=self.dx, dS=self.dS)

    def mass(self):
        return mass_form(ufl.TrialFunction(self.V), self.v, self.density, self.thickness, self.dx)

    def nodes_of(self, cells_name: str) -> np.ndarray:
        """Block (node) indices of the dofs on the cells tagged ``cells_name``."""
        cells = self.tagged.cells(cells_name)
        return np.unique(self.V.dofmap.list[cells].ravel())

    def node_coordinates(self) -> np.ndarray:
        return self.V.tabulate_dof_coordinates()

    def dofs(self) -> int:
        return self.V.dofmap.index_map.size_global * 3


def rolled(points: np.ndarray, curvature: float) -> np.ndarray:
    """The optic rolled isometrically about the x-directed line (y = 0, z = 1/κ):
    (x, y, 0) ↦ (x, sin(κy)/κ, (1 − cos κy)/κ). κ → 0 is the flat lens."""
    x, y = points[:, 0], points[:, 1]
    if abs(curvature) < 1e-12:
        return np.column_stack([x, y, np.zeros_like(x)])
    k = curvature
    return np.column_stack([x, np.sin(k * y) / k, (1.0 - np.cos(k * y)) / k])


@dataclasses.dataclass(frozen=True)
class InjectorLayout:
    """Where things are along the injector axis (x, mm)."""

    taper_start: float = 6.5
    taper_end: float = 9.5
    tip: float = 11.0
    capsule_semi_axes: tuple[float, float, float] = (5.25, 5.25, 2.25)
    capsule_depth: float = 4.0  # capsule centre beyond the nozzle tip

    nozzle_lip: float = 0.5  # mm, radius of the rounded nozzle exit (injection only)

    def cartridge(self, params: LensParameters, lip: float = 0.0) -> TaperedBore:
        return TaperedBore(params.axis_point(), params.bore_radius, params.nozzle_radius,
                           self.taper_start, self.taper_end, self.tip, lip=lip)

    def capsule(self, params: LensParameters) -> Capsule:
        center = params.axis_point() + np.array([self.tip + self.capsule_depth, 0.0, 0.0])
        return Capsule(center, np.asarray(self.capsule_semi_axes), self.tip)


def save_state(path: Path, shell: LensShell, comm: MPI.Comm) -> None:
    """Displacement at the node coordinates (gathered on rank 0), as .npz."""
    owned = shell.V.dofmap.index_map.size_local
    X = shell.node_coordinates()[:owned]
    U = shell.u.x.array[: 3 * owned].reshape(-1, 3)
    gathered = comm.gather((X, U), root=0)
    if comm.rank == 0:
        X = np.vstack([g[0] for g in gathered])
        U = np.vstack([g[1] for g in gathered])
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, coordinates=X, displacement=U)
        tmp.replace(path)


def load_state(path: Path, shell: LensShell) -> None:
    """Set u from a saved state, matching nodes by coordinates (any partition)."""
    from scipy.spatial import cKDTree

    data = np.load(path)
    distance, index = cKDTree(data["coordinates"]).query(shell.node_coordinates())
    if np.max(distance, initial=0.0) > 1e-8:
        raise ParameterError("folded_state", f"{path} was saved for another lens mesh "
                             f"(nodes {np.max(distance):.3g} mm apart)")
    shell.u.x.array[:] = data["displacement"][index].ravel()
    shell.u.x.scatter_forward()


def require_ipctk() -> None:
    """Self-contact needs ipctk (the ``iol`` extra): refuse before any solve if it is missing."""
    try:
        import ipctk  # noqa: F401
    except ImportError as err:
        raise ParameterError("self_contact", "needs ipctk (pip install -e '.[iol]'); "
                             "or set self_contact=false") from err
    serial_ipctk()  # reproducible runs


def lens_self_contact(shell: LensShell, params: LensParameters, excluded_dofs=None):
    """The lens' self-contact (:class:`~eyemech.problems.contact.ipc.SelfContact`), or
    None when ``self_contact`` is off. Needs ipctk (the ``iol`` extra); on N ranks rank 0
    evaluates it on the gathered lens."""
    if not params.self_contact:
        return None
    require_ipctk()
    from eyemech.problems.contact.ipc import SelfContact

    return SelfContact(shell.u, params.self_contact_distance, params.self_contact_stiffness,
                       friction=params.friction, slip=params.friction_slip, excluded_dofs=excluded_dofs)


def lens_newton(ctx: RunContext) -> NewtonOptions:
    """The run's Newton options with the lens' tolerances: relative 1e-6, absolute 1e-9 N
    (shell forces are ~1e-4 N) unless the run asked for looser ones, and 25 iterations."""
    options = ctx.options.newton
    return dataclasses.replace(options, rtol=max(options.rtol, 1e-6), atol=max(options.atol, 1e-9),
                               max_it=max(options.max_it, 25))


# -- measurements ---------------------------------------------------------------------------
class StrainProbe:
    """Largest surface strain per cell, max over the two faces of |eig(E ± h/2 K)| (E the
    membrane Green strain, K the change of curvature), at cell midpoints."""

    def __init__(self, shell: LensShell):
        from eyemech.forms.shell import ShellGeometry

        geo = ShellGeometry(shell.u, shell.orientation)
        space = dolfinx.fem.functionspace(shell.mesh, ("DG", 0, (3, 3)))
        points = space.element.interpolation_points
        self.membrane = dolfinx.fem.Function(space)
        self.bending = dolfinx.fem.Function(space)
        self._expressions = [dolfinx.fem.Expression(geo.membrane_strain(), points),
                             dolfinx.fem.Expression(0.5 * shell.thickness * geo.bending_strain(), points)]
        cells = shell.tagged.cells("haptic")
        self.haptic_cells = cells[cells < shell.mesh.topology.index_map(2).size_local]
        self.comm = shell.mesh.comm

    def haptic_max(self) -> float:
        self.membrane.interpolate(self._expressions[0])
        self.bending.interpolate(self._expressions[1])
        E = self.membrane.x.array.reshape(-1, 3, 3)[self.haptic_cells]
        K = self.bending.x.array.reshape(-1, 3, 3)[self.haptic_cells]
        local = 0.0
        if len(E):
            top = np.abs(np.linalg.eigvalsh(0.5 * ((E + K) + np.transpose(E + K, (0, 2, 1)))))
            bottom = np.abs(np.linalg.eigvalsh(0.5 * ((E - K) + np.transpose(E - K, (0, 2, 1)))))
            local = float(max(top.max(), bottom.max()))
        return self.comm.allreduce(local, op=MPI.MAX)

    def cell_max(self) -> np.ndarray:
        """Largest surface strain of every local cell (optic and haptics), for pictures."""
        self.membrane.interpolate(self._expressions[0])
        self.bending.interpolate(self._expressions[1])
        E = self.membrane.x.array.reshape(-1, 3, 3)
        K = self.bending.x.array.reshape(-1, 3, 3)
        faces = [np.abs(np.linalg.eigvalsh(0.5 * (A + np.transpose(A, (0, 2, 1))))).max(axis=1)
                 for A in (E + K, E - K)]
        return np.maximum(*faces)


def optic_normal(shell: LensShell) -> np.ndarray:
    """Mean deformed normal of the optic (area weighted, from the flat triangles of the
    P2 vertices), the same on every rank."""
    owned = shell.mesh.topology.index_map(2).size_local
    cells = shell.tagged.cells("optic")
    cells = cells[cells < owned]
    nodes = shell.V.dofmap.list[cells][:, :3]
    x = shell.node_coordinates() + shell.u.x.array.reshape(-1, 3)
    p = x[nodes]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    sign = shell.orientation.x.array[shell.orientation.function_space.dofmap.list[cells, 0]]
    # the orientation flips each cell's J normal to +z in the reference; DOLFINx's P2 vertex
    # order is the geometry's, so the same sign applies
    total = shell.mesh.comm.allreduce((normal * sign[:, None]).sum(axis=0), op=MPI.SUM)
    return total / max(np.linalg.norm(total), 1e-300)


def optic_flatness(shell: LensShell) -> float:
    """|∫ n dA| / ∫ dA over the optic (flat triangles of the P2 vertices): 1 for a flat optic,
    sin(θ/2)/(θ/2) for one rolled through the angle θ — 0.05 for the default fold
    (θ = 6 mm / 1 mm), so > 0.9 means unrolled."""
    owned = shell.mesh.topology.index_map(2).size_local
    cells = shell.tagged.cells("optic")
    cells = cells[cells < owned]
    nodes = shell.V.dofmap.list[cells][:, :3]
    p = (shell.node_coordinates() + shell.u.x.array.reshape(-1, 3))[nodes]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    sign = shell.orientation.x.array[shell.orientation.function_space.dofmap.list[cells, 0]]
    comm = shell.mesh.comm
    total = comm.allreduce((normal * sign[:, None]).sum(axis=0), op=MPI.SUM)
    area = comm.allreduce(float(np.linalg.norm(normal, axis=1).sum()), op=MPI.SUM)
    return float(np.linalg.norm(total) / max(area, 1e-300))


def optic_center(shell: LensShell) -> np.ndarray:
    """Mean deformed position of the optic's nodes (the lens centre)."""
    owned = shell.V.dofmap.index_map.size_local
    nodes = shell.nodes_of("optic")
    nodes = nodes[nodes < owned]
    x = shell.node_coordinates()[nodes] + shell.u.x.array.reshape(-1, 3)[nodes]
    total = shell.mesh.comm.allreduce(np.append(x.sum(axis=0), len(x)), op=MPI.SUM)
    return total[:3] / total[3]


# -- pictures -------------------------------------------------------------------------------
def render_frame(shell: LensShell, path: Path, title: str, obstacles: dict,
                 bounds: tuple[float, float] = (-7.0, 21.0)) -> None:
    """The deformed lens (coloured optic / haptic) with the rigid bodies as wireframes."""
    from eyemech.problems.run.output import gather_grid

    grid = gather_grid(shell.u)
    if grid is None:
        return
    render_grid(grid.warp_by_vector(shell.u.name), path, title, obstacles, bounds)


def render_grid(deformed, path: Path, title: str, obstacles: dict,
                bounds: tuple[float, float] = (-7.0, 21.0)) -> None:
    """``render_frame``'s picture of a deformed lens surface (a pyvista dataset in its deformed
    position; the P1 scenes draw their triangles with it)."""
    import pyvista

    from eyemech.problems.run.output import quiet_vtk

    pyvista.OFF_SCREEN = True
    quiet_vtk()
    plotter = pyvista.Plotter(off_screen=True, window_size=(1100, 600))
    plotter.add_mesh(deformed, color="#5b9bd5", show_edges=True, edge_color="#1f3f66", smooth_shading=False)
    for obstacle in obstacles.values():
        mesh = _obstacle_mesh(obstacle, bounds)
        if mesh is not None:
            plotter.add_mesh(mesh, style="wireframe", color="grey", opacity=0.35)
    plotter.add_text(title, font_size=11)
    plotter.camera_position = [(6.0, -26.0, 14.0), (7.0, 0.0, 1.0), (0.0, 0.0, 1.0)]
    tmp = path.with_suffix(".tmp.png")
    plotter.screenshot(str(tmp))
    plotter.close()
    tmp.replace(path)


def write_frame_grid(series, shell: LensShell, time: float, strain: StrainProbe | None = None) -> None:
    """The deformed lens as one ``.vtu`` frame of ``series`` (a ``PyvistaSeries``): the P2
    displacement, and per cell the thickness, the part (1 optic, 0 haptic) and the largest
    surface strain — what notebooks read with ``pyvista.read``."""
    from eyemech.problems.run.output import gather_grid

    if series.out is None:  # no output folder, or fields off: nothing to gather
        return
    cells = shell.mesh.topology.index_map(2).size_local
    part = np.zeros(cells)
    optic = shell.tagged.cells("optic")
    part[optic[optic < cells]] = 1.0
    cell_data = {"thickness (mm)": shell.thickness.x.array[
        shell.thickness.function_space.dofmap.list[:cells, 0]], "optic": part}
    if strain is not None:
        cell_data["surface strain"] = strain.cell_max()[:cells]
    series.write(time, gather_grid(shell.u, cell_data=cell_data))


def _obstacle_mesh(obstacle, bounds):
    import pyvista

    if isinstance(obstacle, TaperedBore):
        x = np.linspace(bounds[0], obstacle.tip, 40)
        theta = np.linspace(0, 2 * np.pi, 25)
        r = obstacle.wall_radius(x)
        X, T = np.meshgrid(x, theta, indexing="ij")
        R = np.repeat(r[:, None], len(theta), axis=1)
        a = obstacle.axis_point
        return pyvista.StructuredGrid(X, a[1] + R * np.cos(T), a[2] + R * np.sin(T))
    if isinstance(obstacle, Capsule):
        sphere = pyvista.ParametricEllipsoid(*obstacle.semi_axes, u_res=24, v_res=12, w_res=12)
        return sphere.translate(obstacle.center)
    if isinstance(obstacle, Plunger):
        a = obstacle.axis_point
        return pyvista.Disc(center=(obstacle.position, a[1], a[2]), inner=0.0, outer=obstacle.radius,
                            normal=(1, 0, 0), c_res=16)
    return None


def write_animation(frames: list[Path], path: Path, seconds_per_frame: float = 0.12) -> str | None:
    """An animated GIF of the PNG frames (imageio), or None when imageio is missing."""
    try:
        import imageio.v2 as imageio
    except ImportError:
        return None
    images = [imageio.imread(f) for f in frames]
    tmp = path.with_suffix(".tmp.gif")
    imageio.mimsave(tmp, images, duration=seconds_per_frame, loop=0, format="GIF")
    tmp.replace(path)
    return path.name
