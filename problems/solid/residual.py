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
from eyemech.problems.solid.incompatible_modes import IncompatibleModes
from eyemech.problems.solid.spaces import ElementFamily


def solid_residual(material: Material | Mapping[int, Material], family: ElementFamily, fields,
                   tests, dx, bulk_modulus=None, condensed_pressure=None,
                   modes: IncompatibleModes | None = None):
    """Residual (sum over blocks) of the stored energy; ``fields``/``tests`` start with
    u (and p for mixed families) as returned by :func:`spaces.solid_fields`.

    ``condensed_pressure``: Q1P0 with its DG0 pressure condensed, the field p̄ of
    :class:`~eyemech.problems.solid.mean_dilatation.MeanDilatation` (held fixed in the
    residual's variation; ``fields`` then start with u alone).

    ``material`` is one law for the whole mesh, or ``{cell_tag: law}`` integrated over
    ``dx(cell_tag)`` (``dx`` must then carry the cell tags as subdomain data).

    ``modes``: incompatible modes on some cells (mixed Q1P0, one law for the mesh): there the
    energy is :func:`~eyemech.forms.incompatible_modes.enhanced_incompressible_energy_density`,
    and the modes' amplitudes and pressure slopes (among ``fields``) get their blocks."""
    u, v = fields[0], tests[0]
    parts = material.items() if isinstance(material, Mapping) else [(None, material)]
    if family.pressure_family is None and (bulk_modulus is None or not _value(bulk_modulus) > 0):
        raise ValueError(f"{family.name} is displacement-only and needs a bulk modulus > 0")
    if modes is not None and (condensed_pressure is not None or len(parts) > 1
                              or family.name != "Q1P0"):
        raise ValueError("incompatible modes need Q1P0 (its pressure mixed) and one law")

    def density(law, F):
        if condensed_pressure is not None:
            return mean_dilatation_work_density(law, F, condensed_pressure)
        if family.pressure_family is None:
            return nearly_incompressible_energy_density(law, F, bulk_modulus)
        return incompressible_energy_density(law, F, fields[1])

    if modes is None:
        F = deformation_gradient(u)
        energy = sum(density(law, F) * (dx if tag is None else dx(tag)) for tag, law in parts)
    else:
        law = parts[0][1]
        enhanced, plain = modes.measures(dx)
        energy = modes.energy_density(law, u, fields[1]) * enhanced
        if plain is not None:
            energy += density(law, deformation_gradient(u)) * plain
    residual = ufl.derivative(energy, u, v)
    if family.pressure_family is not None and condensed_pressure is None:
        residual += ufl.derivative(energy, fields[1], tests[1])
    if modes is not None:
        for block in modes.blocks(fields):
            residual += ufl.derivative(energy, fields[block], tests[block])
    return residual


def _value(number) -> float:
    """A float, or the value of a ``dolfinx.fem.Constant`` (material numbers enter the forms
    as Constants so that changing them recompiles nothing)."""
    return float(getattr(number, "value", number))
