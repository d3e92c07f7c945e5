"""``tonometry``: Goldmann applanation of the pressurised cornea (issue 6, item 6).

The intact cornea of :mod:`eyemech.meshes.cornea` carries the intra-ocular pressure
``iop_mmHg`` as a follower load on its posterior surface (limbus clamped or on springs,
as in ``keratotomy``); then a rigid flat applanator (a :class:`~eyemech.forms.contact.Plane`
normal to the optical axis, penalty contact on the anterior surface) is lowered onto the
apex until the contact disc reaches ``applanation_diameter`` (Goldmann: 3.06 mm).
Imbert–Fick reads the pressure as force over area,

    IOP_reading = F / A,   A = π (3.06 mm)² / 4 = 7.354 mm²,

F the force on the prism: the contact force of the cornea minus the tear meniscus's
capillary attraction (``tear_film_mmHg`` × A, measured by McCafferty et al. 2018 as
4.57 mmHg on a Goldmann prism; 0 gives the dry Imbert–Fick reading F_contact / A,
reported as ``iop_reading_dry_mmHg``).

which is exact for an infinitely thin, perfectly flexible, dry membrane; the corneal
rigidity adds to F (the reading rises with thickness and stiffness) and the tear film's
capillary attraction subtracts from it. Goldmann chose 3.06 mm so that the
two cancel for an average cornea, and 1 g of force then reads 10 mmHg (Goldmann & Schmidt
1957); Ehlers, Bramsen & Sperling (1975) found the readings true at 520 µm central
thickness.

Material: the instantaneous (glassy) response — an applanation lasts a fraction of a
second, ≪ τ = 1 h — i.e. incompressible neo-Hooke with shear modulus μ = E/3 (the
viscoelastic residual with Cv = I); ``youngs_modulus`` is that instantaneous E. Its default,
0.13 MPa, is calibrated as Goldmann calibrated his instrument: the model reads the true IOP
at 520 µm (docs/studies/tonometry_sweep.csv); keratotomy's glassy material (E = 0.21 MPa)
reads ≈ 4.5 mmHg high. The IOP is held constant during applanation (the ≈ 0.5 µl displaced by a
Goldmann tonometer raises it by ≈ 3 %, neglected as in Goldmann's calibration).

Mesh sizes follow the physics: the planform's radial size is the applanation radius (the
contact disc the reading depends on) over ``resolution``, so another prism diameter gets
the same number of rings across its disc; ``mesh_size`` sets an absolute size instead.
Through the thickness ``layers`` cells per local thickness. The hexahedra are counted
before meshing (exact) and a run above ``max_cells`` is refused, naming ``resolution``.

The contact radius is where the gap to the applanator changes sign along the radial grid
lines of the anterior surface, found on the quadratic (Q2) interpolant of the gap along
each line, so that it varies continuously with the applanator's position; the position is
then found by regula falsi so that the mean radius over all lines is the target radius.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import ClassVar

import dolfinx
import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms import contact, follower_pressure
from eyemech.forms import viscoelastic as ve
from eyemech.meshes import MeshError
from eyemech.meshes.cornea import CorneaGeometry, cell_count, cornea
from eyemech.problems.contact.rigid import resultant_force
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.output import PyvistaSeries, displacement_grid, render_png
from eyemech.problems.run.parameters import (
    GEOMETRY,
    MMHG,
    PHYSICS,
    SOLVER,
    ParameterError,
    SceneParameters,
    field,
)
from eyemech.problems.run.scene import Scene
from eyemech.problems.solid.limbus import SUPPORTS, Support, limbus_support, validate_support
from eyemech.problems.solid.spaces import (
    ELEMENTS,
    global_dofs,
    mixed_displacement_pressure,
)
from eyemech.problems.solve.driver import (
    NonlinearSolver,
    SolveFailure,
    Stepping,
    follow_path,
)

GOLDMANN_DIAMETER = 3.06  # mm
CONTACT_QUADRATURE = 6    # the penalty integrand has a kink at the contact edge


@dataclasses.dataclass(frozen=True)
class Parameters(SceneParameters):
    RESOLUTION_KEY: ClassVar[str] = "resolution"

    iop_mmHg: float = field(15.0, "true intra-ocular pressure on the posterior surface", "mmHg",
                            group=PHYSICS)
    youngs_modulus: float = field(0.13, "instantaneous Young's modulus of the cornea, E = 3(μ∞ + μv); "
                                  "0.13 makes the model read the true IOP at 520 µm (Goldmann's "
                                  "calibration, docs/cornea.md)", "MPa", group=PHYSICS)
    central_thickness: float = field(0.52, "central corneal thickness", "mm", group=GEOMETRY)
    limbal_thickness: float = field(0.67, "thickness at the limbus", "mm", group=GEOMETRY)
    anterior_radius: float = field(7.8, "anterior radius of curvature", "mm", group=GEOMETRY)
    posterior_radius: float = field(6.5, "posterior apical radius of curvature", "mm", group=GEOMETRY)
    diameter: float = field(11.7, "planform diameter at the limbus", "mm", group=GEOMETRY)
    applanation_diameter: float = field(GOLDMANN_DIAMETER, "contact disc diameter at the reading", "mm",
                                        group=PHYSICS)
    tear_film_mmHg: float = field(4.57, "capillary attraction of the tear meniscus on the prism, as a "
                                  "pressure over the disc (McCafferty et al. 2018: 4.57 ± 0.18 mmHg)", "mmHg",
                                  group=PHYSICS)
    penalty: float = field(30.0, "applanator penalty factor: α = penalty · E / h, h the planform "
                           "element size", "", group=SOLVER)
    support: Support = field("clamped", "limbus support: " + ", ".join(SUPPORTS), group=PHYSICS)
    limbus_stiffness: float = field(0.4, "spring stiffness per area of the elastic limbus "
                                    "(≈ E_sclera / 5 mm)", "MPa/mm", group=PHYSICS)
    resolution: float = field(3.06, "planform cells per applanation radius "
                              "(applanation_diameter / 2; 3.06: 0.5 mm at Goldmann's 3.06 mm); sets "
                              "the radial element size unless mesh_size is given", group=GEOMETRY)
    mesh_size: float = field(0.0, "radial element size in the planform; 0 = applanation_diameter "
                             "/ 2 / resolution", "mm", group=GEOMETRY)
    max_cells: int = field(20_000, "refuse a mesh of more hexahedra than this (counted before "
                           "meshing; 20,000 Q2P1 cells ≈ 0.6 M unknowns)", group=GEOMETRY)
    azimuthal_divisions: int = field(16, "elements around (rounded up to a multiple of 8)", group=GEOMETRY)
    layers: int = field(2, "element layers through the thickness", group=GEOMETRY)
    geometry_degree: int = field(2, "cell geometry: 2 = 27-node cells on the curved surfaces, "
                                 "1 = trilinear (faceted) cells", group=GEOMETRY)
    max_depth: float = field(1.0, "give up if the applanator has moved this far past the apex "
                             "without reaching the contact diameter", "mm", group=SOLVER)

    def validate(self) -> None:
        self.require_positive("iop_mmHg", "youngs_modulus", "applanation_diameter", "penalty",
                              "max_depth", "resolution", "max_cells")
        self.require_nonnegative("mesh_size")
        self.require_nonnegative("tear_film_mmHg")
        validate_support(self)
        for key in ("iop_mmHg", "youngs_modulus", "central_thickness", "penalty"):
            if not np.isfinite(getattr(self, key)):
                raise ParameterError(key, "must be finite")
        try:
            self.geometry().validate()
        except MeshError as err:
            raise ParameterError(getattr(err, "key", "geometry"), str(err)) from None
        if not self.applanation_diameter <= 0.6 * self.diameter:
            raise ParameterError("applanation_diameter", f"{self.applanation_diameter} mm: at most "
                                 f"0.6 × the corneal diameter ({0.6 * self.diameter:.3g} mm)")
        if not self.planform_size <= self.applanation_diameter / 2:
            key = "mesh_size" if self.mesh_size > 0 else "resolution"
            raise ParameterError(key, f"the planform size {self.planform_size:.3g} mm must not "
                                 f"exceed the contact radius "
                                 f"({self.applanation_diameter / 2} mm) to resolve the disc")

    def geometry(self) -> CorneaGeometry:
        # the clear zone (no incisions) puts a ring of nodes at the contact edge
        return CorneaGeometry(self.anterior_radius, self.posterior_radius, self.central_thickness,
                              self.limbal_thickness, self.diameter, 0, 0.5, self.applanation_diameter,
                              self.diameter / 2, self.planform_size, self.azimuthal_divisions,
                              self.layers,
                              self.geometry_degree)

    @property
    def planform_size(self) -> float:
        """``mesh_size``, or the applanation radius over ``resolution``."""
        if self.mesh_size > 0:
            return self.mesh_size
        return self.applanation_diameter / 2 / self.resolution

    @property
    def estimated_cells(self) -> int | None:
        """The exact hexahedron count, from the level counts; None while the geometry is
        invalid (validate names the key)."""
        try:
            return cell_count(self.geometry())
        except (MeshError, ValueError, ZeroDivisionError):
            return None

    @property
    def penalty_stiffness(self) -> float:
        return contact.default_penalty(self.youngs_modulus, self.planform_size, self.penalty)


class ContactEdge:
    """Mean radius (deformed, from the axis) of the contact disc: along each radial line
    of nodes on the anterior surface (the grid lines and the lines through the cell
    centres, where the Q2 interpolant is quadratic between three nodes), the outermost
    zero of the interpolated gap h − z."""

    def __init__(self, u: dolfinx.fem.Function, tagged, geometry: CorneaGeometry):
        V = u.function_space
        nodes = dolfinx.fem.locate_dofs_topological(V, 2, tagged.facets("anterior"))
        nodes = nodes[nodes < V.dofmap.index_map.size_local]
        X = V.tabulate_dof_coordinates()[nodes]
        radius = np.hypot(X[:, 0], X[:, 1])
        first_ring = 0.6 * geometry.optical_zone / 2  # meshes/cornea.py: r_polar
        polar = radius >= first_ring * (1 - 1e-6)
        rays = 2 * geometry.azimuths
        self.ray = np.rint(np.arctan2(X[:, 1], X[:, 0]) * rays / (2 * np.pi)).astype(int) % rays
        self.u, self.nodes, self.X, self.polar, self.radius = u, nodes, X, polar, radius
        self.comm = tagged.mesh.comm

    def __call__(self, height: float) -> float:
        x = self.X + self.u.x.array.reshape(-1, 3)[self.nodes]
        local = np.column_stack([self.ray, self.radius, x, self.polar])
        data = np.vstack(self.comm.allgather(local))
        gap = height - data[:, 4]
        touching = gap <= 0
        if not touching.any():
            return 0.0
        polar = data[:, 5] > 0
        if not (touching & polar).any():  # the disc is still inside the O-grid core
            return float(np.max(np.hypot(data[touching, 2], data[touching, 3])))
        radii = [self._ray_edge(data[(data[:, 0] == k) & polar], height)
                 for k in np.unique(data[polar, 0])]
        return float(np.mean(radii))

    @staticmethod
    def _ray_edge(rows: np.ndarray, height: float) -> float:
        rows = rows[np.argsort(rows[:, 1], kind="stable")]
        gap = height - rows[:, 4]
        # the outer edge: a stiff cornea can lift off at the centre (annular contact), and
        # Goldmann's mires meet at the outer edge of the applanated area
        touching = np.flatnonzero(gap <= 0)
        i = max(touching[-1] + 1 if len(touching) else 0, 1)
        if i >= len(rows):
            raise SolveFailure(0, 0.0, 0.0, [], "the contact disc reached the limbus")
        i0 = i - 1 if i % 2 == 1 else i - 2  # three nodes of one quadratic edge: i0, i0+1, i0+2
        i0 = min(max(i0, 0), len(rows) - 3)
        s = np.linspace(0.0, 1.0, 401)
        shape = np.stack([2 * (s - 0.5) * (s - 1), 4 * s * (1 - s), 2 * s * (s - 0.5)])
        g = shape.T @ gap[i0:i0 + 3]
        j = np.flatnonzero((g[:-1] <= 0) & (g[1:] > 0))
        if len(j) == 0:
            j, w = (0, 0.0) if g[0] > 0 else (len(s) - 2, 1.0)
        else:
            j = j[0]
            w = g[j] / (g[j] - g[j + 1])
        xy = shape.T @ rows[i0:i0 + 3, 2:4]
        point = (1 - w) * xy[j] + w * xy[j + 1]
        return float(np.hypot(*point))


class Applanation:
    """The pressurised cornea and the applanator: mesh, residual, solver, quantities."""

    def __init__(self, params: Parameters, ctx: RunContext):
        geometry = params.geometry()
        with ctx.timings("mesh"):
            self.tagged = cornea(geometry, ctx.comm)
        mesh = self.tagged.mesh
        family = ELEMENTS["Q2P1"]
        (self.u, self.p), (v, q) = mixed_displacement_pressure(mesh, family)
        metadata = {"quadrature_degree": family.quadrature_degree}
        dx, ds = self.tagged.dx(metadata), self.tagged.ds(metadata)
        ds_contact = self.tagged.ds({"quadrature_degree": CONTACT_QUADRATURE})(self.tagged.tag("anterior"))
        mu = params.youngs_modulus / 3.0
        # glassy response: the viscoelastic law with Cv = I is neo-Hooke with μ∞ + μv
        glassy = ve.Viscoelastic(0.5 * mu, 0.5 * mu, 1.0)
        self.pressure = dolfinx.fem.Constant(mesh, 0.0)
        self.height = dolfinx.fem.Constant(mesh, np.array([0.0, 0.0, 10.0 * params.anterior_radius]))
        self.plane = contact.Plane(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, -1.0),
                                   translation=self.height)
        self.alpha = dolfinx.fem.Constant(mesh, params.penalty_stiffness)
        residual = (ve.residual(glassy, self.u, self.p, v, q, ufl.Identity(3), dx)
                    + follower_pressure(self.pressure, self.u, v, ds(self.tagged.tag("posterior")))
                    + ufl.derivative(contact.penalty_energy(self.plane, self.u, self.alpha, ds_contact),
                                     self.u, v))
        support, bcs = limbus_support(params, self.u, v, self.tagged, ds)
        if support is not None:
            residual += support
        self.solver = NonlinearSolver(list(ufl.extract_blocks(residual)), [self.u, self.p], bcs,
                                      options=ctx.options.newton, timings=ctx.timings)
        self.force_z = resultant_force(self.plane, self.u, self.alpha, ds_contact)[2]
        self.edge = ContactEdge(self.u, self.tagged, geometry)
        V = self.u.function_space
        apex = np.flatnonzero(np.linalg.norm(V.tabulate_dof_coordinates()[:V.dofmap.index_map.size_local],
                                             axis=1) < 1e-9)
        self._apex = apex
        self.comm = ctx.comm

    def apex_z(self) -> float:
        return self.comm.allreduce(float(self.u.x.array.reshape(-1, 3)[self._apex, 2].sum()))

    def set_height(self, h: float) -> None:
        self.height.value = np.array([0.0, 0.0, h])

    def contact_radius(self) -> float:
        return self.edge(float(self.height.value[2]))

    def force(self) -> float:
        """Applanation force (N): the plane pushes the cornea towards −z."""
        return -self.force_z()


def _push(body: Applanation, ctx: RunContext, params: Parameters, top: float) -> list[tuple]:
    """Lower the applanator from the deformed apex until the disc passes the target
    radius; returns the converged (depth, radius) pairs, the last one past the target."""
    target = params.applanation_diameter / 2
    visited: list[tuple[float, float]] = [(0.0, 0.0)]

    class Reached(Exception):
        pass

    def apply(depth: float, _increment: float) -> None:
        body.set_height(top - depth)

    def converged(step) -> None:
        radius = body.contact_radius()
        widest = max(r for _, r in visited)
        if radius < widest - 0.05 * target:
            # seen for stiff corneas (E ≳ 0.4 MPa here): the cap then deflects as a whole
            # under the constant IOP and the disc shrinks; a reading from such a path
            # would be meaningless
            raise SolveFailure(len(visited), step.load, visited[-1][0], [],
                               f"the contact disc shrank from {2 * widest:.3g} to {2 * radius:.3g} mm "
                               "while the applanator advanced (the cap buckles)")
        visited.append((step.load, radius))
        ctx.record_step(stage="applanation", depth_mm=step.load, contact_radius_mm=radius,
                        force_N=body.force(), newton_iterations=step.iterations, cuts=step.cuts,
                        **step.counts())
        if radius >= target:
            raise Reached

    guess = params.anterior_radius - math.sqrt(params.anterior_radius**2 - target**2)  # sagitta
    try:
        follow_path(body.solver, apply, Stepping(end=params.max_depth, quantity="applanator depth", unit="mm",
                                                 initial_step=0.5 * guess / params.max_depth,
                                                 max_step=0.5 * guess / params.max_depth, min_step=1e-5),
                    on_converged=converged, label="applanation", quiet=ctx.options.quiet)
    except Reached:
        return visited
    raise SolveFailure(len(visited), params.max_depth, visited[-1][0], [],
                       f"contact diameter {2 * visited[-1][1]:.3g} mm < {2 * target} mm at max_depth")


def _regula_falsi(body: Applanation, bracket: list[tuple], target: float, top: float) -> tuple:
    """Illinois regula falsi on depth ↦ contact radius − target (each value one Newton
    solve from the last state); the contact radius to 1e-5 relative."""
    (d_lo, r_lo), (d_hi, r_hi) = bracket
    f_lo, f_hi, side = r_lo - target, r_hi - target, 0
    depth, radius = d_hi, r_hi
    for _ in range(30):
        if abs(radius - target) <= 1e-5 * target:
            break
        depth = d_hi - f_hi * (d_hi - d_lo) / (f_hi - f_lo)
        body.set_height(top - depth)
        ok, iterations = body.solver.solve()
        if not ok:
            raise SolveFailure(0, depth, d_hi, body.solver.residual_history, body.solver.reason())
        radius = body.contact_radius()
        f = radius - target
        if f > 0:
            d_hi, f_hi = depth, f
            f_lo, side = (f_lo / 2, 1) if side == 1 else (f_lo, 1)
        else:
            d_lo, f_lo = depth, f
            f_hi, side = (f_hi / 2, -1) if side == -1 else (f_hi, -1)
    return depth, radius


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        body = Applanation(params, ctx)
        iop = params.iop_mmHg * MMHG
        follow_path(body.solver, lambda f, _i: setattr(body.pressure, "value", f * iop),
                    Stepping(initial_step=1.0), label="IOP", quiet=ctx.options.quiet)
        apex_iop = body.apex_z()
        top = apex_iop  # the applanator starts touching the deformed apex
        visited = _push(body, ctx, params, top)
        target = params.applanation_diameter / 2
        depth, radius = _regula_falsi(body, visited[-2:], target, top)
        force = body.force()
        area = math.pi * target**2
        q = ctx.result.quantities
        tear = params.tear_film_mmHg * MMHG * area  # pulls the prism on: the instrument pushes less
        q.update(iop_mmHg=params.iop_mmHg, applanation_force_N=force - tear,
                 applanation_force_g=(force - tear) / 9.80665e-3, contact_force_N=force,
                 iop_reading_mmHg=(force - tear) / area / MMHG,
                 iop_reading_dry_mmHg=force / area / MMHG,
                 contact_diameter_mm=2 * radius, applanation_depth_mm=depth,
                 apex_displacement_iop_mm=apex_iop, penalty_stiffness=params.penalty_stiffness,
                 cells=body.tagged.mesh.topology.index_map(3).size_global, dofs=global_dofs(body.u))
        q["reading_error_mmHg"] = q["iop_reading_mmHg"] - params.iop_mmHg
        if ctx.pictures:
            with ctx.timings("output"):
                _picture(ctx, body, params)
    return ctx.result


def _picture(ctx: RunContext, body: Applanation, params: Parameters) -> None:
    grid = displacement_grid(body.u)
    if grid is None:
        return
    # the applanated cornea for notebooks (pyvista cannot read VTX .bp)
    series = PyvistaSeries(ctx.field_dir, ctx.comm)  # none under --no-fields
    series.write(ctx.result.quantities["applanation_depth_mm"], grid)
    ctx.result.fields.extend(series.files)
    path = ctx.out / "tonometry.png"
    q = ctx.result.quantities
    render_png(grid, path, scalars="displacement (mm)", warp="displacement", camera=(0.0, -1.0, 0.35),
               title=f"applanated to {q['contact_diameter_mm']:.2f} mm: reading "
                     f"{q['iop_reading_mmHg']:.1f} mmHg (true {params.iop_mmHg:g}); prism blue, "
                     f"flattened disc red",
               extras=_tonometer(grid, q["contact_diameter_mm"]),
               scene=ctx.result.scene, parameters=ctx.result.parameters)
    ctx.result.pictures.append(path.name)


# Goldmann's prism: a flat face 7 mm across (its tip); drawn 0.4 mm thick, see-through
PRISM_DIAMETER, PRISM_DRAWN_THICKNESS = 7.0, 0.4


def _tonometer(grid, disc_diameter: float) -> list:
    """The prism's flat face on the deformed apex (translucent blue) and the rim of the
    flattened disc of the reading (red), as extras for :func:`render_png`."""
    import pyvista

    apex = float((grid.points[:, 2] + grid.point_data["displacement"][:, 2]).max())
    prism = pyvista.Cylinder(center=(0.0, 0.0, apex + PRISM_DRAWN_THICKNESS / 2), direction=(0, 0, 1),
                             radius=PRISM_DIAMETER / 2, height=PRISM_DRAWN_THICKNESS, resolution=60)
    angle = np.linspace(0.0, 2.0 * np.pi, 121)
    rim = np.column_stack([disc_diameter / 2 * np.cos(angle), disc_diameter / 2 * np.sin(angle),
                           np.full_like(angle, apex + 0.01)])
    disc = pyvista.lines_from_points(rim)
    return [(prism, {"color": "lightsteelblue", "opacity": 0.3}),
            (disc, {"color": "red", "line_width": 6, "label": "flattened disc"})]


SCENE = Scene(name="tonometry", kind="scene", parameters=Parameters, run=run,
              summary="Goldmann applanation tonometry on the pressurised cornea: Imbert–Fick "
                      "reading vs the true IOP")
