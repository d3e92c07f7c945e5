"""Deformable-on-deformable penalty contact: slave nodes against master triangles
(seed 002, §2.3), added to the assembled residual and Jacobian through the
driver's hooks and refreshed at every Newton iteration.

Formulation (single pass, node to surface). Slave node s with lumped area w_s,
master triangle with nodes x1, x2, x3 and outward unit normal n; N_j(ξ) are the
barycentric weights of the closest point of the triangle to the deformed slave
position x_s:

    g = (x_s − x_1)·n,      Π_c = w_s ψ(g),  ψ' = −p(g)      (paper eq. 9–10)
    δΠ_c = −w_s p(g) D·δu_c,   D = [n; −N1 n; −N2 n; −N3 n]   (eq. 11–12)
    K_c = −w_s p'(g) D Dᵀ      (frozen normal and frozen ξ, eq. 13)

with p(g) = α⟨−g⟩ (Π_c = ½ α w_s ⟨−g⟩², the paper's) or its C¹ round-off
(:func:`penalty_pressure`). The gap is the distance to the triangle's plane,
whose gradient in x_s is exactly n; K_c omits the terms from the rotation of n
and the motion of ξ, of relative size g/h — small because the penalty
penetration is small — so Newton converges nearly quadratically once the
active set has settled.

Search: a global step (a k-d tree on the master triangles' centroids gives the
nearest few candidates) and a local step (the exact closest point on each
candidate triangle, vectorised); the candidate nearest in distance wins, except
that a node keeps its previous triangle while it still projects inside it (up to
a small tolerance) — otherwise nodes over an edge swap triangles every iterate.

Parallel: each rank treats the slave nodes it owns. The master surface (its
triangles as global node numbers, its current node positions) is gathered on all
ranks at every evaluation: simple and cheap for the surfaces of these scenes
(hundreds to a few thousand triangles), not meant for millions. Forces and
stiffness go into the global PETSc vector and matrix by global indices, so the
slave and the master may live on different ranks.

Master triangles: a P1 facet is one triangle; a P2 facet (6 nodes) is split into
4 flat triangles through its edge nodes, as the paper splits hexahedral faces.
Slave weights: the row of the slave surface's mass matrix lumped by HRZ
(diagonal scaled to the surface area), which is positive for P2 vertices too.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import basix
import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

from eyemech.forms.contact import augmented_gap, smoothed_penalty_pressure
from eyemech.meshes.tagged import MeshError, TaggedMesh
from eyemech.problems.run.parameters import ParameterError
from eyemech.problems.run.results import Timings
from eyemech.problems.solid.spaces import PetscNodeLayout
from eyemech.problems.solve.augmentation import relative_change
from eyemech.problems.solve.scalars import assemble_scalar


@dataclasses.dataclass
class ContactState:
    """The pairs found at one evaluation (slave arrays are rank-local)."""

    active: np.ndarray          # indices into the rank's slave nodes
    gaps: np.ndarray            # g of the active pairs (< 0)
    normals: np.ndarray         # (n, 3)
    triangles: np.ndarray       # master triangle index of each active pair
    shape: np.ndarray           # (n, 3) N_j(ξ) at the closest point
    min_gap: float              # smallest gap of any slave node with a partner (rank-local)
    shifts: np.ndarray | None = None  # λ/α of the active pairs (augmented Lagrangian)

    @property
    def law_gaps(self) -> np.ndarray:
        """The gaps the pressure law sees: g − λ/α (:func:`~eyemech.forms.contact.augmented_gap`;
        g itself with no multipliers, the penalty)."""
        return self.gaps if self.shifts is None else self.gaps - self.shifts


class NodeToSurfaceContact:
    """Penalty contact of the ``slave`` facets' nodes against the ``master`` facets.

    ``u`` is the displacement (vector Lagrange P1 or P2), ``penalty`` α in force
    per area per length (MPa/mm), ``bcs`` the Dirichlet conditions (their rows and
    columns are left alone), ``search_depth`` the deepest penetration still
    counted as contact (deeper pairs are taken to be on the wrong side),
    ``candidates`` the triangles tested per slave node, ``smoothing`` ε the width
    over which the penalty pressure is rounded off (:func:`penalty_pressure`; 0 =
    the plain ⟨−g⟩ law), ``block_spaces`` the spaces of a blocked system
    (``kind="mpi"``, displacement first) when ``u`` is one block of it.

    ``pattern_reach`` > 0 preallocates the contact's matrix pattern
    (:meth:`allow_new_nonzeros`, :meth:`grow_pattern`): a slave node is coupled in advance to
    the master triangles whose reference centroids lie within its nearest one's distance
    plus ``pattern_reach``; 0 lets PETSc grow the matrix as pairs form.

    ``method``: "node-to-surface" (this class, the default) or "segment-to-segment",
    which makes a :class:`~eyemech.problems.contact.segment_to_segment.SegmentToSegmentContact`
    (the pressure integrated over the slave surface segmented by the master
    triangles; passes the patch test, docs/contact.md §4).
    """

    METHODS = ("node-to-surface", "segment-to-segment")

    def __new__(cls, *args, method: str = "node-to-surface", **kwargs):
        if method not in cls.METHODS:
            raise ValueError(f"contact method must be one of {', '.join(cls.METHODS)}, got {method!r}")
        if cls is NodeToSurfaceContact and method == "segment-to-segment":
            from eyemech.problems.contact.segment_to_segment import SegmentToSegmentContact

            return super().__new__(SegmentToSegmentContact)
        return super().__new__(cls)

    def __init__(self, u: dolfinx.fem.Function, tagged: TaggedMesh, slave: str, master: str,
                 penalty: float, bcs=(), search_depth: float = np.inf, candidates: int = 8,
                 smoothing: float = 0.0, timings: Timings | None = None,
                 block_spaces=None, method: str = "node-to-surface", pattern_reach: float = 0.0):
        if not penalty > 0:
            raise ValueError(f"the penalty must be > 0, got {penalty}")
        if not smoothing >= 0:
            raise ValueError(f"the smoothing width must be >= 0, got {smoothing}")
        self.smoothing = float(smoothing)
        tagged.require_nonempty(slave, master)
        self.u, self.penalty, self.search_depth = u, float(penalty), float(search_depth)
        self.candidates = candidates
        if not pattern_reach >= 0:
            raise ValueError(f"the pattern reach must be >= 0, got {pattern_reach}")
        self.pattern_reach = float(pattern_reach)
        self._pattern_keys = np.zeros(0, dtype=np.int64)  # (slave, master) node pairs inserted
        self.timings = timings or Timings()
        self.comm = tagged.mesh.comm
        space = u.function_space
        self.bs = space.dofmap.index_map_bs
        if self.bs != 3 or space.ufl_element().embedded_superdegree not in (1, 2):
            raise ValueError("node-to-surface contact needs a 3D vector P1 or P2 displacement")
        self.imap = space.dofmap.index_map
        self.layout = PetscNodeLayout(space, block_spaces)
        self.reference = space.tabulate_dof_coordinates()
        self._slave_setup(tagged, slave)
        self._master_setup(tagged, master)
        self._drop_slaves_on_master()
        self._constrained = set(self.layout.constrained_dofs(bcs).tolist())
        self.state: ContactState | None = None
        # augmented Lagrangian: a contact pressure λ per owned slave node, held fixed during a
        # Newton solve and updated by :meth:`trial_multipliers` / :meth:`commit_multipliers`
        # after it (all zero: the penalty)
        self.multipliers = np.zeros(len(self.slave_blocks))
        self._next_multipliers = self.multipliers

    # -- set-up ---------------------------------------------------------------------------
    def _slave_setup(self, tagged: TaggedMesh, slave: str) -> None:
        """Owned slave nodes and their HRZ-lumped areas."""
        scalar, to_parent = self.u.function_space.sub(0).collapse()
        p, q = ufl.TrialFunction(scalar), ufl.TestFunction(scalar)
        ds = tagged.ds()(tagged.tag(slave))
        mass = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(p * q * ds))
        mass.assemble()
        diagonal = mass.getDiagonal().array.copy()
        mass.destroy()
        one = dolfinx.fem.Constant(tagged.mesh, 1.0)
        area = assemble_scalar(one * ds, self.comm)
        total = self.comm.allreduce(float(diagonal.sum()))
        weights = diagonal * (area / total)
        owned = np.flatnonzero(weights > 0)
        to_parent = np.asarray(to_parent[0] if isinstance(to_parent, list) else to_parent)
        self.slave_blocks = to_parent[owned] // self.bs
        self.slave_weights = weights[owned]
        self.slave_global = self.imap.local_to_global(self.slave_blocks.astype(np.int32))
        self.slave_area = area

    def _master_setup(self, tagged: TaggedMesh, master: str) -> None:
        """Master triangles (global node numbers, outward orientation) on every rank."""
        mesh = tagged.mesh
        tdim = mesh.topology.dim
        mesh.topology.create_connectivity(tdim - 1, tdim)
        mesh.topology.create_connectivity(tdim, tdim - 1)
        f_to_c = mesh.topology.connectivity(tdim - 1, tdim)
        c_to_f = mesh.topology.connectivity(tdim, tdim - 1)
        facets = tagged.facets(master)
        facets = facets[facets < mesh.topology.index_map(tdim - 1).size_local]
        dofmap = self.u.function_space.dofmap
        layout = dofmap.dof_layout
        cell_type = mesh.basix_cell()
        quadratic = self.u.function_space.ufl_element().embedded_superdegree == 2
        triangles = []
        for facet in facets:
            cell = f_to_c.links(facet)[0]
            local = int(np.flatnonzero(c_to_f.links(cell) == facet)[0])
            cell_dofs = dofmap.cell_dofs(cell)
            pieces = facet_triangles(cell_type, local, cell_dofs, layout, quadratic)
            centroid = self.reference[cell_dofs].mean(axis=0)
            for tri in pieces:
                x = self.reference[list(tri)]
                normal = np.cross(x[1] - x[0], x[2] - x[0])
                if np.dot(normal, x.mean(axis=0) - centroid) < 0:
                    tri = (tri[0], tri[2], tri[1])
                triangles.append(tri)
        local_tris = np.asarray(triangles, dtype=np.int32).reshape(-1, 3)
        global_tris = self.imap.local_to_global(local_tris.ravel()).reshape(-1, 3)
        self.triangles = np.vstack(self.comm.allgather(global_tris))
        # the nodes this rank reports positions for (all local ones its triangles use)
        self.master_local = np.unique(local_tris.ravel())
        self.master_nodes = np.unique(self.triangles.ravel())  # sorted global node numbers
        self.triangle_nodes = np.searchsorted(self.master_nodes, self.triangles)
        if len(self.triangles) == 0:
            raise MeshError(f"the master region '{master}' has no facets")
        self.triangle_rank = _geometric_rank(self._reference_master()[self.triangle_nodes])

    def allow_new_nonzeros(self, matrix: PETSc.Mat) -> None:
        """Contact couples dofs the finite-element pattern does not. With a
        ``pattern_reach`` > 0 the couplings of each slave node with the nodes of the
        master triangles whose reference centroids lie within (the distance to the
        nearest centroid + ``pattern_reach``) of the node's reference position are
        inserted here, once, as zeros: the pairs the node can form without sliding
        further than that along the master surface. PETSc grows the matrix for any other
        pair (:meth:`grow_pattern` at a solve's start, or the Jacobian hook). Collective."""
        matrix.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        matrix.setOption(PETSc.Mat.Option.NO_OFF_PROC_ENTRIES, False)
        slaves = np.zeros(0, dtype=np.int64)
        masters = np.zeros((0, self._triangle_coupled_nodes(np.zeros(0, dtype=int)).shape[1]), np.int64)
        if self.pattern_reach > 0:
            reference = self._reference_master()[self.triangle_nodes].mean(axis=1)  # collective
        if self.pattern_reach > 0 and len(self.slave_blocks):
            tree, points = cKDTree(reference), self.reference[self.slave_blocks]
            nearest_distance, _ = tree.query(points)
            within = tree.query_ball_point(points, nearest_distance + self.pattern_reach)
            counts = np.array([len(triangles) for triangles in within])
            triangles = np.concatenate([np.asarray(t, dtype=np.int64) for t in within])
            slaves, masters = np.repeat(self.slave_global, counts), self._triangle_coupled_nodes(triangles)
        self._insert_couplings(matrix, slaves, masters)

    def grow_pattern(self, matrix: PETSc.Mat) -> None:
        """Insert, as zeros, the pairs about to form that the matrix does not have yet:
        each owned slave node within ``pattern_reach`` of its closest master triangle
        (the triangle the search pairs it with) coupled to that triangle's nodes.
        Called at the start of every solve (``NonlinearSolver.pattern_hooks``), so that
        the matrix's pattern, and MUMPS's symbolic analysis, change at the start of a
        solve rather than between its iterations. Collective."""
        slaves = np.zeros(0, dtype=np.int64)
        masters = np.zeros((0, self._triangle_coupled_nodes(np.zeros(0, dtype=int)).shape[1]), np.int64)
        if self.pattern_reach > 0:
            with self.timings("contact_search"):
                corners = self._master_positions()[self.triangle_nodes]  # collective
                positions = self._positions(self.slave_blocks)
                if len(positions):
                    k = min(self.candidates, len(corners))
                    _, nearest = cKDTree(corners.mean(axis=1)).query(positions, k=k)
                    nearest = np.asarray(nearest).reshape(len(positions), k)
                    points, _ = closest_points(positions[:, None, :], corners[nearest])
                    distance = np.linalg.norm(positions[:, None, :] - points, axis=2)
                    rows = np.arange(len(positions))
                    closest = np.argmin(distance, axis=1)
                    near = distance[rows, closest] < self.pattern_reach
                    slaves = self.slave_global[near]
                    masters = self._triangle_coupled_nodes(nearest[rows, closest][near])
        self._insert_couplings(matrix, slaves, masters)

    def _insert_couplings(self, matrix: PETSc.Mat, slaves: np.ndarray, masters: np.ndarray) -> None:
        """Zeros at (slave node, master node) and (master, slave) for ``slaves[i]`` and
        every node of ``masters[i]``, those not inserted before; then a flush (a final
        assembly would squeeze out preallocated slots not yet used). Collective."""
        slaves = np.repeat(np.asarray(slaves, dtype=np.int64), masters.shape[1])
        masters = np.asarray(masters, dtype=np.int64).ravel()
        keys = np.unique(slaves * np.int64(self.imap.size_global) + masters)
        keys = keys[~np.isin(keys, self._pattern_keys, assume_unique=True)]
        self._pattern_keys = np.union1d(self._pattern_keys, keys)
        slaves, masters = np.divmod(keys, np.int64(self.imap.size_global))
        with self.timings("contact_jacobian"):
            nodes, starts = np.unique(slaves, return_index=True)
            for slave, group in zip(nodes, np.split(masters, starts[1:])):
                rows, cols = self._free_dofs(np.array([slave])), self._free_dofs(group)
                if len(rows) and len(cols):
                    matrix.setValues(rows, cols, np.zeros((len(rows), len(cols))),
                                     addv=PETSc.InsertMode.ADD)
                    matrix.setValues(cols, rows, np.zeros((len(cols), len(rows))),
                                     addv=PETSc.InsertMode.ADD)
            matrix.assemblyBegin(PETSc.Mat.AssemblyType.FLUSH)
            matrix.assemblyEnd(PETSc.Mat.AssemblyType.FLUSH)

    def _triangle_coupled_nodes(self, triangles: np.ndarray) -> np.ndarray:
        """Global master nodes a pair with each of ``triangles`` couples to a slave node."""
        return self.triangles[triangles]

    def _free_dofs(self, nodes: np.ndarray) -> np.ndarray:
        """PETSc indices of the nodes' components not held by a Dirichlet condition."""
        dofs = (self.layout.base(nodes)[:, None] + np.arange(self.bs)).ravel()
        if self._constrained:
            dofs = dofs[~np.isin(dofs, list(self._constrained))]
        return dofs.astype(PETSc.IntType)

    # -- shared slave/master nodes and per-node gaps (the eye's detached retina) ----------
    def _drop_slaves_on_master(self) -> None:
        """Slave nodes that are also master nodes (where a detached layer is still
        attached to the body under it: its rim) are not contact points: their gap to
        their own triangles is zero by construction."""
        shared = np.isin(self.slave_global, self.master_nodes)
        if shared.any():
            self.slave_blocks = self.slave_blocks[~shared]
            self.slave_weights = self.slave_weights[~shared]
            self.slave_global = self.slave_global[~shared]
            self._previous = None

    def gaps_of(self, nodes: np.ndarray) -> np.ndarray:
        """Normal gaps (from the last search) of the slave nodes with global node
        numbers ``nodes``, on every rank (collective); inf where unpaired, nan where
        not a slave node (e.g. dropped as shared with the master)."""
        gaps = getattr(self, "slave_gaps", None)
        if gaps is None or len(gaps) != len(self.slave_global):
            self.search()
            gaps = self.slave_gaps
        pieces = self.comm.allgather((self.slave_global, gaps))
        known = dict(zip(np.concatenate([np.ravel(p[0]) for p in pieces]).tolist(),
                         np.concatenate([np.ravel(p[1]) for p in pieces]).tolist()))
        return np.array([known.get(int(n), np.nan) for n in nodes])

    # -- geometry -------------------------------------------------------------------------
    def _positions(self, blocks: np.ndarray) -> np.ndarray:
        values = self.u.x.array.reshape(-1, self.bs)
        return self.reference[blocks] + values[blocks]

    def _master_positions(self) -> np.ndarray:
        local_global = self.imap.local_to_global(self.master_local.astype(np.int32))
        pieces = self.comm.allgather((local_global, self._positions(self.master_local)))
        nodes = np.concatenate([p[0] for p in pieces])
        points = np.vstack([p[1] for p in pieces])
        positions = np.empty((len(self.master_nodes), 3))
        positions[np.searchsorted(self.master_nodes, nodes)] = points
        return positions

    def search(self) -> ContactState:
        """Global (k-d tree) then local (closest point) search at the current ``u``."""
        with self.timings("contact_search"):
            corners = self._master_positions()[self.triangle_nodes]  # (T, 3, 3)
            slaves = self._positions(self.slave_blocks)
            k = min(self.candidates, len(corners))
            if len(slaves) == 0:  # a rank without slave nodes (3 ranks on the coarse eye)
                self.slave_gaps = np.zeros(0)
                return ContactState(np.zeros(0, dtype=int), np.zeros(0), np.zeros((0, 3)),
                                    np.zeros(0, dtype=int), np.zeros((0, 3)), np.inf)
            nearest, best = self._nearest_triangles(slaves, corners, k)
            rows = np.arange(len(slaves))
            tri = self._sticky(slaves, corners, nearest, best, rows)
            self._previous = tri.copy()
            shape = closest_points(slaves, corners[tri])[1]
            a, normal = _planes(corners[tri])
            # the paper's gap G = (x_h − x_t1)·n to the triangle's plane: its Hessian
            # in x_s vanishes, whereas the distance to a nearest edge or vertex
            # would add a tangential stiffness α w (I − n nᵀ) that a frozen-normal
            # Jacobian misses (Newton then oscillates)
            gaps = np.einsum("ij,ij->i", slaves - a, normal)
            # a pair far below the master surface is on the wrong side: not contact
            paired = gaps > -self.search_depth
            shifts = self.multipliers / self.penalty  # λ/α of the augmented Lagrangian
            active = np.flatnonzero(paired & (gaps - shifts < self.smoothing))
            min_gap = float(np.min(gaps[paired], initial=np.inf))
            self.slave_gaps = np.where(paired, gaps, np.inf)  # every owned slave node's gap
            return ContactState(active, gaps[active], normal[active], tri[active],
                                shape[active], min_gap, shifts[active])

    TIE = 1e-9  # distances this close (relative) are one distance: a tie, not a choice

    def _nearest_triangles(self, slaves: np.ndarray, corners: np.ndarray,
                           k: int) -> tuple[np.ndarray, np.ndarray]:
        """Each slave node's ``k`` candidate triangles (k-d tree on the centroids), (n, k),
        and the column of the closest one, ties broken by :meth:`_nearest_of_ties`."""
        _, nearest = cKDTree(corners.mean(axis=1)).query(slaves, k=k)
        nearest = nearest.reshape(len(slaves), k)
        points, _ = closest_points(slaves[:, None, :], corners[nearest])
        distance = np.linalg.norm(slaves[:, None, :] - points, axis=2)
        return nearest, self._nearest_of_ties(distance, nearest)

    def _nearest_of_ties(self, distance: np.ndarray, nearest: np.ndarray) -> np.ndarray:
        """Each slave node's closest candidate, ties broken by the triangles' geometric rank.

        A node over the shared edge of two triangles (the diagonal of a split quadrilateral)
        is as far from both, to round-off; a plain argmin then picks by the last bits, which
        differ with the partition, and the two planes give different gaps (1.6 % of the
        retina-choroid gap on the coarse eye, 1 vs 2 ranks). Among distances equal to
        ``TIE``, the triangle of lowest rank wins on any partition."""
        closest = distance.min(axis=1, keepdims=True)
        tied = distance <= closest * (1.0 + self.TIE) + np.finfo(float).tiny
        rank = np.where(tied, self.triangle_rank[nearest], np.iinfo(np.int64).max)
        return np.argmin(rank, axis=1)

    def _sticky(self, slaves, corners, nearest, best, rows):
        """Keep the previous triangle while the node's projection on its plane stays
        inside it up to a barycentric tolerance ``STICKY``.

        Slave nodes sitting over a master edge would otherwise alternate between
        the two triangles from one Newton iterate to the next (the plane gap jumps
        by the offset times the angle between them) and Newton cycles. The price is
        a gap measured on the previous plane up to STICKY·h beyond its edge.
        """
        previous = getattr(self, "_previous", None)
        if previous is None or len(previous) != len(rows):
            return nearest[rows, best]
        bary = plane_barycentric(slaves, corners[previous])
        keep = bary.min(axis=1) >= -self.STICKY
        return np.where(keep, previous, nearest[rows, best])

    STICKY = 0.02

    # -- assembly hooks -------------------------------------------------------------------
    def _pair_dofs(self, state: ContactState) -> np.ndarray:
        """(n, 12) global dof indices: slave node then the three master nodes."""
        nodes = np.column_stack([self.slave_global[state.active], self.triangles[state.triangles]])
        base = self.layout.base(nodes.ravel()).reshape(nodes.shape)
        return (base[:, :, None] + np.arange(self.bs)).reshape(len(nodes), 4 * self.bs)

    def _pair_vectors(self, state: ContactState) -> np.ndarray:
        """(n, 12) D = [n, −N1 n, −N2 n, −N3 n]."""
        factors = np.column_stack([np.ones(len(state.gaps)), -state.shape])  # (n, 4)
        return (factors[:, :, None] * state.normals[:, None, :]).reshape(len(factors), 4 * self.bs)

    def residual_hook(self, _x: PETSc.Vec, b: PETSc.Vec) -> None:
        """F += −w p(g) D for the active pairs (u already holds the iterate)."""
        self.state = state = self.search()
        pressure, _ = penalty_pressure(state.law_gaps, self.penalty, self.smoothing)
        self._add_force(state, b, pressure)

    def jacobian_hook(self, _x: PETSc.Vec, A: PETSc.Mat) -> None:
        """K += −w p'(g) D Dᵀ (frozen normal) for the active pairs."""
        state = self.search()
        _, slope = penalty_pressure(state.law_gaps, self.penalty, self.smoothing)
        self._add_stiffness(state, A, slope)

    # -- the active set predicted by Newton's direction ------------------------------------
    def predict_active_set(self, solver, below: float, rounds: int = 3) -> None:
        """Install, as ``solver``'s line-search pre-check, the active set predicted by its
        Newton direction (a primal–dual active-set step), at iterates whose residual norm is
        at most ``below``: a pair open at the iterate x that the full step x − y would carry
        through its master triangle gets the penalty's stiffness in the Jacobian, and the
        direction is solved again (at most ``rounds`` times; each a factorisation, counted by
        PETSc's events). A pair that the unforced direction moves away is left open, so a
        pair held at the surface by a forced step is released at the next iterate.

        Why: the Jacobian of an open pair is zero. A retina node a hair above the choroid
        (g ≈ 1e-8 mm) on a soft detached flap, pulled towards it by 1e-9–1e-6 N, gets a
        direction that carries it micrometres through the choroid, where its penalty force is
        10⁴ times the residual; backtracking then creeps at λ ≈ 1e-7, the residual flat to 7
        digits (docs/scleral_buckling.md, "Where the settling's Newton stops at a flat
        residual"). The residual is untouched: the solution is the same, the direction and
        the Newton correction of :meth:`NonlinearSolver._accept_flat_residual` are the
        semismooth Newton's. Off above ``below``: while contact switches far from
        convergence, the prediction was measured to make the suturing steps creep."""
        self._solver, self._prediction_rounds = solver, rounds
        self._prediction_below = float(below)
        self.predicted_pairs = 0  # pairs made active by a prediction, all solves (this rank)
        solver.line_search_precheck = self._predict

    def _predict(self, x_vec: PETSc.Vec, y_vec: PETSc.Vec) -> None:
        """SNES line-search pre-check (the update is x − λ y). Collective."""
        solver = self._solver
        snes = solver.snes
        residual, matrix, ksp = snes.getFunction()[0], snes.getJacobian()[0], snes.getKSP()
        norm = residual.norm()
        if norm > self._prediction_below:
            return
        open_at_x = np.ones(len(self.slave_blocks), dtype=bool)
        if self.state is not None:
            open_at_x[self.state.active] = False
        memory = (None if getattr(self, "_previous", None) is None else self._previous.copy(),
                  getattr(self, "slave_gaps", None), self.state)
        gaps_at_x = memory[1]
        trial, rhs = x_vec.duplicate(), residual.copy()
        try:
            for _ in range(self._prediction_rounds):
                trial.waxpy(-1.0, y_vec, x_vec)
                _set_unknowns(solver, trial)
                predicted = self.search()
                self._previous = None if memory[0] is None else memory[0].copy()
                new = predicted.active[(predicted.gaps < 0) & open_at_x[predicted.active]]
                if self.comm.allreduce(len(new), op=MPI.SUM) == 0:
                    break
                open_at_x[new] = False
                self.predicted_pairs += len(new)
                keep = np.isin(predicted.active, new)
                pairs = ContactState(predicted.active[keep], predicted.gaps[keep],
                                     predicted.normals[keep], predicted.triangles[keep],
                                     predicted.shape[keep], 0.0)
                self._add_stiffness(pairs, matrix, slope=-self.penalty)
                # the pressure's branch in contact continued to the gap at x (> 0 there, so a
                # pull): the direction then takes the node to the penetration its force needs
                # (unpaired at x, or no gaps known: no continuation)
                at_x = np.zeros(len(new)) if gaps_at_x is None else gaps_at_x[pairs.active]
                self._add_force(pairs, rhs, -self.penalty * np.where(np.isfinite(at_x), at_x, 0.0))
                ksp.solve(rhs, y_vec)
        finally:
            _set_unknowns(solver, x_vec)
            self._previous, self.slave_gaps, self.state = memory
            trial.destroy()
            rhs.destroy()

    def _add_force(self, state: ContactState, b: PETSc.Vec, pressure: np.ndarray) -> None:
        """F += −w p D for the pairs of ``state`` with the pressures ``pressure``. Collective."""
        dofs = self._pair_dofs(state)
        values = (-self.slave_weights[state.active] * pressure)[:, None] * self._pair_vectors(state)
        keep = ~np.isin(dofs, list(self._constrained)) if self._constrained else np.ones_like(dofs, bool)
        b.setValues(dofs[keep].astype(PETSc.IntType), values[keep], addv=PETSc.InsertMode.ADD)
        b.assemblyBegin()
        b.assemblyEnd()

    def _add_stiffness(self, state: ContactState, A: PETSc.Mat, slope) -> None:
        """K += −w p'(g) D Dᵀ for the pairs of ``state``, p' = ``slope`` (per pair, or one
        number: −α in contact), then a final assembly. Collective."""
        dofs, D = self._pair_dofs(state), self._pair_vectors(state)
        stiffness = -self.slave_weights[state.active] * slope
        constrained = self._constrained
        # timed apart (inside "assembly"): includes PETSc's mallocs for new nonzeros
        with self.timings("contact_jacobian"):
            for i in range(len(dofs)):
                keep = np.array([d not in constrained for d in dofs[i]])
                index = dofs[i][keep].astype(PETSc.IntType)
                A.setValues(index, index, stiffness[i] * np.outer(D[i][keep], D[i][keep]),
                            addv=PETSc.InsertMode.ADD)
            A.assemble()

    # -- diagnostics ----------------------------------------------------------------------
    def summary(self) -> dict[str, float]:
        """Collective: active nodes, max penetration, contact area and normal force."""
        state = self.state or self.search()
        weights = self.slave_weights[state.active]
        pressure, _ = penalty_pressure(state.law_gaps, self.penalty, self.smoothing)
        touching = state.gaps < 0
        local = np.array([touching.sum(), weights[touching].sum(), (weights * pressure).sum()])
        total = self.comm.allreduce(local, op=MPI.SUM)
        depth = self.comm.allreduce(float(np.max(-state.gaps, initial=0.0)), op=MPI.MAX)
        return {"active_nodes": int(total[0]), "contact_area": float(total[1]),
                "contact_normal_force": float(total[2]), "max_penetration": depth}

    def pairs_across_ranks(self) -> int:
        """Collective: touching pairs whose master triangle has a node another rank owns
        (a parallel diagnostic: 0 on one rank; > 0 shows the partition cuts the contact)."""
        state = self.state or self.search()
        first, last = self.imap.local_range
        nodes = self.triangles[state.triangles[state.gaps < 0]]
        remote = ((nodes < first) | (nodes >= last)).any(axis=1)
        return int(self.comm.allreduce(int(remote.sum()), op=MPI.SUM))

    def nodal_pressures(self) -> tuple[np.ndarray, np.ndarray]:
        """(reference positions (n, 3), contact pressure p(g)) of this rank's slave nodes
        that touch (g < 0)."""
        state = self.state or self.search()
        pressure, _ = penalty_pressure(state.law_gaps, self.penalty, self.smoothing)
        touching = state.gaps < 0
        nodes = self.slave_blocks[state.active[touching]]
        return self.reference[nodes], pressure[touching]

    # -- augmented Lagrangian (Uzawa) ----------------------------------------------------
    def trial_multipliers(self) -> float:
        """Uzawa's next multipliers at the current ``u`` (a converged solve's), λ ← p(g − λ/α)
        per owned slave node (0 for a node without a partner), kept aside until
        :meth:`commit_multipliers`; returns their relative change ‖λ_new − λ‖ / ‖λ_new‖
        over all ranks (collective; 0 when both are zero)."""
        self.search()  # the gaps at this u (the sticky triangles as the last residual's)
        self._next_multipliers, _ = penalty_pressure(
            augmented_gap(self.slave_gaps, self.multipliers, self.penalty), self.penalty,
            self.smoothing)
        return relative_change(self._next_multipliers, self.multipliers, self.comm)

    def commit_multipliers(self) -> None:
        self.multipliers = np.array(self._next_multipliers, dtype=float)

    def multiplier_memory(self) -> np.ndarray:
        return self.multipliers.copy()

    def restore_multipliers(self, saved: np.ndarray) -> None:
        self.multipliers = np.array(saved, dtype=float)

    def multiplier_state(self) -> np.ndarray:
        """(reference position, λ) of every slave node, rows (n, 4) gathered on every rank:
        a checkpoint that does not depend on the partition."""
        local = np.hstack([self.reference[self.slave_blocks], self.multipliers[:, None]])
        return np.vstack(self.comm.allgather(local))

    def restore_multiplier_state(self, saved: np.ndarray) -> None:
        saved = np.asarray(saved, dtype=float).reshape(-1, 4)
        if len(self.slave_blocks) == 0:
            return
        distance, row = cKDTree(saved[:, :3]).query(self.reference[self.slave_blocks])
        if distance.max() > 1e-9 * (1.0 + np.abs(saved[:, :3]).max()):
            raise ValueError("contact checkpoint: slave nodes differ from this mesh's")
        self.multipliers = saved[row, 3].copy()

    # -- a failed solve's retry (NonlinearSolver.memory_hooks) ----------------------------
    def memory(self) -> np.ndarray | None:
        """This rank's sticky memory as it is (each slave node's previous triangle)."""
        previous = getattr(self, "_previous", None)
        return None if previous is None else previous.copy()

    def restore_memory(self, saved: np.ndarray | None) -> None:
        self._previous = None if saved is None else saved.copy()

    # -- checkpoints (docs/restart.md) ------------------------------------------------------
    def sticky_state(self) -> np.ndarray:
        """The sticky memory -- each slave node's previous master triangle -- as reference
        coordinates (slave node, triangle centroid), gathered on every rank: rows (n, 6)
        that do not depend on the partition, so a checkpoint restarts on other ranks."""
        previous = getattr(self, "_previous", None)
        # collective on every rank: a rank without slave nodes never searched, so its
        # memory is None, and skipping the gather there crossed it with the others'
        master = self._reference_master()
        local = np.zeros((0, 6))
        if previous is not None and len(previous) == len(self.slave_blocks):
            centroids = master[self.triangle_nodes[previous]].mean(axis=1)
            local = np.hstack([self.reference[self.slave_blocks], centroids])
        return np.vstack(self.comm.allgather(local))

    def restore_sticky_state(self, saved: np.ndarray) -> None:
        saved = np.asarray(saved, dtype=float).reshape(-1, 6)
        self._previous = None
        if len(saved) == 0:  # the same on every rank (gathered)
            return
        master = self._reference_master()  # collective: also on a rank without slave nodes
        if len(self.slave_blocks) == 0:
            return
        distance, row = cKDTree(saved[:, :3]).query(self.reference[self.slave_blocks])
        if distance.max() > 1e-9 * (1.0 + np.abs(saved[:, :3]).max()):
            raise ValueError("contact checkpoint: slave nodes differ from this mesh's")
        centroids = master[self.triangle_nodes].mean(axis=1)
        # nearest centroid: the same triangle unless the quadrilaterals were split along
        # the other diagonal (then the neighbour on the same plane)
        self._previous = cKDTree(centroids).query(saved[row, 3:])[1]

    def _reference_master(self) -> np.ndarray:
        local_global = self.imap.local_to_global(self.master_local.astype(np.int32))
        pieces = self.comm.allgather((local_global, self.reference[self.master_local]))
        positions = np.empty((len(self.master_nodes), 3))
        positions[np.searchsorted(self.master_nodes, np.concatenate([p[0] for p in pieces]))] = \
            np.vstack([p[1] for p in pieces])
        return positions

    def refuse_initial_penetration(self, key: str, tolerance: float = 0.0) -> None:
        """ParameterError naming ``key`` when slave nodes start inside the master body
        (deeper than ``tolerance`` but within the search depth)."""
        gap = self.min_gap()
        if gap < -tolerance:
            raise ParameterError(key, f"the slave surface starts {-gap:.4g} mm inside the master "
                                      "surface (the bodies interpenetrate before any load)")

    def depth_through(self) -> float:
        """Collective: the deepest slave node under the master surface (the plane of its
        nearest triangle), as a fraction of ``search_depth``; −inf without slave nodes.
        Beyond ``search_depth`` a node is unpaired (on the wrong side) and feels no
        contact: a load step that carries one through that far must be cut, not kept
        (:attr:`NonlinearSolver.converged_depth_hooks`). Leaves the search's state as it
        was (its nearest-triangle choice is :meth:`search`'s without the sticky memory)."""
        if not np.isfinite(self.search_depth):  # every pair counts: none is unpaired
            return -np.inf
        depths = self._depths()
        depth = float(np.max(depths)) / self.search_depth if len(depths) else -np.inf
        return self.comm.allreduce(depth, op=MPI.MAX)

    def _depths(self) -> np.ndarray:
        """Collective: each owned slave node's depth under the plane of its nearest master
        triangle at the current unknowns (negative above it; mm)."""
        corners = self._master_positions()[self.triangle_nodes]  # collective: on every rank
        slaves = self._positions(self.slave_blocks)
        if not len(slaves):
            return np.empty(0)
        nearest, best = self._nearest_triangles(slaves, corners, min(self.candidates, len(corners)))
        a, normal = _planes(corners[nearest[np.arange(len(slaves)), best]])
        return -np.einsum("ij,ij->i", slaves - a, normal)

    def limit_step_depth(self, solver, fraction: float,
                         acting: Callable[[], bool] | None = None) -> None:
        """Install, after ``solver``'s line-search pre-check if it has one, a limit on the
        Newton update x − y: where the full update would carry a slave node deeper than
        ``fraction`` of ``search_depth`` under its master triangle, y is shortened so that
        the deepest node, its depth interpolated linearly between x and x − y, reaches that
        depth; only while ``acting()`` says so (None: always; the same on every rank).
        Why: an open pair contributes no stiffness, so the direction of a soft slave body
        under a load (a detached retina under the pigment epithelium's pump) can carry a
        node through the master body in one full step, beyond ``search_depth``, where it is
        unpaired: Newton then converges to an equilibrium with the node on the wrong side
        (docs/scleral_buckling.md, "Full steps through the choroid"). The residual is
        untouched, and so is a direction that keeps every node within the limit."""
        self._step_depth_limit = fraction * self.search_depth
        self._limited_solver = solver
        self.limited_steps = 0  # updates shortened, all solves (the same on every rank)
        earlier = solver.line_search_precheck

        def precheck(x_vec: PETSc.Vec, y_vec: PETSc.Vec) -> None:
            if earlier is not None:
                earlier(x_vec, y_vec)
            if acting is None or acting():
                self._limit_step(x_vec, y_vec)

        solver.line_search_precheck = precheck

    def _limit_step(self, x_vec: PETSc.Vec, y_vec: PETSc.Vec) -> None:
        """SNES line-search pre-check (the update is x − λ y): y scaled by the largest
        λ ≤ 1 that keeps every slave node within the depth limit. Collective."""
        solver = self._limited_solver
        at_x = self._depths()  # the search's state is not touched
        trial = x_vec.duplicate()
        try:
            trial.waxpy(-1.0, y_vec, x_vec)
            _set_unknowns(solver, trial)
            at_trial = self._depths()
        finally:
            _set_unknowns(solver, x_vec)
            trial.destroy()
        limit = self._step_depth_limit
        # nodes the full update carries past the limit from above it (one already past
        # it at x is left to the penalty, which pushes it back)
        past = (at_trial > limit) & (at_x < limit)
        scale = np.min((limit - at_x[past]) / (at_trial[past] - at_x[past]), initial=1.0)
        scale = self.comm.allreduce(scale, op=MPI.MIN)
        if scale < 1.0:
            y_vec.scale(scale)
            self.limited_steps += 1

    def min_gap(self) -> float:
        """Smallest gap of any paired slave node (collective; negative = penetration)."""
        return self.comm.allreduce(self.search().min_gap, op=MPI.MIN)


def _set_unknowns(solver, vec: PETSc.Vec) -> None:
    """The solver's unknowns (Functions) set to the PETSc vector ``vec`` (ghosts updated):
    a line-search pre-check looks at a trial state through them and then puts x back."""
    vec.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    unknowns = solver.unknowns if len(solver.unknowns) > 1 else solver.unknowns[0]
    dolfinx.fem.petsc.assign(vec, unknowns)
    for u in solver.unknowns:
        u.x.scatter_forward()


def _geometric_rank(corners: np.ndarray) -> np.ndarray:
    """Each triangle's place (0 … T−1) in an order of its reference corners (T, 3, 3) that
    no numbering enters: corners sorted within the triangle, triangles sorted by those
    nine coordinates (exact copies of the mesh's, so every partition agrees)."""
    within = np.lexsort(corners.transpose(2, 0, 1)[::-1], axis=-1)  # corner order by x, y, z
    ordered = np.take_along_axis(corners, within[..., None], axis=1).reshape(len(corners), 9)
    order = np.lexsort(ordered.T[::-1])
    rank = np.empty(len(corners), dtype=np.int64)
    rank[order] = np.arange(len(corners))
    return rank


def penalty_pressure(gaps: np.ndarray, penalty: float, smoothing: float) -> tuple[np.ndarray, np.ndarray]:
    """Contact pressure p(g) ≥ 0 and its slope dp/dg: the smoothed penalty law of
    :func:`eyemech.forms.contact.smoothed_penalty_pressure` (ε = ``smoothing``)."""
    return smoothed_penalty_pressure(gaps, penalty, smoothing)


def _planes(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's (n, 3, 3) first corner and unit normal, (n, 3) each."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    return a, normal


def plane_barycentric(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (n, 3) of the projections of ``points`` (n, 3) on the
    planes of ``triangles`` (n, 3, 3); all ≥ 0 inside."""
    a = triangles[:, 0]
    e1, e2, w = triangles[:, 1] - a, triangles[:, 2] - a, points - a
    d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    r1, r2 = (w * e1).sum(1), (w * e2).sum(1)
    det = d11 * d22 - d12**2
    s = (d22 * r1 - d12 * r2) / det
    t = (d11 * r2 - d12 * r1) / det
    return np.column_stack([1 - s - t, s, t])


def closest_points(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest point on each triangle (…, 3, 3) to each point (…, 3), broadcast, and its
    barycentric weights (N1, N2, N3): the plane projection when it falls inside,
    else the nearest point on the three edges."""
    shape = np.broadcast_shapes(points.shape, triangles.shape[:-2] + (3,))
    triangles = np.broadcast_to(triangles, shape[:-1] + (3, 3))
    a, b, c = triangles[..., 0, :], triangles[..., 1, :], triangles[..., 2, :]
    points = np.broadcast_to(points, shape)
    e1, e2, w = b - a, c - a, points - a
    d11, d12, d22 = (np.einsum("...i,...i", e1, e1), np.einsum("...i,...i", e1, e2),
                     np.einsum("...i,...i", e2, e2))
    r1, r2 = np.einsum("...i,...i", w, e1), np.einsum("...i,...i", w, e2)
    det = d11 * d22 - d12**2
    s = (d22 * r1 - d12 * r2) / det
    t = (d11 * r2 - d12 * r1) / det
    bary = np.stack([1 - s - t, s, t], axis=-1)
    inside = (s >= 0) & (t >= 0) & (s + t <= 1)
    best = a + s[..., None] * e1 + t[..., None] * e2
    if not np.all(inside):
        candidates, weights = [], []
        for i, j in ((0, 1), (1, 2), (2, 0)):
            p, q = triangles[..., i, :], triangles[..., j, :]
            edge = q - p
            lam = np.clip(np.einsum("...i,...i", points - p, edge)
                          / np.einsum("...i,...i", edge, edge), 0.0, 1.0)
            candidates.append(p + lam[..., None] * edge)
            wts = np.zeros(lam.shape + (3,))
            wts[..., i], wts[..., j] = 1 - lam, lam
            weights.append(wts)
        candidates, weights = np.stack(candidates), np.stack(weights)
        pick = np.argmin(np.linalg.norm(candidates - points[None], axis=-1), axis=0)
        edge_best = np.take_along_axis(candidates, pick[None, ..., None], axis=0)[0]
        edge_bary = np.take_along_axis(weights, pick[None, ..., None], axis=0)[0]
        best = np.where(inside[..., None], best, edge_best)
        bary = np.where(inside[..., None], bary, edge_bary)
    return best, bary


def facet_triangles(cell_type: basix.CellType, local_facet: int, cell_dofs: np.ndarray,
                    layout, quadratic: bool) -> list[tuple[int, int, int]]:
    """The flat triangles (local dof numbers, unoriented) that describe one facet of a
    tetrahedron or a hexahedron on the master surface.

    Tetrahedron: P1 one triangle; P2 four through the edge nodes. Hexahedron (seed
    002 §2.3.1 splits quadrilateral faces into triangles): Q1 two triangles across
    the diagonal from the face's first vertex; Q2 the 3×3 face nodes make four
    sub-quadrilaterals, each split the same way (eight triangles).
    """
    topology = basix.topology(cell_type)
    face = list(topology[2][local_facet])
    vertex = {k: int(cell_dofs[layout.entity_dofs(0, k)[0]]) for k in face}
    mid = {}
    if quadratic:
        mid = {frozenset(e): int(cell_dofs[layout.entity_dofs(1, i)[0]])
               for i, e in enumerate(topology[1]) if set(e) <= set(face)}
    if cell_type == basix.CellType.tetrahedron:
        a, b, c = face
        if not quadratic:
            return [(vertex[a], vertex[b], vertex[c])]
        ab, bc, ca = mid[frozenset((a, b))], mid[frozenset((b, c))], mid[frozenset((c, a))]
        return [(vertex[a], ab, ca), (ab, vertex[b], bc), (ca, bc, vertex[c]), (ab, bc, ca)]
    if cell_type != basix.CellType.hexahedron:
        raise ValueError(f"node-to-surface contact supports tetrahedra and hexahedra, not {cell_type.name}")
    # basix numbers a quadrilateral's vertices a b / c d (tensor order): a-b-d-c is its cycle
    a, b, c, d = face
    if not quadratic:
        return _split_quad(vertex[a], vertex[b], vertex[d], vertex[c])
    ab, ac = mid[frozenset((a, b))], mid[frozenset((a, c))]
    bd, cd = mid[frozenset((b, d))], mid[frozenset((c, d))]
    centre = int(cell_dofs[layout.entity_dofs(2, local_facet)[0]])
    quads = [(vertex[a], ab, centre, ac), (ab, vertex[b], bd, centre),
             (centre, bd, vertex[d], cd), (ac, centre, cd, vertex[c])]
    return [tri for quad in quads for tri in _split_quad(*quad)]


def _split_quad(q0: int, q1: int, q2: int, q3: int) -> list[tuple[int, int, int]]:
    """Two triangles of the quadrilateral q0-q1-q2-q3 (cyclic) across q0-q2."""
    return [(q0, q1, q2), (q0, q2, q3)]
