"""Segment-to-segment penalty contact with mortar integration: the contact pressure is
integrated over the slave surface, segmented by the master triangles, instead of
being sampled at the slave nodes. It passes the contact patch test
(``contact-patch``) to solver accuracy on non-matching meshes, where node-to-surface
contact does not (docs/contact.md §4).

Formulation. Π_c = ∫_Γs φ(g) dA (reference slave area), φ the smoothed penalty
density (p = −φ', :func:`eyemech.forms.contact.smoothed_penalty_pressure`). At a
point X of the slave surface, x = Σ_i N_i(X) x_i (the displacement space's own basis
on the slave facet), its master triangle (x1, x2, x3, outward unit normal n) and the
barycentric weights M_j of x's projection on that triangle's plane:

    g = (x − x1)·n,     δΠ_c = −∫ p(g) D·δu_c dA,   D = [N_1 n … N_k n; −M1 n; −M2 n; −M3 n]
    K_c = −∫ p'(g) D Dᵀ dA     (frozen normal, frozen M and frozen segmentation)

The integral is evaluated by segmentation (mortar integration): every slave facet is
split into flat sub-triangles (``facet_triangles``: one for a P1 facet, four for P2,
two / eight for Q1 / Q2 faces); each sub-triangle is intersected with the master
triangles facing it, projected on its plane along its normal (Sutherland–Hodgman
clipping of a triangle by a convex triangle), the intersection polygons are split
into fans of triangles and those carry a Gauss rule. Inside one segment both the
slave and the master shape functions are polynomials, so the rule integrates the
consistent forces exactly when the gap is uniform: a uniform contact pressure is
transmitted as the consistent nodal loads of both surfaces, which is the patch test.
Gauss-point-to-segment integration without segmentation would integrate the master
shape functions (kinked inside a slave facet) only approximately.

Everything is redone at every residual and Jacobian evaluation on the current
positions (the segmentation too); the Jacobian freezes it (as it freezes n and M).
Exactness of the integration holds for flat P1 facets; for P2/Q1/Q2 the slave facet
is integrated over its flat sub-triangles (reference area of the flat triangles, the
exact basis of the space at the mapped points) and the master surface is the flat
triangles of :class:`NodeToSurfaceContact` with linear weights M_j (as there).

Parallel: each rank integrates over the slave facets it owns; the master surface is
gathered on every rank (:class:`NodeToSurfaceContact`), forces and stiffness go into
the PETSc vector and matrix by global indices.
"""

from __future__ import annotations

import dataclasses

import basix
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

from eyemech.meshes.tagged import MeshError, TaggedMesh
from eyemech.problems.contact.node_to_surface import (
    NodeToSurfaceContact,
    facet_triangles,
    penalty_pressure,
    plane_barycentric,
)


@dataclasses.dataclass
class SegmentState:
    """The active quadrature points of one evaluation (rank-local)."""

    facets: np.ndarray          # slave facet (row of ``facet_nodes``) of each point
    shape: np.ndarray           # (n, k) slave shape functions N_i at the point
    triangles: np.ndarray       # master triangle of each point
    master_shape: np.ndarray    # (n, k_m) M_j of the master facet's nodes
    normals: np.ndarray         # (n, 3) master outward normal
    gaps: np.ndarray            # (n,)
    weights: np.ndarray         # (n,) reference area of the point
    reference: np.ndarray       # (n, 3) reference position of the point
    segment: np.ndarray         # (n,) the point's segment (rank-local numbering)
    min_gap: float              # smallest gap of any segment point (rank-local)
    segments: int               # all segments, active or not (rank-local)


class SegmentToSegmentContact(NodeToSurfaceContact):
    """Penalty contact of the ``slave`` surface against the ``master`` facets, integrated
    over the slave surface by segmentation (mortar integration).

    Made by ``NodeToSurfaceContact(..., method="segment-to-segment")`` or directly;
    the arguments are those of :class:`NodeToSurfaceContact` plus ``quadrature_degree``
    (the Gauss rule on each segment triangle; default twice the displacement degree,
    exact for the consistent forces of a uniform pressure) and ``facing`` (a master
    triangle is a partner of a slave sub-triangle when their normals satisfy
    n_s·n_m < −facing: the two surfaces face each other). The slave nodes of the base
    class are kept for the node-wise diagnostics (``gaps_of``, ``min_gap``,
    ``refuse_initial_penetration``).
    """

    def __init__(self, u, tagged: TaggedMesh, slave: str, master: str, penalty: float, bcs=(),
                 search_depth: float = np.inf, candidates: int = 8, smoothing: float = 0.0,
                 timings=None, block_spaces=None, method: str = "segment-to-segment",
                 quadrature_degree: int | None = None, facing: float = 0.5,
                 pattern_reach: float = 0.0):
        super().__init__(u, tagged, slave, master, penalty, bcs, search_depth, candidates,
                         smoothing, timings, block_spaces, pattern_reach=pattern_reach)
        degree = u.function_space.ufl_element().embedded_superdegree
        self.quadrature_degree = int(quadrature_degree or 2 * degree)
        self.facing = float(facing)
        self.method = "segment-to-segment"
        self._segment_setup(tagged, slave, degree)
        self.segments: SegmentState | None = None

    # Segments smaller than this fraction of their slave sub-triangle are dropped: where
    # a master edge lies on a slave edge (the rims of the patch test) clipping leaves
    # slivers of round-off width whose presence depends on the partition.
    SLIVER = 1e-9

    # -- set-up ---------------------------------------------------------------------------
    def _master_setup(self, tagged: TaggedMesh, master: str) -> None:
        """The base class's master triangles, and for each the nodes of its master facet
        (the facet's closure: 3 for P1, 6 for P2, 4 / 9 for Q1 / Q2) with the cell
        reference coordinates of the triangle's corners, so that the master side uses
        the space's own basis M_i of the facet at the projected point."""
        super()._master_setup(tagged, master)
        mesh = tagged.mesh
        tdim = mesh.topology.dim
        f_to_c = mesh.topology.connectivity(tdim - 1, tdim)
        c_to_f = mesh.topology.connectivity(tdim, tdim - 1)
        facets = tagged.facets(master)
        facets = facets[facets < mesh.topology.index_map(tdim - 1).size_local]
        cell_type = mesh.basix_cell()
        degree = self.u.function_space.ufl_element().embedded_superdegree
        points = basix.create_element(basix.ElementFamily.P, cell_type, degree,
                                      basix.LagrangeVariant.gll_warped).points
        dofmap = self.u.function_space.dofmap
        layout = dofmap.dof_layout
        nodes, index, corners = [], [], []
        for facet in facets:  # the base class's loop: same triangles, same order and flips
            cell = f_to_c.links(facet)[0]
            local = int(np.flatnonzero(c_to_f.links(cell) == facet)[0])
            cell_dofs = dofmap.cell_dofs(cell)
            closure = np.asarray(layout.entity_closure_dofs(tdim - 1, local))
            where = {int(d): i for i, d in enumerate(cell_dofs)}
            centroid = self.reference[cell_dofs].mean(axis=0)
            for tri in facet_triangles(cell_type, local, cell_dofs, layout, degree == 2):
                x = self.reference[list(tri)]
                if np.dot(np.cross(x[1] - x[0], x[2] - x[0]), x.mean(axis=0) - centroid) < 0:
                    tri = (tri[0], tri[2], tri[1])
                nodes.append(cell_dofs[closure])
                index.append(closure)
                corners.append(points[[where[d] for d in tri]])
        k = len(layout.entity_closure_dofs(tdim - 1, 0))
        nodes = np.asarray(nodes, dtype=np.int32).reshape(-1, k)
        global_nodes = self.imap.local_to_global(nodes.ravel()).reshape(-1, k)
        self.master_facet_nodes = np.vstack(self.comm.allgather(global_nodes))
        self.master_facet_index = np.vstack(self.comm.allgather(
            np.asarray(index, dtype=int).reshape(-1, k)))
        self.master_corner_reference = np.vstack(self.comm.allgather(
            np.asarray(corners, dtype=float).reshape(-1, 3, tdim)))
        self.master_facet_rows = np.searchsorted(self.master_nodes, self.master_facet_nodes)
        self.master_facet_id = np.unique(self.master_facet_nodes, axis=0, return_inverse=True)[1].ravel()
        if not (self.triangles[:, :, None] == self.master_facet_nodes[:, None, :]).any(axis=2).all():
            raise AssertionError("master facets out of step with the master triangles")

    def _segment_setup(self, tagged: TaggedMesh, slave: str, degree: int) -> None:
        mesh = tagged.mesh
        tdim = mesh.topology.dim
        f_to_c = mesh.topology.connectivity(tdim - 1, tdim)
        c_to_f = mesh.topology.connectivity(tdim, tdim - 1)
        facets = tagged.facets(slave)
        facets = facets[facets < mesh.topology.index_map(tdim - 1).size_local]
        cell_type = mesh.basix_cell()
        self.basis = basix.create_element(basix.ElementFamily.P, cell_type, degree,
                                          basix.LagrangeVariant.gll_warped)
        points = self.basis.points
        dofmap = self.u.function_space.dofmap
        layout = dofmap.dof_layout
        quadratic = degree == 2
        closures, nodes, subs, sub_ref, sub_area = [], [], [], [], []
        for facet in facets:
            cell = f_to_c.links(facet)[0]
            local = int(np.flatnonzero(c_to_f.links(cell) == facet)[0])
            cell_dofs = dofmap.cell_dofs(cell)
            closure = np.asarray(layout.entity_closure_dofs(tdim - 1, local))
            where = {int(d): i for i, d in enumerate(cell_dofs)}
            centroid = self.reference[cell_dofs].mean(axis=0)
            tris, refs, areas = [], [], []
            for tri in facet_triangles(cell_type, local, cell_dofs, layout, quadratic):
                x = self.reference[list(tri)]
                normal = np.cross(x[1] - x[0], x[2] - x[0])
                if np.dot(normal, x.mean(axis=0) - centroid) < 0:  # outward of the slave body
                    tri = (tri[0], tri[2], tri[1])
                tris.append(tri)
                refs.append(points[[where[d] for d in tri]])
                areas.append(0.5 * np.linalg.norm(normal))
            closures.append(closure)
            nodes.append(cell_dofs[closure])
            subs.append(tris)
            sub_ref.append(refs)
            sub_area.append(areas)
        k = len(layout.entity_closure_dofs(tdim - 1, 0))
        m = len(facet_triangles(cell_type, 0, np.arange(len(points)), layout, quadratic))
        self.facet_closure = np.asarray(closures, dtype=int).reshape(-1, k)
        self.facet_nodes = np.asarray(nodes, dtype=np.int32).reshape(-1, k)        # local blocks
        self.facet_global = self.imap.local_to_global(self.facet_nodes.ravel()).reshape(-1, k)
        self.sub_nodes = np.asarray(subs, dtype=np.int32).reshape(-1, m, 3)          # local blocks
        self.sub_reference = np.asarray(sub_ref, dtype=float).reshape(-1, m, 3, tdim)
        self.sub_area = np.asarray(sub_area, dtype=float).reshape(-1, m)
        # facets whose nodes all belong to the master surface (a layer still attached) are
        # not contact surface: their gap is zero by construction
        attached = np.isin(self.facet_global, self.master_nodes).all(axis=1)
        keep = ~attached
        self.facet_closure, self.facet_nodes = self.facet_closure[keep], self.facet_nodes[keep]
        self.facet_global, self.sub_nodes = self.facet_global[keep], self.sub_nodes[keep]
        self.sub_reference, self.sub_area = self.sub_reference[keep], self.sub_area[keep]
        if self.comm.allreduce(len(self.facet_nodes)) == 0:
            raise MeshError(f"the slave region '{slave}' has no facets off the master surface")
        rule = basix.make_quadrature(basix.CellType.triangle, self.quadrature_degree)
        self.rule_points, self.rule_weights = np.asarray(rule[0]), np.asarray(rule[1])

    # -- segmentation and gaps --------------------------------------------------------------
    def search_segments(self) -> SegmentState:
        """Segment the slave sub-triangles by the facing master triangles at the current
        ``u`` and evaluate the gap at every segment quadrature point. The Jacobian at the
        iterate whose residual was just evaluated reuses that segmentation (compared by
        the local values of u, owned and ghosts: the same on every rank or recomputed)."""
        values = self.u.x.array
        cached = getattr(self, "_cache", None)
        same = cached is not None and np.array_equal(cached[0], values)
        if self.comm.allreduce(same, op=MPI.LAND):
            return cached[1]
        state = self._segment()
        self._cache = (values.copy(), state)
        return state

    def _segment(self) -> SegmentState:
        with self.timings("contact_search"):
            positions = self._master_positions()
            corners = positions[self.triangle_nodes]                     # (T, 3, 3)
            if len(self.facet_nodes) == 0:
                return _empty_state(self.facet_nodes.shape[1])
            m = self.sub_nodes.shape[1]
            slave_tris = self._positions(self.sub_nodes.reshape(-1)).reshape(-1, 3, 3)
            normal_m = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
            size_m = np.linalg.norm(corners - corners.mean(axis=1)[:, None], axis=2).max(axis=1)
            normal_m /= np.linalg.norm(normal_m, axis=1)[:, None]
            normal_s = np.cross(slave_tris[:, 1] - slave_tris[:, 0], slave_tris[:, 2] - slave_tris[:, 0])
            normal_s /= np.linalg.norm(normal_s, axis=1)[:, None]
            centre_s = slave_tris.mean(axis=1)
            size_s = np.linalg.norm(slave_tris - centre_s[:, None], axis=2).max(axis=1)
            reach = size_s + size_m.max()
            depth = min(self.search_depth, reach.max())
            tree = cKDTree(corners.mean(axis=1))
            near = tree.query_ball_point(centre_s, reach + depth + self.smoothing)
            lengths = np.fromiter((len(ts) for ts in near), dtype=int, count=len(near))
            pairs = np.column_stack([np.repeat(np.arange(len(near)), lengths),
                                     np.fromiter((t for ts in near for t in ts), dtype=int,
                                                 count=lengths.sum())])
            if len(pairs):
                facing = np.einsum("ij,ij->i", normal_s[pairs[:, 0]], normal_m[pairs[:, 1]]) < -self.facing
                pairs = pairs[facing]
            # heights of the master corners over the slave plane (≈ the gap): pairs entirely
            # beyond the search depth or above the active band cannot contribute
            height = np.einsum("njd,nd->nj", corners[pairs[:, 1]] - slave_tris[pairs[:, 0], :1],
                               normal_s[pairs[:, 0]])
            margin = 0.1 * reach[pairs[:, 0]]
            pairs = pairs[(height.min(axis=1) < self.smoothing + margin)
                          & (height.max(axis=1) > -self.search_depth - margin)]
            # master corners in the barycentric (s, t) coordinates of the slave sub-triangle
            st = np.stack([plane_barycentric(corners[pairs[:, 1], j], slave_tris[pairs[:, 0]])[:, 1:]
                           for j in range(3)], axis=1) if len(pairs) else np.zeros((0, 3, 2))
            # only those whose (s, t) bounding box meets the unit triangle are clipped
            meets = ((st[..., 0].max(axis=1) > 0) & (st[..., 1].max(axis=1) > 0)
                     & (st.sum(axis=2).min(axis=1) < 1))
            pairs, st = pairs[meets], st[meets]
            polygons, counts = clip_triangles(st)
            fans = [(polygons[:, 0], polygons[:, i], polygons[:, i + 1], counts > i + 1)
                    for i in range(1, polygons.shape[1] - 1)]
            areas = [(b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
                     for a, b, c, _ in fans]
            # a segment (polygon) is kept when its area is not a round-off sliver; inside
            # it, fan triangles of zero area (repeated vertices) carry no points
            segment = sum(np.where(valid, area, 0.0) for area, (*_, valid) in zip(areas, fans)) > self.SLIVER
            sub_index, tri_index, bary, weight, segment_id = [], [], [], [], []
            for area2, (a, b, c, valid) in zip(areas, fans):
                rows = np.flatnonzero(valid & segment & (area2 > 1e-3 * self.SLIVER))
                if len(rows) == 0:
                    continue
                a, b, c = a[rows, None], b[rows, None], c[rows, None]
                r = self.rule_points[None]
                q = (a + r[..., :1] * (b - a) + r[..., 1:] * (c - a)).reshape(-1, 2)
                nq = len(self.rule_weights)
                sub_index.append(np.repeat(pairs[rows, 0], nq))
                tri_index.append(np.repeat(pairs[rows, 1], nq))
                bary.append(np.column_stack([1 - q.sum(axis=1), q]))
                weight.append((2.0 * area2[rows, None] * self.rule_weights[None]).ravel())
                segment_id.append(np.repeat(rows, nq))
            if not sub_index:
                return _empty_state(self.facet_nodes.shape[1])
            segment_id = np.concatenate(segment_id)
            sub_index, tri_index = np.concatenate(sub_index), np.concatenate(tri_index)
            bary, weight = np.vstack(bary), np.concatenate(weight)
            facet, sub = np.divmod(sub_index, m)
            weight = weight * self.sub_area[facet, sub]
            # slave basis at the points: the sub-triangle's corners in the cell's reference
            cell_ref = np.einsum("nj,njd->nd", bary, self.sub_reference[facet, sub])
            table = self.basis.tabulate(0, cell_ref)[0, :, :, 0]                      # (n, ndofs)
            shape = np.take_along_axis(table, self.facet_closure[facet], axis=1)   # (n, k)
            x = np.einsum("nk,nkd->nd", shape, self._positions(self.facet_nodes[facet].ravel())
                          .reshape(len(facet), -1, 3))
            X = np.einsum("nk,nkd->nd", shape, self.reference[self.facet_nodes[facet]])
            # master side: the projection on the flat triangle, mapped to the master cell's
            # reference coordinates, where the facet's own basis M_i is evaluated
            linear = plane_barycentric(x, corners[tri_index])
            master_ref = np.einsum("nj,njd->nd", linear, self.master_corner_reference[tri_index])
            master_table = self.basis.tabulate(0, master_ref)[0, :, :, 0]
            master_shape = np.take_along_axis(master_table, self.master_facet_index[tri_index], axis=1)
            x_master = np.einsum("nk,nkd->nd", master_shape, positions[self.master_facet_rows[tri_index]])
            normal = normal_m[tri_index]
            gaps = np.einsum("ij,ij->i", x - x_master, normal)
            paired = gaps > -self.search_depth
            active = np.flatnonzero(paired & (gaps < self.smoothing))
            min_gap = float(np.min(gaps[paired], initial=np.inf))
            return SegmentState(facet[active], shape[active], tri_index[active],
                                master_shape[active], normal[active], gaps[active],
                                weight[active], X[active], segment_id[active], min_gap,
                                len(np.unique(segment_id)))

    def _triangle_coupled_nodes(self, triangles: np.ndarray) -> np.ndarray:
        """A segment couples the slave facet to every node of the master facet (not only
        the triangle's three)."""
        return self.master_facet_nodes[triangles]

    # -- assembly hooks ---------------------------------------------------------------------
    def _segment_dofs(self, state: SegmentState) -> np.ndarray:
        nodes = np.column_stack([self.facet_global[state.facets],
                                 self.master_facet_nodes[state.triangles]])
        base = self.layout.base(nodes.ravel()).reshape(nodes.shape)
        return (base[:, :, None] + np.arange(self.bs)).reshape(len(nodes), nodes.shape[1] * self.bs)

    @staticmethod
    def _segment_vectors(state: SegmentState) -> np.ndarray:
        factors = np.column_stack([state.shape, -state.master_shape])
        return (factors[:, :, None] * state.normals[:, None, :]).reshape(len(factors), 3 * factors.shape[1])

    def residual_hook(self, _x: PETSc.Vec, b: PETSc.Vec) -> None:
        """F += −∫ p(g) D dA over the segments (u already holds the iterate)."""
        self.segments = state = self.search_segments()
        dofs = self._segment_dofs(state)
        pressure, _ = penalty_pressure(state.gaps, self.penalty, self.smoothing)
        values = (-state.weights * pressure)[:, None] * self._segment_vectors(state)
        keep = ~np.isin(dofs, list(self._constrained)) if self._constrained else np.ones_like(dofs, bool)
        b.setValues(dofs[keep].astype(PETSc.IntType), values[keep], addv=PETSc.InsertMode.ADD)
        b.assemblyBegin()
        b.assemblyEnd()

    def jacobian_hook(self, _x: PETSc.Vec, A: PETSc.Mat) -> None:
        """K += −∫ p'(g) D Dᵀ dA (frozen normal, M and segmentation), summed per
        (slave facet, master facet) pair before insertion."""
        state = self.search_segments()
        _, slope = penalty_pressure(state.gaps, self.penalty, self.smoothing)
        stiffness = -state.weights * slope
        D = self._segment_vectors(state)
        dofs = self._segment_dofs(state)
        constrained = np.isin(dofs, list(self._constrained)) if self._constrained \
            else np.zeros(dofs.shape, bool)
        with self.timings("contact_jacobian"):
            # one block per (slave facet, master facet): the same dofs for all its points
            pair = state.facets.astype(np.int64) * (self.master_facet_id.max() + 1) \
                + self.master_facet_id[state.triangles]
            order = np.argsort(pair, kind="stable")
            groups, starts = np.unique(pair[order], return_index=True)
            for rows, first in zip(np.split(order, starts[1:]), order[starts]):
                if len(rows) == 0 or not np.any(stiffness[rows]):
                    continue
                index = dofs[first]
                keep = ~constrained[first]
                Dk = D[rows][:, keep]
                block = (Dk * stiffness[rows, None]).T @ Dk
                A.setValues(index[keep].astype(PETSc.IntType), index[keep].astype(PETSc.IntType),
                            block, addv=PETSc.InsertMode.ADD)
            A.assemble()

    # -- diagnostics ------------------------------------------------------------------------
    def _current(self) -> SegmentState:
        """The segments at the current u (collective; reused when u has not changed)."""
        return self.search_segments()

    def summary(self) -> dict[str, float]:
        """Collective: touching segments (under the base class's key ``active_nodes``;
        segments, unlike their quadrature points, do not depend on how the partition
        numbers the nodes), contact area, normal force and max penetration."""
        state = self._current()
        pressure, _ = penalty_pressure(state.gaps, self.penalty, self.smoothing)
        touching = state.gaps < 0
        local = np.array([len(np.unique(state.segment[touching])), state.weights[touching].sum(),
                          (state.weights * pressure).sum()])
        total = self.comm.allreduce(local, op=MPI.SUM)
        depth = self.comm.allreduce(float(np.max(-state.gaps, initial=0.0)), op=MPI.MAX)
        return {"active_nodes": int(total[0]), "contact_area": float(total[1]),
                "contact_normal_force": float(total[2]), "max_penetration": depth}

    def pairs_across_ranks(self) -> int:
        state = self._current()
        first, last = self.imap.local_range
        nodes = self.master_facet_nodes[state.triangles[state.gaps < 0]]
        remote = ((nodes < first) | (nodes >= last)).any(axis=1)
        return int(self.comm.allreduce(int(remote.sum()), op=MPI.SUM))

    def nodal_pressures(self) -> tuple[np.ndarray, np.ndarray]:
        """(reference positions, contact pressure p(g)) of this rank's touching segment
        quadrature points (the pressure field this method integrates)."""
        state = self._current()
        pressure, _ = penalty_pressure(state.gaps, self.penalty, self.smoothing)
        touching = state.gaps < 0
        return state.reference[touching], pressure[touching]

    def min_gap(self) -> float:
        """Smallest gap of any slave node or segment point (collective)."""
        nodes = super().min_gap()
        return min(nodes, self.comm.allreduce(self.search_segments().min_gap, op=MPI.MIN))


def _empty_state(k: int) -> SegmentState:
    return SegmentState(np.zeros(0, dtype=int), np.zeros((0, k)), np.zeros(0, dtype=int),
                        np.zeros((0, k)), np.zeros((0, 3)), np.zeros(0), np.zeros(0),
                        np.zeros((0, 3)), np.zeros(0, dtype=int), np.inf, 0)


def clip_triangles(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The unit triangle (0, 0), (1, 0), (0, 1) clipped by each of ``triangles`` (n, 3, 2)
    (either orientation), vectorised Sutherland–Hodgman: polygons (n, 9, 2) padded
    beyond their vertex counts (n,) (a triangle clipped by a triangle has at most 6)."""
    n = len(triangles)
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    flip = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]) < 0
    triangles = np.where(flip[:, None, None], triangles[:, [0, 2, 1]], triangles)
    size = 9
    points = np.zeros((n, size, 2))
    points[:, :3] = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
    count = np.full(n, 3)
    rows = np.arange(n)
    for i in range(3):
        p, edge = triangles[:, i], triangles[:, (i + 1) % 3] - triangles[:, i]
        side = (edge[:, None, 0] * (points[..., 1] - p[:, None, 1])
                - edge[:, None, 1] * (points[..., 0] - p[:, None, 0]))      # (n, size)
        out = np.zeros_like(points)
        new = np.zeros(n, dtype=int)
        for j in range(size - 1):
            valid = j < count
            k = np.where(count > 0, (j - 1) % np.maximum(count, 1), 0)
            current, previous = points[:, j], points[rows, k]
            sc, sp = side[:, j], side[rows, k]
            with np.errstate(divide="ignore", invalid="ignore"):
                cross = previous + (current - previous) * (sp / (sp - sc))[:, None]
            enter = valid & (sc >= 0) & (sp < 0)
            leave = valid & (sc < 0) & (sp >= 0)
            keep = valid & (sc >= 0)
            for mask, value in ((enter | leave, cross), (keep, current)):
                at = np.minimum(new, size - 1)
                out[rows[mask], at[mask]] = value[mask]
                new = new + mask
        points, count = out, np.minimum(new, size)
    return points, count


def clip_convex(polygon: np.ndarray, triangle: np.ndarray) -> np.ndarray:
    """The part of the convex ``polygon`` (n, 2) inside the ``triangle`` (3, 2) (either
    orientation): Sutherland–Hodgman clipping by the triangle's three edges."""
    a, b, c = triangle
    if (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) < 0:
        triangle = triangle[[0, 2, 1]]
    out = [np.asarray(p, dtype=float) for p in polygon]
    for i in range(3):
        p, q = triangle[i], triangle[(i + 1) % 3]
        edge = q - p

        def side(x, p=p, edge=edge):
            return edge[0] * (x[1] - p[1]) - edge[1] * (x[0] - p[0])

        points, out = out, []
        if not points:
            break
        for j, current in enumerate(points):
            previous = points[j - 1]
            sc, sp = side(current), side(previous)
            if sc >= 0:
                if sp < 0:
                    out.append(previous + (current - previous) * (sp / (sp - sc)))
                out.append(current)
            elif sp >= 0:
                out.append(previous + (current - previous) * (sp / (sp - sc)))
    return np.asarray(out).reshape(-1, 2)
