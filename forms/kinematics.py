"""Finite-strain kinematics shared by every solid model (total Lagrangian)."""

from __future__ import annotations

import ufl


def deformation_gradient(u: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """F = I + Grad u."""
    dim = ufl.shape(u)[0]
    return ufl.variable(ufl.Identity(dim) + ufl.grad(u))


def without_variables(expression: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """``expression`` with its derivatives evaluated and its ``ufl.variable`` wrappers
    removed. A variable's label is numbered per process, and FFCx hashes an interpolated
    expression's labels as they are (forms renumber theirs): an expression built on
    :func:`deformation_gradient` would compile anew in every run and every sweep case.
    Interpolated expressions pass through this first (tests/test_eye_calibration.py)."""
    from ufl.algorithms import strip_variables
    from ufl.algorithms.apply_algebra_lowering import apply_algebra_lowering
    from ufl.algorithms.apply_derivatives import apply_derivatives

    return strip_variables(apply_derivatives(apply_algebra_lowering(expression)))


def isochoric_invariants(F: ufl.core.expr.Expr):
    """(Ī1, Ī2, J) of C = FᵀF with C̄ = J^(-2/3) C, the reduced invariants of the
    buckling paper's strain energy (seed 002, eq. 1)."""
    J = ufl.det(F)
    C = F.T * F
    I1 = ufl.tr(C)
    I2 = 0.5 * (I1**2 - ufl.tr(C * C))
    return J ** (-2.0 / 3.0) * I1, J ** (-4.0 / 3.0) * I2, J
