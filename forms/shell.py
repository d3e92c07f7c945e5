r"""Kirchhoff–Love (Koiter-type) shell on a triangle mesh of a surface in 3D.

Total Lagrangian. With reference position X on the (faceted) mid-surface, the
displacement u (C0 Lagrange, P2 or P3) and the surface gradient ``grad`` (UFL's
tangential gradient on a manifold):

    F = P + grad u,   P = I - N⊗N                       (surface deformation gradient)
    a_α = F g_α,      n = s (a_1 × a_2)/|a_1 × a_2|       (deformed basis and normal)
    E = ½ (FᵀF - P)                                       (membrane: change of metric)
    K = -Fᵀ grad n = n · ∂∂u   (on flat facets)          (bending: change of curvature)

with g_α the columns of the cell Jacobian and s = ±1 the cell orientation. Plane-stress
St Venant–Kirchhoff (the shell paper's χ):

    C(A) = E_Y/(1-ν²) ((1-ν) A + ν tr(A) P)
    W = ½ h C(E):E + ½ h³/12 C(K):K                       per unit reference area.

C0 elements carry no slope continuity, so the energy adds, on every interior edge,
the symmetric interior-penalty (Nitsche) terms of C0-IP plates (Engel et al. 2002,
Brenner & Sung 2005), written in the rotation of the normal across the edge:

    Π_edge = ∫ [ -{M_νν} Δθ + ½ γ {D} Δθ² ] dS,   γ = α p(p+1)/h_E,
    θ = atan2(n⁺·m⁻, n⁺·n⁻),  Δθ = θ - θ₀,       M = h³/12 C(K),  M_νν = ν·Mν,

m^± the deformed outward co-normals, ν the reference co-normal and θ₀ the kink of
the faceted reference surface (so a curved shell is not pre-stressed by its
facets). θ is the exact signed angle between the two deformed normals, so large
rigid rotations cost nothing. Clamped edges get the same terms against the fixed
neighbour (θ_b = atan2(-n·ν, n·N)).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import ufl
import ufl.algorithms

from eyemech.forms.kinematics import deformation_gradient

Kinematics = Literal["linear", "nonlinear"]


@dataclasses.dataclass(frozen=True)
class ShellMaterial:
    """Plane-stress St Venant–Kirchhoff; ``thickness`` may be a number or a field."""

    youngs_modulus: float
    poisson_ratio: float
    thickness: object  # float, dolfinx Constant or Function

    def plane_stress(self, strain, P):
        E, nu = self.youngs_modulus, self.poisson_ratio
        return E / (1.0 - nu ** 2) * ((1.0 - nu) * strain + nu * ufl.tr(strain) * P)

    @property
    def shear_modulus(self):
        """In-plane small-strain shear modulus μ = E / (2 (1 + ν))."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))

    def bending_stiffness(self):
        """Flexural rigidity D = E h³ / (12 (1 − ν²)): bending moment per unit curvature."""
        E, nu, h = self.youngs_modulus, self.poisson_ratio, self.thickness
        return E * h ** 3 / (12.0 * (1.0 - nu ** 2))


def _unit(v):
    return v / ufl.sqrt(ufl.dot(v, v))


@dataclasses.dataclass
class ShellGeometry:
    """Reference and deformed surface quantities (UFL) of one displacement ``u``;
    ``linear`` gives their first-order (small displacement) versions."""

    u: object
    orientation: object  # DG0 ±1
    linear: bool = False

    def __post_init__(self):
        mesh = ufl.domain.extract_unique_domain(self.u)
        self.mesh = mesh
        J = ufl.Jacobian(mesh)
        g = [J[:, 0], J[:, 1]]
        self.N = self.orientation * _unit(ufl.cross(g[0], g[1]))
        self.P = ufl.Identity(3) - ufl.outer(self.N, self.N)
        self.G = ufl.grad(self.u)
        self.F = self.P + self.G
        if self.linear:
            self.n = self.N - self.G.T * self.N  # N + δn, δn = -Gᵀ N
        else:
            self.n = self.orientation * _unit(ufl.cross(self.F * g[0], self.F * g[1]))

    def membrane_strain(self):
        if self.linear:
            return 0.5 * (self.P * self.G + self.G.T * self.P)
        return 0.5 * (self.F.T * self.F - self.P)

    def bending_strain(self):
        """K_ij = n · ∂_i ∂_j x: equal to -Fᵀ grad n because n ⟂ F, and cheaper to
        differentiate. On flat (affine) facets ∂∂X = 0, so K₀ = 0 inside cells and the
        reference curvature lives in the edge kinks θ₀."""
        i, j, k = ufl.indices(3)
        H = ufl.grad(ufl.grad(self.u))
        normal = self.N if self.linear else self.n
        return ufl.as_tensor(normal[k] * H[k, i, j], (i, j))


def _tangent(geometry: ShellGeometry, side: str):
    """Reference edge direction τ = N × ν of one side (so that τ × N = ν, outward)."""
    return ufl.cross(geometry.N(side), ufl.FacetNormal(geometry.mesh)(side))


def _co_normal(geometry: ShellGeometry, side: str):
    """Deformed outward co-normal m = t × n of one side of an edge (t = F τ/|F τ|)."""
    t = _unit(geometry.F(side) * _tangent(geometry, side))
    return ufl.cross(t, geometry.n(side))


def _atan2_change(sine, cosine, d_sine, d_cosine):
    """First-order change of atan2(sine, cosine)."""
    return (cosine * d_sine - sine * d_cosine) / (sine ** 2 + cosine ** 2)


def normal_rotation_jump(geometry: ShellGeometry):
    """θ - θ₀ on interior edges: change of the signed angle between the normals of
    the two cells (positive = the sense of [[∂w/∂ν]] for a plate)."""
    N_p, N_m = geometry.N("+"), geometry.N("-")
    nu_m = ufl.FacetNormal(geometry.mesh)("-")
    sine0, cosine0 = ufl.dot(N_p, nu_m), ufl.dot(N_p, N_m)
    if not geometry.linear:
        n_p, n_m = geometry.n("+"), geometry.n("-")
        theta = ufl.atan2(ufl.dot(n_p, _co_normal(geometry, "-")), ufl.dot(n_p, n_m))
        return theta - ufl.atan2(sine0, cosine0)
    dn_p, dn_m = geometry.n("+") - N_p, geometry.n("-") - N_m
    tau = _tangent(geometry, "-")
    G = geometry.G("-")
    dt = G * tau - ufl.dot(tau, G * tau) * tau
    dm = ufl.cross(dt, N_m) + ufl.cross(tau, dn_m)
    d_sine = ufl.dot(dn_p, nu_m) + ufl.dot(N_p, dm)
    d_cosine = ufl.dot(dn_p, N_m) + ufl.dot(N_p, dn_m)
    return _atan2_change(sine0, cosine0, d_sine, d_cosine)


def clamped_rotation(geometry: ShellGeometry):
    """Rotation of the normal at a clamped edge (whose neighbour does not move)."""
    nu = ufl.FacetNormal(geometry.mesh)
    if geometry.linear:
        return -ufl.dot(geometry.n - geometry.N, nu)
    return ufl.atan2(-ufl.dot(geometry.n, nu), ufl.dot(geometry.n, geometry.N))


def bending_moment(geometry: ShellGeometry, material: ShellMaterial):
    h = material.thickness
    return h ** 3 / 12.0 * material.plane_stress(geometry.bending_strain(), geometry.P)


def penalty(degree: int, factor: float, h_edge):
    """γ = α p(p+1)/h: the trace-inverse constant grows like p², the edge term like 1/h."""
    return factor * degree * (degree + 1) / h_edge


def normal_height(mesh):
    """2|T|/|e|: the cell's height over the facet. The trace inverse inequality
    ‖∂v/∂ν‖²_e ≤ C p²/h ‖∇v‖²_T holds with this h on stretched cells; the cell diameter
    is the long side and underestimates the penalty a clamped edge needs there."""
    return 2.0 * ufl.CellVolume(mesh) / ufl.FacetArea(mesh)


def shell_energy(u, material: ShellMaterial, orientation, *, degree: int, penalty_factor,
                 dx: ufl.Measure, dS: ufl.Measure, ds_clamped: ufl.Measure | None = None,
                 kinematics: Kinematics = "nonlinear"):
    """Total Lagrangian Kirchhoff–Love energy (membrane + bending + interior penalty);
    ``kinematics="linear"``: the same with strains and rotations to first order in u
    (a quadratic energy: the small-displacement shell)."""
    geo = ShellGeometry(u, orientation, linear=(kinematics == "linear"))
    h = material.thickness
    E, K = geo.membrane_strain(), geo.bending_strain()
    M = bending_moment(geo, material)
    bulk = (0.5 * h * ufl.inner(material.plane_stress(E, geo.P), E) + 0.5 * ufl.inner(M, K)) * dx

    mesh = geo.mesh
    nu = ufl.FacetNormal(mesh)
    size = ufl.CellDiameter(mesh)
    D = material.bending_stiffness()
    jump = normal_rotation_jump(geo)
    moment_avg = 0.5 * (ufl.dot(nu("+"), M("+") * nu("+")) + ufl.dot(nu("-"), M("-") * nu("-")))
    gamma = penalty(degree, penalty_factor, 0.5 * (size("+") + size("-")))
    D_avg = 0.5 * (D("+") + D("-")) if ufl.algorithms.extract_coefficients(D) else D
    edges = (-moment_avg * jump + 0.5 * gamma * D_avg * jump ** 2) * dS
    if ds_clamped is not None:
        theta = clamped_rotation(geo)
        edges += (-ufl.dot(nu, M * nu) * theta
                  + 0.5 * penalty(degree, penalty_factor, normal_height(mesh)) * D * theta ** 2) * ds_clamped
    return bulk + edges


def end_rotation(u, co_normal, reference_angle, plane=(0, 2)):
    """Angle (in the plane of axes ``plane``) of the deformed material direction
    F ν at an edge, unwrapped around ``reference_angle`` (updated after each
    converged step so that rotations beyond ±π stay continuous)."""
    F = deformation_gradient(u)
    a = F * co_normal
    i, k = plane
    c, s = ufl.cos(reference_angle), ufl.sin(reference_angle)
    along = c * a[i] + s * a[k]
    across = -s * a[i] + c * a[k]
    return reference_angle + ufl.atan2(across, along)




class _Variations:
    """The nonlinear shell's quantities with their first variations in the directions v
    (``d``) and w (``D``): everything the explicit second variation needs, in the cell's
    covariant frame (2×2 strains: a_α = F g_α, E_αβ = g_α·E g_β = ½(a_α·a_β − g_α·g_β),
    K_αβ = g_α·K g_β = n·∂_α∂_β x) — the same tensors as the 3×3 ones of ``ShellGeometry``
    (E = Kᵀ E_αβ K with K the pseudo-inverse of the cell Jacobian), but with 3 independent
    components instead of 9, which is what the size of the generated kernel scales with.
    All of it is unrestricted UFL unless ``restrict`` (one side of a facet) is given."""

    def __init__(self, u, v, w, orientation, restrict=None):
        r = restrict or (lambda x: x)
        mesh = ufl.domain.extract_unique_domain(u)
        J = ufl.Jacobian(mesh)
        g = [r(J[:, 0]), r(J[:, 1])]
        pseudo_inverse = r(ufl.JacobianInverse(mesh))
        self.metric_inverse = pseudo_inverse * pseudo_inverse.T  # G^αβ
        self.pseudo_inverse = pseudo_inverse
        self.s = r(orientation)
        self.N = r(orientation * _unit(ufl.cross(J[:, 0], J[:, 1])))
        self.P = ufl.Identity(3) - ufl.outer(self.N, self.N)
        self.F = self.P + r(ufl.grad(u))
        self.dG, self.DG = r(ufl.grad(v)), r(ufl.grad(w))
        pairs = ((0, 0), (0, 1), (1, 1))

        def second(f):  # ∂_α∂_β f for (αβ) in pairs: g_α · grad grad f · g_β
            H = r(ufl.grad(ufl.grad(f)))
            i, j, k = ufl.indices(3)
            return [ufl.as_vector(H[k, i, j] * g[al][i] * g[be][j], k) for al, be in pairs]

        self.U, self.dU, self.DU = second(u), second(v), second(w)
        self.a = [self.F * gi for gi in g]
        da = [self.dG * gi for gi in g]
        Da = [self.DG * gi for gi in g]
        self.da, self.Da = da, Da
        dot = ufl.dot

        def matrix(entries):  # symmetric 2×2 from the (00, 01, 11) entries
            return ufl.as_matrix([[entries[0], entries[1]], [entries[1], entries[2]]])

        a = self.a
        self.E = matrix([0.5 * (dot(a[al], a[be]) - dot(g[al], g[be])) for al, be in pairs])
        self.dE = matrix([0.5 * (dot(da[al], a[be]) + dot(a[al], da[be])) for al, be in pairs])
        self.DE = matrix([0.5 * (dot(Da[al], a[be]) + dot(a[al], Da[be])) for al, be in pairs])
        self.dDE = matrix([0.5 * (dot(da[al], Da[be]) + dot(Da[al], da[be])) for al, be in pairs])
        self.c = ufl.cross(a[0], a[1])
        self.length = ufl.sqrt(dot(self.c, self.c))
        self.c_hat = self.c / self.length
        self.n = self.s * self.c_hat
        self.dc = ufl.cross(da[0], a[1]) + ufl.cross(a[0], da[1])
        self.Dc = ufl.cross(Da[0], a[1]) + ufl.cross(a[0], Da[1])
        self.dDc = ufl.cross(da[0], Da[1]) + ufl.cross(Da[0], da[1])
        self.dn = self._unit_variation(self.dc)
        self.Dn = self._unit_variation(self.Dc)
        n, dn, Dn = self.n, self.dn, self.Dn
        self.K = matrix([dot(n, x) for x in self.U])
        self.dK = matrix([dot(dn, x) + dot(n, dx) for x, dx in zip(self.U, self.dU)])
        self.DK = matrix([dot(Dn, x) + dot(n, Dx) for x, Dx in zip(self.U, self.DU)])
        # the part of ΔδK that is a product of first variations (the rest is Δδn · U)
        self.dDK_products = matrix([dot(dn, Dx) + dot(Dn, dx) for dx, Dx in zip(self.dU, self.DU)])

    def _unit_variation(self, dc):
        """δn = s (δc − ĉ (ĉ·δc)) / |c|."""
        return self.s * (dc - self.c_hat * ufl.dot(self.c_hat, dc)) / self.length

    def weighted_U(self, S):
        """x = Σ_αβ S^αβ U_αβ (S symmetric 2×2): Δδn·x is S:(Δδn·U)."""
        return S[0, 0] * self.U[0] + 2.0 * S[0, 1] * self.U[1] + S[1, 1] * self.U[2]

    def normal_second_variation(self, x):
        """Δδn · x for a u-only vector x (the weights back-propagated onto Δδn):
        δcᵀ ∇²(s ĉ·x) Δc + (s P_c x/|c|) · Δδc, ∇²(s ĉ·x) = −s/|c|² (x ĉᵀ + ĉ xᵀ + (ĉ·x)(I − 3ĉĉᵀ))."""
        return _unit_second_variation(self.c_hat, self.length, self.s, x, self.dc, self.Dc, self.dDc)


class _CovariantLaw:
    """Plane-stress St Venant–Kirchhoff on covariant 2×2 strains: with A = Kᵀ Ã K,
    C(A):B = c ((1-ν) tr(Ã G⁻¹ B̃ G⁻¹) + ν tr(G⁻¹Ã) tr(G⁻¹B̃)), c = E_Y/(1-ν²)."""

    def __init__(self, material: ShellMaterial, metric_inverse):
        self.c = material.youngs_modulus / (1.0 - material.poisson_ratio ** 2)
        self.nu = material.poisson_ratio
        self.Gi = metric_inverse

    def stress(self, A):
        """S̃ with C(A):B = S̃:B̃ (contravariant)."""
        Gi = self.Gi
        return self.c * ((1.0 - self.nu) * Gi * A * Gi + self.nu * ufl.tr(Gi * A) * Gi)

    def pair(self, A, B):
        return ufl.inner(self.stress(A), B)


def _unit_second_variation(c_hat, length, s, x, dc, Dc, dDc=None):
    """Δδ(s ĉ) · x for ĉ = c/|c| with the variations δc, Δc, Δδc of c."""
    dot = ufl.dot
    hessian = -s / length ** 2 * (dot(dc, x) * dot(c_hat, Dc) + dot(dc, c_hat) * dot(x, Dc)
                                  + dot(c_hat, x) * (dot(dc, Dc) - 3.0 * dot(dc, c_hat) * dot(c_hat, Dc)))
    if dDc is None:
        return hessian
    y = s * (x - c_hat * dot(c_hat, x)) / length
    return hessian + dot(y, dDc)


def shell_jacobian(u, v, w, material: ShellMaterial, orientation, *, degree: int, penalty_factor,
                   dx: ufl.Measure, dS: ufl.Measure):
    """Π''(u)[v, w] of the nonlinear ``shell_energy`` (no clamped edges) written out by hand:
    the same bilinear form as ``derivative(derivative(energy, u, v), u, w)`` up to
    round-off, but every second variation of an intermediate quantity (the normal, the edge
    tangent) is contracted at once with the u-only weight it meets in the energy, so the
    argument-dependent factors stay first variations, and the strains are the covariant
    2×2 ones (``_Variations``). UFL's symbolic derivative instead carries Δδn, Δδm, … as
    full (test × trial) expressions through the whole composite energy, and FFCx emits
    megabytes of C per kernel for it.

    Bulk:   h [C(δE):ΔE + C(E):ΔδE] + h³/12 [C(δK):ΔK + C(K):ΔδK],
            δE_αβ = ½(δa_α·a_β + a_α·δa_β), ΔδE_αβ = ½(δa_α·Δa_β + Δa_α·δa_β),
            δK = δn·U + n·δU, ΔδK = Δδn·U + δn·ΔU + Δn·δU  (U_αβ = ∂_α∂_β u).
    Edges:  e = −{M_νν} θ + ½ γ {D} θ²  ⇒
            Δδe = −δ{M_νν} Δθ − Δ{M_νν} δθ + γ{D} δθ Δθ + (γ{D} θ − {M_νν}) Δδθ − θ Δδ{M_νν},
            θ = atan2(S, C), S = n⁺·m⁻, C = n⁺·n⁻, m = t × n, t = Fτ/|Fτ|."""
    h = material.thickness
    Db = h ** 3 / 12.0
    q = _Variations(u, v, w, orientation)
    law = _CovariantLaw(material, q.metric_inverse)
    SK = law.stress(q.K)
    bulk = (h * (law.pair(q.dE, q.DE) + law.pair(q.E, q.dDE))
            + Db * (law.pair(q.dK, q.DK) + ufl.inner(SK, q.dDK_products)
                    + q.normal_second_variation(q.weighted_U(SK))))
    edges = _edge_second_variation(u, v, w, material, orientation, degree, penalty_factor)
    return bulk * dx + edges * dS


def _edge_second_variation(u, v, w, material: ShellMaterial, orientation, degree: int,
                           penalty_factor):
    """The interior edges' part of :func:`shell_jacobian` (its "Edges" line): Δδe, to be
    integrated over dS."""
    Db = material.thickness ** 3 / 12.0
    mesh = ufl.domain.extract_unique_domain(u)
    nu = ufl.FacetNormal(mesh)
    size = ufl.CellDiameter(mesh)
    D = material.bending_stiffness()
    D_avg = 0.5 * (D("+") + D("-")) if ufl.algorithms.extract_coefficients(D) else D
    gamma = penalty(degree, penalty_factor, 0.5 * (size("+") + size("-")))
    p = _Variations(u, v, w, orientation, lambda x: x("+"))
    m = _Variations(u, v, w, orientation, lambda x: x("-"))
    dot, cross = ufl.dot, ufl.cross
    # the deformed tangent of the "-" side and its variations (f = F τ is linear in u)
    tau = cross(m.N, nu("-"))
    f = m.F * tau
    f_len = ufl.sqrt(dot(f, f))
    t = f / f_len
    df, Df = m.dG * tau, m.DG * tau
    dt = (df - t * dot(t, df)) / f_len
    Dt = (Df - t * dot(t, Df)) / f_len
    co = cross(t, m.n)
    dco = cross(dt, m.n) + cross(t, m.dn)
    Dco = cross(Dt, m.n) + cross(t, m.Dn)
    sine, cosine = dot(p.n, co), dot(p.n, m.n)
    d_sine = dot(p.dn, co) + dot(p.n, dco)
    D_sine = dot(p.Dn, co) + dot(p.n, Dco)
    d_cosine = dot(p.dn, m.n) + dot(p.n, m.dn)
    D_cosine = dot(p.Dn, m.n) + dot(p.n, m.Dn)
    r2 = sine ** 2 + cosine ** 2
    theta = ufl.atan2(sine, cosine) - ufl.atan2(dot(p.N, nu("-")), dot(p.N, m.N))
    d_theta = (cosine * d_sine - sine * d_cosine) / r2
    D_theta = (cosine * D_sine - sine * D_cosine) / r2
    # Δδθ without the second variations of S and C (those are weighted below)
    dD_theta_products = ((D_cosine * d_sine - D_sine * d_cosine) / r2
                         - 2.0 * d_theta * (sine * D_sine + cosine * D_cosine) / r2
                         + (cosine * (dot(p.dn, Dco) + dot(p.Dn, dco))
                            - sine * (dot(p.dn, m.Dn) + dot(p.Dn, m.dn))) / r2
                         + cosine * dot(p.n, cross(dt, m.Dn) + cross(Dt, m.dn)) / r2)

    def side_weights(side_q, side):
        """L^αβ with M_νν = L:K (covariant): h³/12 ν·C(K)ν, ν̃ = K ν (K the pseudo-inverse)."""
        n_ = nu(side)
        nt = side_q.pseudo_inverse * n_
        law_ = _CovariantLaw(material, side_q.metric_inverse)
        thick = Db(side) if _varies(Db) else Db
        return thick * law_.c * ((1.0 - law_.nu) * ufl.outer(nt, nt)
                                 + law_.nu * dot(n_, side_q.P * n_) * side_q.metric_inverse)

    L_p, L_m = side_weights(p, "+"), side_weights(m, "-")
    M_avg = 0.5 * (ufl.inner(L_p, p.K) + ufl.inner(L_m, m.K))
    dM = 0.5 * (ufl.inner(L_p, p.dK) + ufl.inner(L_m, m.dK))
    DM = 0.5 * (ufl.inner(L_p, p.DK) + ufl.inner(L_m, m.DK))
    dDM_products = 0.5 * (ufl.inner(L_p, p.dDK_products) + ufl.inner(L_m, m.dDK_products))
    weight = gamma * D_avg * theta - M_avg  # what Δδθ meets
    # Δδθ's second variations: (C ΔδS − S ΔδC)/r², ΔδS ∋ Δδn⁺·m⁻ + Δδt·(n⁻×n⁺) + Δδn⁻·(n⁺×t),
    # ΔδC ∋ Δδn⁺·n⁻ + n⁺·Δδn⁻; and −θ Δδ{M_νν} ∋ −½θ Δδn·(L:U) on each side
    x_plus = weight * (cosine * co - sine * m.n) / r2 - 0.5 * theta * p.weighted_U(L_p)
    x_minus = weight * (cosine * cross(p.n, t) - sine * p.n) / r2 - 0.5 * theta * m.weighted_U(L_m)
    y_t = weight * cosine * cross(m.n, p.n) / r2
    edges = (-dM * D_theta - DM * d_theta + gamma * D_avg * d_theta * D_theta
             + weight * dD_theta_products - theta * dDM_products
             + p.normal_second_variation(x_plus) + m.normal_second_variation(x_minus)
             + _unit_second_variation(t, f_len, 1.0, y_t, df, Df))
    return edges


def _varies(value) -> bool:
    return bool(ufl.algorithms.extract_coefficients(value))
