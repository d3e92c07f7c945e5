"""gmsh geometries returned as DOLFINx meshes with named cell and facet tags."""

from eyemech.meshes.tagged import MeshError, TaggedMesh, from_gmsh
from eyemech.meshes.sphere import spherical_shell
from eyemech.meshes.cook import cook_membrane
from eyemech.meshes.cornea import CorneaGeometry, cornea
from eyemech.meshes.eye import EyeGeometry, half_eye

__all__ = ["CorneaGeometry", "EyeGeometry", "MeshError", "TaggedMesh", "cook_membrane", "cornea",
           "from_gmsh", "half_eye", "spherical_shell"]
