r"""Node-to-rigid-surface penalty contact for the lens, evaluated in numpy, and the lens'
self distance measured with ipctk (:mod:`.self_distance`).

Why numpy and not UFL (forms/contact.py): the lens' rigid bodies move every time step
(plunger, closing cartridge) and are cut into regions (the cartridge acts only inside
the injector, the capsule only outside it); a nodal penalty on the P2 nodes is a few
vectorised lines per obstacle, costs microseconds, and keeps the (minutes to compile)
shell form free of contact terms, so one compiled kernel serves every scene.

Each obstacle gives, at deformed node positions x (n, 3), a signed gap g (> 0 free,
< 0 penetrating; a distance in mm, first-order accurate near the surface) and its unit
normal n = ∇g, and a mask of where it acts. The penalty energy and its derivatives are

    Π_c = Σ_nodes ½ k ⟨−g⟩²,   f = ∂Π_c/∂u = −k ⟨−g⟩ n,   ∂²Π_c/∂u² ≈ k n⊗n (g < 0)

with ⟨·⟩ smoothed over ±ε (``smoothing``, 2 µm by default) so that the force is C¹

(the curvature term k g ∂n/∂x is left out of the Jacobian: a quasi-Newton tangent).
k is a nodal stiffness (N/mm); the penetration under a nodal force f is f/k.

**Wall friction** (``friction``: μ for every obstacle, or per obstacle name): the
lagged, smoothed Coulomb dissipation of IPC (Li et al. 2020) that the lens' self-contact
uses too. At the start of each time step (:meth:`NodalContact.begin_step`) every pressed
node keeps its normal force λ = k⟨d⟩, normal n and anchor a — the wall's material point
under it at the step's end: its position xₙ for a wall at rest, turned with the wall for a
twisted injector. Within the step its slip is s = P (x − a), P = I − n⊗n, and it adds the
potential

    D = μ λ f₀(|s|),  f₀(r) = −r³/(3ε²) + r²/ε + ε/3 (r < ε),  r (r ≥ ε),

whose force −∂D/∂x = −μ λ f₁(r) s/r (f₁ = f₀′, 1 beyond ε) opposes the slip with at most
μλ, and whose Hessian μλ P[(f₁/r) I + (f₁′ − f₁/r) ŝ⊗ŝ]P is positive semidefinite. Lagging λ
and n makes D a potential within a step (a symmetric tangent); ε = ``slip`` (mm per step)
is the slip below which the law is viscous instead of sticking.
"""


from __future__ import annotations

from collections.abc import Callable

import dolfinx.fem
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from eyemech.forms.contact import smoothed_penalty_pressure, tangential_slips


class NodalContact:
    """Penalty contact of the (owned) nodes of a vector Lagrange ``u`` with rigid obstacles,
    as NonlinearSolver hooks; nodes in ``excluded`` (e.g. prescribed ones) are skipped."""

    def __init__(self, u: dolfinx.fem.Function, obstacles: dict, stiffness: float,
                 excluded: np.ndarray | None = None, smoothing: float = 2e-3,
                 friction: float | dict[str, float] = 0.0, slip: float = 1e-3):
        V = u.function_space
        self.owned = V.dofmap.index_map.size_local
        self.X = V.tabulate_dof_coordinates()[: self.owned]
        self.u, self.obstacles, self.stiffness = u, obstacles, float(stiffness)
        self.comm = V.mesh.comm
        self.smoothing = float(smoothing)
        # Coulomb μ per obstacle (a number: the same for all; a missing name: frictionless)
        self.friction = {name: float(friction.get(name, 0.0) if isinstance(friction, dict) else friction)
                         for name in obstacles}
        self.slip = float(slip)
        self._lagged = None  # (nodes, μλ, normals, start positions) of the step's sliders
        self.active = np.ones(self.owned, bool)
        if excluded is not None:
            self.active[excluded[excluded < self.owned]] = False
        self.seconds = 0.0

    def positions(self, values: np.ndarray | None = None) -> np.ndarray:
        values = self.u.x.array if values is None else values
        return self.X + values[: 3 * self.owned].reshape(-1, 3)

    def _pressed(self, x: np.ndarray, band: float = 0.0):
        """(node, depth, normal, obstacle name) of every node/obstacle pair with gap < band."""
        for name, obstacle in self.obstacles.items():
            gap, normal, acts = obstacle.gap_normal(x)
            hit = np.flatnonzero(acts & self.active & (gap < band))
            if len(hit):
                yield hit, -gap[hit], normal[hit], name

    def _smoothed(self, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """⟨d⟩ smoothed over |d| < ε by the C¹ ramp (d + ε)²/(4ε), and its derivative: a
        kinked ⟨d⟩ makes Newton cycle when a node sits at the wall (measured: residuals
        alternating 1e-2 / 1e-4 for 25 iterations); ε = ``smoothing`` mm."""
        value, slope = smoothed_penalty_pressure(-depth, 1.0, self.smoothing)  # the one law
        return value, -slope

    def begin_step(self, wall_motion: dict[str, Callable[[np.ndarray], np.ndarray]] | None = None) -> None:
        """Lag the wall friction at the step's start (the current ``u``): each pressed
        node's normal force, normal and anchor — the wall's material point under it, where
        the wall will be at the step's end. ``wall_motion`` maps an obstacle's name to that
        motion (points at the step's start → at its end; e.g. :func:`turn_about_x` for a
        twisted injector), so a node stuck to a moving wall is dragged along; walls not named
        stand still. The motion must not change the obstacle's shape as the body sees it
        (a surface of revolution turned about its axis): it enters the friction only. A
        no-op without friction."""
        if not any(mu > 0.0 for mu in self.friction.values()):
            return
        wall_motion = wall_motion or {}
        x = self.positions()
        found = [(nodes, self.friction[name] * self.stiffness * self._smoothed(depth)[0], normal,
                  wall_motion[name](x[nodes]) if name in wall_motion else x[nodes])
                 for nodes, depth, normal, name in self._pressed(x, self.smoothing)
                 if self.friction[name] > 0.0]
        if not found:
            self._lagged = None
            return
        self._lagged = tuple(np.concatenate(parts) for parts in zip(*found))

    def _slip(self, x: np.ndarray):
        """(nodes, μλ, tangential projectors P, slips s, |s|) of the lagged sliders at x."""
        nodes, weight, normal, anchor = self._lagged
        return (nodes, weight, *tangential_slips(normal, anchor, x[nodes]))

    def _f1(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """f₁(r)/r and f₁′(r) of the smoothed Coulomb law (finite at r = 0)."""
        eps = self.slip
        inside = r < eps
        over_r = np.where(inside, 2.0 / eps - r / eps ** 2, 1.0 / np.maximum(r, eps))
        slope = np.where(inside, 2.0 / eps - 2.0 * r / eps ** 2, 0.0)
        return over_r, slope

    def friction_forces(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(nodes, ∂D/∂x per node) at positions x: the residual's friction part."""
        if self._lagged is None:
            return np.zeros(0, int), np.zeros((0, 3))
        nodes, weight, _, slip, r = self._slip(x)
        return nodes, (weight * self._f1(r)[0])[:, None] * slip

    def residual_hook(self, x_vec: PETSc.Vec, F: PETSc.Vec) -> None:
        start = PETSc.Log.getTime()
        x = self.X + x_vec.array_r[: 3 * self.owned].reshape(-1, 3)
        with F.localForm() as local:
            values = local.array
            for nodes, depth, normal, _ in self._pressed(x, self.smoothing):
                force = -self.stiffness * self._smoothed(depth)[0][:, None] * normal
                np.add.at(values.reshape(-1, 3), nodes, force)
            nodes, gradient = self.friction_forces(x)
            np.add.at(values.reshape(-1, 3), nodes, gradient)
        self.seconds += PETSc.Log.getTime() - start

    def friction_hessians(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(nodes, ∂²D/∂x² per node, 3×3) at positions x."""
        if self._lagged is None:
            return np.zeros(0, int), np.zeros((0, 3, 3))
        nodes, weight, projector, slip, r = self._slip(x)
        over_r, slope = self._f1(r)
        direction = slip / np.maximum(r, 1e-300)[:, None]
        inner = (over_r[:, None, None] * np.eye(3)[None]
                 + (slope - over_r)[:, None, None] * np.einsum("ni,nj->nij", direction, direction))
        return nodes, weight[:, None, None] * projector @ inner @ projector

    def jacobian_hook(self, x_vec: PETSc.Vec, J: PETSc.Mat) -> None:
        start = PETSc.Log.getTime()
        x = self.X + x_vec.array_r[: 3 * self.owned].reshape(-1, 3)
        added = False
        for nodes, depth, normal, _ in self._pressed(x, self.smoothing):
            slope = self._smoothed(depth)[1]
            blocks = self.stiffness * slope[:, None, None] * np.einsum("ni,nj->nij", normal, normal)
            for node, block in zip(nodes, blocks):
                dofs = np.arange(3 * node, 3 * node + 3, dtype=np.int32)
                J.setValuesLocal(dofs, dofs, block.ravel(), addv=PETSc.InsertMode.ADD_VALUES)
            added = True
        nodes, blocks = self.friction_hessians(x)
        for node, block in zip(nodes, blocks):
            dofs = np.arange(3 * node, 3 * node + 3, dtype=np.int32)
            J.setValuesLocal(dofs, dofs, block.ravel(), addv=PETSc.InsertMode.ADD_VALUES)
            added = True
        # J.assemble() is collective: when any rank added a block every rank assembles (a
        # rank whose nodes touch nothing skipped it and left the others waiting in it: the
        # fold on 3 ranks; tests/mpi_rigid_wall.py)
        if self.comm.allreduce(added, op=MPI.LOR):
            J.assemble()
        self.seconds += PETSc.Log.getTime() - start

    def max_penetration(self) -> dict[str, float]:
        """Deepest penetration (mm) of the current state, per obstacle (over all ranks:
        each rank holds only its owned nodes)."""
        x = self.positions()
        depth = {name: 0.0 for name in self.obstacles}
        for _nodes, d, _n, name in self._pressed(x):
            depth[name] = max(depth[name], float(d.max()))
        names = list(depth)
        deepest = np.empty(len(names))
        self.comm.Allreduce(np.array([depth[n] for n in names]), deepest, op=MPI.MAX)
        return dict(zip(names, map(float, deepest)))

    def forces(self) -> dict[str, np.ndarray]:
        """Resultant force (N) each obstacle exerts on the lens (summed over the ranks)."""
        x = self.positions()
        total = {name: np.zeros(3) for name in self.obstacles}
        for _nodes, d, normal, name in self._pressed(x, self.smoothing):
            total[name] += self.stiffness * (self._smoothed(d)[0][:, None] * normal).sum(axis=0)
        return {name: self.comm.allreduce(force, op=MPI.SUM) for name, force in total.items()}
