"""Cook's membrane as a thin slab: the tapered panel with corners (0, 0), (48, 44),
(48, 60), (0, 44) mm, one element through the thickness (plane strain is imposed by
the scene with w = 0).

A structured n × n transfinite mesh of the panel, extruded by one layer: hexahedra
(recombined) or tetrahedra (each prism split in three). Tags: cell ``panel``;
facets ``clamped`` (x = 0), ``loaded`` (x = 48), ``front``/``back`` (z = 0, z = t).
"""

from __future__ import annotations

from mpi4py import MPI

from eyemech.meshes.tagged import TaggedMesh, from_gmsh

CORNERS = ((0.0, 0.0), (48.0, 44.0), (48.0, 60.0), (0.0, 44.0))
TIP = (48.0, 60.0)


def cook_membrane(elements_per_side: int, hexahedra: bool = True, order: int = 1,
                  thickness: float = 1.0, comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    if elements_per_side < 1:
        raise ValueError("need at least one element per side")

    def build(model):
        import gmsh

        geo = model.geo
        points = [geo.addPoint(x, y, 0.0) for x, y in CORNERS]
        lines = [geo.addLine(points[i], points[(i + 1) % 4]) for i in range(4)]
        for line in lines:
            geo.mesh.setTransfiniteCurve(line, elements_per_side + 1)
        surface = geo.addPlaneSurface([geo.addCurveLoop(lines)])
        geo.mesh.setTransfiniteSurface(surface, cornerTags=points)
        if hexahedra:
            geo.mesh.setRecombine(2, surface)
        extruded = geo.extrude([(2, surface)], 0, 0, thickness, numElements=[1], recombine=hexahedra)
        geo.synchronize()
        # extrude returns [top, volume, side of line 0, side of line 1, ...]
        top, volume = extruded[0][1], extruded[1][1]
        sides = [tag for _, tag in extruded[2:6]]
        model.addPhysicalGroup(3, [volume], tag=1, name="panel")
        model.addPhysicalGroup(2, [sides[3]], tag=1, name="clamped")   # line 3: (0,44)-(0,0)
        model.addPhysicalGroup(2, [sides[1]], tag=2, name="loaded")    # line 1: (48,44)-(48,60)
        model.addPhysicalGroup(2, [surface], tag=3, name="front")
        model.addPhysicalGroup(2, [top], tag=4, name="back")
        model.mesh.generate(3)
        if order > 1:
            gmsh.option.setNumber("Mesh.SecondOrderIncomplete", 0)
            model.mesh.setOrder(order)

    return from_gmsh(build, comm)
