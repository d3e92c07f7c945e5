"""The cornea's limbus, held rigidly or by the sclera's compliance: shared by
``keratotomy`` and ``tonometry``."""

from __future__ import annotations

from typing import Literal, get_args

import dolfinx
import numpy as np
import ufl

from eyemech.forms.elastic import spring_support_energy
from eyemech.problems.run.parameters import ParameterError

Support = Literal["clamped", "elastic"]
SUPPORTS = get_args(Support)


def validate_support(params) -> None:
    """ParameterError for a non-positive or infinite ``limbus_stiffness`` of an elastic limbus."""
    if params.support == "elastic":
        params.require_positive("limbus_stiffness")
        if not np.isfinite(params.limbus_stiffness):
            raise ParameterError("limbus_stiffness", "must be finite")


def limbus_support(params, u, v, tagged, ds):
    """The limbus held by ``params.support``: (residual term or None, Dirichlet conditions).
    ``clamped``: u = 0 on the limbus face. ``elastic``: distributed springs of stiffness
    ``limbus_stiffness`` per area in all directions (forms/elastic.py), the sclera's
    compliance in place of a rigid wall."""
    V = u.function_space
    if params.support == "elastic":
        stiffness = dolfinx.fem.Constant(tagged.mesh, params.limbus_stiffness)  # compiled once
        energy = spring_support_energy(u, stiffness, ds(tagged.tag("limbus")))
        return ufl.derivative(energy, u, v), []
    fdim = tagged.mesh.topology.dim - 1
    clamp = dolfinx.fem.dirichletbc(np.zeros(3), dolfinx.fem.locate_dofs_topological(
        V, fdim, tagged.facets("limbus")), V)
    return None, [clamp]
