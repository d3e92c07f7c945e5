"""Wilson–Taylor incompatible modes: a Q1 hexahedron that bends without locking.

A trilinear (Q1) hexahedron cannot bend: its displacement is linear along each edge, so a
curvature κ of a thin layer comes with a parasitic shear ≈ κ h / 2 and the layer's bending
stiffness is overestimated by ≈ 1 + ¼ (h / t)² (tests/test_wall_bending_locking.py). Wilson,
Taylor, Doherty & Ghaboussi (1973) add to each cell the three internal "bubble" modes
N_i = 1 − ξ_i² (ξ ∈ [−1, 1]³; 4 X_i (1 − X_i) on DOLFINx's reference cell X ∈ [0, 1]³),
each with a vector amplitude α_i local to the cell — 9 unknowns per cell, continuous across
no face ("incompatible"). Their gradients are the quadratic displacement a bent cell needs.

Taylor, Beresford & Wilson (1976) evaluate the modes' gradient with the Jacobian J₀ at the
cell's centre and weight it by det J₀ / det J, so that its cell integral vanishes for every α:

    G(α) = (det J₀ / det J) Σ_i α_i ⊗ (J₀⁻ᵀ ∂N_i/∂X),   ∫_K G dX = det J₀ (Σ_i α_i ⊗ J₀⁻ᵀ ∫ ∂N_i/∂X dX̂) = 0,

so a homogeneous deformation leaves α = 0 and is reproduced exactly on any mesh (the patch
test; the uncorrected modes fail it on distorted cells). At finite strain the modes enhance
the deformation gradient, F = I + Grad u + G(α) (Simo & Armero 1992; Simo & Rifai 1990's
enhanced assumed strain is the general frame).

Incompressible (the mixed Q1P0 element): the modes' dilatations are linear in ξ, which a
constant pressure per cell does not hold, so each cell's pressure gains a linear part
(:func:`pressure_slopes`), and the constant part holds the volume the cell's faces enclose
(:func:`enhanced_incompressible_energy_density`). The energy is stationary in u, p, π and α.
Hourglassing in finite compression, known for enhanced elements (Wriggers & Reese 1996): a
plane-strain block of 4 × 4 cells has its first unstable mode at 50 % compression (Q1P0 at
60 %; with the constant pressure on det F instead, at 40 %). Verified in
tests/test_incompatible_modes.py.
"""

from __future__ import annotations

import ufl


def incompatible_gradient(modes: ufl.core.expr.Expr, reference_coordinates: ufl.core.expr.Expr,
                          centre_jacobian: ufl.core.expr.Expr | None):
    """G(α) of the three bubble modes of a hexahedron, a (d, d) tensor. ``modes``: the
    cellwise-constant amplitudes, a (d, d) tensor whose column i is the vector α_i of mode i;
    ``reference_coordinates``: X ∈ [0, 1]³ in each cell, a cellwise-trilinear coefficient
    (FFCx does not tabulate UFL's ``CellCoordinate`` in integrals); ``centre_jacobian``:
    the cell's Jacobian at its centre, cellwise constant (Taylor's correction); None:
    Wilson's original modes with the Jacobian where they are evaluated, which fail the patch
    test on distorted cells."""
    mesh = ufl.domain.extract_unique_domain(modes)
    X = reference_coordinates
    dim = ufl.shape(X)[0]
    slopes = ufl.diag(ufl.as_vector([4 * (1 - 2 * X[i]) for i in range(dim)]))  # ∂N_i/∂X_i
    if centre_jacobian is None:
        return modes * slopes * ufl.JacobianInverse(mesh)
    J = ufl.Jacobian(mesh)
    return ufl.det(centre_jacobian) / ufl.det(J) * modes * slopes * ufl.inv(centre_jacobian)


def enhanced_deformation_gradient(u: ufl.core.expr.Expr, modes: ufl.core.expr.Expr,
                                  reference_coordinates: ufl.core.expr.Expr,
                                  centre_jacobian: ufl.core.expr.Expr | None):
    """F = I + Grad u + G(α), a ``ufl.variable`` (as :func:`~.kinematics.deformation_gradient`)."""
    dim = ufl.shape(u)[0]
    return ufl.variable(ufl.Identity(dim) + ufl.grad(u)
                        + incompatible_gradient(modes, reference_coordinates, centre_jacobian))


def pressure_slopes(slopes: ufl.core.expr.Expr, reference_coordinates: ufl.core.expr.Expr):
    """Σ_i π_i ξ_i (ξ = 2X − 1 ∈ [−1, 1]³): the linear part of a cell's pressure, added to its
    constant (DG0) pressure where the modes act. The modes' own dilatations are linear in
    ξ: against a constant pressure alone they leave the linear part of det F − 1 free, and
    a single layer of cells bends incompressibly at half its stiffness (E' = 2μ instead of
    4μ in plane strain); π_i holds it, and the modes' dilatations satisfy its inf-sup
    condition cell by cell. ``slopes``: a cellwise-constant vector (π_1, π_2, π_3)."""
    return ufl.dot(slopes, 2 * reference_coordinates - ufl.as_vector([1] * ufl.shape(slopes)[0]))


def enhanced_incompressible_energy_density(material, u, modes, slopes, reference_coordinates,
                                           centre_jacobian, pressure):
    """W(F) + p (det F₀ − 1) + (Σ π_i ξ_i)(det F − 1), F the enhanced and F₀ = I + Grad u the
    compatible deformation gradient; p the cell's constant pressure, π its slopes.

    The constant pressure holds the volume the cell's faces enclose (∫_K det F₀ dX, which
    the 2 × 2 × 2 Gauss rule integrates exactly for trilinear cells), not ∫_K det F dX: a
    liquid's pressure on the faces does work on that volume, and only when the solid
    conserves it too do the two cancel in a hydrostatic state, the solid's pressure
    balancing the liquid's in all its variations (a thin layer in a liquid is not buckled
    by the liquid's pressure). The modes change the cell's volume at second order only
    (∫_K G dX = 0), so the small-strain element is the same either way."""
    F = enhanced_deformation_gradient(u, modes, reference_coordinates, centre_jacobian)
    dim = ufl.shape(u)[0]
    compatible = ufl.Identity(dim) + ufl.grad(u)
    linear = pressure_slopes(slopes, reference_coordinates)
    return material.strain_energy(F) + linear * (ufl.det(F) - 1) + pressure * (ufl.det(compatible) - 1)
