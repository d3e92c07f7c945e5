"""gmsh geometries returned as DOLFINx meshes with named cell and facet tags."""

from eyemech.meshes.tagged import MeshError, TaggedMesh, from_gmsh
from eyemech.meshes.sphere import spherical_shell

__all__ = ["MeshError", "TaggedMesh", "from_gmsh", "spherical_shell"]
