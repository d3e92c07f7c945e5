"""A liquid-filled cavity: its enclosed volume and the follower pressure on its wall.

Both are written on the reference wall with Nanson's formula n da = J F^-T N dA.
The enclosed volume is V = 1/3 ∮ x·n da (divergence theorem with div x = 3); a
symmetry plane through the origin has x·n = 0, so an open wall closed only by such
planes still gives the exact volume of the modelled part.
"""

from __future__ import annotations

import ufl


def _nanson(u):
    """J F^-T = cof F, the map from reference area vectors N dA to deformed n da."""
    dim = len(u)
    F = ufl.Identity(dim) + ufl.grad(u)
    return ufl.det(F) * ufl.inv(F).T


def enclosed_volume(u, wall_measure, outward_sign: float = -1.0):
    """Volume enclosed by the deformed wall, as a UFL functional.

    ``wall_measure`` integrates over the wall facets of the solid; the solid's
    facet normal N points away from the solid, i.e. into the cavity, so the cavity's
    outward normal is −N and ``outward_sign`` defaults to −1.
    """
    x = ufl.SpatialCoordinate(u.ufl_function_space().mesh) + u
    N = ufl.FacetNormal(u.ufl_function_space().mesh)
    return outward_sign / 3.0 * ufl.dot(x, _nanson(u) * N) * wall_measure


def follower_pressure(pressure, u, v, wall_measure):
    """Virtual work residual of a cavity pressure acting on the deformed wall.

    The liquid pushes on the solid with traction −P n (n the solid's outward normal,
    pointing into the cavity), so the residual term is +∫ P (J F^-T N)·v dA.
    ``pressure`` may be a Constant, an expression or an unknown (Real space).
    """
    N = ufl.FacetNormal(u.ufl_function_space().mesh)
    return pressure * ufl.dot(_nanson(u) * N, v) * wall_measure
