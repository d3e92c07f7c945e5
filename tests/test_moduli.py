"""Every law of forms/ carries its small-strain moduli (``shear_modulus``,
``youngs_modulus``, ``bulk_modulus`` where the law has one), and each is checked here
against the law's own linearisation, not against its formula: the second derivative
d²W/dt² of the law's energy along F = I + t D at t = 0, evaluated by DOLFINx (one compiled
expression for every law and direction), for

- simple shear D = e₁⊗e₂:                  μ = d²W/dt²,
- the isochoric stretch D = diag(1, −½, −½):  E = d²W/dt² (an incompressible law),
- uniform dilatation D = I:                   K = d²W/dt² / 9,
- uniaxial stress of a compressible law: the quadratic form Q(D) = d²W/dt² on the axial
  strain a = diag(1, 0, 0) and the lateral b = diag(0, 1, 1), minimised over the
  lateral strain: E = Q(a) − Q(a, b)² / Q(b).

The first derivative there is checked to vanish (a stress-free reference, so the second
derivative is the small-strain stiffness). The shell's plane-stress law is read from its
stress–strain map instead (its energy is ½ h C(E):E). ≈ 10 s, most of it compilation."""

from __future__ import annotations

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from eyemech.forms import CompressibleNeoHooke, MooneyRivlin, NeoHooke, PolynomialIsochoric, Yeoh
from eyemech.forms.shell import ShellMaterial
from eyemech.forms.viscoelastic import Viscoelastic, isochoric_cauchy_green

ISOCHORIC = {
    "neo-Hooke": NeoHooke(0.35),
    "Mooney-Rivlin": MooneyRivlin(0.2, 0.07),
    "polynomial": PolynomialIsochoric(((1, 0, 0.1), (0, 1, 0.04), (2, 0, 3.0), (1, 1, -0.5),
                                       (0, 3, 2.0))),
    "Yeoh": Yeoh(0.12, 4.0, 30.0),
}
VISCOELASTIC = Viscoelastic(mu_inf=0.03, mu_v=0.05, tau=3000.0)
COMPRESSIBLE = CompressibleNeoHooke(youngs_modulus=2.5, poisson_ratio=0.3)

SHEAR = np.zeros((3, 3))
SHEAR[0, 1] = 1.0
DIRECTIONS = {"shear": SHEAR, "isochoric stretch": np.diag([1.0, -0.5, -0.5]),
              "dilatation": np.eye(3), "axial": np.diag([1.0, 0.0, 0.0]),
              "lateral": np.diag([0.0, 1.0, 1.0]), "axial + lateral": np.diag([1.0, 1.0, 1.0])}


def _energies() -> dict[str, callable]:
    """Energy densities W(F) whose second derivatives at F = I are read."""
    energies = {name: law.strain_energy for name, law in ISOCHORIC.items()}
    # relaxed: the viscous branch has flowed to Cv = C̄ (no stress in it); glassy: Cv = I
    energies["viscoelastic relaxed"] = lambda F: VISCOELASTIC.free_energy(F, isochoric_cauchy_green(F))
    energies["viscoelastic glassy"] = lambda F: VISCOELASTIC.free_energy(F, ufl.Identity(3))
    energies["compressible neo-Hooke"] = COMPRESSIBLE.strain_energy
    return energies


@pytest.fixture(scope="module")
def curvatures() -> dict[tuple[str, str], float]:
    """d²W/dt² at t = 0 along F = I + t D, by (energy, direction)."""
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1)
    zero = dolfinx.fem.Constant(mesh, 0.0)
    keys, rows = [], []
    for name, energy in _energies().items():
        for direction, D in DIRECTIONS.items():
            t = ufl.variable(zero)
            W = energy(ufl.Identity(3) + t * ufl.as_matrix(D.tolist()))
            first = ufl.diff(W, t)
            keys.append((name, direction))
            rows.append(ufl.as_vector([first, ufl.diff(first, t)]))
    values = dolfinx.fem.Expression(ufl.as_matrix([[r[0], r[1]] for r in rows]),
                                    np.zeros((1, 3))).eval(mesh, np.array([0], np.int32))
    values = values.reshape(len(keys), 2)
    del mesh, zero
    for key, (slope, _) in zip(keys, values):
        assert abs(slope) < 1e-13, f"{key}: the reference is not stress free"
    return {key: float(curvature) for key, (_, curvature) in zip(keys, values)}


@pytest.mark.parametrize("name", ISOCHORIC)
def test_isochoric_laws_carry_the_moduli_of_their_linearisation(curvatures, name):
    law = ISOCHORIC[name]
    assert law.shear_modulus == pytest.approx(curvatures[name, "shear"], rel=1e-12)
    assert law.youngs_modulus == pytest.approx(curvatures[name, "isochoric stretch"], rel=1e-12)
    # the isochoric law has no bulk stiffness of its own: a dilatation costs nothing
    assert abs(curvatures[name, "dilatation"]) < 1e-12 * law.shear_modulus


def test_viscoelastic_law_carries_its_relaxed_and_glassy_moduli(curvatures):
    law = VISCOELASTIC
    relaxed = lambda direction: curvatures["viscoelastic relaxed", direction]
    glassy = lambda direction: curvatures["viscoelastic glassy", direction]
    assert law.shear_modulus == pytest.approx(relaxed("shear"), rel=1e-12)
    assert law.youngs_modulus == pytest.approx(relaxed("isochoric stretch"), rel=1e-12)
    assert law.glassy_shear_modulus == pytest.approx(glassy("shear"), rel=1e-12)
    assert law.glassy_youngs_modulus == pytest.approx(glassy("isochoric stretch"), rel=1e-12)
    # the standard linear solid's creep time from the two moduli (forms/viscoelastic.py)
    assert law.retardation_time == pytest.approx(law.tau * glassy("shear") / relaxed("shear"),
                                                 rel=1e-12)


def test_compressible_law_carries_shear_youngs_and_bulk_moduli(curvatures):
    law = COMPRESSIBLE
    Q = lambda direction: curvatures["compressible neo-Hooke", direction]
    mixed = 0.5 * (Q("axial + lateral") - Q("axial") - Q("lateral"))
    assert law.shear_modulus == pytest.approx(Q("shear"), rel=1e-12)
    assert law.youngs_modulus == pytest.approx(Q("axial") - mixed ** 2 / Q("lateral"), rel=1e-12)
    assert law.bulk_modulus == pytest.approx(Q("dilatation") / 9.0, rel=1e-12)


def test_shell_law_carries_its_in_plane_moduli():
    """The plane-stress law of the shell (ShellMaterial.plane_stress), in the plane x₃ = 0:
    a shear strain ε₁₂ gives σ₁₂ = 2μ ε₁₂; a stretch ε₁₁ with the lateral ε₂₂ that
    leaves σ₂₂ = 0 gives σ₁₁ = E ε₁₁ (the law is linear: two evaluations fix ε₂₂)."""
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1)
    law = ShellMaterial(youngs_modulus=1.7e3, poisson_ratio=0.42, thickness=0.2)
    P = dolfinx.fem.Constant(mesh, np.diag([1.0, 1.0, 0.0]))
    strains = [np.diag([1.0, 0.0, 0.0]), np.diag([0.0, 1.0, 0.0]), SHEAR + SHEAR.T]
    stresses = dolfinx.fem.Expression(
        ufl.as_tensor([law.plane_stress(dolfinx.fem.Constant(mesh, e), P) for e in strains]),
        np.zeros((1, 3))).eval(mesh, np.array([0], np.int32)).reshape(3, 3, 3)
    (s11_a, s22_a), (s11_b, s22_b) = stresses[0][[0, 1], [0, 1]], stresses[1][[0, 1], [0, 1]]
    lateral = -s22_a / s22_b  # ε₂₂ per unit ε₁₁ with σ₂₂ = 0
    assert law.youngs_modulus == pytest.approx(s11_a + lateral * s11_b, rel=1e-12)
    assert law.shear_modulus == pytest.approx(stresses[2][0, 1] / 2.0, rel=1e-12)

