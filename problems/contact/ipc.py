r"""Self-contact of a shell (the lens: haptics on the optic, the rolled optic's rims) by
ipctk's barrier potential, with continuous collision detection limiting every Newton
update, and optional lagged regularised Coulomb friction (IPC, Li et al. 2020).

Why ipctk and not a hand-written search: it gives the candidate pairs (BVH), exact
point–triangle / edge–edge distances with their gradients and Hessians, the smooth
barrier, the friction potential and a conservative continuous collision detection
(Tight-Inclusion CCD) — the pieces that make "the lens never passes through itself" a
property of the algorithm, not of the step size.

**The collision surface.** Every P2 triangle is split into its four flat sub-triangles
through its six nodes (vertices 0, 1, 2 and the edge nodes 3, 4, 5 — basix numbers edge i
opposite vertex i), so *every* node of the P2 field is a collision vertex and the barrier
force on a vertex is the force on that node's three dofs: no interpolation, no
lumping, no midside node left out. What is kept intersection-free is this piecewise-flat
interpolant of the P2 mid-surface (the curved P2 triangle differs from it by O(h² κ):
≈ 4 µm for the 0.3 mm sub-triangles of a fold of radius 1 mm). The shell's thickness is
not added: the barrier keeps the mid-surfaces apart (distance > 0), not h apart.

**Potential** (energy in N·mm): Π_s(x) = κ Σ_k b(d_k², d̂²),
b(s, ŝ) = −(s − ŝ)² ln(s/ŝ) for s < ŝ (ipctk's barrier on squared distances), summed over
the point–triangle and edge–edge pairs k closer than d̂ whose vertices are not all within
``exclusion`` of each other in the reference (flat) lens. Residual hook: F += ∇Π_s;
Jacobian hook: J += ∇²Π_s exact (projecting it to positive semi-definite, as IPC does for
its energy line search, makes this Newton converge only linearly).

**Why the exclusion.** In the flat lens, neighbouring sub-triangles are a fraction of an
element apart: pairs within d̂ at rest would feel the barrier before anything touches.
Two primitives are skipped when every vertex pair is within ``exclusion`` in the
reference *along the surface* (a path of collision edges shorter than ``exclusion``;
a second sheet or a haptic lying next to the optic's rim are not excluded); the default
d̂ + 2 (longest collision edge) makes the flat lens' neighbours barrier-free (checked at
construction). Excluded pairs can only meet by creasing the sheet to a radius
≲ exclusion/π — the shell's bending stiffness resists that long before.

**Non-penetration by construction.** (1) The initial state is checked intersection-free
(exact, ``ipctk.has_intersections``); (2) every Newton update x → x − λ y passes the
line-search pre-check :meth:`limit_step`, which scales y by ipctk's collision-free step
size along the straight path (additive CCD: conservative, it stops with ≥ 10 % of the
gap left); (3) Π_s → ∞ as d → 0, so no converged state sits at d = 0. Hence every iterate —
converged or not — is intersection-free, whatever Δt, k or the plunger do.

**Friction** (μ = ``friction`` > 0): IPC's lazy (lagged) smoothed Coulomb dissipation
D(Δx) = Σ_k μ λ_k f₀(‖T_kᵀ Δx‖), with the normal forces λ_k and tangent bases T_k taken at
the start of the step (x_n) and Δx = x − x_n; f₀ is C¹, linear (viscous) below the slip
``slip`` (mm per step) and |·| above it. Residual += ∇D, Jacobian += ∇²D (PSD-projected:
unprojected, Newton wandered).

**On N ranks.** ipctk works on one whole surface, and the lens is small (≈ 1700
collision vertices, ≈ 5000 dofs), so rank 0 holds the whole collision mesh and evaluates
everything; the other ranks only exchange arrays with it (see :class:`_Lens`):
- the node numbering is DOLFINx's global one: rank r owns the nodes
  ``[start_r, start_r + n_r)`` and the ranks' ranges follow each other, so gathering the
  owned nodes in rank order gives the nodes in global order (the collision faces of the
  owned cells are gathered in that numbering);
- every evaluation gathers the owned positions to rank 0; it returns the barrier (+ friction)
  gradient rows, and the Hessian entries with their PETSc row/column indices, to the rank
  owning each row, which adds them to its owned residual rows / Jacobian rows;
- the CCD step fraction, the minimum distance and the intersection test are broadcast: every
  rank scales the Newton update by the same fraction (taken as an ``allreduce(MIN)`` of it,
  so no rank can step further than another), and an intersecting state is refused on all.
On one rank all of this is the identity (the same code path as before).
"""

from __future__ import annotations

import time

import dolfinx.fem
import numpy as np
from petsc4py import PETSc

# the four flat sub-triangles of a P2 triangle, in basix's node order (edge i is opposite
# vertex i: 3 = (1, 2), 4 = (0, 2), 5 = (0, 1)); all counter-clockwise like the parent
# The barrier's Hessian is used exact (not projected): IPC projects it per pair to PSD for its
# energy line search, but in our Newton (no energy line search; the CCD keeps iterates
# intersection-free) the projection made convergence linear (factor 0.3-0.7 per iteration,
# the injection crawling at dt ~ 0.1 ms and failing), the exact one quadratic (5-7
# iterations; measured on the coarse injection, docs/iol.md §3b). The friction's lagged
# Hessian stays projected: unprojected, Newton wandered (residuals up to 0.3). None = exact.
HESSIAN_PROJECTION = None
FRICTION_HESSIAN_PROJECTION = "CLAMP"
P2_SUBTRIANGLES = np.array([[0, 5, 4], [1, 3, 5], [2, 4, 3], [3, 4, 5]])


def collision_faces(cell_nodes: np.ndarray, degree: int) -> np.ndarray:
    """Flat collision triangles from the node lists of the cells (n, (p+1)(p+2)/2)."""
    if degree == 1:
        return cell_nodes[:, :3].copy()
    if degree == 2:
        return cell_nodes[:, P2_SUBTRIANGLES].reshape(-1, 3)
    raise ValueError(f"self-contact supports P1 and P2 shells, not degree {degree}")


class SelfContactError(RuntimeError):
    """The state handed to the self-contact is already intersecting (or touching)."""


class _Lens:
    """How the distributed P1/P2 vector field ``u`` maps onto rank 0's whole lens.

    Rank r owns nodes ``local_range`` = [start_r, end_r) of DOLFINx's global node numbering,
    stored first in its arrays, and the ranges follow each other in rank order: gathering
    the owned rows in rank order gives the global order. A node's dofs in the PETSc system
    (u the first, or only, block of the unknowns) are ``row_start_r + 3 (g − start_r) + c``
    with ``row_start_r`` the owner's first row (equal to 3 g + c with u alone)."""

    def __init__(self, V):
        self.comm = V.mesh.comm
        self.root = self.comm.rank == 0
        index_map = V.dofmap.index_map
        self.n_owned = index_map.size_local
        self.start = index_map.local_range[0]
        self.local_to_global = index_map.local_to_global
        # every rank's first node (and, after ``set_rows``, first PETSc row)
        self.node_starts = np.array(self.comm.allgather(self.start) + [index_map.size_global])
        self.row_starts: np.ndarray | None = None

    def gather_rows(self, owned: np.ndarray) -> np.ndarray | None:
        """Owned rows (n_owned, ...) of every rank, stacked in global order on rank 0."""
        if self.comm.size == 1:
            return owned
        parts = self.comm.gather(np.ascontiguousarray(owned), root=0)
        return np.concatenate(parts) if self.root else None

    def gather_positions(self, X_owned: np.ndarray, values: np.ndarray) -> np.ndarray | None:
        """Positions X + u of all nodes (F-ordered, for ipctk) on rank 0, None elsewhere."""
        x = self.gather_rows(X_owned + values[: 3 * self.n_owned].reshape(-1, 3))
        return np.asfortranarray(x) if self.root else None

    def bcast(self, value):
        return value if self.comm.size == 1 else self.comm.bcast(value, root=0)

    def scatter_gradient(self, grad: np.ndarray | None) -> np.ndarray:
        """Each rank's owned rows (3 n_owned) of rank 0's gradient (3 N)."""
        if self.comm.size == 1:
            return grad
        parts = None
        if self.root:
            parts = [grad[3 * a: 3 * b] for a, b in zip(self.node_starts[:-1], self.node_starts[1:])]
        return self.comm.scatter(parts, root=0)

    def set_rows(self, row_start: int) -> None:
        """The PETSc row of this rank's first owned u dof (from the Jacobian's ownership)."""
        if self.row_starts is None:
            self.row_starts = np.array(self.comm.allgather(int(row_start)))

    def petsc_index(self, dofs: np.ndarray) -> np.ndarray:
        """PETSc global indices of global u dofs 3 g + c."""
        nodes = dofs // 3
        owner = np.searchsorted(self.node_starts, nodes, side="right") - 1
        return self.row_starts[owner] + dofs - 3 * self.node_starts[owner]

    def scatter_entries(self, rows, cols, values):
        """Rank 0's entries (global u dofs) -> each owner's (PETSc rows, PETSc cols, values)."""
        if self.root:
            rows, cols = self.petsc_index(rows), self.petsc_index(cols)
        if self.comm.size == 1:
            return rows, cols, values
        parts = None
        if self.root:
            owner = np.searchsorted(self.row_starts, rows, side="right") - 1
            order = np.argsort(owner, kind="stable")
            bounds = np.searchsorted(owner[order], np.arange(self.comm.size + 1))
            parts = [(rows[order[a:b]], cols[order[a:b]], values[order[a:b]])
                     for a, b in zip(bounds[:-1], bounds[1:])]
        return self.comm.scatter(parts, root=0)


class SelfContact:
    """ipctk barrier self-contact (and lagged friction) of the vector P1/P2 field ``u`` on a
    triangle mesh, as NonlinearSolver hooks plus a line-search pre-check (see module doc).

    ``dhat`` (mm) is the barrier's reach, ``stiffness`` κ (N/mm³: b is in mm⁴), ``friction``
    μ, ``slip`` the friction's regularisation (mm per step), ``excluded_dofs`` local dof
    indices whose residual rows must stay DOLFINx's (Dirichlet rows).

    On N ranks every public method is collective; ipctk runs on rank 0, where ``X``,
    ``faces``, ``n_nodes``, ``energy``/``gradient``/``hessian`` refer to the whole lens in
    DOLFINx's global node numbering (on other ranks ``X`` and ``faces`` are None)."""

    def __init__(self, u: dolfinx.fem.Function, dhat: float, stiffness: float, *,
                 friction: float = 0.0, slip: float = 1e-3, exclusion: float | None = None,
                 excluded_dofs: np.ndarray | None = None):
        V = u.function_space
        self.lens = lens = _Lens(V)
        self.u = u
        self.dhat, self.stiffness = float(dhat), float(stiffness)
        self.friction, self.slip = float(friction), float(slip)
        degree = V.ufl_element().basix_element.degree
        self._X_owned = V.tabulate_dof_coordinates()[: lens.n_owned]
        owned_cells = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
        cell_nodes = V.dofmap.list[:owned_cells]
        cell_nodes = lens.local_to_global(cell_nodes.ravel()).reshape(cell_nodes.shape)
        faces = lens.gather_rows(collision_faces(cell_nodes, degree))
        X = lens.gather_rows(self._X_owned)
        # Dirichlet rows (owned or ghost here) as global dofs, on rank 0
        excluded = np.zeros(0, np.int64) if excluded_dofs is None else np.asarray(excluded_dofs, np.int64)
        excluded = 3 * lens.local_to_global((excluded // 3).astype(np.int32)).astype(np.int64) + excluded % 3
        excluded = lens.comm.gather(excluded, root=0) if lens.comm.size > 1 else [excluded]
        self.keep_owned = np.ones(3 * lens.n_owned, bool)
        if excluded_dofs is not None:
            local = np.asarray(excluded_dofs)
            self.keep_owned[local[local < 3 * lens.n_owned]] = False
        self.seconds = 0.0
        self.step_limits: list[float] = []  # CCD fractions < 1 applied to Newton updates
        self.X = self.faces = None
        self.n_nodes = lens.bcast(len(X) if lens.root else None)
        problem = None
        if lens.root:
            try:
                self._build(X, faces, np.concatenate(excluded), exclusion)
            except SelfContactError as err:
                problem = str(err)
        self._raise_everywhere(problem)
        self.exclusion = lens.bcast(getattr(self, "exclusion", None))
        self.excluded_pairs = lens.bcast(getattr(self, "excluded_pairs", None))

    def _raise_everywhere(self, problem: str | None) -> None:
        problem = self.lens.bcast(problem)
        if problem is not None:
            raise SelfContactError(problem)

    def _build(self, X: np.ndarray, faces: np.ndarray, excluded: np.ndarray,
               exclusion: float | None) -> None:
        """Rank 0: the whole lens' ipctk collision mesh, exclusions, barrier and CCD."""
        import ipctk

        self._ipctk = ipctk
        self.X = np.asfortranarray(X)
        self.faces = np.asfortranarray(faces.astype(np.int32))
        self.edges = np.asfortranarray(ipctk.edges(self.faces))
        self.mesh = ipctk.CollisionMesh(self.X, self.edges, self.faces)
        lengths = np.linalg.norm(self.X[self.edges[:, 0]] - self.X[self.edges[:, 1]], axis=1)
        self.longest_edge = float(lengths.max())
        self.exclusion = float(exclusion) if exclusion is not None else self.dhat + 2 * self.longest_edge
        pairs = self._near_along_the_surface(self.exclusion)
        self.excluded_pairs = len(pairs)
        self.mesh.can_collide = ipctk.SparseCanCollide(
            {(int(i), int(j)): False for i, j in pairs}, True)
        self.barrier = ipctk.BarrierPotential(self.dhat)
        # additive CCD (Li et al. 2021): advances by certified lower bounds of the distance
        # and stops at 10 % of the initial gap (rescaling 0.9) — conservative by construction,
        # and milliseconds here where Tight-Inclusion at its default tolerance took minutes
        # on the nearly coplanar pairs of a folded sheet
        self._ccd = ipctk.AdditiveCCD(conservative_rescaling=0.9)
        self.friction_potential = ipctk.FrictionPotential(self.slip) if self.friction > 0 else None
        self.keep = np.ones(3 * self.n_nodes, bool)
        self.keep[excluded] = False
        self._tangential = None
        self._cache = None
        self._x_start = self.X.copy()
        self._check_root(self.X, "the reference (flat) lens")

    def _near_along_the_surface(self, radius: float) -> np.ndarray:
        """Vertex pairs (i < j) joined by a path of collision edges shorter than ``radius``:
        neighbours on the sheet, not parts that merely lie close (a second sheet, a haptic
        running next to the optic's rim)."""
        import scipy.sparse
        from scipy.sparse.csgraph import dijkstra

        i, j = self.edges[:, 0], self.edges[:, 1]
        lengths = np.linalg.norm(self.X[i] - self.X[j], axis=1)
        graph = scipy.sparse.coo_matrix((lengths, (i, j)), shape=(self.n_nodes,) * 2).tocsr()
        distance = dijkstra(graph, directed=False, limit=radius)
        near = np.argwhere(np.isfinite(distance))
        return near[near[:, 0] < near[:, 1]]

    # -- state ------------------------------------------------------------------------------
    def positions(self, values: np.ndarray | None = None) -> np.ndarray | None:
        """Positions of all nodes on rank 0 (None elsewhere; collective): X + ``values`` (this
        rank's local dof array, owned first; default u's)."""
        values = self.u.x.array if values is None else values
        return self.lens.gather_positions(self._X_owned, values)

    def _collisions(self, x: np.ndarray, reach: float | None = None):
        """The pairs closer than ``reach`` (d̂): the barrier's at the last x are kept, since
        SNES asks for the residual and then the Jacobian at the same iterate (a build is
        ≈ 0.07 s on the lens, mostly the exclusion look-ups)."""
        reach = self.dhat if reach is None else reach
        if reach == self.dhat and self._cache is not None and np.array_equal(self._cache[0], x):
            return self._cache[1]
        collisions = self._ipctk.NormalCollisions()
        collisions.build(self.mesh, x, reach, broad_phase=self._ipctk.BVH())
        if reach == self.dhat:
            self._cache = (x.copy(), collisions)
        return collisions

    def check(self, x: np.ndarray | None = None, what: str = "the lens") -> None:
        """Raise :class:`SelfContactError` (on every rank) when ``x`` (rank 0's positions;
        default the current state) intersects itself."""
        x = self.positions() if x is None else x
        problem = None
        if self.lens.root:
            try:
                self._check_root(x, what)
            except SelfContactError as err:
                problem = str(err)
        self._raise_everywhere(problem)

    def _check_root(self, x: np.ndarray, what: str) -> None:
        """Rank 0: intersecting, or (the reference) non-excluded pairs closer than d̂ (the
        barrier would be infinite or active before anything moved)."""
        if self._ipctk.has_intersections(self.mesh, x, broad_phase=self._ipctk.BVH()):
            raise SelfContactError(f"{what} intersects itself: the barrier cannot start from it")
        if what.startswith("the reference") and len(self._collisions(x)):
            raise SelfContactError(f"{what} has non-excluded pairs closer than d̂ = {self.dhat} mm: "
                                   f"raise the exclusion ({self.exclusion:.3g} mm)")

    def min_distance(self, reach: float = 0.25) -> float:
        """Smallest distance (mm) between non-excluded primitives within ``reach``
        (``inf`` when none is that close); the same on every rank."""
        x = self.positions()
        distance = None
        if self.lens.root:
            collisions = self._collisions(x, max(reach, self.dhat))
            distance = float(np.sqrt(collisions.compute_minimum_distance(self.mesh, x))) \
                if len(collisions) else float("inf")
        return self.lens.bcast(distance)

    def intersecting(self) -> bool:
        x = self.positions()
        crossing = bool(self._ipctk.has_intersections(self.mesh, x, broad_phase=self._ipctk.BVH())) \
            if self.lens.root else None
        return self.lens.bcast(crossing)

    def begin_step(self, x: np.ndarray | None = None) -> None:
        """Lag the friction's normal forces and tangent bases at the current (converged)
        state (or rank 0's ``x``); call before every attempt of a time step (u is then u_n)."""
        x = self.positions() if x is None else x
        if not self.lens.root:
            return
        self._x_start = np.asfortranarray(x)
        if self.friction_potential is None:
            return
        normal = self._collisions(self._x_start)
        tangential = self._ipctk.TangentialCollisions()
        tangential.build(self.mesh, self._x_start, normal, self.barrier, self.stiffness, self.friction)
        self._tangential = tangential

    # -- energy and hooks -------------------------------------------------------------------
    def energy(self, x: np.ndarray) -> float:
        value = self.stiffness * self.barrier(self._collisions(x), self.mesh, x)
        if self._tangential is not None and len(self._tangential):
            value += self.friction_potential(self._tangential, self.mesh, x - self._x_start)
        return float(value)

    def gradient(self, x: np.ndarray) -> np.ndarray:
        grad = self.stiffness * self.barrier.gradient(self._collisions(x), self.mesh, x)
        if self._tangential is not None and len(self._tangential):
            grad = grad + self.friction_potential.gradient(self._tangential, self.mesh, x - self._x_start)
        return grad

    def hessian(self, x: np.ndarray):
        methods = self._ipctk.PSDProjectionMethod
        psd = getattr(methods, HESSIAN_PROJECTION or "NONE")
        hess = self.stiffness * self.barrier.hessian(self._collisions(x), self.mesh, x, psd)
        if self._tangential is not None and len(self._tangential):
            psd = getattr(methods, FRICTION_HESSIAN_PROJECTION or "NONE")
            hess = hess + self.friction_potential.hessian(self._tangential, self.mesh,
                                                          x - self._x_start, psd)
        return hess

    def _x_of(self, vec: PETSc.Vec) -> np.ndarray | None:
        """Rank 0: all positions at the SNES iterate ``vec`` (u its first block)."""
        return self.lens.gather_positions(self._X_owned, vec.array_r)

    def residual_hook(self, x_vec: PETSc.Vec, F: PETSc.Vec) -> None:
        start = time.perf_counter()
        x = self._x_of(x_vec)
        grad = None
        if self.lens.root:
            grad = self.gradient(x)
            grad[~self.keep] = 0.0
        owned = self.lens.scatter_gradient(grad)
        array = F.getArray()  # the owned entries (u's first)
        array[: owned.size] += np.where(self.keep_owned, owned, 0.0)
        self.seconds += time.perf_counter() - start

    def jacobian_hook(self, x_vec: PETSc.Vec, J: PETSc.Mat) -> None:
        start = time.perf_counter()
        self.lens.set_rows(J.getOwnershipRange()[0])
        x = self._x_of(x_vec)
        entries = None
        if self.lens.root:
            hess = self.hessian(x).tocoo()
            mask = (hess.data != 0.0) & self.keep[hess.row] & self.keep[hess.col]
            entries = (hess.row[mask].astype(np.int64), hess.col[mask].astype(np.int64), hess.data[mask])
        count = self.lens.bcast(None if entries is None else len(entries[2]))
        if count:  # collective: J.assemble() on every rank
            import scipy.sparse

            rows, cols, values = self.lens.scatter_entries(*(entries or (None,) * 3))
            # distant nodes (a haptic on the optic) are not coupled in the FE pattern
            J.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
            if len(values):
                first = int(rows.min())
                csr = scipy.sparse.csr_matrix((values, (rows - first, cols)),
                                              shape=(int(rows.max()) - first + 1, J.getSize()[1]))
                for row in np.flatnonzero(np.diff(csr.indptr)):
                    span = slice(csr.indptr[row], csr.indptr[row + 1])
                    J.setValues(first + int(row), csr.indices[span].astype(PETSc.IntType),
                                csr.data[span], addv=PETSc.InsertMode.ADD_VALUES)
            J.assemble()
        self.seconds += time.perf_counter() - start

    def limit_step(self, x_vec: PETSc.Vec, y_vec: PETSc.Vec) -> None:
        """SNES line-search pre-check: the update is x − λ y; scale y so that the straight
        path from x to x − y is collision free (ipctk CCD). The fraction is rank 0's (the
        whole lens), and the minimum over the ranks, so every rank scales alike."""
        start = time.perf_counter()
        x0 = self._x_of(x_vec)
        n = 3 * self.lens.n_owned
        x1 = self.lens.gather_positions(self._X_owned, x_vec.array_r[:n] - y_vec.array_r[:n])
        fraction = 1.0
        if self.lens.root:
            fraction = float(self._ipctk.compute_collision_free_stepsize(
                self.mesh, x0, x1, broad_phase=self._ipctk.BVH(), narrow_phase_ccd=self._ccd))
        if self.lens.comm.size > 1:
            from mpi4py import MPI

            fraction = self.lens.comm.allreduce(fraction, op=MPI.MIN)
        if fraction < 1.0:
            y_vec.scale(fraction)
            self.step_limits.append(fraction)
        self.seconds += time.perf_counter() - start

    def attach(self, solver) -> None:
        """Add the hooks and the pre-check to a :class:`NonlinearSolver`."""
        solver.residual_hooks.append(self.residual_hook)
        solver.jacobian_hooks.append(self.jacobian_hook)
        solver.snes.setLineSearchPreCheck(self.limit_step)
