"""A thick spherical shell, one octant with three symmetry planes.

Tags: cell ``wall``; facets ``cavity_wall`` (inner surface), ``outer``,
``symmetry_x``/``symmetry_y``/``symmetry_z`` (the planes x = 0, y = 0, z = 0).
The octant is what an inflation problem needs: the solution is radial, and the
symmetry planes pass through the origin so the cavity volume formula stays exact.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from eyemech.meshes.tagged import TaggedMesh, from_gmsh

FACET_NAMES = ("cavity_wall", "outer", "symmetry_x", "symmetry_y", "symmetry_z")


def spherical_shell(inner_radius: float, outer_radius: float, mesh_size: float,
                    order: int = 2, hexahedra: bool = False,
                    comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    """Octant of a thick sphere: unstructured tetrahedra, or (``hexahedra=True``) a
    structured hexahedral cube-sphere mesh; geometric ``order`` 1 or 2."""
    if not 0 < inner_radius < outer_radius:
        raise ValueError("need 0 < inner_radius < outer_radius")
    if hexahedra:
        return _hexahedral_shell(inner_radius, outer_radius, mesh_size, order, comm)

    def build(model):
        occ = model.occ
        outer = occ.addSphere(0, 0, 0, outer_radius)
        inner = occ.addSphere(0, 0, 0, inner_radius)
        shell, _ = occ.cut([(3, outer)], [(3, inner)])
        box = occ.addBox(0, 0, 0, 2 * outer_radius, 2 * outer_radius, 2 * outer_radius)
        octant, _ = occ.intersect(shell, [(3, box)])
        occ.synchronize()
        volume = octant[0][1]
        model.addPhysicalGroup(3, [volume], tag=1, name="wall")
        groups = {name: [] for name in FACET_NAMES}
        for dim, tag in model.getBoundary(octant, oriented=False):
            x, y, z = occ.getCenterOfMass(dim, tag)
            # the far corner of a spherical patch's bounding box lies at its radius
            radius = max(abs(c) for c in occ.getBoundingBox(dim, tag))
            if abs(x) < 1e-8 * outer_radius:
                groups["symmetry_x"].append(tag)
            elif abs(y) < 1e-8 * outer_radius:
                groups["symmetry_y"].append(tag)
            elif abs(z) < 1e-8 * outer_radius:
                groups["symmetry_z"].append(tag)
            elif radius < 0.5 * (inner_radius + outer_radius):
                groups["cavity_wall"].append(tag)
            else:
                groups["outer"].append(tag)
        for tag, (name, surfaces) in enumerate(groups.items(), start=1):
            model.addPhysicalGroup(2, surfaces, tag=tag, name=name)
        _mesh(model, mesh_size, order)

    return from_gmsh(build, comm)


def _mesh(model, mesh_size: float, order: int) -> None:
    import gmsh

    gmsh.option.setNumber("Mesh.CharacteristicLengthMax", mesh_size)
    gmsh.option.setNumber("Mesh.CharacteristicLengthMin", 0.5 * mesh_size)
    model.mesh.generate(3)
    if order > 1:
        model.mesh.setOrder(order)


# -- structured hexahedra ---------------------------------------------------------
#
# The octant shell is the image of a *reference* region with flat faces: the points
# p of the first octant with 1 <= max(p) <= 2, i.e. the gap between the cubes of
# side 1 and 2, split into three frustum blocks {p_i = max(p)} (the three cube faces
# around the corner (1, 1, 1)). Gmsh meshes these blocks transfinitely (exact,
# conforming hexahedra, order 1 or 2 with straight edges), and every node is then
# moved by the equiangular cube-sphere map
#
#     m = max(p),  q = p / m ∈ [0, 1]³,  e = tan(π q / 4),
#     x = (A + (B − A)(m − 1)) e / |e|,
#
# which is smooth inside each block, continuous across them, sends the planes p_i = 0
# to the symmetry planes x_i = 0, m = 1 to the cavity wall and m = 2 to the outer
# surface. Second-order nodes are mapped too, so the Q2 geometry is curved and lies
# on the spheres; equal angles keep the cells nearly as regular as a cube-sphere can.

_CORNER = (1.0, 1.0, 1.0)


def _hexahedral_shell(inner_radius: float, outer_radius: float, mesh_size: float, order: int,
                      comm: MPI.Comm) -> TaggedMesh:
    mean_radius = 0.5 * (inner_radius + outer_radius)
    tangential = max(2, int(np.ceil(0.25 * np.pi * mean_radius / mesh_size)))
    radial = max(1, int(np.ceil((outer_radius - inner_radius) / mesh_size)))

    def build(model):
        import gmsh

        volumes, faces = _reference_blocks(model.geo, tangential, radial)
        model.geo.synchronize()
        model.addPhysicalGroup(3, volumes, tag=1, name="wall")
        for tag, name in enumerate(FACET_NAMES, start=1):
            model.addPhysicalGroup(2, faces[name], tag=tag, name=name)
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
        gmsh.option.setNumber("Mesh.Recombine3DAll", 1)
        model.mesh.generate(3)
        if order > 1:
            gmsh.option.setNumber("Mesh.SecondOrderIncomplete", 0)
            model.mesh.setOrder(order)
        tags, coords, _ = model.mesh.getNodes()
        mapped = _cube_sphere(coords.reshape(-1, 3), inner_radius, outer_radius)
        for tag, x in zip(tags, mapped):
            model.mesh.setNode(int(tag), x.tolist(), [])

    return from_gmsh(build, comm)


def _cube_sphere(p: np.ndarray, inner_radius: float, outer_radius: float) -> np.ndarray:
    m = p.max(axis=1, keepdims=True)
    e = np.tan(0.25 * np.pi * p / m)
    radius = inner_radius + (outer_radius - inner_radius) * (m - 1.0)
    return radius * e / np.linalg.norm(e, axis=1, keepdims=True)


def _reference_blocks(geo, tangential: int, radial: int):
    """The three frustum blocks in gmsh's geo kernel, transfinite and recombined.
    Returns the volume tags and the facet tags by name."""
    points: dict[tuple, int] = {}
    lines: dict[tuple, int] = {}
    surfaces: dict[frozenset, int] = {}

    def point(c):
        key = tuple(float(v) for v in c)
        if key not in points:
            points[key] = geo.addPoint(*key)
        return points[key]

    def line(a, b):
        if (b, a) in lines:
            return -lines[(b, a)]
        if (a, b) not in lines:
            lines[(a, b)] = geo.addLine(a, b)
            radial_line = abs(_level(a, points) - _level(b, points)) > 0.5
            geo.mesh.setTransfiniteCurve(lines[(a, b)], (radial if radial_line else tangential) + 1)
        return lines[(a, b)]

    def quad(corners):
        key = frozenset(corners)
        if key not in surfaces:
            loop = geo.addCurveLoop([line(corners[i], corners[(i + 1) % 4]) for i in range(4)])
            surfaces[key] = geo.addPlaneSurface([loop])
            geo.mesh.setTransfiniteSurface(surfaces[key])
            geo.mesh.setRecombine(2, surfaces[key])
        return surfaces[key]

    faces = {name: [] for name in FACET_NAMES}
    volumes = []
    for axis in range(3):
        # the cube face p_axis = max(p): corners in the two other coordinates
        a, b = (axis + 1) % 3, (axis + 2) % 3
        square = [(0, 0), (1, 0), (1, 1), (0, 1)]
        layers = []
        for level in (1.0, 2.0):
            corners = []
            for s, t in square:
                c = [0.0, 0.0, 0.0]
                c[axis], c[a], c[b] = level, level * s, level * t
                corners.append(point(c))
            layers.append(corners)
        inner, outer = layers
        sides = [[inner[i], inner[(i + 1) % 4], outer[(i + 1) % 4], outer[i]] for i in range(4)]
        block = [quad(inner), quad(outer)] + [quad(side) for side in sides]
        faces["cavity_wall"].append(block[0])
        faces["outer"].append(block[1])
        # side 0 lies in p_b = 0, side 3 in p_a = 0; sides 1 and 2 are internal
        faces[f"symmetry_{'xyz'[b]}"].append(block[2])
        faces[f"symmetry_{'xyz'[a]}"].append(block[5])
        loop = geo.addSurfaceLoop(block)
        volume = geo.addVolume([loop])
        geo.mesh.setTransfiniteVolume(volume, inner + outer)
        geo.mesh.setRecombine(3, volume)
        volumes.append(volume)
    return volumes, faces


def _level(tag: int, points: dict[tuple, int]) -> float:
    coords = next(c for c, t in points.items() if t == tag)
    return max(coords)
