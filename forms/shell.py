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

    def bending_stiffness(self):
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
                  + 0.5 * penalty(degree, penalty_factor, size) * D * theta ** 2) * ds_clamped
    return bulk + edges


def end_rotation(u, co_normal, reference_angle, plane=(0, 2)):
    """Angle (in the plane of axes ``plane``) of the deformed material direction
    F ν at an edge, unwrapped around ``reference_angle`` (updated after each
    converged step so that rotations beyond ±π stay continuous)."""
    F = ufl.Identity(3) + ufl.grad(u)
    a = F * co_normal
    i, k = plane
    c, s = ufl.cos(reference_angle), ufl.sin(reference_angle)
    along = c * a[i] + s * a[k]
    across = -s * a[i] + c * a[k]
    return reference_angle + ufl.atan2(across, along)
