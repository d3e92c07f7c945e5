"""UFL only: energies, residuals, constitutive laws, contact and cavity terms.

A form takes functions and parameters and returns UFL; nothing here builds a mesh,
assembles, solves or writes a file.
"""

from eyemech.forms.kinematics import deformation_gradient, isochoric_invariants
from eyemech.forms.hyperelastic import (
    Material,
    MooneyRivlin,
    NeoHooke,
    PolynomialIsochoric,
    incompressible_energy_density,
)
from eyemech.forms.cavity import enclosed_volume, follower_pressure
from eyemech.forms.viscoelastic import Viscoelastic

__all__ = [
    "Material",
    "MooneyRivlin",
    "NeoHooke",
    "PolynomialIsochoric",
    "Viscoelastic",
    "deformation_gradient",
    "enclosed_volume",
    "follower_pressure",
    "incompressible_energy_density",
    "isochoric_invariants",
]
