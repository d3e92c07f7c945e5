"""gmsh geometries returned as DOLFINx meshes with named cell and facet tags."""

# The PyPI DOLFINx wheel must import dolfinx_solver (it orders MPI ahead of the compiled
# bindings) before dolfinx or petsc4py; a conda-forge or Docker DOLFINx has no such module.
# Every module of this package is imported after this file, so none repeats it.
try:
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass


from eyemech.meshes.cook import cook_membrane
from eyemech.meshes.cornea import CorneaGeometry, cornea
from eyemech.meshes.eye import EyeGeometry, half_eye
from eyemech.meshes.sphere import spherical_shell
from eyemech.meshes.tagged import MeshError, TaggedMesh, from_gmsh

__all__ = ["CorneaGeometry", "EyeGeometry", "MeshError", "TaggedMesh", "cook_membrane", "cornea",
           "from_gmsh", "half_eye", "spherical_shell"]
