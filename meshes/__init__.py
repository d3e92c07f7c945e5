"""gmsh geometries returned as DOLFINx meshes with named cell and facet tags."""

from eyemech.meshes.tagged import MeshError, TaggedMesh, from_gmsh
from eyemech.meshes.sphere import spherical_shell
from eyemech.meshes.cornea import CorneaGeometry, cornea

__all__ = ["CorneaGeometry", "cornea", "MeshError", "TaggedMesh", "from_gmsh", "spherical_shell"]
