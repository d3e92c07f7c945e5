"""Suture loads of scleral buckling (seed 002, §2.2), as UFL.

The paper pulls each suture point with a nodal force tangent to the buckle's
cross-section outline. A force on one node of a continuum is a point load, whose
displacement grows without bound as the mesh is refined (and inverts elements at the
default resolution), so the force is spread over the suture's bite instead: a
traction F w(X) with the weight w = (1 − |X − X_s|²/b²)₊ / (π b²/2) of unit integral
over a flat patch, b the bite radius. A point on the symmetry plane has half its bite
in the model and so receives half the force, which is half a suture: what a half
model should carry. Directions are set per step (from the last converged state), so
within a Newton solve the loads are dead.

w has unit integral on a sphere through its centre too (the cap within chord b has
area π b², and dA = π d(c²) in the chord c), but a mesh that does not resolve the bite
integrates it to something else (1.16-1.18 on the coarse eye), and a bite that
overhangs the surface's edge loses what overhangs. Each bite's weight is therefore
scaled by s = (its exact share)/(its integral on the mesh), assembled once per mesh,
so the pull the mesh delivers is the one asked for (tests/test_sutures.py).
"""

from __future__ import annotations

import math

import ufl


def bite_weight(X, centre, bite_radius):
    """w(X): a paraboloid bump of unit integral (on a flat surface) around ``centre``."""
    distance2 = ufl.dot(X - centre, X - centre)
    return ufl.max_value(1.0 - distance2 / bite_radius**2, 0.0) / (0.5 * math.pi * bite_radius**2)


def half_space_share(offset: float, bite_radius: float) -> float:
    """∫ w dA over the half plane x ≥ 0 for a bite centred at x = ``offset`` (flat
    patch): ½ on the symmetry plane, 1 at a bite radius or more inside it, 0 outside.
    With t = offset/b, ½ + (8/3π) ∫₀ᵗ (1 − x²)^{3/2} dx."""
    t = min(max(offset / bite_radius, -1.0), 1.0)
    root = math.sqrt(max(1.0 - t * t, 0.0))
    integral = t * (5.0 - 2.0 * t * t) * root / 8.0 + 3.0 * math.asin(t) / 8.0
    return 0.5 + 8.0 / (3.0 * math.pi) * integral


def suture_residual(forces, centres, bite_radius, v, measure, scales=None):
    """−Σ_s s_s ∫ F_s·v w_s dA: the external work of the suture forces (residual sign).

    ``forces`` and ``centres`` are sequences of 3-vectors (dolfinx Constants for the
    forces so a scene can turn and scale them between steps; Constants or tuples for the
    centres), ``bite_radius`` a number or a Constant, ``scales`` one number or Constant
    per bite (the normalisation of its weight on the mesh; 1 if omitted)."""
    X = ufl.SpatialCoordinate(measure.ufl_domain())
    if scales is None:
        scales = [1.0] * len(forces)
    work = sum(s * ufl.dot(F, v) * bite_weight(X, ufl.as_vector(c), bite_radius)
               for F, c, s in zip(forces, centres, scales))
    return -work * measure



def tied_leg_stretch(x, x_tied, anchor, anchor_tied, shortening):
    """ℓ − (ℓ_tied − s): how much a tied mattress suture's leg is stretched at a point x of
    its bite. The leg runs from x to where it leaves the buckle (``anchor``); ℓ =
    |anchor − x| now, ℓ_tied = |anchor_tied − x_tied| when the surgeon began to tie it,
    and the knot takes ``shortening`` s out of it. Signed and smooth: the points of a bite
    turn with the sclera, so a taut leg's stretch varies across its bite, and a pointwise
    ⟨·⟩₊ put a kink under Newton wherever it crossed zero (the default eye's settling
    stalled at a residual of 5e-5); that a suture cannot push is the leg's, as a whole
    (:class:`~eyemech.problems.scleral_buckling.suture_terms.MattressSutures`)."""
    length = ufl.sqrt(ufl.dot(anchor - x, anchor - x))
    length_tied = ufl.sqrt(ufl.dot(anchor_tied - x_tied, anchor_tied - x_tied))
    return length - length_tied + shortening


def tied_leg_energy(stretch, stiffness, weight):
    """½ k stretch² w: the energy density of a taut tied leg (:func:`tied_leg_stretch`), k
    its axial stiffness (N/mm), w its bite's weight (unit integral per leg), so that the
    leg's tension is T = k ∫ stretch w dA. Its derivative in the displacement pulls each
    point of the bite along the leg's own direction, (anchor − x)/ℓ, exact within a Newton
    solve; the anchor rides on the buckle's travel δ, so ∂/∂δ is the leg's push on the
    buckle: suture and buckle exchange equal and opposite forces."""
    return 0.5 * stiffness * stretch**2 * weight
