"""A thick spherical shell, one octant with three symmetry planes.

Tags: cell ``wall``; facets ``cavity_wall`` (inner surface), ``outer``,
``symmetry_x``/``symmetry_y``/``symmetry_z`` (the planes x = 0, y = 0, z = 0).
The octant is what an inflation problem needs: the solution is radial, and the
symmetry planes pass through the origin so the cavity volume formula stays exact.
"""

from __future__ import annotations

from mpi4py import MPI

from eyemech.meshes.tagged import TaggedMesh, from_gmsh

FACET_NAMES = ("cavity_wall", "outer", "symmetry_x", "symmetry_y", "symmetry_z")


def spherical_shell(inner_radius: float, outer_radius: float, mesh_size: float,
                    order: int = 2, hexahedra: bool = False,
                    comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    """Octant of a thick sphere, tetrahedra (or hexahedra) of geometric ``order``."""
    if not 0 < inner_radius < outer_radius:
        raise ValueError("need 0 < inner_radius < outer_radius")

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
        _mesh(model, mesh_size, order, hexahedra)

    return from_gmsh(build, comm)


def _mesh(model, mesh_size: float, order: int, hexahedra: bool) -> None:
    import gmsh

    gmsh.option.setNumber("Mesh.CharacteristicLengthMax", mesh_size)
    gmsh.option.setNumber("Mesh.CharacteristicLengthMin", 0.5 * mesh_size)
    if hexahedra:
        # All-hex by subdividing a tet mesh is crude; structured shells live in
        # meshes/layered.py. This option exists for comparisons only.
        gmsh.option.setNumber("Mesh.SubdivisionAlgorithm", 2)
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
    model.mesh.generate(3)
    if order > 1:
        model.mesh.setOrder(order)
