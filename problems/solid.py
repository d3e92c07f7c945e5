"""The hyperelastic solid residual for any element family of :mod:`spaces`:
mixed u–p (incompressible, pressure multiplier) or displacement only (bulk penalty)."""

from __future__ import annotations

import ufl

from eyemech.forms import Material, incompressible_energy_density, nearly_incompressible_energy_density
from eyemech.problems.spaces import ElementFamily


def solid_residual(material: Material, family: ElementFamily, fields, tests, dx,
                   bulk_modulus: float | None = None):
    """Residual (sum over blocks) of the stored energy; ``fields``/``tests`` start with
    u (and p for mixed families) as returned by :func:`spaces.solid_fields`."""
    u, v = fields[0], tests[0]
    if family.pressure_family is None:
        if bulk_modulus is None or not bulk_modulus > 0:
            raise ValueError(f"{family.name} is displacement-only and needs a bulk modulus > 0")
        energy = nearly_incompressible_energy_density(material, u, bulk_modulus) * dx
        return ufl.derivative(energy, u, v)
    p, q = fields[1], tests[1]
    energy = incompressible_energy_density(material, u, p) * dx
    return ufl.derivative(energy, u, v) + ufl.derivative(energy, p, q)
