"""The calibrated eye: the scene's healthy coarse eye, inflated from 0 to
40 mmHg, against the living human eye's pressure–volume curve (Pallikaris et al., IOVS
46:409, 2005: ln(P/10 mmHg) = K ΔV, mean K = 0.0126 µL⁻¹), with the Yeoh coats
(``calibrated``) and the tension-only fibre coats (``fibres``); the table-1 eye unchanged;
the Yeoh law's reduction to neo-Hooke. Fit and numbers: docs/scleral_buckling.md,
"Calibrated eye" and "A living eye's wall"."""

from __future__ import annotations

import dolfinx
import dolfinx.fem
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from eyemech.forms import NeoHooke, Yeoh
from eyemech.problems import scleral_buckling
from eyemech.problems.run.parameters import ParameterError
from eyemech.problems.studies.eye_calibration import (
    deviations,
    equibiaxial_tangent_modulus,
    healthy_eye,
    inflation_curve,
)


def _integral(expression, mesh) -> float:
    return dolfinx.fem.assemble_scalar(dolfinx.fem.form(expression * ufl.dx(domain=mesh)))


@pytest.fixture(scope="module")
def cube():
    return dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1)


def test_yeoh_is_neo_hooke_without_its_higher_terms_and_exact_in_uniaxial_stretch(cube):
    # a non-homogeneous deformation: W integrated over the cube, both laws from one F
    V = dolfinx.fem.functionspace(cube, ("Lagrange", 1, (3,)))
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.vstack([0.2 * x[0] * x[1], -0.1 * x[2] ** 2 + 0.05 * x[0],
                                       0.15 * x[1] * x[2]]))
    F = ufl.variable(ufl.Identity(3) + ufl.grad(u))
    c10 = dolfinx.fem.Constant(cube, 0.0833)
    zero = dolfinx.fem.Constant(cube, 0.0)
    neo = _integral(NeoHooke(c10).strain_energy(F), cube)
    assert neo > 1e-4
    assert abs(_integral(Yeoh(c10, zero, zero).strain_energy(F), cube) - neo) < 1e-14 * neo

    # uniaxial incompressible stretch λ: Ī1 − 3 = λ² + 2/λ − 3, W the cubic in it
    lam, c20, c30 = 1.3, 45.0, 7.0
    F = ufl.as_matrix([[lam, 0, 0], [0, lam**-0.5, 0], [0, 0, lam**-0.5]])
    x = lam**2 + 2 / lam - 3
    exact = 0.0833 * x + c20 * x**2 + c30 * x**3
    assert abs(_integral(Yeoh(0.0833, c20, c30).strain_energy(F), cube) - exact) < 1e-12 * exact


@pytest.fixture(scope="module")
def curves():
    """Step 1 of the scene on the coarse healthy eye, 0 → 40 mmHg, every material set."""
    return {material: inflation_curve(healthy_eye(resolution="coarse", material=material),
                                      comm=MPI.COMM_SELF)
            for material in ("table-1", "calibrated", "fibres")}


def test_calibrated_eye_follows_the_living_eyes_pressure_volume_curve(curves):
    """ΔV from 10 mmHg at 15, 20, …, 40 mmHg within 20 % of Pallikaris' mean curve."""
    dev = deviations(curves["calibrated"]["volumes"])
    assert sorted(dev) == [15.0, 20.0, 25.0, 30.0, 35.0, 40.0]
    # measured (coarse): −10.7, −6.8, −3.7, −0.9, +1.5, +3.6 %; the fit (default eye) gives
    # −8.3 … +6.1 %; 20 % is the issue's tolerance (single eyes' K spreads −48 … +75 % about the mean)
    assert max(abs(d) for d in dev.values()) < 0.20, dev
    # the table-1 eye is several times too compliant (measured +2.5 … +6.4)
    assert min(deviations(curves["table-1"]["volumes"]).values()) > 2.0


def test_fibre_eye_follows_the_living_eyes_pressure_volume_curve(curves):
    """The fibre coats (tension-only fibres, c4 = 4.5 c20: Yeoh's energy in inflation to
    leading order, not fitted anew) keep the living eye's curve: ΔV from 10 mmHg within 20 %
    of Pallikaris' mean at 15, 20, …, 40 mmHg."""
    dev = deviations(curves["fibres"]["volumes"])
    assert sorted(dev) == [15.0, 20.0, 25.0, 30.0, 35.0, 40.0]
    # measured (coarse): −11.4, −7.8, −4.8, −2.2, 0.0, +2.0 %; default eye −9.3 … +4.7 %;
    # 20 % as for the calibrated eye
    assert max(abs(d) for d in dev.values()) < 0.20, dev


def test_table_1_eye_is_unchanged(curves):
    """Table 1's neo-Hookean eye reproduces its volumes (whole eye, coarse, no tear):
    4469.05 mm³ unloaded, 4784.22 mm³ at 15 mmHg; to the Newton tolerance."""
    volumes = curves["table-1"]["volumes"]
    assert volumes[0.0] == pytest.approx(4469.0506, rel=1e-6)
    assert volumes[15.0] == pytest.approx(4784.2167, rel=1e-5)


def test_calibrated_sclera_tangent_modulus_is_physiological():
    """Equibiaxial tangent modulus of the calibrated sclera at its Laplace stress at
    15 mmHg, σ = P R / (2 t) with R = 11.5 mm, t = 0.5 mm (equator) … 1.0 mm (posterior
    pole): within 1–10 MPa, the range of the human sclera's moduli at physiological
    stress."""
    params = scleral_buckling.Parameters(material="calibrated")
    pressure = 15.0 * 133.322e-6  # MPa
    for thickness in (0.5, 1.0):
        _, modulus = equibiaxial_tangent_modulus(params.c_sclera, params.c20_sclera,
                                                 pressure * 11.5 / (2 * thickness))
        assert 1.0 < modulus < 10.0, (thickness, modulus)  # measured 5.2 and 3.1 MPa


def test_bad_stiffening_is_refused():
    with pytest.raises(ParameterError, match="c20_sclera"):
        scleral_buckling.Parameters(material="calibrated", c20_sclera=-1.0).validate()
    # a c20 that table-1 would silently ignore
    with pytest.raises(ParameterError, match="c20_cornea.*material=calibrated"):
        scleral_buckling.Parameters(c20_cornea=5.0).validate()


def test_new_stiffening_values_compile_nothing(compilations):
    """c20 is a cellwise field: a second value (never used before) reuses the kernels."""
    import random

    for c20 in (40.0 + random.random(), 70.0 + random.random()):
        inflation_curve(healthy_eye(resolution="coarse", material="calibrated", c20_sclera=c20,
                                    c20_cornea=0.4 * c20), pressures=(10.0,), comm=MPI.COMM_SELF)
        if c20 < 70.0:
            first = len(compilations)
    assert compilations[first:] == [], compilations[first:]
