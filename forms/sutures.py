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
"""

from __future__ import annotations

import math

import ufl


def bite_weight(X, centre, bite_radius):
    """w(X): a paraboloid bump of unit integral (on a flat surface) around ``centre``."""
    distance2 = ufl.dot(X - centre, X - centre)
    return ufl.max_value(1.0 - distance2 / bite_radius**2, 0.0) / (0.5 * math.pi * bite_radius**2)


def suture_residual(forces, centres, bite_radius, v, measure):
    """−Σ_s ∫ F_s·v w_s dA: the external work of the suture forces (residual sign).

    ``forces`` and ``centres`` are sequences of 3-vectors (dolfinx Constants for the
    forces so a scene can turn and scale them between steps; Constants or tuples for the
    centres), ``bite_radius`` a number or a Constant."""
    X = ufl.SpatialCoordinate(measure.ufl_domain())
    work = sum(ufl.dot(F, v) * bite_weight(X, ufl.as_vector(c), bite_radius)
               for F, c in zip(forces, centres))
    return -work * measure
