"""Suture forces of scleral buckling (seed 002, §2.2): where they act, which way they
pull, and how hard (the UFL load is :func:`eyemech.forms.sutures.suture_residual`).

Each suture pulls its bite on the sclera towards the buckle, along the tangent from
the bite to the buckle's cross-section outline in the bite's meridional plane; the
direction is recomputed from the last converged positions after every step.
"""

from __future__ import annotations

import dataclasses

import dolfinx
import numpy as np

from eyemech.forms.sutures import suture_residual
from eyemech.problems.solid.probes import NodeProbe


@dataclasses.dataclass(frozen=True)
class SuturePoint:
    azimuth_deg: float   # about the optic axis, 0 = the tear's meridian (+y)
    side: int            # −1 posterior, +1 anterior of the buckle (radial tire: +1 the +x side)
    centre: tuple[float, float, float]


class SutureForces:
    """Force Constants of the sutures, their directions, and their residual term."""

    def __init__(self, mesh: dolfinx.mesh.Mesh, V: dolfinx.fem.FunctionSpace,
                 points: list[SuturePoint], candidates: np.ndarray, bite_radius: float):
        self.points = points
        self.probe = NodeProbe(V, np.array([p.centre for p in points]), candidates)
        self.forces = [dolfinx.fem.Constant(mesh, np.zeros(3)) for _ in points]
        # Constants, not literals: the bites' places follow the buckle's position and the
        # suture width, and literals would compile the eye's residual anew for each of them
        self.centres = [dolfinx.fem.Constant(mesh, np.array(p.centre, dtype=float)) for p in points]
        self.bite_radius = dolfinx.fem.Constant(mesh, float(bite_radius))
        self.directions = np.zeros((len(points), 3))
        self.magnitude = 0.0

    def residual(self, v, measure):
        return suture_residual(self.forces, self.centres, self.bite_radius, v, measure)

    def set_magnitude(self, magnitude: float) -> None:
        self.magnitude = magnitude
        for constant, direction in zip(self.forces, self.directions):
            constant.value[:] = magnitude * direction

    def update_directions(self, u, anchors: np.ndarray) -> None:
        """Point each force from its bite (deformed) to its anchor on the buckle outline
        (``anchors``: one 3D point per suture point)."""
        tangent = anchors - self.probe.positions(u)
        self.directions = tangent / np.linalg.norm(tangent, axis=1, keepdims=True)
        self.set_magnitude(self.magnitude)
