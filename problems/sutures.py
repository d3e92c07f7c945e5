"""Suture forces of scleral buckling (seed 002, §2.2).

Pulling the suture strings over the buckle is modelled as nodal forces at the suture
points on the sclera, directed along the tangent from the point to the buckle's
cross-section outline in the point's meridional plane, with directions taken from
the last converged step. Within a Newton solve the forces are dead loads, so they add
to the residual only (no Jacobian term).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from eyemech.problems.probes import NodeProbe


@dataclasses.dataclass(frozen=True)
class SuturePoint:
    azimuth_deg: float   # about the optic axis, 0 = the tear's meridian (+y)
    side: int            # −1 posterior, +1 anterior of the buckle
    weight: float        # 0.5 on the symmetry plane (half the suture is modelled)


class SutureForces:
    """Residual hook: −F w d at each suture node (owned, unconstrained components)."""

    def __init__(self, probe: NodeProbe, points: list[SuturePoint], constrained: np.ndarray):
        """``constrained``: local (unrolled) displacement dofs with Dirichlet conditions;
        their residual rows belong to the boundary condition."""
        self.probe, self.points = probe, points
        self.directions = np.zeros((len(points), 3))
        self.magnitude = 0.0
        self._constrained = set(int(d) for d in constrained)

    def update_directions(self, u, anchors: np.ndarray) -> None:
        """Point each force from its suture node (deformed) to its anchor on the buckle
        outline (``anchors``: one 3D point per suture point)."""
        tangent = anchors - self.probe.positions(u)
        self.directions = tangent / np.linalg.norm(tangent, axis=1, keepdims=True)

    def forces(self) -> np.ndarray:
        weights = np.array([p.weight for p in self.points])[:, None]
        return self.magnitude * weights * self.directions

    def residual_hook(self, _x, vec) -> None:
        if self.magnitude == 0.0:
            return
        array = vec.array
        bs = self.probe.bs
        for force, mine, block in zip(self.forces(), self.probe.mine, self.probe.blocks):
            if not mine:
                continue
            for component in range(bs):
                dof = int(block) * bs + component
                if dof not in self._constrained:
                    array[dof] -= force[component]  # residual = internal − external
