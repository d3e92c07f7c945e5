"""The hyperelastic solid residual for any element family of :mod:`spaces`:
mixed u–p (incompressible, pressure multiplier) or displacement only (bulk penalty).
A mesh may carry several materials by cell tag."""

from __future__ import annotations

from typing import Mapping

import ufl

from eyemech.forms import (
    Material,
    deformation_gradient,
    incompressible_energy_density,
    mean_dilatation_work_density,
    nearly_incompressible_energy_density,
)
from eyemech.problems.solid.spaces import ElementFamily


def solid_residual(material: Material | Mapping[int, Material], family: ElementFamily, fields,
                   tests, dx, bulk_modulus=None, condensed_pressure=None):
    """Residual (sum over blocks) of the stored energy; ``fields``/``tests`` start with
    u (and p for mixed families) as returned by :func:`spaces.solid_fields`.

    ``condensed_pressure``: Q1P0 with its DG0 pressure condensed, the field p̄ of
    :class:`~eyemech.problems.solid.mean_dilatation.MeanDilatation` (held fixed in the
    residual's variation; ``fields`` then start with u alone).

    ``material`` is one law for the whole mesh, or ``{cell_tag: law}`` integrated over
    ``dx(cell_tag)`` (``dx`` must then carry the cell tags as subdomain data)."""
    u, v = fields[0], tests[0]
    parts = material.items() if isinstance(material, Mapping) else [(None, material)]
    if family.pressure_family is None and (bulk_modulus is None or not _value(bulk_modulus) > 0):
        raise ValueError(f"{family.name} is displacement-only and needs a bulk modulus > 0")
    F = deformation_gradient(u)
    energy = 0
    for tag, law in parts:
        measure = dx if tag is None else dx(tag)
        if condensed_pressure is not None:
            energy += mean_dilatation_work_density(law, F, condensed_pressure) * measure
        elif family.pressure_family is None:
            energy += nearly_incompressible_energy_density(law, F, bulk_modulus) * measure
        else:
            energy += incompressible_energy_density(law, F, fields[1]) * measure
    residual = ufl.derivative(energy, u, v)
    if family.pressure_family is not None and condensed_pressure is None:
        residual += ufl.derivative(energy, fields[1], tests[1])
    return residual


def _value(number) -> float:
    """A float, or the value of a ``dolfinx.fem.Constant`` (material numbers enter the forms
    as Constants so that changing them recompiles nothing)."""
    return float(getattr(number, "value", number))
