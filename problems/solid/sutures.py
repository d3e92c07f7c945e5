"""Suture forces of scleral buckling (seed 002, §2.2): where they act, which way they
pull, and how hard (the UFL load is :func:`eyemech.forms.sutures.suture_residual`).

Each suture pulls its bite on the sclera towards the buckle, along the tangent from
the bite to the buckle's cross-section outline in the bite's meridional plane; the
direction is recomputed from the last converged positions after every step.

Each bite's weight is normalised on the mesh (:meth:`SutureForces.normalise`): the
half model delivers exactly its share of every suture's pull (½ on the symmetry plane
x = 0), whatever the mesh size.
"""

from __future__ import annotations

import dataclasses

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms.sutures import bite_weight, half_space_share, suture_residual
from eyemech.problems.solid.probes import NodeProbe
from eyemech.problems.solve.scalars import assemble_scalar


@dataclasses.dataclass(frozen=True)
class SuturePoint:
    azimuth_deg: float   # about the optic axis, 0 = the tear's meridian (+y)
    side: int            # −1 posterior, +1 anterior of the buckle (radial tire: +1 the +x side)
    centre: tuple[float, float, float]


class BitesMissed(RuntimeError):
    """Bites whose weight integrates to nothing on the mesh: off the loaded surface, or
    narrower than its cells (no quadrature point inside the bite)."""

    def __init__(self, centres: list):
        self.centres = centres
        super().__init__(f"suture bites off the loaded surface or between its quadrature points: "
                         f"{centres}")


class SutureForces:
    """Force Constants of the sutures, their directions, and their residual term."""

    def __init__(self, mesh: dolfinx.mesh.Mesh, V: dolfinx.fem.FunctionSpace,
                 points: list[SuturePoint], candidates: np.ndarray, bite_radius: float):
        self.mesh = mesh
        self.points = points
        self.probe = NodeProbe(V, np.array([p.centre for p in points]), candidates)
        self.forces = [dolfinx.fem.Constant(mesh, np.zeros(3)) for _ in points]
        # Constants, not literals: the bites' places follow the buckle's position and the
        # suture width, and literals would compile the eye's residual anew for each of them
        self.centres = [dolfinx.fem.Constant(mesh, np.array(p.centre, dtype=float)) for p in points]
        self.bite_radius = dolfinx.fem.Constant(mesh, float(bite_radius))
        # the share of each suture's pull the half model carries (x ≥ 0: ½ on x = 0)
        self.shares = np.array([half_space_share(p.centre[0], float(bite_radius)) for p in points])
        # share / ∫ w_s dA on the mesh, set by normalise (Constants: set per mesh, no recompile)
        self.scales = [dolfinx.fem.Constant(mesh, 1.0) for _ in points]
        self.mesh_integrals = np.full(len(points), np.nan)
        self.directions = np.zeros((len(points), 3))
        self.magnitude = 0.0

    def normalise(self, measure, comm: MPI.Comm) -> None:
        """Scale each bite's weight so that its integral over ``measure`` (the surface
        the residual integrates over, reference configuration) is its exact share: the
        mesh then delivers the asked pull however coarsely it resolves the bite."""
        X = ufl.SpatialCoordinate(measure.ufl_domain())
        # one form for every bite: its centre is a Constant
        centre_constant = dolfinx.fem.Constant(self.mesh, np.zeros(3))
        form = dolfinx.fem.form(bite_weight(X, centre_constant, self.bite_radius) * measure)
        values = []
        for point in self.points:
            centre_constant.value[:] = point.centre
            values.append(assemble_scalar(form, comm))
        self.mesh_integrals = np.array(values)
        if np.any(self.mesh_integrals <= 0.0):
            missing = [p.centre for p, a in zip(self.points, values) if a <= 0.0]
            raise BitesMissed(missing)
        for scale, share, integral in zip(self.scales, self.shares, self.mesh_integrals):
            scale.value = share / integral

    def residual(self, v, measure):
        return suture_residual(self.forces, self.centres, self.bite_radius, v, measure,
                               self.scales)

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
