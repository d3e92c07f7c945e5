r"""A rotation-free triangle shell (vertex positions the only unknowns): the fast lens model.

Same mechanics as ``forms/shell.py`` (geometrically nonlinear Kirchhoff–Love, total
Lagrangian, plane-stress St Venant–Kirchhoff, a thickness per triangle), discretised on
the P1 triangles of the same gmsh meshes with compiled (numba) kernels instead of UFL.

**Frames.** Every triangle T (vertices 0, 1, 2 in the mesh's consistent orientation)
gets an orthonormal reference frame: e₁ along X₁ − X₀, N = (X₁−X₀)×(X₂−X₀)/|·|,
e₂ = N × e₁; ξ = (ξ¹, ξ²) are the coordinates in that plane (the reference metric is the
identity in them).

**Membrane: constant-strain triangle.** With the P1 shape-function gradients d_i = ∂φ_i/∂ξ
and a_α = Σ_i x_i d_iα (the deformed tangent vectors),

    E_αβ = ½ (a_α·a_β − δ_αβ),
    W_m = ½ h A C(E):E,   C(E):E = λ̄ (tr E)² + 2μ E:E,  λ̄ = E_Y ν/(1−ν²), μ = E_Y/(2(1+ν))

— the plane-stress St Venant–Kirchhoff law of ``ShellMaterial.plane_stress`` (C(A)
= E_Y/(1−ν²)((1−ν)A + ν tr A P)).

**Bending: quadratic patch fits (Phaal & Calladine 1992; the quadratic patch of the
EBST, Flores & Oñate 2005) and a Green-formula curvature (the BST of Oñate & Zárate 2000).**
The patch of T is T's 3 vertices and the 3 vertices opposite T across its edges. A quadratic
q_T(ξ) = c₀ + c₁ξ¹ + c₂ξ² + c₃(ξ¹)² + c₄ξ¹ξ² + c₅(ξ²)² (each Cartesian component of the
position) is fitted to the patch: interpolation at the 6 nodes; on a boundary edge without
opposite node, one condition instead:

- ``free`` (and ``simply`` supported — its displacement is fixed separately): the
  natural condition M_νν = 0, i.e. q,_νν + ν q,_ττ = 0 (ν, τ the edge's in-plane
  co-normal and tangent, ν Poisson's ratio);
- ``clamped``: the slope across the edge at its midpoint m is the reference one,
  q,_ν(m) = ν (the 3D reference co-normal).

The fit is linear in the nodal positions (the inverse of a 6×6 matrix per triangle, once).
Two curvatures are built from it, both of the form H_αβ(x) = Σ_i B^i_αβ x_i + b_αβ:

- ``bending="edge"`` (default): one gradient per edge shared by its two triangles,
  g_e = ½ (∇q_T + ∇q_T')(m_e) (∇q_T on a boundary edge), and the Green formula
  ∫_T ∂_α∂_β x = ∮ ν_α ∂_β x with the midpoint rule on each edge:
      H_αβ(T) = (1/A_T) Σ_e ℓ_e sym(ν_e ⊗ g_e)_αβ            (stencil: 12 nodes)
  Exact for quadratic fields (patch test), and the curvatures of a periodic oscillation
  sum to zero over the triangles (the shared g_e telescopes), so no oscillation can lower
  the energy: second-order convergence on one-diagonal, alternating-diagonal and gmsh meshes.
- ``bending="patch"``: H_αβ = ∂_α∂_β q_T, the fit's own constant second derivatives
  (stencil: 6 nodes, half the cost). Also exact for quadratics, but not telescoping: on the
  alternating-diagonal mesh an oscillation of period 2h lowers the energy and the plate is
  ≈ 75 % too soft, not converging (a known defect; docs/iol.md §4b).

With n = (x₁−x₀)×(x₂−x₀)/|·| the deformed normal of T,

    K_αβ = n · H_αβ(x),   κ = K(x) − K(X),
    W_b = ½ D A [ν (tr κ)² + (1−ν) κ:κ],   D = E_Y h³/(12(1−ν²))

— ½ (h³/12) C(κ):κ, the bending energy of ``forms/shell.py``. Rigid motions give κ = 0
(the fits commute with rotations, n rotates with x).

**Total energy, dynamics.** Π(x) = Σ_T (W_m + W_b) − f_ext·u; consistent P1 mass
M = Σ_T ρ h A/12 (1 + δ_ij) I₃ (the P2 model's ∫ ρ h u·v dA on P1). Backward Euler with the
scene's mass-proportional damping c (as ``ImplicitDynamics``):

    R(u) = ∇Π(u) + M [(1/Δt² + c/Δt)(u − u_n) − v_n/Δt],   J = ∇²Π(u) + (1/Δt² + c/Δt) M.

**Kernels.** Energy, gradient and the exact Hessian of both element energies are written out
(numba, ``@njit(cache=True)``): with C_i = ∂c/∂x_i (c = (x₁−x₀)×(x₂−x₀)), N_i = P C_i/|c|,
P = I − nnᵀ, the second derivative of K = n·H is
B_i N_j + B_j N_iᵀ + C_iᵀ S C_j + G_ij (i, j over the stencil; N, C, G only for
T's vertices) with S = −(H nᵀ + n Hᵀ + (n·H)(I − 3nnᵀ))/|c|² and
G the bilinear part of c contracted with PH/|c|. They are assembled straight into a CSR
matrix whose pattern (and every element entry's position in it) is computed once; the
Newton systems are factorised by MUMPS as symmetric LDLᵀ (PETSc Cholesky, sym = 2), the
symbolic analysis done once and reused while the pattern stays.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from numba import njit

from eyemech.problems.run.results import record_stopping_criterion

FREE, CLAMPED = 0, 1
# the kernels' floating-point licences: reassociation and fused multiply–adds (vectorised sums;
# the answers change at round-off: the derivative checks of tests/test_rotation_free.py), but
# not "nnan"/"ninf" — a degenerate state must still give a non-finite residual that Newton sees
FASTMATH = {"reassoc", "contract", "nsz", "arcp"}
BOUNDARY_KINDS = {"free": FREE, "simply": FREE, "clamped": CLAMPED}


class MeshInputError(ValueError):
    """A mesh the rotation-free shell cannot use (non-manifold, inverted, degenerate)."""


# --------------------------------------------------------------------------------------------
# topology and the patch operators (numpy, once per mesh)
# --------------------------------------------------------------------------------------------
def orient(points: np.ndarray, triangles: np.ndarray, up=None) -> np.ndarray:
    """The triangles with their vertex order flipped where the normal points against
    ``up(centroids)`` (a callable returning one vector per triangle), as the P2 model's
    orientation field does; without ``up`` the order is kept as given."""
    triangles = np.array(triangles, dtype=np.int64)
    if up is None:
        return triangles
    p = points[triangles]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    flip = np.einsum("ij,ij->i", normal, up(p.mean(axis=1))) < 0
    triangles[flip] = triangles[flip][:, [0, 2, 1]]
    return triangles


def edge_topology(points: np.ndarray, triangles: np.ndarray):
    """Per triangle and local edge k (opposite vertex k): the vertex across that edge
    (−1 on the boundary) and the boundary edges (as sorted vertex pairs). Refuses
    degenerate triangles, edges shared by more than two triangles and neighbours whose
    orientations disagree (an inverted triangle)."""
    n_tri = len(triangles)
    if n_tri == 0:
        raise MeshInputError("the mesh has no triangles")
    if triangles.min() < 0 or triangles.max() >= len(points):
        raise MeshInputError("triangle vertex indices out of range")
    p = points[triangles]
    area2 = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    scale = max(float(np.ptp(points, axis=0).max()), 1e-300)
    bad = np.flatnonzero(area2 <= 1e-12 * scale ** 2)
    if len(bad):
        raise MeshInputError(f"{len(bad)} degenerate (zero-area) triangles, e.g. triangle {bad[0]}")
    a = triangles[:, [1, 2, 0]].ravel()  # edge k of triangle t: (v[k+1], v[k+2])
    b = triangles[:, [2, 0, 1]].ravel()
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * len(points) + hi
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    unique, start, counts = np.unique(sorted_key, return_index=True, return_counts=True)
    if counts.max() > 2:
        i = int(np.argmax(counts > 2))
        e = unique[i]
        raise MeshInputError(f"non-manifold mesh: edge ({e // len(points)}, {e % len(points)}) is shared "
                             f"by {counts[i]} triangles")
    opposite = -np.ones(3 * n_tri, dtype=np.int64)
    pairs = start[counts == 2]
    first, second = order[pairs], order[pairs + 1]
    if np.any(a[first] == a[second]):
        i = first[np.flatnonzero(a[first] == a[second])[0]] // 3
        raise MeshInputError(f"inverted triangle: triangle {i} and its neighbour traverse their "
                             "common edge in the same direction (inconsistent orientation)")
    flat = triangles.ravel()
    opposite[first] = flat[second]
    opposite[second] = flat[first]
    neighbour = -np.ones(3 * n_tri, dtype=np.int64)
    neighbour[first] = second // 3
    neighbour[second] = first // 3
    return opposite.reshape(n_tri, 3), neighbour.reshape(n_tri, 3)


def patch_operators(points: np.ndarray, triangles: np.ndarray, opposite: np.ndarray,
                    boundary_kind: np.ndarray, poisson_ratio: float):
    """Per triangle: the patch nodes (6; a boundary slot repeats vertex 0 with weight 0), the
    second-derivative operator B (3 components × 6 nodes: ∂₁₁, ∂₂₂, ∂₁₂), its constant part b
    (3 × 3, from clamped edges), the reference curvature K(X), the P1 gradients d (3 × 2), the
    area and the condition number of the fit. ``boundary_kind[t, k]``: FREE or CLAMPED for a
    boundary edge k of triangle t."""
    n_tri = len(triangles)
    nodes = np.empty((n_tri, 6), dtype=np.int64)
    B = np.zeros((n_tri, 3, 6))
    b = np.zeros((n_tri, 3, 3))
    d = np.empty((n_tri, 3, 2))
    area = np.empty(n_tri)
    condition = np.empty(n_tri)
    fits = {"inverse": np.empty((n_tri, 6, 6)), "rhs": np.zeros((n_tri, 6, 3)),
            "frame": np.empty((n_tri, 2, 3)), "origin": np.empty((n_tri, 3)), "xi": np.empty((n_tri, 3, 2))}
    nu = poisson_ratio
    for t in range(n_tri):
        v = triangles[t]
        X = points[v]
        e1 = X[1] - X[0]
        c = np.cross(e1, X[2] - X[0])
        area[t] = 0.5 * np.linalg.norm(c)
        N = c / np.linalg.norm(c)
        e1 = e1 / np.linalg.norm(e1)
        e2 = np.cross(N, e1)
        frame = np.array([e1, e2])  # 2 × 3
        xi = (X - X[0]) @ frame.T  # 3 × 2
        # P1 gradients: [1 ξ¹ ξ²] coefficients
        V1 = np.column_stack([np.ones(3), xi])
        d[t] = np.linalg.inv(V1)[1:].T
        rows = np.zeros((6, 6))
        rhs = np.zeros((6, 3))
        nodes[t, :3] = v
        for k in range(3):
            rows[k] = _basis(xi[k])
        for k in range(3):
            j = opposite[t, k]
            i, i2 = (k + 1) % 3, (k + 2) % 3
            if j >= 0:
                nodes[t, 3 + k] = j
                rows[3 + k] = _basis((points[j] - X[0]) @ frame.T)
                continue
            nodes[t, 3 + k] = v[0]
            tau = xi[i2] - xi[i]
            tau /= np.linalg.norm(tau)
            con = np.array([tau[1], -tau[0]])  # outward: triangles are counter-clockwise in ξ
            if boundary_kind[t, k] == CLAMPED:
                m = 0.5 * (xi[i] + xi[i2])
                rows[3 + k] = [0.0, con[0], con[1], 2 * m[0] * con[0], m[1] * con[0] + m[0] * con[1],
                               2 * m[1] * con[1]]
                rhs[3 + k] = con @ frame
            else:
                rows[3 + k] = [0.0, 0.0, 0.0, 2 * (con[0] ** 2 + nu * tau[0] ** 2),
                               2 * (con[0] * con[1] + nu * tau[0] * tau[1]),
                               2 * (con[1] ** 2 + nu * tau[1] ** 2)]
        # scale ξ to O(1) for the conditioning estimate
        condition[t] = np.linalg.cond(rows @ np.diag(_scaling(xi)))
        inverse = np.linalg.inv(rows)
        # second derivatives: ∂₁₁ = 2c₃, ∂₂₂ = 2c₅, ∂₁₂ = c₄
        second = np.array([2.0 * inverse[3], 2.0 * inverse[5], inverse[4]])  # 3 × 6 (over fit rows)
        B[t] = second
        B[t][:, 3:][:, opposite[t] < 0] = 0.0
        b[t] = second @ rhs
        fits["inverse"][t], fits["rhs"][t], fits["frame"][t], fits["origin"][t] = inverse, rhs, frame, X[0]
        fits["xi"][t] = xi
    return nodes, B, b, d, area, condition, fits


def edge_operators(points, triangles, opposite, neighbour, nodes, area, fits):
    """The Green-formula curvature with one gradient per edge (``bending="edge"``):

        H_αβ(T) = (1/A_T) Σ_edges ℓ_e sym(ν_e ⊗ g_e)_αβ,   g_e,β = ½ (∂_β q_T + ∂_β q_T')(m_e)

    (m_e the edge midpoint, q_T, q_T' the patch quadratics of the two triangles, g_e = ∂_β q_T
    on a boundary edge). Exact for quadratic fields (the midpoint rule integrates the linear
    gradient of a quadratic exactly along an edge) and, because both triangles use the same
    g_e with opposite co-normals, the sum over triangles of the curvature of a periodic
    oscillation telescopes to zero: an oscillation cannot lower the energy on average, which
    is what makes the 6-node patch curvature too soft on alternating-diagonal meshes.
    Returns the stencil (12 nodes: the patch and the two further nodes of each neighbour's
    patch; unused slots repeat vertex 0 with weight 0) and B (3 × 12), b (3 × 3)."""
    n_tri = len(triangles)
    stencil = np.empty((n_tri, 12), dtype=np.int64)
    B = np.zeros((n_tri, 3, 12))
    b = np.zeros((n_tri, 3, 3))

    def gradient_rows(t, p):
        """∂q/∂ξ_γ at local point p of triangle t's fit: (2 × 6) over the fit rows."""
        inv = fits["inverse"][t]
        return np.array([inv[1] + 2 * p[0] * inv[3] + p[1] * inv[4],
                         inv[2] + p[0] * inv[4] + 2 * p[1] * inv[5]])

    for t in range(n_tri):
        slots = list(nodes[t, :3]) + [j for j in opposite[t] if j >= 0]
        for other in neighbour[t]:
            if other >= 0:  # a neighbour's padded slots repeat its vertex 0, already listed
                slots += [j for j in nodes[other] if j not in slots]
        index = {j: i for i, j in enumerate(slots)}
        frame, xi = fits["frame"][t], fits["xi"][t]
        weights = np.zeros((3, 12))  # H components over stencil slots
        constant = np.zeros((3, 3))
        for k in range(3):
            i, i2 = (k + 1) % 3, (k + 2) % 3
            tau = xi[i2] - xi[i]
            length = np.linalg.norm(tau)
            tau = tau / length
            con = np.array([tau[1], -tau[0]])
            mid = 0.5 * (points[triangles[t, i]] + points[triangles[t, i2]])
            sides = [t] if neighbour[t, k] < 0 else [t, neighbour[t, k]]
            for side in sides:
                share = 1.0 / len(sides)
                fr, origin = fits["frame"][side], fits["origin"][side]
                rows = gradient_rows(side, (mid - origin) @ fr.T)  # 2 × 6 in the side's frame
                # ∂/∂ξ_β of T = Σ_γ ∂/∂ξ'_γ (e'_γ · e_β)
                turn = fr @ frame.T  # (γ, β)
                grad_rows = turn.T @ rows  # (β, fit rows)
                grad_const = grad_rows @ fits["rhs"][side]  # (β, xyz)
                patch = nodes[side]
                valid = np.ones(6, dtype=bool)
                valid[3:] = opposite[side] >= 0
                for beta in range(2):
                    for comp, (alpha_, beta_, factor) in enumerate(((0, 0, 1.0), (1, 1, 1.0), (0, 1, 0.5))):
                        c = 0.0
                        if beta == beta_:
                            c += factor * con[alpha_]
                        if comp == 2 and beta == alpha_:
                            c += factor * con[beta_]
                        if c == 0.0:
                            continue
                        w = share * length * c / area[t]
                        for r in range(6):
                            if valid[r]:
                                weights[comp, index[patch[r]]] += w * grad_rows[beta, r]
                        constant[comp] += w * grad_const[beta]
        stencil[t, :len(slots)] = slots
        stencil[t, len(slots):] = slots[0]
        B[t] = weights
        b[t] = constant
    return stencil, B, b


def _basis(p):
    return np.array([1.0, p[0], p[1], p[0] ** 2, p[0] * p[1], p[1] ** 2])


def _scaling(xi):
    h = max(np.abs(xi).max(), 1e-300)
    return np.array([1.0, h, h, h * h, h * h, h * h])


# --------------------------------------------------------------------------------------------
# element kernels (numba)
# --------------------------------------------------------------------------------------------
@njit(inline="always")
def _add(hess, data, place, direct, p, q, value):
    """A Hessian entry (p ≤ q) added to the element matrix, or (``direct``) straight to its
    place ``place[p, q]`` in the CSR values."""
    if direct:
        data[place[p, q]] += value
    else:
        hess[p, q] += value


@njit(cache=True, fastmath=FASTMATH)
def membrane_element(x, d, area, h, lam, mu, grad, hess, want_hess, a1, a2, dE, data, place, direct):
    """CST energy ½ h A C(E):E; adds its gradient (9) and the p ≤ q entries of its Hessian
    (9 × 9) to grad/hess (a1, a2: scratch 3-vectors, dE: 3 × 9)."""
    a1[:] = 0.0
    a2[:] = 0.0
    for i in range(3):
        for c in range(3):
            a1[c] += x[i, c] * d[i, 0]
            a2[c] += x[i, c] * d[i, 1]
    E11 = 0.5 * (a1 @ a1 - 1.0)
    E22 = 0.5 * (a2 @ a2 - 1.0)
    E12 = 0.5 * (a1 @ a2)
    k = h * area
    C11 = lam + 2.0 * mu
    S11 = C11 * E11 + lam * E22
    S22 = lam * E11 + C11 * E22
    S12 = 4.0 * mu * E12
    energy = 0.5 * k * (E11 * S11 + E22 * S22 + E12 * S12)
    for i in range(3):
        for c in range(3):
            dE[0, 3 * i + c] = d[i, 0] * a1[c]
            dE[1, 3 * i + c] = d[i, 1] * a2[c]
            dE[2, 3 * i + c] = 0.5 * (d[i, 0] * a2[c] + d[i, 1] * a1[c])
    for p in range(9):
        grad[p] += k * (S11 * dE[0, p] + S22 * dE[1, p] + S12 * dE[2, p])
    if want_hess:  # the p ≤ q entries (``bending_element``)
        for p in range(9):
            g0 = C11 * dE[0, p] + lam * dE[1, p]
            g1 = lam * dE[0, p] + C11 * dE[1, p]
            g2 = 4.0 * mu * dE[2, p]
            for q in range(p, 9):
                _add(hess, data, place, direct, p, q, k * (g0 * dE[0, q] + g1 * dE[1, q] + g2 * dE[2, q]))
        for i in range(3):
            for j in range(i, 3):
                s = k * (S11 * d[i, 0] * d[j, 0] + S22 * d[i, 1] * d[j, 1]
                         + S12 * 0.5 * (d[i, 0] * d[j, 1] + d[i, 1] * d[j, 0]))
                for c in range(3):
                    _add(hess, data, place, direct, 3 * i + c, 3 * j + c, s)
    return energy


@njit(cache=True, fastmath=FASTMATH)
def bending_element(x, B, b, K0, area, D, nu, grad, hess, want_hess, work, data, place, direct):
    """Bending energy ½ D A [ν (tr κ)² + (1−ν) κ:κ] of one triangle (x: stencil positions,
    vertices 0–2 first); adds its gradient (3 × stencil) and the p ≤ q entries of its
    Hessian (what the upper-triangle scatter reads; ``assemble`` mirrors them for the full
    pattern). ``work``: scratch (``bending_scratch()``), so the element loop allocates
    nothing. The curvature part is nonzero only in the blocks of a vertex (0–2) with any
    stencil node: the (vertex, node ≥ 3) blocks are w_j N_iᵀ, the vertex–vertex blocks have
    all four terms. Only the i ≤ j blocks are computed (the lens's bending Hessian pass 1.01 →
    0.87 ms against all blocks: docs/iol.md §4b)."""
    Cs, Nn, H, dk, SC, S, M = work
    NP = B.shape[1]
    e1x, e1y, e1z = x[1, 0] - x[0, 0], x[1, 1] - x[0, 1], x[1, 2] - x[0, 2]
    e2x, e2y, e2z = x[2, 0] - x[0, 0], x[2, 1] - x[0, 1], x[2, 2] - x[0, 2]
    cx, cy, cz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    L = np.sqrt(cx * cx + cy * cy + cz * cz)
    n0, n1, n2 = cx / L, cy / L, cz / L
    n = (n0, n1, n2)
    # C_i = ∂c/∂x_i: skew(e2 − e1), −skew(e2), skew(e1)
    _skew3(e2x - e1x, e2y - e1y, e2z - e1z, 1.0, Cs[0])
    _skew3(e2x, e2y, e2z, -1.0, Cs[1])
    _skew3(e1x, e1y, e1z, 1.0, Cs[2])
    for i in range(3):  # N_i = P C_i / L
        for col in range(3):
            dot = n0 * Cs[i, 0, col] + n1 * Cs[i, 1, col] + n2 * Cs[i, 2, col]
            for a in range(3):
                Nn[i, a, col] = (Cs[i, a, col] - n[a] * dot) / L
    kappa0 = 0.0
    kappa1 = 0.0
    kappa2 = 0.0
    for k in range(3):
        for cc in range(3):
            acc = b[k, cc]
            for i in range(NP):
                acc += B[k, i] * x[i, cc]
            H[k, cc] = acc
    kappa0 = n0 * H[0, 0] + n1 * H[0, 1] + n2 * H[0, 2] - K0[0]
    kappa1 = n0 * H[1, 0] + n1 * H[1, 1] + n2 * H[1, 2] - K0[1]
    kappa2 = n0 * H[2, 0] + n1 * H[2, 1] + n2 * H[2, 2] - K0[2]
    m0 = kappa0 + nu * kappa1
    m1 = nu * kappa0 + kappa1
    m2 = 2.0 * (1.0 - nu) * kappa2
    k_b = D * area
    energy = 0.5 * k_b * (kappa0 * m0 + kappa1 * m1 + kappa2 * m2)
    for k in range(3):
        for i in range(NP):
            for cc in range(3):
                dk[k, 3 * i + cc] = B[k, i] * n[cc]
        for i in range(3):
            for cc in range(3):
                dk[k, 3 * i + cc] += Nn[i, 0, cc] * H[k, 0] + Nn[i, 1, cc] * H[k, 1] + Nn[i, 2, cc] * H[k, 2]
    for p in range(3 * NP):
        grad[p] += k_b * (m0 * dk[0, p] + m1 * dk[1, p] + m2 * dk[2, p])
    if not want_hess:
        return energy
    c1 = 2.0 * (1.0 - nu)
    for p in range(3 * NP):
        g0 = k_b * (dk[0, p] + nu * dk[1, p])
        g1 = k_b * (nu * dk[0, p] + dk[1, p])
        g2 = k_b * c1 * dk[2, p]
        for q in range(p, 3 * NP):
            _add(hess, data, place, direct, p, q, g0 * dk[0, q] + g1 * dk[1, q] + g2 * dk[2, q])
    # Σ_k m_k ∇²κ_k with y = k_b Σ_k m_k H_k (∇²κ is linear in H)
    y0 = k_b * (m0 * H[0, 0] + m1 * H[1, 0] + m2 * H[2, 0])
    y1 = k_b * (m0 * H[0, 1] + m1 * H[1, 1] + m2 * H[2, 1])
    y2 = k_b * (m0 * H[0, 2] + m1 * H[1, 2] + m2 * H[2, 2])
    y = (y0, y1, y2)
    ny = n0 * y0 + n1 * y1 + n2 * y2
    inv = 1.0 / (L * L)
    for a in range(3):
        for c in range(3):
            S[a, c] = -(y[a] * n[c] + n[a] * y[c] - 3.0 * ny * n[a] * n[c]) * inv
        S[a, a] -= ny * inv
    g0, g1, g2 = (y0 - n0 * ny) / L, (y1 - n1 * ny) / L, (y2 - n2 * ny) / L
    _skew3(g0, g1, g2, -1.0, M)  # −skew(g)
    for j in range(3):  # SC_j = S C_j
        for a in range(3):
            for c in range(3):
                SC[j, a, c] = S[a, 0] * Cs[j, 0, c] + S[a, 1] * Cs[j, 1, c] + S[a, 2] * Cs[j, 2, c]
    alpha = (-1.0, 1.0, 0.0)
    beta = (-1.0, 0.0, 1.0)
    wk0, wk1, wk2 = k_b * m0, k_b * m1, k_b * m2
    for i in range(3):  # blocks (i, j ≥ i); none between two non-vertex nodes
        wi = wk0 * B[0, i] + wk1 * B[1, i] + wk2 * B[2, i]
        for j in range(i, 3):
            wj = wk0 * B[0, j] + wk1 * B[1, j] + wk2 * B[2, j]
            ab, ba = alpha[i] * beta[j], beta[i] * alpha[j]
            for a in range(3):
                for c in range(a if j == i else 0, 3):
                    _add(hess, data, place, direct, 3 * i + a, 3 * j + c,
                         wi * Nn[j, a, c] + wj * Nn[i, c, a]
                         + Cs[i, 0, a] * SC[j, 0, c] + Cs[i, 1, a] * SC[j, 1, c] + Cs[i, 2, a] * SC[j, 2, c]
                         + ab * M[a, c] + ba * M[c, a])
        for j in range(3, NP):
            wj = wk0 * B[0, j] + wk1 * B[1, j] + wk2 * B[2, j]
            for a in range(3):
                for c in range(3):
                    _add(hess, data, place, direct, 3 * i + a, 3 * j + c, wj * Nn[i, c, a])
    return energy


@njit(cache=True)
def _skew3(vx, vy, vz, s, out):
    out[0, 0] = 0.0
    out[0, 1] = -s * vz
    out[0, 2] = s * vy
    out[1, 0] = s * vz
    out[1, 1] = 0.0
    out[1, 2] = -s * vx
    out[2, 0] = -s * vy
    out[2, 1] = s * vx
    out[2, 2] = 0.0


@njit(cache=True)
def bending_scratch(n_nodes):
    return (np.zeros((3, 3, 3)), np.zeros((3, 3, 3)), np.zeros((3, 3)), np.zeros((3, 3 * n_nodes)),
            np.zeros((3, 3, 3)), np.zeros((3, 3)), np.zeros((3, 3)))


@njit(cache=True, fastmath=FASTMATH)
def assemble(x, tri, nodes, B, b, K0, d, area, thickness, E, nu, scatter_start, scatter_local, scatter_pos,
             grad, data, want_hess, bending_only, mirror, places):
    """Σ over triangles: energy, gradient into ``grad`` (3n), Hessian into the CSR ``data``.
    With ``places`` (n_tri, m, m; ``RotationFreeShell.places``) every element entry p ≤ q is
    added straight at ``data[places[t, p, q]]`` (the upper pattern); else triangle t adds its
    element matrix's flat entries ``scatter_local[k]`` at ``data[scatter_pos[k]]`` for k in
    ``scatter_start[t]:scatter_start[t + 1]`` (``scatter_lists``; ``mirror=True``: the
    kernels' p ≤ q entries copied to q > p, for the full pattern)."""
    lam = E * nu / (1.0 - nu * nu)
    mu = 0.5 * E / (1.0 + nu)
    energy = 0.0
    NP = nodes.shape[1]
    direct = want_hess and places.shape[0] == tri.shape[0]
    xe = np.zeros((NP, 3))
    gb = np.zeros(3 * NP)
    hb = np.zeros((3 * NP, 3 * NP))
    work = bending_scratch(NP)
    a1, a2, dE = np.zeros(3), np.zeros(3), np.zeros((3, 9))
    for t in range(tri.shape[0]):
        h = thickness[t]
        for i in range(NP):
            xe[i] = x[nodes[t, i]]
        gb[:] = 0.0
        if want_hess and not direct:
            hb[:, :] = 0.0
        place = places[t] if direct else places[0]
        D = E * h ** 3 / (12.0 * (1.0 - nu * nu))
        energy += bending_element(xe, B[t], b[t], K0[t], area[t], D, nu, gb, hb, want_hess, work, data, place,
                                  direct)
        if not bending_only:
            energy += membrane_element(xe[:3], d[t], area[t], h, lam, mu, gb[:9], hb[:9, :9], want_hess,
                                       a1, a2, dE, data, place[:9, :9], direct)
        for i in range(NP):
            for cc in range(3):
                grad[3 * nodes[t, i] + cc] += gb[3 * i + cc]
        if want_hess and not direct:
            if mirror:  # the kernels wrote the p ≤ q entries
                for p in range(3 * NP):
                    for q in range(p + 1, 3 * NP):
                        hb[q, p] = hb[p, q]
            flat = hb.ravel()
            for k in range(scatter_start[t], scatter_start[t + 1]):
                data[scatter_pos[k]] += flat[scatter_local[k]]
    return energy


@njit(cache=True)
def reference_curvature(X, nodes, B, b):
    K0 = np.zeros((nodes.shape[0], 3))
    for t in range(nodes.shape[0]):
        e1 = X[nodes[t, 1]] - X[nodes[t, 0]]
        e2 = X[nodes[t, 2]] - X[nodes[t, 0]]
        c = np.cross(e1, e2)
        n = c / np.sqrt(c @ c)
        for k in range(3):
            Hk = b[t, k].copy()
            for i in range(nodes.shape[1]):
                Hk += B[t, k, i] * X[nodes[t, i]]
            K0[t, k] = n @ Hk
    return K0


def scatter_lists(nodes: np.ndarray, positions: np.ndarray, upper=None):
    """Where each element matrix entry goes in the CSR values, as flat lists per triangle
    (``assemble``'s ``scatter_start``, ``scatter_local``, ``scatter_pos``). Stencil slots that
    repeat an earlier node (padding: zero rows and columns) are left out. ``positions``
    (n_tri, m, m): the entries' places in the full pattern. ``upper``: (keep, renumber) of the
    upper-triangle pattern — then only the element's p ≤ q entries are listed, each at its own
    or its transpose's place in the upper pattern (the element matrices are symmetric), which
    halves the scatter."""
    n_tri, n_slots = nodes.shape
    first = np.ones((n_tri, n_slots), dtype=bool)
    for i in range(1, n_slots):
        first[:, i] = ~np.any(nodes[:, :i] == nodes[:, i:i + 1], axis=1)
    valid = np.repeat(first, 3, axis=1)  # per element dof
    m = 3 * n_slots
    both = valid[:, :, None] & valid[:, None, :]
    if upper is not None:
        both &= np.triu(np.ones((m, m), dtype=bool))[None]
    t, p, q = np.nonzero(both)
    pos = positions[t, p, q]
    if upper is not None:
        keep, renumber = upper
        pos = np.where(keep[pos], renumber[pos], renumber[positions[t, q, p]])
    order = np.lexsort((pos, t))
    start = np.zeros(n_tri + 1, dtype=np.int64)
    np.add.at(start, t + 1, 1)
    return np.cumsum(start), (p * m + q)[order].astype(np.int32), pos[order].astype(np.int32)


# --------------------------------------------------------------------------------------------
# the shell
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Material:
    youngs_modulus: float
    poisson_ratio: float
    density: float = 0.0


class RotationFreeShell:
    """The rotation-free shell on (points, triangles): energy, gradient, exact Hessian in a
    CSR matrix with a fixed pattern, consistent mass.

    ``thickness``: a number or one value per triangle. ``boundary``: a callable
    (edge midpoints (m, 3) → kind per edge, "free" | "simply" | "clamped") for the bending
    condition on boundary edges; default free everywhere. Displacement supports are the
    solver's (``fixed`` dofs)."""

    def __init__(self, points, triangles, thickness, material: Material, boundary=None, up=None,
                 bending: str = "edge"):
        import scipy.sparse

        points = np.ascontiguousarray(points, dtype=float)
        if points.ndim != 2 or points.shape[1] != 3:
            raise MeshInputError("points must be an (n, 3) array")
        self.X = points
        self.tri = orient(points, triangles, up)
        self.opposite, self.neighbour = edge_topology(points, self.tri)
        self.material = material
        thickness = np.broadcast_to(np.asarray(thickness, dtype=float), (len(self.tri),)).copy()
        if not np.all(thickness > 0):
            raise ValueError("thickness must be > 0 on every triangle")
        self.thickness = thickness
        kind = np.full((len(self.tri), 3), FREE, dtype=np.int64)
        t_b, k_b = np.nonzero(self.opposite < 0)
        if boundary is not None and len(t_b):
            mid = 0.5 * (points[self.tri[t_b, (k_b + 1) % 3]] + points[self.tri[t_b, (k_b + 2) % 3]])
            kinds = boundary(mid)
            kind[t_b, k_b] = [BOUNDARY_KINDS[k] for k in kinds]
        self.boundary_kind = kind
        (self.nodes, self.B, self.b, self.d, self.area,
         self.condition, fits) = patch_operators(points, self.tri, self.opposite, kind,
                                                 material.poisson_ratio)
        if not np.all(np.isfinite(self.condition)) or self.condition.max() > 1e10:
            t = int(np.argmax(self.condition))
            raise MeshInputError(f"the quadratic patch of triangle {t} is singular (its 6 nodes on one "
                                 "conic)")
        if bending == "edge":
            self.nodes, self.B, self.b = edge_operators(points, self.tri, self.opposite, self.neighbour,
                                                        self.nodes, self.area, fits)
        elif bending != "patch":
            raise ValueError(f"bending must be 'patch' or 'edge', got {bending!r}")
        self.bending = bending
        self.K0 = reference_curvature(points, self.nodes, self.B, self.b)
        n = len(points)
        self.n_dofs = 3 * n
        # CSR pattern and the element entries' positions, once
        m = 3 * self.nodes.shape[1]
        dofs = (3 * self.nodes[:, :, None] + np.arange(3)).reshape(len(self.tri), m)
        rows = np.repeat(dofs, m, axis=1).ravel()
        cols = np.tile(dofs, (1, m)).ravel()
        key = rows * self.n_dofs + cols
        unique, inverse = np.unique(key, return_inverse=True)
        self.positions = inverse.reshape(len(self.tri), m, m).astype(np.int64)
        r, c = unique // self.n_dofs, unique % self.n_dofs
        indptr = np.zeros(self.n_dofs + 1, dtype=np.int64)
        np.add.at(indptr, r + 1, 1)
        self.indptr, self.indices = np.cumsum(indptr), c.astype(np.int64)
        self.diagonal = np.searchsorted(unique, np.arange(self.n_dofs) * (self.n_dofs + 1))
        self._scipy = scipy.sparse
        self.mass_data = self._mass()
        # the upper triangle alone (what an LDLᵀ factorisation reads): half the scatter and copy
        keep = r <= c
        renumber = np.cumsum(keep) - 1
        up_indptr = np.zeros(self.n_dofs + 1, dtype=np.int64)
        np.add.at(up_indptr, r[keep] + 1, 1)
        self.upper = {"indptr": np.cumsum(up_indptr), "indices": c[keep].astype(np.int64),
                      "diagonal": renumber[self.diagonal], "mass": self.mass_data[keep]}
        self.scatter = {False: scatter_lists(self.nodes, self.positions, None),
                        True: scatter_lists(self.nodes, self.positions, (keep, renumber))}
        # every element entry's place in the upper pattern (its own or its transpose's): the
        # kernels add the p ≤ q entries there directly, without an element matrix. A padding slot
        # repeats a node, so its (zero) entries land on that node's places
        own = self.positions
        self.places = np.where(keep[own], renumber[own], renumber[own.transpose(0, 2, 1)]).astype(np.int32)
        self._no_places = np.zeros((1, m, m), dtype=np.int32)

    # -- assembly --------------------------------------------------------------------------
    def new_data(self) -> np.ndarray:
        return np.zeros(len(self.indices))

    def evaluate(self, u: np.ndarray, grad: np.ndarray, data: np.ndarray | None = None,
                 bending_only: bool = False, upper: bool = False) -> float:
        """Strain energy at displacement u (3n); adds the gradient to ``grad`` and, when
        ``data`` is given, the Hessian into the CSR values ``data`` (of the upper triangle's
        pattern ``self.upper`` when ``upper``)."""
        x = self.X + u.reshape(-1, 3)
        want = data is not None
        start, local, pos = self.scatter[upper]
        places = self.places if upper else self._no_places
        return assemble(x, self.tri, self.nodes, self.B, self.b, self.K0, self.d, self.area, self.thickness,
                        float(self.material.youngs_modulus), float(self.material.poisson_ratio),
                        start, local, pos, grad, data if want else np.zeros(1), want, bending_only, not upper,
                        places)

    def energy(self, u: np.ndarray, bending_only: bool = False) -> float:
        return self.evaluate(u, np.zeros(self.n_dofs), bending_only=bending_only)

    def matrix(self, data: np.ndarray):
        return self._scipy.csr_matrix((data, self.indices, self.indptr), shape=(self.n_dofs,) * 2)

    def _mass(self) -> np.ndarray:
        """Consistent P1 mass ρ h A/12 (1 + δ_ij) I₃ in the CSR values."""
        data = self.new_data()
        m = self.material.density * self.thickness * self.area / 12.0
        local = np.kron(np.ones((3, 3)) + np.eye(3), np.eye(3))  # 9 × 9
        pos = self.positions[:, :9, :9]
        np.add.at(data, pos.ravel(), (m[:, None, None] * local).ravel())
        return data

    def lumped_mass(self) -> np.ndarray:
        return np.asarray(self.matrix(self.mass_data).sum(axis=1)).ravel()

    def pressure_load(self, q: float, direction=(0.0, 0.0, 1.0)) -> np.ndarray:
        """Consistent nodal forces of a dead load q per unit reference area along ``direction``."""
        f = np.zeros((len(self.X), 3))
        np.add.at(f, self.tri.ravel(), np.repeat(q * self.area / 3.0, 3)[:, None] * np.asarray(direction))
        return f.ravel()


# --------------------------------------------------------------------------------------------
# linear solver: MUMPS LDLᵀ through PETSc, symbolic analysis reused
# --------------------------------------------------------------------------------------------
class SymmetricSolver:
    """The CSR system factorised by MUMPS as symmetric (PETSc Cholesky → LDLᵀ, sym = 2);
    Dirichlet dofs become identity rows and columns. The symbolic analysis is done at the
    first factorisation and reused (same nonzero pattern)."""

    def __init__(self, shell: RotationFreeShell, fixed: np.ndarray | None = None, upper: bool = False,
                 pattern: tuple | None = None):
        """``pattern``: (indptr, indices, diagonal positions) of an upper-triangle pattern other
        than the shell's (the shell's grown by contact pairs)."""
        import eyemech.meshes  # noqa: F401, I001  (first: it orders MPI ahead of PETSc for the PyPI wheel)
        from petsc4py import PETSc

        self.PETSc = PETSc
        self.shell = shell
        n = shell.n_dofs
        fixed = np.zeros(0, dtype=np.int64) if fixed is None else np.unique(np.asarray(fixed, dtype=np.int64))
        self.fixed = fixed
        mask = np.zeros(n, dtype=bool)
        mask[fixed] = True
        if pattern is not None:
            indptr, indices, diagonal = pattern
        elif upper:
            indptr, indices, diagonal = shell.upper["indptr"], shell.upper["indices"], shell.upper["diagonal"]
        else:
            indptr, indices, diagonal = shell.indptr, shell.indices, shell.diagonal
        rows = np.repeat(np.arange(n), np.diff(indptr))
        self.zero = np.flatnonzero(mask[rows] | mask[indices])
        self.diagonal = diagonal
        self.fixed_diagonal = diagonal[fixed]
        self._indptr = indptr.astype(PETSc.IntType)
        self._indices = indices.astype(PETSc.IntType)
        # the matrix keeps (does not copy) these arrays: `factor` writes the values in place
        self._values = np.zeros(len(indices))
        self.A = PETSc.Mat().createAIJWithArrays((n, n), (self._indptr, self._indices, self._values),
                                                 comm=PETSc.COMM_SELF)
        self.A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        self.A.setOption(PETSc.Mat.Option.NEW_NONZERO_LOCATION_ERR, True)
        self.ksp = PETSc.KSP().create(PETSc.COMM_SELF)
        self.ksp.setType("preonly")
        pc = self.ksp.getPC()
        pc.setType("cholesky")
        pc.setFactorSolverType("mumps")
        self.ksp.setOperators(self.A)
        pc.setFactorSetUpSolverType()
        factor = pc.getFactorMatrix()
        factor.setMumpsIcntl(8, 0)  # no scaling: 20 % of a factorisation at this size, residuals unchanged
        self.b = self.A.createVecRight()
        self.x = self.A.createVecRight()
        self.factorisations = 0

    def factor(self, data: np.ndarray) -> None:
        values = self._values
        values[:] = data
        values[self.zero] = 0.0
        values[self.fixed_diagonal] = 1.0
        self.A.assemble()  # the values changed in place: a new state, so the PC refactorises
        self.ksp.setOperators(self.A)
        self.ksp.setUp()
        self.factorisations += 1

    def negative_pivots(self) -> int:
        """The number of negative pivots of the last LDLᵀ factorisation (MUMPS INFOG(12)): the
        matrix's negative eigenvalues (Sylvester's law of inertia)."""
        return int(self.ksp.getPC().getFactorMatrix().getMumpsInfog(12))

    def factor_positive(self, data: np.ndarray, shift: float = 1e-4, growth: float = 4.0) -> int:
        """Factorise ``data``; where it is indefinite, factorise data + δI instead, δ = ``shift``
        × max|diag| grown ×``growth`` until no pivot is negative (the inertia correction of
        IPOPT, Wächter & Biegler 2006, §3.1): the Newton step is then a descent direction of
        the incremental potential. Returns the factorisations made."""
        self.factor(data)
        made = 1
        if not self.negative_pivots():
            return made
        delta = shift * float(np.abs(data[self.diagonal]).max())
        while True:
            shifted = data.copy()
            shifted[self.diagonal] += delta
            self.factor(shifted)
            made += 1
            if not self.negative_pivots():
                return made
            delta *= growth

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        rhs = rhs.copy()
        rhs[self.fixed] = 0.0
        self.b.array[:] = rhs
        self.ksp.solve(self.b, self.x)
        return self.x.array.copy()


# --------------------------------------------------------------------------------------------
# statics and backward-Euler dynamics
# --------------------------------------------------------------------------------------------
def solve_linear(shell: RotationFreeShell, force: np.ndarray, fixed) -> np.ndarray:
    """The linear (small-displacement) response: ∇²Π(0) u = f (the exact second variation
    at the reference is the linear shell's stiffness)."""
    data = shell.new_data()
    shell.evaluate(np.zeros(shell.n_dofs), np.zeros(shell.n_dofs), data)
    solver = SymmetricSolver(shell, fixed)
    solver.factor(data)
    return solver.solve(force)


class Dynamics:
    """Backward Euler with mass-proportional damping c (as ``ImplicitDynamics``), Newton on
    R(u) = ∇Π(u) − f + M[(1/Δt² + c/Δt)(u − u_n) − v_n/Δt] with the exact Hessian.
    ``extra``: callables (u, grad, data or None) → energy adding more terms, on the full
    pattern; without them the Jacobian is kept as its upper triangle (``upper``), which
    ``set_contact`` (ipctk self-contact, growing the pattern) and ``set_obstacles`` (rigid
    walls, nodal penalty) build on. Counts: iterations (linear solves), residual and Jacobian
    passes, numeric factorisations (the inertia correction's included), Hessians shifted to
    positive definite (``shifted``), rejected reused-factor iterations, pattern growths (each a
    new symbolic factorisation) and CCD-limited updates."""

    def __init__(self, shell: RotationFreeShell, time_step: float, damping: float, fixed=None,
                 rtol: float = 1e-6, atol: float = 1e-11, max_iterations: int = 25, upper: bool = True):
        if not time_step > 0 or not np.isfinite(time_step):
            raise ValueError(f"time_step must be > 0, got {time_step!r}")
        self.shell = shell
        self.dt, self.c = time_step, damping
        self.upper = upper
        self.solver = SymmetricSolver(shell, fixed, upper=upper)
        self._fixed = fixed
        self.rtol, self.atol, self.max_iterations = rtol, atol, max_iterations
        record_stopping_criterion("rotation-free Newton", rtol, atol, "l2 norm of the residual")
        self.u = np.zeros(shell.n_dofs)
        self.v = np.zeros(shell.n_dofs)
        self.force = np.zeros(shell.n_dofs)
        self.M = shell.matrix(shell.mass_data).copy()  # a copy: the pattern arrays are the shell's
        self.M.eliminate_zeros()  # vertex–vertex blocks only: a fifth of the 12-node pattern
        self.data = np.zeros(len(shell.upper["indices"])) if upper else shell.new_data()
        self.mass_data = shell.upper["mass"] if upper else shell.mass_data
        self.grad = np.zeros(shell.n_dofs)
        self.extra = []
        # Newton's start (`_predict`): "select" takes the one of u_n and two polynomial
        # extrapolations of the past positions with the smallest incremental potential;
        # "previous" takes u_n (statics)
        self.predictor = "select"
        self.predictor_order = 4  # the higher extrapolation's degree (`_predict`)
        # the degree of the last step's chosen start (0: u_n; None: no choice was made)
        self._chosen_degree: int | None = None
        # (u, ∇Π(u), Π(u)) of the last gradient pass: the next step starts where this one
        # ended, so R(u_n) needs no new pass when nothing but the shell enters the gradient
        self._last_pass: tuple[np.ndarray, np.ndarray, float] | None = None
        self._strain_energy = 0.0  # Π(u) (shell + extra terms) of the last `_system` call
        # the velocities before v, newest first, with their step lengths (v_{n−1}, v_{n−2}, …)
        self.past: tuple[tuple[float, np.ndarray], ...] = ()
        self.v_step: float | None = None  # the step v was computed over (None: v was given: Δt)
        # None: a fresh Hessian and factorisation every iteration (Newton). A number s: every step
        # starts with fresh factors, which later iterations of the step reuse while each reduces
        # the residual to below s times the previous one (else fresh factors at the new iterate;
        # an iteration on reused factors that does not reduce it is undone first)
        self.stall: float | None = None
        # energy backtracking (off: it did not lower the iterations of the release)
        self.line_search = False
        # an indefinite Hessian (MUMPS' negative pivots) is shifted to positive definite before
        # the Newton solve (``SymmetricSolver.factor_positive``): the released roll's first
        # Hessian has 4 negative pivots, and Newton took 22 iterations from it, 10 with the shift
        # (the same converged steps: tests/test_rotation_free.py)
        self.inertia_correction = True
        # values of the `fixed` dofs at the end of the next step (None: held where they are):
        # a prescribed motion (the fold's rolled optic), set before `step`
        self.prescribed: np.ndarray | None = None
        self.contact = None
        self.obstacles = None
        self._keys = None  # the upper pattern as sorted row · n + col (with contact or obstacles)
        self.clock = dict.fromkeys(("residual", "jacobian", "factorisation", "solve", "contact", "other"),
                                   0.0)
        self.counts = dict.fromkeys(("iterations", "residuals", "jacobians", "factorisations", "shifted",
                                     "rejected", "pattern_growths", "step_limits"), 0)

    def set_contact(self, contact) -> None:
        """Self-contact (``surface_contact.SurfaceSelfContact``): its barrier joins the energy,
        its CCD limits every update, the energy line search is on; the Jacobian's pattern starts as the
        shell's upper triangle and grows by the 3 × 3 blocks of vertex pairs a contact Hessian brings
        (``_grow``)."""
        if not self.upper or self.extra:
            raise ValueError("self-contact runs on the upper-triangle Jacobian without extra terms")
        self.contact = contact
        # full Newton steps cycle against the barrier (a folded strip pressed onto itself:
        # residuals alternating 1e-7 / 1e-6 for 60 iterations, or 45 iterations in its first
        # step); the Armijo backtracking on the incremental potential, barrier included (IPC's
        # energy line search), takes 11 there
        self.line_search = True
        self.pattern_reach = 4.0  # the grown pattern holds the pairs within this many d̂
        self._init_keys()
        self._shell_map = np.arange(len(self._keys))
        self.shell_data = np.zeros(len(self._keys))

    def set_obstacles(self, obstacles) -> None:
        """Rigid obstacles met by the vertices (``surface_contact.NodalObstacles``): their
        penalty joins the energy; its Hessian blocks sit on the vertices' own 3 × 3 diagonal
        blocks, which the shell's pattern holds."""
        if not self.upper:
            raise ValueError("rigid obstacles run on the upper-triangle Jacobian")
        self.obstacles = obstacles
        self._init_keys()

    def _init_keys(self) -> None:
        if self._keys is None:
            n = self.shell.n_dofs
            up = self.shell.upper
            self._shell_keys = np.repeat(np.arange(n), np.diff(up["indptr"])) * n + up["indices"]
            self._keys = self._shell_keys.copy()

    def _obstacle_terms(self, u: np.ndarray, with_jacobian: bool) -> None:
        t0 = time.process_time()
        x = self.shell.X + u.reshape(-1, 3)
        self.grad += self.obstacles.gradient(x)
        if with_jacobian:
            nodes, blocks = self.obstacles.blocks(x)
            if len(nodes):
                a, c = np.triu_indices(3)
                n = self.shell.n_dofs
                keys = (3 * nodes[:, None] + a) * n + 3 * nodes[:, None] + c
                np.add.at(self.data, np.searchsorted(self._keys, keys.ravel()), blocks[:, a, c].ravel())
        self.clock["contact"] += time.process_time() - t0

    def _grow(self, keys: np.ndarray) -> None:
        """Add the (upper) 3 × 3 blocks of the vertex pairs of ``keys`` (row · n + col) to the
        pattern: a new matrix and symbolic factorisation (counted in ``pattern_growths``)."""
        n = self.shell.n_dofs
        v = np.sort(np.column_stack([keys // n // 3, keys % n // 3]), axis=1)
        v = np.unique(v, axis=0)
        a = 3 * v[:, 0, None, None] + np.arange(3)[None, :, None]
        b = 3 * v[:, 1, None, None] + np.arange(3)[None, None, :]
        blocks = (np.minimum(a, b) * n + np.maximum(a, b)).ravel()
        self._keys = np.union1d(self._keys, blocks)
        self._shell_map = np.searchsorted(self._keys, self._shell_keys)
        rows = self._keys // n
        indptr = np.zeros(n + 1, dtype=np.int64)
        np.add.at(indptr, rows + 1, 1)
        pattern = (np.cumsum(indptr), self._keys % n, np.searchsorted(self._keys, np.arange(n) * (n + 1)))
        self.solver = SymmetricSolver(self.shell, self._fixed, upper=True, pattern=pattern)
        self.mass_data = np.zeros(len(self._keys))
        self.mass_data[self._shell_map] = self.shell.upper["mass"]
        self.data = np.zeros(len(self._keys))
        self.counts["pattern_growths"] += 1

    def _contact_terms(self, u: np.ndarray, with_jacobian: bool) -> None:
        """Adds the barrier's gradient to ``grad`` and, with the Jacobian, its Hessian to
        ``data`` (growing the pattern first when it brings new vertex pairs)."""
        t0 = time.process_time()
        x = self.shell.X + u.reshape(-1, 3)
        self.grad += self.contact.gradient(x)
        if with_jacobian:
            hessian = self.contact.hessian(x)
            if hessian is not None:
                h = hessian.tocoo()
                keep = (h.row <= h.col) & (h.data != 0.0)
                keys = h.row[keep].astype(np.int64) * self.shell.n_dofs + h.col[keep]
                pos = np.searchsorted(self._keys, keys)
                if np.any(pos >= len(self._keys)) \
                        or np.any(self._keys[np.minimum(pos, len(self._keys) - 1)] != keys):
                    # a superset: every pair within `pattern_reach` d̂, not only the active ones
                    reach = self.pattern_reach * self.contact.dhat
                    self._grow(np.union1d(keys, self.contact.pairs_within(x, reach)))
                    pos = np.searchsorted(self._keys, keys)
                self._contact_entries = (pos, h.data[keep])
            else:
                self._contact_entries = None
        self.clock["contact"] += time.process_time() - t0

    @property
    def v_previous(self) -> np.ndarray | None:
        """v_{n−1}, the velocity of the step before the last (None: no such step)."""
        return self.past[0][1] if self.past else None

    @v_previous.setter
    def v_previous(self, value: np.ndarray | None) -> None:
        self.past = () if value is None else ((self.dt, value),)

    def save_state(self) -> tuple:
        """What ``step`` changes (u, v and the velocity history), for ``restore_state``."""
        return self.u.copy(), self.v.copy(), self.past, self.v_step

    def restore_state(self, state: tuple) -> None:
        u, v, self.past, self.v_step = state
        self.u, self.v = u.copy(), v.copy()

    def reset(self, u0: np.ndarray, v0: np.ndarray | None = None) -> None:
        self.u = np.array(u0, dtype=float)
        self.v = np.zeros_like(self.u) if v0 is None else np.array(v0, dtype=float)
        self.past, self.v_step = (), None
        self._last_pass = None
        self._chosen_degree = None
        self.clock = dict.fromkeys(self.clock, 0.0)
        self.counts = dict.fromkeys(self.counts, 0)

    def _system(self, u, u_n, v_n, with_jacobian: bool) -> np.ndarray:
        coefficient = 1.0 / self.dt ** 2 + self.c / self.dt
        t0, contact0 = time.process_time(), self.clock["contact"]  # contact time is booked apart
        self.grad[:] = 0.0
        if with_jacobian and self.contact is not None:
            self.shell_data[:] = 0.0
            energy = self.shell.evaluate(u, self.grad, self.shell_data, upper=True)
            self._contact_terms(u, True)  # may grow the pattern (new data / mass arrays)
            self.data[:] = 0.0
            self.data[self._shell_map] = self.shell_data
            self.data += coefficient * self.mass_data
            if self._contact_entries is not None:
                np.add.at(self.data, *self._contact_entries)
            if self.obstacles is not None:
                self._obstacle_terms(u, True)
            self.clock["jacobian"] += time.process_time() - t0 - (self.clock["contact"] - contact0)
            self.counts["jacobians"] += 1
        elif with_jacobian:
            np.multiply(self.mass_data, coefficient, out=self.data)  # the kernels add the Hessian to it
            energy = self.shell.evaluate(u, self.grad, self.data, upper=self.upper)
            for term in self.extra:
                energy += term(u, self.grad, self.data)
            if self.obstacles is not None:
                self._obstacle_terms(u, True)
            self.clock["jacobian"] += time.process_time() - t0 - (self.clock["contact"] - contact0)
            self.counts["jacobians"] += 1
        else:
            energy = self.shell.evaluate(u, self.grad)
            for term in self.extra:
                energy += term(u, self.grad, None)
            if self.contact is not None:
                self._contact_terms(u, False)
            if self.obstacles is not None:
                self._obstacle_terms(u, False)
            self.clock["residual"] += time.process_time() - t0 - (self.clock["contact"] - contact0)
        self.counts["residuals"] += 1
        self._strain_energy = energy
        if self.contact is None and self.obstacles is None and not self.extra:
            self._last_pass = (u.copy(), self.grad.copy(), energy)
        return self._residual(u, u_n, v_n)

    def _residual(self, u, u_n, v_n) -> np.ndarray:
        """R(u) from the gradient in ``grad``."""
        coefficient = 1.0 / self.dt ** 2 + self.c / self.dt
        r = self.grad - self.force + self.M @ (coefficient * (u - u_n) - v_n / self.dt)
        r[self.solver.fixed] = 0.0
        return r

    def _start_residual(self, u_n, v_n) -> np.ndarray:
        """R(u_n), from the last gradient pass where it was at u_n and nothing but the shell
        (whose gradient does not change between steps) entered it; else a new pass."""
        last = self._last_pass
        if last is not None and self.contact is None and self.obstacles is None and not self.extra \
                and np.array_equal(last[0], u_n):
            self.grad[:] = last[1]
            self._strain_energy = last[2]
            return self._residual(u_n, u_n, v_n)
        return self._system(u_n, u_n, v_n, False)

    def _potential(self, u, u_n, v_n, strain_energy: float) -> float:
        """``incremental_potential`` with Π(u) (shell and extra terms) given: the gradient pass
        that gave R(u) returned it, so only the barriers' energies are new work."""
        coefficient = 1.0 / self.dt ** 2 + self.c / self.dt
        w = u - u_n
        value = strain_energy - self.force @ u + w @ (self.M @ (0.5 * coefficient * w - v_n / self.dt))
        if self.contact is not None or self.obstacles is not None:
            t0 = time.process_time()
            x = self.shell.X + u.reshape(-1, 3)
            value += (0.0 if self.contact is None else self.contact.energy(x)) + \
                (0.0 if self.obstacles is None else self.obstacles.energy(x))
            self.clock["contact"] += time.process_time() - t0
        return value

    def incremental_potential(self, u, u_n, v_n) -> float:
        """Φ(u) = Π(u) − f·u + ½ (1/Δt² + c/Δt)(u − u_n)ᵀM(u − u_n) − (u − u_n)ᵀM v_n/Δt,
        whose gradient is R(u): the backward-Euler step minimises it."""
        coefficient = 1.0 / self.dt ** 2 + self.c / self.dt
        w = u - u_n
        x = self.shell.X + u.reshape(-1, 3)
        barrier = (0.0 if self.contact is None else self.contact.energy(x)) + \
            (0.0 if self.obstacles is None else self.obstacles.energy(x))
        return (self.shell.energy(u) + barrier + sum(term(u, np.zeros_like(u), None) for term in self.extra)
                - self.force @ u + w @ (self.M @ (0.5 * coefficient * w - v_n / self.dt)))

    def _line_search(self, u, du, r, u_n, v_n):
        """u − α du with α = 1, halved (at most 10 times) until the incremental potential Φ
        falls (Armijo, 10⁻⁴): large rotation increments of a displacement-only shell stretch
        the membrane when linearised, and Φ, not ‖R‖, tells a better state. The full step is
        taken when −du is not a descent direction of Φ (an indefinite Jacobian). With
        self-contact it runs only where the barrier acts (a pair within d̂ at u or at u − du):
        elsewhere the full step is the plain Newton one, as without contact."""
        trial = u - du
        slope = r @ du
        search = self.line_search and slope > 0.0
        if search and self.contact is not None:
            X = self.shell.X
            search = bool(len(self.contact.collisions(X + u.reshape(-1, 3)))
                          or len(self.contact.collisions(X + trial.reshape(-1, 3))))
        if search:
            phi0 = self.incremental_potential(u, u_n, v_n)
            alpha = 1.0
            for _ in range(10):
                if self.incremental_potential(trial, u_n, v_n) <= phi0 - 1e-4 * alpha * slope:
                    break
                alpha *= 0.5
                trial = u - alpha * du
        return trial, self._system(trial, u_n, v_n, False)

    def _collision_free_fraction(self, u: np.ndarray, step: np.ndarray) -> float:
        """The fraction of the straight path u → u + step that is collision-free (CCD)."""
        t0 = time.process_time()
        x0 = self.shell.X + u.reshape(-1, 3)
        fraction = self.contact.step_fraction(x0, x0 + step.reshape(-1, 3))
        self.clock["contact"] += time.process_time() - t0
        return fraction

    def _extrapolation(self, u_n: np.ndarray, v_n: np.ndarray, degree: int) -> np.ndarray:
        """The polynomial of ``degree`` through u_n and the ``degree`` positions before it
        (rebuilt from the velocities and their step lengths: u_{n−1} = u_n − h_n v_n, …) at
        t_n + Δt; with equal steps u_n + Δt v_n, u_n + Δt (2v_n − v_{n−1}),
        u_n + Δt (3v_n − 3v_{n−1} + v_{n−2}), …"""
        steps = [self.v_step or self.dt] + [h for h, _ in self.past]
        velocities = [v_n] + [v for _, v in self.past]
        times, points = [0.0], [u_n]
        for k in range(degree):
            times.append(times[-1] - steps[k])
            points.append(points[-1] - steps[k] * velocities[k])
        out = np.zeros_like(u_n)
        for i, (t_i, p_i) in enumerate(zip(times, points)):
            weight = np.prod([(self.dt - t_j) / (t_i - t_j) for j, t_j in enumerate(times) if j != i])
            out += weight * p_i
        return out

    def _predict(self, u_n, v_n, r_n, energy_n: float) -> tuple[np.ndarray, np.ndarray, bool]:
        """Newton's start, its residual, and whether the Jacobian there is assembled already.
        ``select``: of u_n (residual r_n, Π(u_n) = ``energy_n``) and the extrapolations of the
        past positions of degree 2 (u_n + Δt (2v_n − v_{n−1}) for equal steps; degree 1,
        u_n + Δt v_n, while there is one past step only) and of the highest degree the history
        gives up to ``predictor_order``, the one with the smallest incremental potential Φ (one
        gradient pass each, which also gives Π: a fraction of a Newton iteration). The step
        minimises Φ, so a lower Φ is a start nearer the solution in the energy norm; the
        residual's norm, dominated by the stiff membrane forces, is not: chosen by ‖R‖ among u_n
        and the degree-1 and 2 extrapolations, the released lens started from u_n in steps 2–17
        and its first update raised ‖R‖ 3–45×. Released lens, 30 steps: 91 Newton iterations by
        ‖R‖, 82 by Φ, 69 by Φ with the degree-4 candidate, which makes the steps from the 18th on
        one iteration each (docs/iol.md §4b).

        Where the highest-degree extrapolation was chosen in the last step (and no motion is
        prescribed, which replaces part of the start), it is evaluated first with the Jacobian
        (the Hessian pass gives the gradient and Π too) and taken when its Φ is below Φ(u_n):
        the smooth motion then costs no candidate pass beyond the first Newton iteration's (on
        the release from the 11th step on, where it is always the one chosen); else the full
        choice follows."""
        if self.predictor == "previous" or not np.any(v_n):
            self._chosen_degree = None
            return u_n.copy(), r_n, False
        available = 1 + len(self.past)
        top = min(self.predictor_order, available)
        phi_n = self._potential(u_n, u_n, v_n, energy_n)
        if top > 2 and self._chosen_degree == top and self.prescribed is None:
            u = self._extrapolation(u_n, v_n, top)
            if self.contact is None or self._collision_free_fraction(u_n, u - u_n) == 1.0:
                r = self._system(u, u_n, v_n, True)
                if self._potential(u, u_n, v_n, self._strain_energy) < phi_n:
                    return u, r, True
        best, best_r, best_phi, self._chosen_degree = u_n.copy(), r_n, phi_n, 0
        for degree in sorted({min(2, available), top}):
            u = self._extrapolation(u_n, v_n, degree)
            if self.contact is not None and self._collision_free_fraction(u_n, u - u_n) < 1.0:
                continue  # the barrier is not defined past a crossing
            r = self._system(u, u_n, v_n, False)
            phi = self._potential(u, u_n, v_n, self._strain_energy)
            if phi < best_phi:
                best, best_r, best_phi, self._chosen_degree = u, r, phi, degree
        return best, best_r, False

    def _prescribe(self, u_n: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The start iterate u with the fixed dofs at ``prescribed``. With self-contact the
        move u_n → u must not cross the surface (the barrier is undefined past a crossing):
        where the CCD shortens it, the step is refused (RuntimeError: the caller cuts Δt)."""
        u = u.copy()
        u[self.solver.fixed] = self.prescribed
        if self.contact is not None and self._collision_free_fraction(u_n, u - u_n) < 1.0:
            raise RuntimeError(f"the prescribed motion over Δt = {self.dt:g} s crosses the surface")
        return u

    def step(self) -> int:
        """One step from (u, v); returns the Newton iterations (each one linear solve, rejected
        ones included; ``max_iterations`` caps those on fresh factors and those on reused
        ones, each). The tolerance is relative to the residual at u_n (as in ``iol-speed``'s
        P2 loop, whose first iterate is u_n): ‖R‖ ≤ max(rtol ‖R(u_n)‖, atol). Raises
        RuntimeError when Newton does not converge (the state is then left at the last
        converged step)."""
        u_n, v_n = self.u.copy(), self.v.copy()
        r_n = self._start_residual(u_n, v_n)
        norm0 = np.linalg.norm(r_n)
        u, r, assembled = self._predict(u_n, v_n, r_n, self._strain_energy)
        if self.prescribed is not None:
            u = self._prescribe(u_n, u)
            r, assembled = self._system(u, u_n, v_n, False), False
            # the free dofs' reaction to the prescribed move is what Newton reduces
            norm0 = np.linalg.norm(r)
        tolerance = max(self.rtol * norm0, self.atol)
        norm, iterations, factorised, fresh = np.linalg.norm(r), 0, 0, True
        while norm > tolerance:
            # the cap bounds the iterations on fresh factors and, separately, those on reused ones
            if max(factorised, iterations - factorised) >= self.max_iterations or not np.isfinite(norm):
                self.counts["iterations"] += iterations  # a failed step's iterations count too
                raise RuntimeError(f"rotation-free Newton: no convergence in {iterations} iterations "
                                   f"(residual {norm:.3e} of {norm0:.3e}) at Δt = {self.dt:g} s")
            if fresh:
                if not assembled:  # the Jacobian (and the same residual again)
                    self._system(u, u_n, v_n, True)
                assembled = False
                t0 = time.process_time()
                if self.inertia_correction:
                    made = self.solver.factor_positive(self.data)
                    self.counts["shifted"] += made > 1
                else:
                    made = self.solver.factor(self.data) or 1
                self.clock["factorisation"] += time.process_time() - t0
                self.counts["factorisations"] += made
                factorised += 1
            t0 = time.process_time()
            du = self.solver.solve(r)
            self.clock["solve"] += time.process_time() - t0
            if self.contact is not None:
                fraction = self._collision_free_fraction(u, -du)
                if fraction < 1.0:
                    du = fraction * du
                    self.counts["step_limits"] += 1
            iterations += 1
            trial, r_trial = self._line_search(u, du, r, u_n, v_n)
            new = np.linalg.norm(r_trial)
            if not fresh and not new < norm:  # the reused factors no longer contract: undo, refresh
                self.counts["rejected"] += 1
                fresh = True
                continue
            fresh = self.stall is None or new > self.stall * norm
            u, r, norm = trial, r_trial, new
        self.counts["iterations"] += iterations
        self.u = u
        self.past = ((self.v_step or self.dt, v_n),) + self.past[:self.predictor_order - 2]
        self.v = (u - u_n) / self.dt
        self.v_step = self.dt
        return iterations


# --------------------------------------------------------------------------------------------
# benchmark meshes and runs (the shell benchmarks of docs/shell.md on this element)
# --------------------------------------------------------------------------------------------
def rectangle_mesh(length: float, width: float, nx: int, ny: int, kind: str = "structured",
                   seed: int = 0):
    """Points and triangles of [0, length] × [0, width] (z = 0): ``structured`` (each square
    cut along the same diagonal — direction-biased on purpose), ``crossed`` (alternating
    diagonals) or ``unstructured`` (gmsh frontal-Delaunay, size length/nx)."""
    if kind == "unstructured":
        return _gmsh_rectangle(length, width, length / nx, seed)
    xs, ys = np.linspace(0.0, length, nx + 1), np.linspace(0.0, width, ny + 1)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    points = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    tris = []
    for i in range(nx):
        for j in range(ny):
            a, b = i * (ny + 1) + j, (i + 1) * (ny + 1) + j
            c, d = (i + 1) * (ny + 1) + j + 1, i * (ny + 1) + j + 1
            if kind == "structured" or (i + j) % 2 == 0:
                tris += [[a, b, c], [a, c, d]]
            else:
                tris += [[a, b, d], [b, c, d]]
    return points, np.array(tris, dtype=np.int64)


def _gmsh_rectangle(length, width, size, seed):
    import gmsh

    initialised = gmsh.isInitialized()
    if not initialised:
        gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("rectangle")
    try:
        gmsh.model.occ.addRectangle(0, 0, 0, length, width)
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", size)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.option.setNumber("Mesh.RandomSeed", 1 + seed)
        gmsh.model.mesh.generate(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        points = coords.reshape(-1, 3)
        index = {int(t): i for i, t in enumerate(tags)}
        _, elements = gmsh.model.mesh.getElementsByType(2)
        tris = np.array([index[int(t)] for t in elements], dtype=np.int64).reshape(-1, 3)
    finally:
        gmsh.model.remove()
        if not initialised:
            gmsh.finalize()
    used = np.unique(tris)
    remap = -np.ones(len(points), dtype=np.int64)
    remap[used] = np.arange(len(used))
    return points[used], orient(points[used], remap[tris], lambda c: np.tile([0, 0, 1.0], (len(c), 1)))


# Timoshenko & Woinowsky-Krieger, Theory of plates and shells (1959), Tables 8 and 35:
# centre deflection of a square plate under uniform load q, in q L⁴ / D
PLATE_REFERENCE = {"simply": 0.00406235, "clamped": 0.00126532}


def plate_centre_deflection(support: str, divisions: int, kind: str = "structured",
                            poisson_ratio: float = 0.3, bending: str = "edge") -> float:
    """Linear centre deflection of the square plate (L = 10, h = 0.1, E = 1.092e6: D = 1 at
    ν = 0.3) under q = 1, in units of q L⁴ / D, with all edges ``support`` (simply: w = 0 and
    M_νν = 0; clamped: u = 0 and zero slope). All displacement components of boundary nodes
    are held (the in-plane ones do not enter a linear plate's bending)."""
    L, h, E = 10.0, 0.1, 1.092e6
    points, tris = rectangle_mesh(L, L, divisions, divisions, kind)
    shell = RotationFreeShell(points, tris, h, Material(E, poisson_ratio),
                              boundary=lambda m: [support] * len(m), bending=bending)
    D = E * h ** 3 / (12 * (1 - poisson_ratio ** 2))
    on_edge = np.flatnonzero(np.isclose(points[:, 0], 0) | np.isclose(points[:, 0], L)
                             | np.isclose(points[:, 1], 0) | np.isclose(points[:, 1], L))
    fixed = (3 * on_edge[:, None] + np.arange(3)).ravel()
    u = solve_linear(shell, shell.pressure_load(1.0), fixed).reshape(-1, 3)
    centre = np.argmin(np.linalg.norm(points[:, :2] - 0.5 * L, axis=1))
    if np.linalg.norm(points[centre, :2] - 0.5 * L) > 1e-9 * L:
        # no node at the centre (unstructured): the linear interpolant on the triangle holding it
        return _value_at(points, tris, u[:, 2], np.array([0.5 * L, 0.5 * L])) * D / L ** 4
    return u[centre, 2] * D / L ** 4


def _value_at(points, tris, values, p):
    for t in tris:
        a, b, c = points[t, :2]
        T = np.column_stack([b - a, c - a])
        lam = np.linalg.solve(T, p - a)
        if lam.min() >= -1e-12 and lam.sum() <= 1 + 1e-12:
            return values[t[0]] * (1 - lam.sum()) + values[t[1]] * lam[0] + values[t[2]] * lam[1]
    raise ValueError("point outside the mesh")


# --------------------------------------------------------------------------------------------
# the lens
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass
class FastLens:
    """The lens of ``LensParameters`` on the P1 triangles of its gmsh mesh (the P2 model's
    vertices), thickness per triangle (optic / haptics), free edges."""

    shell: RotationFreeShell
    optic_nodes: np.ndarray
    tip_nodes: np.ndarray  # the vertices of the first haptic's tip edge
    optic_triangles: np.ndarray
    haptic_triangles: np.ndarray

    @classmethod
    def build(cls, params, bending: str = "edge") -> "FastLens":
        from eyemech.meshes.iol import intraocular_lens  # noqa: I001 (first: it orders MPI ahead of DOLFINx)

        import dolfinx.mesh
        from mpi4py import MPI

        tagged = intraocular_lens(params.geometry(), MPI.COMM_SELF)
        mesh = tagged.mesh
        points = np.array(mesh.geometry.x, dtype=float)
        triangles = np.array(mesh.geometry.dofmaps[0], dtype=np.int64)
        optic = tagged.cells("optic")
        thickness = np.full(len(triangles), params.haptic_thickness)
        thickness[optic] = params.optic_thickness
        shell = RotationFreeShell(points, triangles, thickness,
                                  Material(params.youngs_modulus, params.poisson_ratio, params.density),
                                  up=lambda c: np.tile([0.0, 0.0, 1.0], (len(c), 1)), bending=bending)
        mesh.topology.create_connectivity(1, 0)
        tip = dolfinx.mesh.entities_to_geometry(mesh, 1, tagged.facets("tip_1"))
        haptic = np.setdiff1d(np.arange(len(triangles)), optic)
        return cls(shell, np.unique(triangles[optic]), np.unique(np.asarray(tip)), np.asarray(optic), haptic)

    def rolled_displacement(self, radius: float) -> np.ndarray:
        from eyemech.problems.lens.model import rolled

        X = self.shell.X
        return (rolled(X, 1.0 / radius) - X).ravel()


def release(params, steps: int | None = None, lens: FastLens | None = None, stall: float | None = None,
            self_contact: bool = False, obstacles: dict | None = None) -> dict:
    """The released rolled lens of ``iol-speed`` on the rotation-free model: per step the tip
    and optic-centre mean displacements, Newton iterations, and the CPU/wall time per phase.
    ``stall``: ``Dynamics.stall`` (None: a fresh factorisation every Newton iteration).
    ``self_contact``: ipctk self-contact on the P1 triangles (d̂ = ``self_contact_distance``,
    κ = ``self_contact_stiffness``), and ipctk's intersection check after every step (its
    time booked as contact); ``history["intersecting"]`` counts the steps that intersect.
    ``obstacles``: rigid ones (name → gap/normal obstacle, e.g. the capsule) met through the
    nodal penalty of stiffness ``contact_stiffness``; ``history["penetration"]`` per step."""
    lens = lens or FastLens.build(params)
    dyn = Dynamics(lens.shell, params.time_step, params.damping, rtol=params.rtol, atol=params.atol,
                   max_iterations=params.max_iterations)
    dyn.stall = stall
    contact = None
    if self_contact:
        from eyemech.problems.lens.surface_contact import SurfaceSelfContact

        contact = SurfaceSelfContact(lens.shell.X, lens.shell.tri, params.self_contact_distance,
                                     params.self_contact_stiffness)
        dyn.set_contact(contact)
    walls = None
    if obstacles:
        from eyemech.problems.lens.surface_contact import NodalObstacles

        walls = NodalObstacles(obstacles, params.contact_stiffness)
        dyn.set_obstacles(walls)
    steps = params.steps if steps is None else steps
    dyn.reset(lens.rolled_displacement(params.roll_radius))
    history = {"tip": [], "optic": [], "iterations": [], "intersecting": 0, "min_distance": np.inf,
               "penetration": []}
    from eyemech.problems.lens.time_error import TimeErrorTally, rotation_free_step_error

    time_error = TimeErrorTally()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for _ in range(steps):
        history["iterations"].append(dyn.step())
        time_error.add(rotation_free_step_error(dyn))
        u = dyn.u.reshape(-1, 3)
        history["tip"].append(u[lens.tip_nodes].mean(axis=0).tolist())
        history["optic"].append(u[lens.optic_nodes].mean(axis=0).tolist())
        if contact is not None:
            t0 = time.process_time()
            x = lens.shell.X + u
            history["intersecting"] += contact.intersecting(x)
            history["min_distance"] = min(history["min_distance"], contact.min_distance(x))
            dyn.clock["contact"] += time.process_time() - t0
        if walls is not None:
            history["penetration"].append(walls.max_penetration(lens.shell.X + u))
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    clock = dict(dyn.clock)
    clock["other"] = cpu - sum(v for k, v in clock.items() if k != "other")
    return {"wall": wall, "cpu": cpu, "phases_cpu": clock, "counts": dict(dyn.counts), "history": history,
            "time_error": time_error.quantities(), "dofs": lens.shell.n_dofs, "cells": len(lens.shell.tri),
            "nodes": len(lens.shell.X)}


# MacNeal & Harder, Finite Elem. Anal. Des. 1 (1985) 3-20: midpoint of the free edge, linear
SCORDELIS_LO_REFERENCE = 0.3024


def scordelis_lo_deflection(divisions: int, kind: str = "structured", bending: str = "edge") -> float:
    """The Scordelis–Lo roof of ``scordelis-lo`` (R 25, L 50, 80°, h 0.25, E 4.32e8, ν 0, self
    weight 90 per unit area) on the rotation-free element, linear: the vertical deflection at
    the midpoint of a free edge. Diaphragm ends: u_y = u_z = 0 and M_νν = 0; u_x held at the
    node nearest the roof's centre (removes the axial translation; the load is symmetric).
    The mesh is ``rectangle_mesh`` of the unit square mapped onto the roof."""
    R, L, half = 25.0, 50.0, np.radians(40.0)
    square, tris = rectangle_mesh(1.0, 1.0, divisions, divisions, kind)
    angle = (2.0 * square[:, 1] - 1.0) * half
    points = np.column_stack([L * square[:, 0], R * np.sin(angle), R * np.cos(angle)])
    ends = lambda m: ["simply" if (np.isclose(p[0], 0.0) or np.isclose(p[0], L)) else "free" for p in m]  # noqa: E731
    shell = RotationFreeShell(points, tris, 0.25, Material(4.32e8, 0.0), boundary=ends,
                              up=lambda c: np.column_stack([0.0 * c[:, 0], c[:, 1], c[:, 2]]),
                              bending=bending)
    end_nodes = np.flatnonzero(np.isclose(points[:, 0], 0.0) | np.isclose(points[:, 0], L))
    centre = np.argmin(np.linalg.norm(points - [L / 2, 0.0, R], axis=1))
    fixed = np.concatenate([3 * end_nodes + 1, 3 * end_nodes + 2, [3 * centre]])
    u = solve_linear(shell, shell.pressure_load(90.0, (0.0, 0.0, -1.0)), fixed).reshape(-1, 3)
    target = np.array([L / 2, R * np.sin(half), R * np.cos(half)])
    node = np.argmin(np.linalg.norm(points - target, axis=1))
    if np.linalg.norm(points[node] - target) > 1e-6 * L:
        raise ValueError("no node at the midpoint of the free edge: use an even number of divisions")
    return -float(u[node, 2])


def cantilever_frequency(divisions: int = 24, width_divisions: int = 4, kind: str = "structured",
                         bending: str = "edge") -> dict:
    """First bending frequency of the clamped strip of ``cantilever-vibration`` (6 × 1 × 0.13 mm,
    E 1 MPa, ν 0, ρ 1.2e-9 t/mm³) from K(0) φ = ω² M φ (consistent mass), against
    Euler–Bernoulli's ω₁ = 1.8751² √(EI/ρA)/L² = 105.8 rad/s."""
    import scipy.sparse.linalg

    L, b, h, E, rho = 6.0, 1.0, 0.13, 1.0, 1.2e-9
    points, tris = rectangle_mesh(L, b, divisions, width_divisions, kind)
    shell = RotationFreeShell(points, tris, h, Material(E, 0.0, rho),
                              boundary=lambda m: ["clamped" if np.isclose(p[0], 0.0) else "free" for p in m],
                              bending=bending)
    data = shell.new_data()
    shell.evaluate(np.zeros(shell.n_dofs), np.zeros(shell.n_dofs), data)
    free = np.setdiff1d(np.arange(shell.n_dofs), (3 * np.flatnonzero(np.isclose(points[:, 0], 0.0))[:, None]
                                                  + np.arange(3)).ravel())
    K = shell.matrix(data)[free][:, free].tocsc()
    M = shell.matrix(shell.mass_data)[free][:, free].tocsc()
    omega2 = scipy.sparse.linalg.eigsh(K, k=1, M=M, sigma=0.0, which="LM", return_eigenvectors=False)
    exact = 1.8751040687 ** 2 * np.sqrt(E * b * h ** 3 / 12 / (rho * b * h)) / L ** 2
    omega = float(np.sqrt(omega2[0]))
    return {"omega": omega, "omega_exact": exact, "error": omega / exact - 1}


def rolled_energy_ratio(divisions: int = 16, kind: str = "structured", angles=(0.0, 90.0),
                        poisson_ratio: float = 0.3, radius: float = 4.0, bending: str = "edge") -> dict:
    """Bending energy of the unit square (h = 0.01, E = 1) rolled isometrically onto a
    cylinder of ``radius`` whose axis makes each of ``angles`` (degrees) with the x axis, over
    the exact ½ D A / R². ``structured``: every square cut along the same diagonal (the mesh
    direction is biased on purpose), so 0° and 90° roll along and across it. Below 1 by the
    triangles at free edges parallel to the axis (their fit imposes M_νν = 0, an O(h) strip)."""
    points, tris = rectangle_mesh(1.0, 1.0, divisions, divisions, kind)
    h, E = 0.01, 1.0
    shell = RotationFreeShell(points, tris, h, Material(E, poisson_ratio), bending=bending)
    D = E * h ** 3 / (12 * (1 - poisson_ratio ** 2))
    exact = 0.5 * D / radius ** 2
    out = {}
    for angle in angles:
        t = np.radians(angle)
        axis = np.array([np.cos(t), np.sin(t), 0.0])
        across = np.array([-np.sin(t), np.cos(t), 0.0])
        p = points - [0.5, 0.5, 0.0]
        s_ = p @ across
        x = (0.5 + (p @ axis)[:, None] * axis + (radius * np.sin(s_ / radius))[:, None] * across)
        x = np.column_stack([x[:, 0], x[:, 1], radius * (1 - np.cos(s_ / radius))])
        out[angle] = shell.energy((x - points).ravel(), bending_only=True) / exact
    return out


def cantilever_rolling(divisions: int = 32, width_divisions: int = 2, moment_fraction: float = 1.0,
                       load_steps: int = 8, kind: str = "structured", line_search: bool = False,
                       bending: str = "edge") -> dict:
    """The strip of ``cantilever-rolling`` (L = 12, b = 1, h = 0.1, E = 1.2e6, ν = 0), root
    clamped (positions and slope), rolled by the end moment M = moment_fraction · 2π E I / L.
    The moment does work on the mean angle φ of the last row of segments in the x–z plane
    (−(M/b) Σ_j w_j φ_j, trapezoid weights w_j along the end, φ unwrapped about the last
    converged value). Returns the tip (u, w) at the end's midpoint and its distance from the
    exact circle's tip as a fraction of L."""
    L, b, h, E = 12.0, 1.0, 0.1, 1.2e6
    points, tris = rectangle_mesh(L, b, divisions, width_divisions, kind)
    root = np.isclose(points[:, 0], 0.0)
    shell = RotationFreeShell(points, tris, h, Material(E, 0.0),
                              boundary=lambda m: ["clamped" if np.isclose(p[0], 0.0) else "free" for p in m],
                              bending=bending)
    I = b * h ** 3 / 12
    full = 2 * np.pi * E * I / L
    end = np.flatnonzero(np.isclose(points[:, 0], L))
    end = end[np.argsort(points[end, 1])]
    inner = np.array([np.argmin(np.linalg.norm(points - (points[j] - [L / divisions, 0, 0]), axis=1))
                      for j in end])
    weights = np.full(len(end), b / (len(end) - 1))
    weights[[0, -1]] *= 0.5
    state = {"moment": 0.0, "reference": np.zeros(len(end))}

    def moment_term(u, grad, data):
        x = points + u.reshape(-1, 3)
        d = x[end] - x[inner]
        phi = np.arctan2(d[:, 2], d[:, 0])
        phi = state["reference"] + (phi - state["reference"] + np.pi) % (2 * np.pi) - np.pi
        r2 = d[:, 0] ** 2 + d[:, 2] ** 2
        scale = -state["moment"] / b * weights
        gx, gz = -d[:, 2] / r2, d[:, 0] / r2
        for sign, nodes in ((1.0, end), (-1.0, inner)):
            np.add.at(grad, 3 * nodes, sign * scale * gx)
            np.add.at(grad, 3 * nodes + 2, sign * scale * gz)
        if data is not None:
            hxx, hzz, hxz = 2 * d[:, 0] * d[:, 2] / r2 ** 2, -2 * d[:, 0] * d[:, 2] / r2 ** 2, \
                (d[:, 2] ** 2 - d[:, 0] ** 2) / r2 ** 2
            for si, ni in ((1.0, end), (-1.0, inner)):
                for sj, nj in ((1.0, end), (-1.0, inner)):
                    for (a, c), value in (((0, 0), hxx), ((2, 2), hzz), ((0, 2), hxz), ((2, 0), hxz)):
                        pos = _positions(shell, 3 * ni + a, 3 * nj + c)
                        np.add.at(data, pos, si * sj * scale * value)
        return float(np.sum(scale * phi))

    fixed = (3 * np.flatnonzero(root)[:, None] + np.arange(3)).ravel()
    dyn = Dynamics(shell, 1.0, 0.0, fixed=fixed, rtol=1e-8, atol=1e-9, max_iterations=100, upper=False)
    dyn.predictor = "previous"
    dyn.line_search = line_search
    # statics under the end moment: with the indefinite Hessians shifted, Newton stalled at a
    # residual of 1e-3 (of 5.8) after 100 iterations on the way to the full circle
    dyn.inertia_correction = False
    dyn.extra.append(moment_term)
    for k in range(1, load_steps + 1):
        state["moment"] = k / load_steps * moment_fraction * full
        dyn.v[:] = 0.0
        dyn.step()
        x = points + dyn.u.reshape(-1, 3)
        d = x[end] - x[inner]
        state["reference"] = state["reference"] + (np.arctan2(d[:, 2], d[:, 0]) - state["reference"]
                                                   + np.pi) % (2 * np.pi) - np.pi
    u = dyn.u.reshape(-1, 3)
    tip = u[end].mean(axis=0)
    angle = 2 * np.pi * moment_fraction
    radius = L / angle
    exact = (radius * np.sin(angle) - L, radius * (1 - np.cos(angle)))
    return {"tip_u": float(tip[0]), "tip_w": float(tip[2]), "tip_u_exact": exact[0], "tip_w_exact": exact[1],
            "tip_error": float(np.hypot(tip[0] - exact[0], tip[2] - exact[1]) / L),
            "end_rotation": float(np.mean(state["reference"]))}


def _positions(shell: RotationFreeShell, rows, cols):
    """Places of the (row, col) entries in the CSR values (they must be in the pattern)."""
    rows, cols = np.broadcast_arrays(rows, cols)
    start, stop = shell.indptr[rows], shell.indptr[rows + 1]
    out = np.empty(rows.shape, dtype=np.int64)
    for k, (r0, r1, c) in enumerate(zip(start.ravel(), stop.ravel(), cols.ravel())):
        out.flat[k] = r0 + np.searchsorted(shell.indices[r0:r1], c)
        if shell.indices[out.flat[k]] != c:
            raise ValueError(f"entry ({rows.flat[k]}, {c}) is not in the pattern")
    return out
