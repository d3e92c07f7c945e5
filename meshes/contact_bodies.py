"""Bodies for the contact benchmarks.

``quarter_half_space``: a half-space truncated to the lower half (z ≤ 0) of a ball of
radius L centred at the origin, one quarter (x ≥ 0, y ≥ 0). Tags: cell ``body``; facets
``contact`` (the flat face z = 0), ``far`` (the spherical surface), ``symmetry_x``,
``symmetry_y``. Elements are graded from ``contact_size`` within ``zone`` of the origin
— where an indenter touches the flat face — to ``far_size``, linearly over the distance
``ramp`` beyond the zone. ``quarter_half_space_cells`` estimates its number of cells
before meshing.

``layered_caps``: two concentric spherical caps about the z axis (one quarter), a
soft inner layer a small ``gap`` inside a stiffer outer one — the detached retina
under the choroid. Tags: cells ``soft``, ``stiff``; facets ``slave`` (outer face of
the soft layer), ``master`` (inner face of the stiff layer), ``pressure`` (inner
face of the soft layer), ``fixed`` (outer face of the stiff layer), ``soft_rim``
and ``stiff_rim`` (the conical cuts), ``symmetry_x``, ``symmetry_y``.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from eyemech.meshes.tagged import TaggedMesh, from_gmsh


def quarter_half_space(radius: float, contact_size: float, far_size: float, zone: float,
                       ramp: float, order: int = 2, comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    if not 0 < contact_size <= far_size:
        raise ValueError("need 0 < contact_size <= far_size")

    def build(model):
        occ = model.occ
        ball = occ.addSphere(0, 0, 0, radius)
        box = occ.addBox(0, 0, -2 * radius, 2 * radius, 2 * radius, 2 * radius)
        quarter, _ = occ.intersect([(3, ball)], [(3, box)])
        occ.synchronize()
        model.addPhysicalGroup(3, [quarter[0][1]], tag=1, name="body")
        groups = {"contact": [], "far": [], "symmetry_x": [], "symmetry_y": []}
        tol = 1e-8 * radius
        for dim, tag in model.getBoundary(quarter, oriented=False):
            x, y, z = occ.getCenterOfMass(dim, tag)
            if abs(x) < tol:
                groups["symmetry_x"].append(tag)
            elif abs(y) < tol:
                groups["symmetry_y"].append(tag)
            elif abs(z) < tol:
                groups["contact"].append(tag)
            else:
                groups["far"].append(tag)
        for tag, (name, surfaces) in enumerate(groups.items(), start=1):
            model.addPhysicalGroup(2, surfaces, tag=tag, name=name)
        centre = occ.addPoint(0, 0, 0)
        occ.synchronize()
        _graded_field(model, [centre], contact_size, far_size, zone, ramp)
        model.mesh.generate(3)
        if order > 1:
            model.mesh.setOrder(order)

    return from_gmsh(build, comm)


# tetrahedra per h³ of volume in gmsh's Delaunay meshes of a graded body (a regular
# tetrahedron of edge h fills h³/(6√2), gmsh's are smaller on average); calibrated on
# graded quarter balls of 300 to 2.5e4 cells, within −40 % … +25 %
CELLS_PER_UNIT_DENSITY = 6.0


def graded_size(distance: np.ndarray, fine: float, coarse: float, zone: float,
                ramp: float | None = None) -> np.ndarray:
    """The element size the graded field asks for at ``distance`` from the refined point:
    ``fine`` within ``zone``, rising linearly to ``coarse`` over ``ramp`` (2·``coarse``)."""
    length = 2 * coarse if ramp is None else ramp
    share = np.clip((distance - zone) / length, 0.0, 1.0)
    return fine + (coarse - fine) * share


def quarter_half_space_cells(radius: float, contact_size: float, far_size: float, zone: float,
                             ramp: float) -> float:
    """Expected number of tetrahedra of ``quarter_half_space``: CELLS_PER_UNIT_DENSITY ·
    ∫ h⁻³ dV with h the graded field's size; the body's volume at distance ρ from the centre
    per unit ρ is πρ²/2 (a quarter of a half ball). Costs microseconds, needs no gmsh."""
    # a geometric grid in ρ resolves the fine zone however small it is against the body
    rho = np.geomspace(1e-3 * min(contact_size, zone), radius, 4000)
    h = np.minimum(graded_size(rho, contact_size, far_size, zone, ramp), far_size)
    integrand = np.pi * rho**2 / 2 / h**3
    return float(CELLS_PER_UNIT_DENSITY * np.sum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(rho)))


def _graded_field(model, points: list[int], fine: float, coarse: float, zone: float,
                  ramp: float | None = None) -> None:
    import gmsh

    distance = model.mesh.field.add("Distance")
    model.mesh.field.setNumbers(distance, "PointsList", points)
    threshold = model.mesh.field.add("Threshold")
    model.mesh.field.setNumber(threshold, "InField", distance)
    model.mesh.field.setNumber(threshold, "SizeMin", fine)
    model.mesh.field.setNumber(threshold, "SizeMax", coarse)
    model.mesh.field.setNumber(threshold, "DistMin", zone)
    model.mesh.field.setNumber(threshold, "DistMax", zone + (2 * coarse if ramp is None else ramp))
    model.mesh.field.setAsBackgroundMesh(threshold)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    # the refined point only carries the field; it is not embedded in the mesh
    gmsh.option.setNumber("Mesh.CharacteristicLengthMax", coarse)


def layered_caps(inner_radius: float, soft_thickness: float, gap: float, stiff_thickness: float,
                 half_angle_deg: float, mesh_size: float, order: int = 2,
                 comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    """Soft layer r ∈ [R, R + t_s], stiff layer r ∈ [R + t_s + gap, R + t_s + gap + t_m],
    both cut to polar angle θ ≤ ``half_angle_deg`` about +z, quarter x, y ≥ 0."""
    if not (inner_radius > 0 and soft_thickness > 0 and gap > 0 and stiff_thickness > 0):
        raise ValueError("radii, thicknesses and gap must be positive")
    theta = np.radians(half_angle_deg)
    r_slave = inner_radius + soft_thickness
    r_master = r_slave + gap
    r_out = r_master + stiff_thickness

    def build(model):
        occ = model.occ
        far = 2 * r_out
        cone = occ.addCone(0, 0, 0, 0, 0, far, 0, far * np.tan(theta))
        box = occ.addBox(0, 0, 0, far, far, far)
        wedge, _ = occ.intersect([(3, cone)], [(3, box)])

        def layer(r0, r1):
            shell, _ = occ.cut([(3, occ.addSphere(0, 0, 0, r1))], [(3, occ.addSphere(0, 0, 0, r0))])
            part, _ = occ.intersect(shell, occ.copy(wedge))
            return part

        soft = layer(inner_radius, r_slave)
        stiff = layer(r_master, r_out)
        occ.remove(wedge, recursive=True)
        occ.synchronize()
        model.addPhysicalGroup(3, [t for _, t in soft], tag=1, name="soft")
        model.addPhysicalGroup(3, [t for _, t in stiff], tag=2, name="stiff")
        groups = {name: [] for name in ("slave", "master", "pressure", "fixed", "soft_rim",
                                        "stiff_rim", "symmetry_x", "symmetry_y")}
        tol = 1e-6 * r_out
        for body, (inner_name, outer_name, rim_name) in (
                (soft, ("pressure", "slave", "soft_rim")), (stiff, ("master", "fixed", "stiff_rim"))):
            for dim, tag in model.getBoundary(body, oriented=False):
                x, y, z = occ.getCenterOfMass(dim, tag)
                xmin, ymin, zmin, xmax, ymax, zmax = occ.getBoundingBox(dim, tag)
                if xmax - xmin < tol and abs(x) < tol:
                    groups["symmetry_x"].append(tag)
                elif ymax - ymin < tol and abs(y) < tol:
                    groups["symmetry_y"].append(tag)
                elif model.getType(dim, tag) != "Sphere":
                    groups[rim_name].append(tag)  # the conical cut
                elif zmax < 0.5 * (inner_radius + r_slave) + (r_master - inner_radius) * (body is stiff):
                    groups[inner_name].append(tag)  # a quarter cap about +z reaches z = r at its pole
                else:
                    groups[outer_name].append(tag)
        for tag, (name, surfaces) in enumerate(groups.items(), start=1):
            model.addPhysicalGroup(2, surfaces, tag=tag, name=name)
        import gmsh

        gmsh.option.setNumber("Mesh.CharacteristicLengthMax", mesh_size)
        gmsh.option.setNumber("Mesh.CharacteristicLengthMin", 0.3 * mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        model.mesh.generate(3)
        if order > 1:
            model.mesh.setOrder(order)

    return from_gmsh(build, comm)


def stacked_blocks(width: float, lower_height: float, upper_height: float, lower_size: float,
                   upper_size: float, comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    """Two boxes [0, w]² × [0, h1] and [0, w]² × [h1, h1 + h2] touching at z = h1, meshed
    separately (tetrahedra, P1 geometry) with different sizes, so their faces do not
    match. Tags: cells ``lower``, ``upper``; facets ``master`` (top of the lower
    block), ``slave`` (bottom of the upper block), ``bottom``, ``top``, ``symmetry_x``
    (x = 0), ``symmetry_y`` (y = 0), ``sides`` (x = w, y = w)."""

    def build(model):
        import gmsh

        occ = model.occ
        lower = occ.addBox(0, 0, 0, width, width, lower_height)
        upper = occ.addBox(0, 0, lower_height, width, width, upper_height)
        occ.synchronize()
        model.addPhysicalGroup(3, [lower], tag=1, name="lower")
        model.addPhysicalGroup(3, [upper], tag=2, name="upper")
        groups = {name: [] for name in ("master", "slave", "bottom", "top", "symmetry_x",
                                        "symmetry_y", "sides")}
        tol = 1e-5 * width  # OCC pads bounding boxes by about 1e-7
        for body, (low_name, high_name) in ((lower, ("bottom", "master")), (upper, ("slave", "top"))):
            for dim, tag in model.getBoundary([(3, body)], oriented=False):
                x, y, z = occ.getCenterOfMass(dim, tag)
                xmin, ymin, zmin, xmax, ymax, zmax = occ.getBoundingBox(dim, tag)
                if zmax - zmin < tol:
                    groups[low_name if z < (lower_height if body == upper else lower_height / 2) + tol
                           else high_name].append(tag)
                elif abs(x) < tol and xmax - xmin < tol:
                    groups["symmetry_x"].append(tag)
                elif abs(y) < tol and ymax - ymin < tol:
                    groups["symmetry_y"].append(tag)
                else:
                    groups["sides"].append(tag)
        for tag, (name, surfaces) in enumerate(groups.items(), start=1):
            model.addPhysicalGroup(2, surfaces, tag=tag, name=name)
        for body, size in ((lower, lower_size), (upper, upper_size)):
            points = model.getBoundary([(3, body)], recursive=True)
            model.mesh.setSize(points, size)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 1)
        model.mesh.generate(3)

    return from_gmsh(build, comm)
