r"""Self-contact of the rotation-free P1 shell on its own triangles (issue 23, item 3): the
ipctk barrier and continuous collision detection of ``problems/contact/ipc.py`` (IPC, Li et
al. 2020), with the shell's vertices as the collision vertices and its triangles as the
collision faces — no sub-triangles and no gathering across ranks (one process, numpy arrays).

**Potential** (N·mm): Π_s(x) = κ Σ_k b(d_k², d̂²), b(s, ŝ) = −(s − ŝ)² ln(s/ŝ) for s < ŝ,
over the point–triangle and edge–edge pairs closer than d̂ whose vertices are not all within
``exclusion`` of each other along the reference surface (default d̂ + 2 × the longest edge:
the flat sheet's neighbours are barrier-free; checked at construction). Gradient and the exact
Hessian (not PSD-projected, as ``problems/contact/ipc.py``: the projection makes Newton linear).

**Non-penetration**: the reference state is checked intersection-free; ``step_fraction``
scales every Newton update so that the straight path stays collision-free (ipctk's additive
CCD, which stops with ≥ 10 % of the gap left); Π_s → ∞ as d → 0. So every iterate is
intersection-free (``tests/test_rotation_free.py``: a folded sheet pressed onto itself).

**Pattern.** The contact Hessian couples vertices the shell's stencil does not; ``Dynamics``
grows its sparsity pattern by the 3 × 3 blocks of the new vertex pairs when a Hessian brings
them, and keeps it (a new symbolic factorisation only then, counted as ``symbolic``).
"""

from __future__ import annotations

import numpy as np

from eyemech.forms.contact import tangential_slips


def serial_ipctk() -> None:
    """ipctk on one thread: with its default (one per core) the barrier's and friction's sums
    and the CCD's reductions run in parallel and their order varies from run to run: two
    identical coarse P1 injections ended 1e-9 apart and could take different step paths;
    on one thread they are bitwise equal and no slower in CPU time (docs/iol.md §4b
    "Reproducibility"; tests/test_iol_injection.py)."""
    import ipctk

    if ipctk.get_num_threads() != 1:
        ipctk.set_num_threads(1)


class SelfContactError(RuntimeError):
    """A state the barrier cannot start from (intersecting, or pairs within d̂ at rest)."""


class SurfaceSelfContact:
    """ipctk self-contact of the P1 triangle surface (points X (n, 3), triangles (m, 3))."""

    def __init__(self, X: np.ndarray, triangles: np.ndarray, dhat: float, stiffness: float,
                 exclusion: float | None = None, margin: float | None = None,
                 friction: float = 0.0, slip: float = 1e-3):
        """``margin`` δ (default 4 d̂): the candidate pairs are those within d̂ + δ of each
        other at the positions x_b of their build (ipctk's sweep and prune, boxes inflated by
        d̂ + δ), reused for every x with max_v |x_v − x_b,v − t| ≤ δ/2 for the mean move t
        (``_covers``) — no pair outside them can then come within d̂ — and rebuilt otherwise
        (``rebuilds`` counts them). Every broad phase here is ipctk's sweep and prune: on the lens
        it builds the candidates in 3.7 ms where its BVH takes 5.2 (the same 549 pairs) and
        sweeps a CCD path in 1.3 ms against 1.9 (load 6–7, docs/iol.md §4b)."""
        import ipctk
        import scipy.sparse
        from scipy.sparse.csgraph import dijkstra

        if not dhat > 0 or not stiffness > 0:
            raise ValueError(f"self-contact needs d̂ > 0 and a stiffness > 0, got {dhat!r}, {stiffness!r}")
        serial_ipctk()
        self._ipctk = ipctk
        self.dhat, self.stiffness = float(dhat), float(stiffness)
        self.X = np.asfortranarray(X, dtype=float)
        self.faces = np.asfortranarray(np.asarray(triangles, dtype=np.int32))
        self.edges = np.asfortranarray(ipctk.edges(self.faces))
        self.mesh = ipctk.CollisionMesh(self.X, self.edges, self.faces)
        i, j = self.edges[:, 0], self.edges[:, 1]
        lengths = np.linalg.norm(self.X[i] - self.X[j], axis=1)
        self.exclusion = float(exclusion) if exclusion is not None else self.dhat + 2.0 * float(lengths.max())
        n = len(self.X)
        graph = scipy.sparse.coo_matrix((lengths, (i, j)), shape=(n, n)).tocsr()
        near = np.argwhere(np.isfinite(dijkstra(graph, directed=False, limit=self.exclusion)))
        near = near[near[:, 0] < near[:, 1]]
        self.mesh.can_collide = ipctk.SparseCanCollide({(int(a), int(b)): False for a, b in near}, True)
        self.barrier = ipctk.BarrierPotential(self.dhat)
        # lagged smoothed Coulomb between the lens' own surfaces (ipctk, as problems/contact/ipc.py)
        self.friction = float(friction)
        self.friction_potential = ipctk.FrictionPotential(float(slip)) if self.friction > 0 else None
        self._tangential, self._x_start = None, None
        self._ccd = ipctk.AdditiveCCD(conservative_rescaling=0.9)
        self._cache: tuple[np.ndarray, object] | None = None
        self.margin = 4.0 * self.dhat if margin is None else float(margin)
        self._candidates, self._x_build = None, None
        self.clearance = 0.0
        self.rebuilds = 0
        self.narrow_phases_skipped = 0
        self.step_limits: list[float] = []
        if self.intersecting(self.X) or len(self.collisions(self.X)):
            raise SelfContactError("the reference surface intersects itself or has non-excluded pairs "
                                   f"closer than d̂ = {self.dhat} mm")

    def _drift(self, x: np.ndarray) -> float:
        """max_v |x_v − x_b,v − t| for the mean move t from the build positions x_b (∞ before a
        build): a pair's distance is translation invariant and 1-Lipschitz in each of its
        vertices, so it differs from its value at x_b by at most twice this."""
        if self._x_build is None:
            return float("inf")
        move = x - self._x_build
        move -= move.mean(axis=0)
        return float(np.sqrt(np.max(np.sum(move ** 2, axis=1))))

    def _covers(self, x: np.ndarray) -> bool:
        """Whether x is within δ/2 of the build positions up to a common translation t (the mean
        move): a pair's distance then changes by at most δ — the lens pushed through the
        injector moves ≈ 0.4 mm per step as a whole, which without t would rebuild the
        candidates at every iterate."""
        return self._drift(x) <= 0.5 * self.margin

    def _candidates_for(self, x: np.ndarray):
        """Candidates valid at x: the kept ones, or new ones built at x (with ``clearance``, the
        smallest distance of their pairs at x, at most d̂ + δ)."""
        if not self._covers(x):
            x = np.asfortranarray(x)
            self._candidates = self._ipctk.Candidates()
            self._candidates.build(self.mesh, x, self.dhat + self.margin,
                                   broad_phase=self._ipctk.SweepAndPrune())
            near = self._ipctk.NormalCollisions()
            near.build(self._candidates, self.mesh, x, self.dhat + self.margin)
            self.clearance = min(float(np.sqrt(near.compute_minimum_distance(self.mesh, x))),
                                 self.dhat + self.margin) if len(near) else self.dhat + self.margin
            self._x_build = np.array(x)
            self.rebuilds += 1
        return self._candidates

    def collisions(self, x: np.ndarray):
        """The pairs closer than d̂ at x, from the kept candidates; the last x's are kept
        (residual and Hessian are asked at the same iterate)."""
        if self._cache is not None and np.array_equal(self._cache[0], x):
            return self._cache[1]
        candidates = self._candidates_for(x)
        collisions = self._ipctk.NormalCollisions()
        # every kept pair is at least clearance − 2 drift apart: none within d̂ is certain
        # without ipctk's narrow phase (the released lens: no pair near, every iterate)
        if self.clearance - 2.0 * self._drift(x) > self.dhat * (1.0 + 1e-9):
            self.narrow_phases_skipped += 1
        else:
            collisions.build(candidates, self.mesh, np.asfortranarray(x), self.dhat)
        self._cache = (np.array(x), collisions)
        return collisions

    def begin_step(self, x: np.ndarray) -> None:
        """Lag the friction's normal forces and tangent bases at the step's start x (every
        attempt of a step); a no-op without friction."""
        self._tangential = None
        if self.friction_potential is None:
            return
        self._x_start = np.asfortranarray(x)
        tangential = self._ipctk.TangentialCollisions()
        tangential.build(self.mesh, self._x_start, self.collisions(x), self.barrier, self.stiffness,
                         self.friction)
        self._tangential = tangential if len(tangential) else None

    def energy(self, x: np.ndarray) -> float:
        value = self.stiffness * float(self.barrier(self.collisions(x), self.mesh, np.asfortranarray(x)))
        if self._tangential is not None:
            slip = np.asfortranarray(x) - self._x_start
            value += float(self.friction_potential(self._tangential, self.mesh, slip))
        return value

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """∇Π_s, dofs 3 v + c."""
        collisions = self.collisions(x)
        grad = self.stiffness * self.barrier.gradient(collisions, self.mesh, np.asfortranarray(x)) \
            if len(collisions) else np.zeros(x.size)
        if self._tangential is not None:
            grad = grad + self.friction_potential.gradient(self._tangential, self.mesh,
                                                           np.asfortranarray(x) - self._x_start)
        return grad

    def hessian(self, x: np.ndarray):
        """∇²Π_s (scipy sparse, exact), or None without active pairs."""
        collisions = self.collisions(x)
        none = self._ipctk.PSDProjectionMethod.NONE
        hessian = self.stiffness * self.barrier.hessian(collisions, self.mesh, np.asfortranarray(x), none) \
            if len(collisions) else None
        if self._tangential is not None:
            friction = self.friction_potential.hessian(self._tangential, self.mesh,
                                                       np.asfortranarray(x) - self._x_start, none)
            hessian = friction if hessian is None else hessian + friction
        return hessian

    def pairs_within(self, x: np.ndarray, reach: float) -> np.ndarray:
        """The (row · 3n + col) keys of the Hessian entries of every pair closer than ``reach``
        (a barrier of that reach: its Hessian's pattern) — the superset a growing Jacobian
        pattern takes, so that the pairs coming within d̂ over the next iterations are in it."""
        x = np.asfortranarray(x)
        collisions = self._ipctk.NormalCollisions()
        collisions.build(self.mesh, x, reach, broad_phase=self._ipctk.SweepAndPrune())
        if not len(collisions):
            return np.zeros(0, dtype=np.int64)
        h = self._ipctk.BarrierPotential(reach).hessian(collisions, self.mesh, x,
                                                        self._ipctk.PSDProjectionMethod.NONE).tocoo()
        return h.row.astype(np.int64) * x.size + h.col

    def step_fraction(self, x0: np.ndarray, x1: np.ndarray) -> float:
        """The largest fraction of the straight path x0 → x1 that is collision-free (CCD). With
        both ends within δ/2 of the candidates' build positions (up to translations t0, t1),
        every point of the path is too (up to the interpolated translation: a ball is convex), so
        the kept candidates hold every pair that can meet on it; else a full broad-phase sweep."""
        candidates = self._candidates_for(x0)
        if self._covers(x1):
            fraction = float(candidates.compute_collision_free_stepsize(
                self.mesh, np.asfortranarray(x0), np.asfortranarray(x1), narrow_phase_ccd=self._ccd))
        else:
            fraction = float(self._ipctk.compute_collision_free_stepsize(
                self.mesh, np.asfortranarray(x0), np.asfortranarray(x1),
                broad_phase=self._ipctk.SweepAndPrune(), narrow_phase_ccd=self._ccd))
        if fraction < 1.0:
            self.step_limits.append(fraction)
        return fraction

    def intersecting(self, x: np.ndarray) -> bool:
        return bool(self._ipctk.has_intersections(self.mesh, np.asfortranarray(x),
                                                  broad_phase=self._ipctk.SweepAndPrune()))

    def min_distance(self, x: np.ndarray) -> float:
        """The smallest distance of the pairs within d̂ (``inf`` when none is)."""
        collisions = self.collisions(x)
        return float(np.sqrt(collisions.compute_minimum_distance(self.mesh, np.asfortranarray(x)))) \
            if len(collisions) else float("inf")


class NodalObstacles:
    """Rigid obstacles (``problems/lens/injector.py``: a signed gap g, its normal n and where
    it acts, per vertex) met by the P1 vertices through the smoothed nodal penalty of
    ``problems/contact/rigid_wall.NodalContact``: Π_c = Σ_v φ(g_v), p = −φ′ = k⟨−g⟩ smoothed
    over ±ε (``forms.contact.smoothed_penalty_pressure``), force −p ∇g (the energy's gradient:
    ``_gap_gradient``), Hessian −p′ ∇g⊗∇g (the curvature term p ∇²g left out, as there: a
    quasi-Newton tangent)."""

    def __init__(self, obstacles: dict, stiffness: float, smoothing: float = 2e-3,
                 excluded: dict | None = None, friction: dict | None = None, slip: float = 1e-3):
        """``excluded``: obstacle name → vertices it does not act on (the plunger head on the
        haptics, the closing chamber on the prescribed optic). ``friction``: obstacle name →
        Coulomb μ (``begin_step`` lags it), ``slip`` ε its regularisation (mm per step)."""
        if not stiffness > 0:
            raise ValueError(f"the obstacles' stiffness must be > 0, got {stiffness!r}")
        if not slip > 0:
            raise ValueError(f"the friction's slip must be > 0, got {slip!r}")
        self.obstacles, self.stiffness, self.smoothing = obstacles, float(stiffness), float(smoothing)
        self.excluded = {name: np.asarray(nodes, dtype=np.int64) for name, nodes in (excluded or {}).items()}
        self.friction = {name: float(mu) for name, mu in (friction or {}).items() if mu > 0.0}
        self.slip = float(slip)
        self._lagged = None  # (vertices, μλ, normals, anchors) of the step's sliders
        self._last: tuple[np.ndarray, list] | None = None

    def begin_step(self, x: np.ndarray, wall_motion: dict | None = None) -> None:
        """Lag the wall friction at the step's start x (``rigid_wall.NodalContact.begin_step``):
        each pressed vertex keeps μλ (λ = the penalty pressure k⟨−g⟩), the unit normal and its
        anchor — x, or x moved as the wall moves over the step (``wall_motion``: name → map of
        points, the twisted injector's turn)."""
        from eyemech.forms.contact import smoothed_penalty_pressure

        self._lagged = None
        if not self.friction:
            return
        wall_motion = wall_motion or {}
        found = []
        for name, (nodes, g, grad) in zip(self.obstacles, self._pressed_by_name(x)):
            if nodes is None or name not in self.friction:
                continue
            pressure, _ = smoothed_penalty_pressure(g, self.stiffness, self.smoothing)
            normal = grad / np.linalg.norm(grad, axis=1)[:, None]
            anchor = wall_motion[name](x[nodes]) if name in wall_motion else x[nodes].copy()
            found.append((nodes, self.friction[name] * pressure, normal, anchor))
        if found:
            self._lagged = tuple(np.concatenate(parts) for parts in zip(*found))

    def _slip(self, x: np.ndarray):
        """(vertices, μλ, projectors P = I − n⊗n, slips s = P(x − a), |s|) of the sliders."""
        nodes, weight, normal, anchor = self._lagged
        return (nodes, weight, *tangential_slips(normal, anchor, x[nodes]))

    def _f0_f1(self, r: np.ndarray):
        """IPC's smoothed Coulomb: f₀(r), f₁(r)/r and f₁′(r) (finite at r = 0), ε = ``slip``."""
        eps = self.slip
        inside = r < eps
        f0 = np.where(inside, -r ** 3 / (3 * eps ** 2) + r ** 2 / eps + eps / 3, r)
        over_r = np.where(inside, 2.0 / eps - r / eps ** 2, 1.0 / np.maximum(r, eps))
        slope = np.where(inside, 2.0 / eps - 2.0 * r / eps ** 2, 0.0)
        return f0, over_r, slope

    def friction_energy(self, x: np.ndarray) -> float:
        """D = Σ μλ f₀(|s|): a potential within the step (λ, n, a lagged)."""
        if self._lagged is None:
            return 0.0
        _, weight, _, _, r = self._slip(x)
        return float(np.sum(weight * self._f0_f1(r)[0]))

    def _pressed(self, x: np.ndarray) -> list:
        """(vertices, gaps, ∇g) per obstacle where g < ε; the last x's are kept (Newton asks
        energy, gradient and Hessian at the same iterate)."""
        return [entry for entry in self._pressed_by_name(x) if entry[0] is not None]

    def _pressed_by_name(self, x: np.ndarray) -> list:
        """``_pressed``'s entries in the order of ``obstacles``, (None, None, None) where
        nothing is pressed."""
        if self._last is not None and np.array_equal(self._last[0], x):
            return self._last[1]
        pressed = []
        for name, obstacle in self.obstacles.items():
            gap, _, acts = obstacle.gap_normal(x)
            if name in self.excluded:
                acts = acts.copy()
                acts[self.excluded[name]] = False
            hit = np.flatnonzero(acts & (gap < self.smoothing))
            pressed.append((hit, gap[hit], self._gap_gradient(obstacle, x[hit])) if len(hit)
                           else (None, None, None))
        self._last = (np.array(x), pressed)
        return pressed

    @staticmethod
    def _gap_gradient(obstacle, x: np.ndarray, step: float = 1e-7) -> np.ndarray:
        """∇g at x by central differences of the obstacle's gap (step 1e-7 mm on gaps of
        O(1) mm: error ~1e-9). Why not the obstacle's normal: it is ∇g only to first order
        (the tapered bore's −e_ρ leaves out the taper's slope dR/dx = −0.067; the capsule's is
        exact on its surface only), and a force that is not the energy's gradient defeats the
        energy line search that self-contact turns on (the coarse P1 injection stalled in the
        taper at 0.1 % residual reduction per iteration)."""
        shifts = step * np.vstack([np.eye(3), -np.eye(3)])  # the 6 points of every vertex, one call
        gap = obstacle.gap_normal((x[None, :, :] + shifts[:, None, :]).reshape(-1, 3))[0].reshape(6, -1)
        return ((gap[:3] - gap[3:]) / (2.0 * step)).T

    def energy(self, x: np.ndarray) -> float:
        """Σ φ(g): k (ε − g)³/(12ε) for |g| < ε, ½ k g² + k ε²/6 below (C², φ′ = −p)."""
        k, eps, total = self.stiffness, self.smoothing, 0.0
        for _, g, _ in self._pressed(x):
            total += float(np.sum(np.where(g <= -eps, 0.5 * k * g ** 2 + k * eps ** 2 / 6,
                                           k * (eps - g) ** 3 / (12 * eps))))
        return total + self.friction_energy(x)

    def gradient(self, x: np.ndarray) -> np.ndarray:
        from eyemech.forms.contact import smoothed_penalty_pressure

        grad = np.zeros_like(x)
        for nodes, g, n in self._pressed(x):
            pressure, _ = smoothed_penalty_pressure(g, self.stiffness, self.smoothing)
            np.add.at(grad, nodes, -pressure[:, None] * n)
        if self._lagged is not None:  # ∂D/∂x = μλ f₁(r)/r s
            nodes, weight, _, slip, r = self._slip(x)
            np.add.at(grad, nodes, (weight * self._f0_f1(r)[1])[:, None] * slip)
        return grad.ravel()

    def blocks(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(vertices, their 3 × 3 Hessian blocks −p′ n⊗n)."""
        from eyemech.forms.contact import smoothed_penalty_pressure

        nodes, blocks = [np.zeros(0, dtype=np.int64)], [np.zeros((0, 3, 3))]
        for hit, g, n in self._pressed(x):
            _, slope = smoothed_penalty_pressure(g, self.stiffness, self.smoothing)
            nodes.append(hit)
            blocks.append(-slope[:, None, None] * np.einsum("ni,nj->nij", n, n))
        if self._lagged is not None:  # μλ P[(f₁/r) I + (f₁′ − f₁/r) ŝ⊗ŝ]P, positive semidefinite
            hit, weight, projector, slip, r = self._slip(x)
            _, over_r, slope = self._f0_f1(r)
            direction = slip / np.maximum(r, 1e-300)[:, None]
            inner = (over_r[:, None, None] * np.eye(3)[None]
                     + (slope - over_r)[:, None, None] * np.einsum("ni,nj->nij", direction, direction))
            nodes.append(hit)
            blocks.append(weight[:, None, None] * projector @ inner @ projector)
        return np.concatenate(nodes), np.concatenate(blocks)

    def max_penetration(self, x: np.ndarray) -> float:
        return max([float(-g.min()) for _, g, _ in self._pressed(x)] + [0.0])
