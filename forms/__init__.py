"""UFL only: energies, residuals, constitutive laws, contact and cavity terms.

A form takes functions and parameters and returns UFL; nothing here builds a mesh,
assembles, solves or writes a file.
"""

# first, before any form is built: Constants in a canonical operand order
from eyemech.forms import ordering  # noqa: F401, I001
from eyemech.forms.cavity import (
    axis_volumes,
    enclosed_volume,
    follower_pressure,
    liquid_law_residual,
    liquid_pressure,
    volume_density,
)
from eyemech.forms.hyperelastic import (
    Material,
    MooneyRivlin,
    NeoHooke,
    PolynomialIsochoric,
    Yeoh,
    cauchy_stress,
    incompressible_energy_density,
    mean_dilatation_energy_density,
    mean_dilatation_pressure,
    mean_dilatation_work_density,
    nearly_incompressible_energy_density,
    volumetric_energy,
    von_mises,
)
from eyemech.forms.kinematics import (
    deformation_gradient,
    isochoric_invariants,
    without_variables,
)
from eyemech.forms.viscoelastic import Viscoelastic

__all__ = [
    "axis_volumes",
    "liquid_law_residual",
    "liquid_pressure",
    "volume_density",
    "Material",
    "MooneyRivlin",
    "NeoHooke",
    "PolynomialIsochoric",
    "Viscoelastic",
    "Yeoh",
    "cauchy_stress",
    "deformation_gradient",
    "without_variables",
    "enclosed_volume",
    "follower_pressure",
    "incompressible_energy_density",
    "mean_dilatation_energy_density",
    "mean_dilatation_pressure",
    "mean_dilatation_work_density",
    "isochoric_invariants",
    "nearly_incompressible_energy_density",
    "volumetric_energy",
    "von_mises",
]

from eyemech.forms import contact  # noqa: E402  (obstacles: contact.Plane, contact.Ring, ...)
from eyemech.forms.elastic import CompressibleNeoHooke, compressible_neo_hooke, lame  # noqa: E402

__all__ += ["contact", "CompressibleNeoHooke", "compressible_neo_hooke", "lame"]
