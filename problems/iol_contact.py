r"""Node-to-rigid-surface penalty contact for the lens, evaluated in numpy, and the lens'
self distance measured with ipctk.

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

import dataclasses
import time
from collections.abc import Callable

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

try:
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass
import dolfinx.fem


def _radial(x: np.ndarray, axis_point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ρ about the x-directed axis through ``axis_point`` and the unit radial direction."""
    d = x[:, 1:] - axis_point[1:]
    rho = np.sqrt(np.sum(d ** 2, axis=1) + 1e-24)
    e = np.zeros_like(x)
    e[:, 1:] = d / rho[:, None]
    return rho, e


@dataclasses.dataclass
class TaperedBore:
    """The cartridge bore: axis along +x through ``axis_point``; radius ``radius`` up to
    ``taper_start``, then linear down to ``nozzle_radius`` at ``taper_end``, straight to the
    nozzle tip ``tip``. Acts for x < tip (the body is inside). ``scale`` shrinks the whole
    bore towards ``radius`` (the closing loading chamber of the folding stage)."""

    axis_point: np.ndarray
    radius: float
    nozzle_radius: float
    taper_start: float
    taper_end: float
    tip: float
    opening: float = 0.0  # extra radius (mm) added everywhere: the chamber before it closes
    lip: float = 0.0  # radius (mm) of the rounded nozzle exit (0: a sharp edge)

    def wall_radius(self, x: np.ndarray) -> np.ndarray:
        s = np.clip((x - self.taper_start) / (self.taper_end - self.taper_start), 0.0, 1.0)
        return self.radius + (self.nozzle_radius - self.radius) * s + self.opening

    def gap_normal(self, x):
        """Inside the bore g = R(x) − ρ, n = −e_ρ. With a ``lip``, the last ``lip`` mm are the
        inside of a torus (tube radius ``lip``) that turns the wall from axial to radial at the
        tip: g = D − lip, n = (x − x_c, ρ − ρ_c)/D from the lip's centre circle (x_c, ρ_c).
        Why: with a sharp edge the wall's force on a node at the nozzle radius jumps from
        k (ρ − R) to 0 as the node crosses x = tip, and Newton cycled between two states
        (residuals 4e-3 / 5e-4 for 25 iterations, the optic leaving the nozzle)."""
        rho, e = _radial(x, self.axis_point)
        gap, normal, acts = self.wall_radius(x[:, 0]) - rho, -e, x[:, 0] < self.tip
        if self.lip > 0.0:
            x_c, rho_c = self.tip - self.lip, self.nozzle_radius + self.opening + self.lip
            dx, drho = x[:, 0] - x_c, rho - rho_c
            on_lip = (dx > 0.0) & (drho < 0.0)
            D = np.sqrt(dx ** 2 + drho ** 2) + 1e-300
            gap = np.where(on_lip, D - self.lip, gap)
            normal = np.where(on_lip[:, None], (dx / D)[:, None] * np.array([1.0, 0.0, 0.0])
                              + (drho / D)[:, None] * e, normal)
            acts = np.where(dx > 0.0, on_lip, acts)
        return gap, normal, acts


def turn_about_x(axis_point: np.ndarray, angle: float) -> Callable[[np.ndarray], np.ndarray]:
    """The rigid turn by ``angle`` (rad, right-handed about +x) about the x-directed line
    through ``axis_point``: the motion of a twisted injector's wall over one step."""
    cos, sin = np.cos(angle), np.sin(angle)

    def turned(x: np.ndarray) -> np.ndarray:
        y, z = x[:, 1] - axis_point[1], x[:, 2] - axis_point[2]
        return np.column_stack([x[:, 0], axis_point[1] + cos * y - sin * z, axis_point[2] + sin * y + cos * z])
    return turned


@dataclasses.dataclass
class Plunger:
    """A flat plunger head x = ``position`` of ``radius`` about the x-directed axis through
    ``axis_point``, pushing along +x (the body lies at larger x)."""

    position: float
    axis_point: np.ndarray
    radius: float

    def gap_normal(self, x):
        normal = np.zeros_like(x)
        normal[:, 0] = 1.0
        rho, _ = _radial(x, self.axis_point)
        return x[:, 0] - self.position, normal, rho < self.radius


@dataclasses.dataclass
class Capsule:
    """A rigid ellipsoidal bag (semi-axes ``semi_axes`` along x, y, z about ``center``); the
    body is inside. Acts where x > ``entry`` (outside the injector). Gap ≈ (1 − s)/|∇s|,
    s = |A⁻¹(x − c)|: exact on the surface to first order."""

    center: np.ndarray
    semi_axes: np.ndarray
    entry: float

    def gap_normal(self, x):
        y = (x - self.center) / self.semi_axes
        s = np.sqrt(np.sum(y ** 2, axis=1) + 1e-24)
        grad_s = y / self.semi_axes / s[:, None]
        norm = np.linalg.norm(grad_s, axis=1) + 1e-24
        return (1.0 - s) / norm, -grad_s / norm[:, None], x[:, 0] > self.entry


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
        eps = self.smoothing
        if eps <= 0.0:
            return np.maximum(depth, 0.0), (depth > 0.0).astype(float)
        inside = depth >= eps
        value = np.where(inside, depth, (depth + eps) ** 2 / (4.0 * eps))
        slope = np.where(inside, 1.0, (depth + eps) / (2.0 * eps))
        return value, slope

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
        projector = np.eye(3)[None] - np.einsum("ni,nj->nij", normal, normal)
        slip = np.einsum("nij,nj->ni", projector, x[nodes] - anchor)
        return nodes, weight, projector, slip, np.linalg.norm(slip, axis=1)

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
        if added:
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


def self_distance_probe(u: dolfinx.fem.Function):
    """A :class:`SelfDistance` when ipctk is installed (on rank 0, which measures), else None."""
    comm = u.function_space.mesh.comm
    available = False
    if comm.rank == 0:
        try:
            import ipctk  # noqa: F401
            available = True
        except ImportError:
            pass
    return SelfDistance(u) if comm.bcast(available, root=0) else None


class SelfDistance:
    """Smallest distance between distant parts of the lens mid-surface, by ipctk, on the
    flat triangles through the P2 vertex nodes.

    The lens is small (hundreds of nodes), so under MPI its triangles and node positions
    are gathered on rank 0, which measures and broadcasts the result: every rank count
    measures the same surface (each rank alone sees only its part, and two parts of the
    lens that meet may sit on different ranks).

    Only pairs of primitives whose vertices all lie more than ``exclusion`` apart in the
    reference (flat) lens count: on a flat mesh, neighbouring elements are a fraction of
    an element apart, which says nothing about self-contact; parts that were apart along
    the lens and come together (a haptic on the optic, the rolled optic's rims) are what
    is measured. ipctk gives the candidates within ``search_radius`` and their distances.
    """

    def __init__(self, u: dolfinx.fem.Function, exclusion: float = 1.0):
        V = u.function_space
        self.u, self.comm = u, V.mesh.comm
        index_map = V.dofmap.index_map
        self.owned = index_map.size_local
        local_count = self.owned + index_map.num_ghosts
        to_global = index_map.local_to_global(np.arange(local_count, dtype=np.int32))
        self.owned_global = to_global[: self.owned]
        owned_cells = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
        cells = to_global[V.dofmap.list[:owned_cells, :3]]  # the vertex nodes of each P2 triangle
        X = V.tabulate_dof_coordinates()[: self.owned]
        gathered = self.comm.gather((cells, self.owned_global, X), root=0)
        self.exclusion = exclusion
        if self.comm.rank != 0:
            return
        import ipctk

        cells = np.vstack([g[0] for g in gathered])
        self.nodes, faces = np.unique(cells, return_inverse=True)
        faces = faces.reshape(-1, 3)
        self.slot = np.full(max(int(g[1].max(initial=-1)) for g in gathered) + 1, -1, np.int64)
        self.slot[self.nodes] = np.arange(len(self.nodes))
        self.X = np.empty((len(self.nodes), 3))
        for _, node, x in gathered:
            keep = self.slot[node] >= 0
            self.X[self.slot[node[keep]]] = x[keep]
        self.faces = np.asfortranarray(faces.astype(np.int32))
        self.edges = np.asfortranarray(ipctk.edges(self.faces))
        self.mesh = ipctk.CollisionMesh(np.asfortranarray(self.X), self.edges, self.faces)
        self._ipctk = ipctk

    def positions(self) -> np.ndarray | None:
        """Deformed positions of the vertex nodes on rank 0 (None elsewhere); collective."""
        x = self.u.x.array[: 3 * self.owned].reshape(-1, 3)
        gathered = self.comm.gather((self.owned_global, x), root=0)
        if self.comm.rank != 0:
            return None
        u = np.empty_like(self.X)
        for node, values in gathered:
            keep = self.slot[node] >= 0
            u[self.slot[node[keep]]] = values[keep]
        return np.asfortranarray(self.X + u)

    def __call__(self, search_radius: float = 0.25, distances: bool = True) -> tuple[float, bool]:
        """(minimum distance in mm — ``inf`` when nothing distant is within
        ``search_radius``, NaN when ``distances`` is False —, whether the surface
        intersects itself); collective, measured on rank 0."""
        x = self.positions()
        found = self._measure(x, search_radius, distances) if self.comm.rank == 0 else None
        return self.comm.bcast(found, root=0)

    def _measure(self, x: np.ndarray, search_radius: float, distances: bool) -> tuple[float, bool]:
        """The measurement on rank 0: ipctk's exact triangle–edge intersection test is
        cheap and always done, the distance search only when ``distances``."""
        ipctk = self._ipctk
        if not distances:
            return float("nan"), bool(ipctk.has_intersections(self.mesh, x, broad_phase=ipctk.BVH()))
        collisions = ipctk.NormalCollisions()
        t0 = time.perf_counter()
        collisions.build(self.mesh, x, search_radius, broad_phase=ipctk.BVH())
        self.timing = [time.perf_counter() - t0, len(collisions)]
        best = np.inf
        for i in range(len(collisions)):
            collision = collisions[i]
            ids = [v for v in collision.vertex_ids(self.edges, self.faces) if v >= 0]
            split = 2 if isinstance(collision, ipctk.EdgeEdgeNormalCollision) else 1
            first, second = self.X[ids[:split]], self.X[ids[split:]]
            if np.min(np.linalg.norm(first[:, None] - second[None], axis=2)) < self.exclusion:
                continue
            best = min(best, float(np.sqrt(collision.compute_distance(collision.dof(x, self.edges,
                                                                                     self.faces)))))
        # An element of NormalCollisions refers into the container: let it go first. Python
        # clears a frame's locals in the order they were bound, so a `collision` left alive
        # outlived `collisions` and its deallocation read freed memory (SIGSEGV once VTK had
        # reused that memory: the lens notebook's run, 2026-11-22).
        collision = None
        del collision, collisions
        t0 = time.perf_counter()
        crossing = bool(ipctk.has_intersections(self.mesh, x, broad_phase=ipctk.BVH()))
        self.timing.append(time.perf_counter() - t0)
        return best, crossing
