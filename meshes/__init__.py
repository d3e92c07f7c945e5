"""gmsh geometries returned as DOLFINx meshes with named cell and facet tags."""

from eyemech.meshes.tagged import MeshError, TaggedMesh, from_gmsh
from eyemech.meshes.sphere import spherical_shell
from eyemech.meshes.cook import cook_membrane

__all__ = ["cook_membrane", "MeshError", "TaggedMesh", "from_gmsh", "spherical_shell"]
