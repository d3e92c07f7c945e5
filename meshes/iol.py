"""A one-piece intra-ocular lens as a flat mid-surface (z = 0) for the shell: an optic disc
and two C-loop haptics, meshed by gmsh with triangles graded at the haptic–optic
junctions (seed 000, Fig. 4: 743 triangles, 473 nodes).

Each haptic's centre line is a polar curve leaving the optic rim and sweeping
``haptic_sweep`` degrees around it while its radius grows from inside the rim to the
tip radius, r(s) = r₀ + (r_tip − r₀) sin(π s / 2)^{0.7}, s ∈ [0, 1]; the band is
``haptic_width`` wide, widening to ``root_width`` where it joins the optic. The second
haptic is the first turned by 180° (the lens is point symmetric), and the overall
length (the diameter of the circle enclosing the haptics, as IOLs are specified) is
2 (r_tip + width/2).

Tags: cells ``optic`` and ``haptic``; edges ``tip_1``, ``tip_2`` (the haptics' end caps).
"""

from __future__ import annotations

import dataclasses

import dolfinx.mesh
import gmsh
import numpy as np
from dolfinx.io import gmsh as gmshio
from mpi4py import MPI

from eyemech.meshes.tagged import MeshError, TaggedMesh, gmsh_session

# the size field's grading: junction_size within JUNCTION_NEAR of a junction, growing linearly
# to mesh_size at JUNCTION_FAR (mm)
JUNCTION_NEAR, JUNCTION_FAR = 0.4, 2.5


@dataclasses.dataclass(frozen=True)
class LensGeometry:
    optic_diameter: float = 6.0       # mm
    overall_length: float = 13.0      # mm, diameter of the circle enclosing the haptics
    haptic_width: float = 0.45        # mm, in plane
    root_width: float = 0.9           # mm, at the junction
    haptic_sweep: float = 150.0       # degrees of arc the haptic turns about the optic
    mesh_size: float = 0.60           # mm, optic interior
    haptic_size: float = 0.42         # mm, along the haptics
    junction_size: float = 0.16       # mm, at the haptic–optic junctions

    def validate(self) -> None:
        for key in ("optic_diameter", "overall_length", "haptic_width", "root_width", "haptic_sweep",
                    "mesh_size", "haptic_size", "junction_size"):
            if not getattr(self, key) > 0:
                raise MeshError(f"lens geometry: {key} must be positive, got {getattr(self, key)!r}")
        if self.overall_length <= self.optic_diameter + 2 * self.haptic_width:
            raise MeshError(f"lens geometry: overall_length {self.overall_length} leaves no room for "
                            f"haptics around a {self.optic_diameter} mm optic")
        if not self.haptic_sweep < 300:
            raise MeshError("lens geometry: haptic_sweep must be below 300° (the loops would overlap)")

    @property
    def tip_radius(self) -> float:
        return 0.5 * self.overall_length - 0.5 * self.haptic_width

    def center_line(self, start_angle: float, samples: int = 40) -> tuple[np.ndarray, np.ndarray]:
        """Points (samples, 2) of a haptic's centre line and the band width there."""
        r_optic = 0.5 * self.optic_diameter
        r0 = r_optic - 0.5 * self.root_width  # starts inside the optic: the union is one piece
        s = np.linspace(0.0, 1.0, samples)
        radius = r0 + (self.tip_radius - r0) * np.sin(0.5 * np.pi * s) ** 0.7
        angle = start_angle + np.radians(self.haptic_sweep) * s
        width = self.haptic_width + (self.root_width - self.haptic_width) * np.exp(-(s / 0.12) ** 2)
        return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)]), width

    def junction_points(self) -> np.ndarray:
        """Where each haptic's band crosses the optic rim (the grading centres)."""
        points = []
        for start in (0.0, np.pi):
            line, _ = self.center_line(start, 400)
            r = np.linalg.norm(line, axis=1)
            i = int(np.argmax(r >= 0.5 * self.optic_diameter))
            points.append(line[i])
        return np.asarray(points)

    def element_size(self, xy: np.ndarray, haptic: bool) -> np.ndarray:
        """gmsh's target size at the points ``xy`` (n, 2) of the optic or of a haptic
        (``_grade``'s size field)."""
        distance = np.linalg.norm(xy[:, None, :] - self.junction_points()[None], axis=2).min(axis=1)
        ramp = np.clip((distance - JUNCTION_NEAR) / (JUNCTION_FAR - JUNCTION_NEAR), 0.0, 1.0)
        size = self.junction_size + ramp * (self.mesh_size - self.junction_size)
        return np.minimum(size, self.haptic_size) if haptic else size

    @property
    def estimated_triangles(self) -> int:
        """Triangles before meshing: ∫ dA / (√3/4 h²) over the optic and the haptic bands (h
        the size field, equilateral triangles) plus half a triangle per boundary edge, ∮ ds / (2h),
        for the smaller, skewed cells gmsh lays along the rim and the narrow bands. Within 1 % of
        the built default lens and 15 % of the coarse one (tests/test_mesh_resolution.py)."""
        r_optic = 0.5 * self.optic_diameter
        n_r, n_t = 80, 240  # midpoint rule on the disc
        r = (np.arange(n_r) + 0.5) * r_optic / n_r
        angle = (np.arange(n_t) + 0.5) * 2.0 * np.pi / n_t
        rr, tt = (a.ravel() for a in np.meshgrid(r, angle))
        disc = np.column_stack([rr * np.cos(tt), rr * np.sin(tt)])
        area = float(np.sum(rr * (r_optic / n_r) * (2.0 * np.pi / n_t) / self.element_size(disc, False) ** 2))
        rim = disc[rr == r[-1]] * (r_optic / r[-1])
        boundary = float(np.sum(2.0 * np.pi * r_optic / n_t / self.element_size(rim, False)))
        for start in (0.0, np.pi):
            line, width = self.center_line(start, 800)
            middle, band = 0.5 * (line[1:] + line[:-1]), 0.5 * (width[1:] + width[:-1])
            ds = np.linalg.norm(np.diff(line, axis=0), axis=1)
            outside = np.linalg.norm(middle, axis=1) >= r_optic  # the band's root lies in the optic
            size = self.element_size(middle[outside], True)
            area += float(np.sum(ds[outside] * band[outside] / size ** 2))
            boundary += 2.0 * float(np.sum(ds[outside] / size))  # both sides of the band
        return int(round(area / (0.25 * np.sqrt(3.0)) + 0.5 * boundary))


def _band(model, line: np.ndarray, width: np.ndarray) -> tuple[int, int]:
    """An OCC surface bounded by the two offsets of ``line``; returns (surface, tip curve)."""
    tangent = np.gradient(line, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1)[:, None]
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    left = line + 0.5 * width[:, None] * normal
    right = line - 0.5 * width[:, None] * normal
    occ = model.occ
    left_pts = [occ.addPoint(x, y, 0.0) for x, y in left]
    right_pts = [occ.addPoint(x, y, 0.0) for x, y in right]
    left_curve = occ.addBSpline(left_pts)
    right_curve = occ.addBSpline(right_pts)
    tip = occ.addLine(left_pts[-1], right_pts[-1])
    root = occ.addLine(right_pts[0], left_pts[0])
    loop = occ.addCurveLoop([left_curve, tip, -right_curve, root])
    return occ.addPlaneSurface([loop]), tip


def _build(model, geo: LensGeometry) -> None:
    occ = model.occ
    r_optic = 0.5 * geo.optic_diameter
    disc = occ.addDisk(0.0, 0.0, 0.0, r_optic, r_optic)
    bands = [_band(model, *geo.center_line(start)) for start in (0.0, np.pi)]
    occ.fuse([(2, disc)], [(2, s) for s, _ in bands])
    occ.synchronize()
    surfaces = [tag for _, tag in model.getEntities(2)]
    optic, haptic = [], []
    for tag in surfaces:
        x, y, _ = occ.getCenterOfMass(2, tag)
        (optic if np.hypot(x, y) < r_optic else haptic).append(tag)
    if not optic or not haptic:
        raise MeshError("lens geometry: the optic and haptics did not split into separate regions")
    # the end caps: boundary curves nearest to the haptic tips
    tips = []
    for start in (0.0, np.pi):
        line, _ = geo.center_line(start)
        end = line[-1]
        curves = model.getEntities(1)
        best = min(curves, key=lambda c: np.hypot(*(np.array(occ.getCenterOfMass(1, c[1])[:2]) - end)))
        tips.append(best[1])
    model.addPhysicalGroup(2, optic, 1, name="optic")
    model.addPhysicalGroup(2, haptic, 2, name="haptic")
    model.addPhysicalGroup(1, [tips[0]], 1, name="tip_1")
    model.addPhysicalGroup(1, [tips[1]], 2, name="tip_2")
    _grade(model, geo, optic)
    model.mesh.generate(2)


def _grade(model, geo: LensGeometry, optic: list[int]) -> None:
    """Size field: junction_size at the junctions growing to haptic_size / mesh_size."""
    field = model.mesh.field
    junctions = [model.occ.addPoint(x, y, 0.0) for x, y in geo.junction_points()]
    model.occ.synchronize()
    distance = field.add("Distance")
    field.setNumbers(distance, "PointsList", junctions)
    near = field.add("Threshold")
    field.setNumber(near, "InField", distance)
    field.setNumber(near, "SizeMin", geo.junction_size)
    field.setNumber(near, "SizeMax", geo.mesh_size)
    field.setNumber(near, "DistMin", JUNCTION_NEAR)
    field.setNumber(near, "DistMax", JUNCTION_FAR)
    # the haptic bands: a constant size on the haptic surfaces
    haptic_surfaces = [t for _, t in model.getEntities(2) if t not in optic]
    band = field.add("Restrict")
    constant = field.add("MathEval")
    field.setString(constant, "F", repr(geo.haptic_size))
    field.setNumber(band, "InField", constant)
    field.setNumbers(band, "SurfacesList", haptic_surfaces)
    smallest = field.add("Min")
    field.setNumbers(smallest, "FieldsList", [near, band])
    field.setAsBackgroundMesh(smallest)
    for key in ("MeshSizeExtendFromBoundary", "MeshSizeFromPoints", "MeshSizeFromCurvature"):
        gmsh.option.setNumber(f"Mesh.{key}", 0)
    gmsh.option.setNumber("Mesh.Algorithm", 6)


def intraocular_lens(geo: LensGeometry = LensGeometry(), comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    """The lens mid-surface in the plane z = 0, ghosted across shared edges (the shell's
    interior-penalty terms integrate over interior edges)."""
    geo.validate()
    error = None
    with gmsh_session(comm) as model:
        if model is not None:
            try:
                _build(model, geo)
            except Exception as err:  # reported on every rank, not a deadlock
                error = err
        error = comm.bcast(error, root=0)
        if error is not None:
            raise error
        partitioner = dolfinx.mesh.create_cell_partitioner(dolfinx.mesh.GhostMode.shared_facet, 2)
        data = gmshio.model_to_mesh(model, comm, 0, gdim=3, partitioner=partitioner)
    data.mesh.topology.create_connectivity(1, 2)
    return TaggedMesh(data.mesh, data.cell_tags, data.facet_tags,
                      {name: (g.dim, g.tag) for name, g in data.physical_groups.items()})
