"""A liquid-filled cavity: its enclosed volume and the follower pressure on its wall.

Both are written on the reference wall with Nanson's formula n da = J F^-T N dA.
The enclosed volume is V = 1/3 ∮ x·n da (divergence theorem with div x = 3); a
symmetry plane through the origin has x·n = 0, so an open wall closed only by such
planes still gives the exact volume of the modelled part.
"""

from __future__ import annotations

import ufl

from eyemech.forms.kinematics import deformation_gradient


def _nanson(u):
    """J F^-T = cof F, the map from reference area vectors N dA to deformed n da."""
    F = deformation_gradient(u)
    return ufl.det(F) * ufl.inv(F).T


def volume_density(u, outward_sign: float = -1.0, axis: int | None = None):
    """Integrand (per reference wall area) of the enclosed volume: 1/3 x·n da, or with
    ``axis`` = k the field x_k e_k (also of divergence 1): x_k n_k da."""
    x = ufl.SpatialCoordinate(u.ufl_function_space().mesh) + u
    N = ufl.FacetNormal(u.ufl_function_space().mesh)
    area_vector = _nanson(u) * N
    if axis is None:
        return outward_sign / 3.0 * ufl.dot(x, area_vector)
    return outward_sign * x[axis] * area_vector[axis]


def enclosed_volume(u, wall_measure, outward_sign: float = -1.0):
    """Volume enclosed by the deformed wall, as a UFL functional.

    ``wall_measure`` integrates over the wall facets of the solid; the solid's
    facet normal N points away from the solid, i.e. into the cavity, so the cavity's
    outward normal is −N and ``outward_sign`` defaults to −1.
    """
    return volume_density(u, outward_sign) * wall_measure


def axis_volumes(u, wall_measure, outward_sign: float = -1.0):
    """The enclosed volume computed with each of the fields x_k e_k (k = 0, 1, 2).

    Every field with divergence 1 gives the same volume for a closed wall, and
    x_k e_k·n also vanishes on any coordinate plane through the origin, so for a
    wall closed by such symmetry planes the three values agree. For an open wall
    each misses a different flux through the hole: they differ (the same
    origin-dependence as 1/3 ∮ (x − c)·n da, tested without moving the origin off
    the symmetry planes).
    """
    dim = len(u)
    return [volume_density(u, outward_sign, axis=k) * wall_measure for k in range(dim)]


def liquid_pressure(volume, initial_volume, initial_pressure, bulk_modulus):
    """The static liquid's law (seed 002, eq. 5): P = P_ini − K (V − V_ini) / V_ini.
    Works on floats and on UFL expressions alike."""
    return initial_pressure - bulk_modulus * (volume - initial_volume) / initial_volume


def liquid_law_residual(pressure, test, u, wall_measure, wall_area, initial_volume,
                        initial_pressure, bulk_modulus, outward_sign: float = -1.0):
    """Row of the cavity pressure P (a Real-space unknown with test function ``test``):

        r_P = (V − V_ini) + V_ini (P − P_ini) / K = 0,

    the liquid law scaled by V_ini / K so that the row is a volume, its coupling to
    the wall displacements ∂V/∂u is an area like the wall's pressure column, and the
    diagonal V_ini/K stays finite as K → ∞ (incompressible liquid). Constant terms
    are spread over the reference wall area ``wall_area`` to write r_P as one wall
    integral.
    """
    constant = (initial_volume * (pressure - initial_pressure) / bulk_modulus - initial_volume) / wall_area
    return (volume_density(u, outward_sign) + constant) * test * wall_measure


def held_liquid(volume, pressure, initial_volume, initial_pressure, bulk_modulus):
    """The liquid a cavity of volume V at pressure P holds, as its volume at P_ini:
    V_l = V + V_ini (P − P_ini) / K (the liquid law solved for the liquid's amount).
    Floats or UFL alike."""
    return volume + initial_volume * (pressure - initial_pressure) / bulk_modulus


def vented_law_pressure(volume, liquid_volume, initial_volume, initial_pressure, bulk_modulus):
    """The pressure the liquid law gives a cavity of volume V holding the liquid V_l (its
    volume at P_ini): P_ini − K (V − V_l) / V_ini. Floats or UFL alike."""
    return initial_pressure - bulk_modulus * (volume - liquid_volume) / initial_volume


def vented_liquid_law_residual(pressure, test, u, wall_measure, wall_area, initial_volume,
                               initial_pressure, bulk_modulus, liquid_volume, limit, venting,
                               outward_sign: float = -1.0):
    """Row of the cavity pressure P for a cavity vented at the pressure ``limit``: the
    liquid is held until the law's pressure reaches P_lim, then P stays at P_lim and the
    liquid the wall displaces leaves (the operating surgeon's paracentesis),

        P = min(P_lim, P_ini − K (V − V_l) / V_ini),

    written as its two branches, a = 1 while the cavity vents (chosen outside the form,
    before every assembly: :class:`eyemech.problems.solid.cavity.VentedCavity`, semismooth
    Newton on the min), scaled by V_ini / K as :func:`liquid_law_residual` is:

        r_P = (1 − a) [(V − V_l) + V_ini (P − P_ini) / K] + a V_ini (P − P_lim) / K.

    V_l is the liquid held (its volume at P_ini): V_ini less what has been vented, updated
    between load steps (:func:`held_liquid`), so vented liquid does not come back. With
    a = 0 and V_l = V_ini this is :func:`liquid_law_residual`. Constant terms are spread
    over the reference wall area ``wall_area``."""
    held = (initial_volume * (pressure - initial_pressure) / bulk_modulus - liquid_volume) / wall_area
    pinned = initial_volume * (pressure - limit) / bulk_modulus / wall_area
    law = volume_density(u, outward_sign) + held
    return ((1 - venting) * law + venting * pinned) * test * wall_measure


def follower_pressure(pressure, u, v, wall_measure):
    """Virtual work residual of a cavity pressure acting on the deformed wall.

    The liquid pushes on the solid with traction −P n (n the solid's outward normal,
    pointing into the cavity), so the residual term is +∫ P (J F^-T N)·v dA.
    ``pressure`` may be a Constant, an expression or an unknown (Real space).
    """
    N = ufl.FacetNormal(u.ufl_function_space().mesh)
    return pressure * ufl.dot(_nanson(u) * N, v) * wall_measure
