"""A living eye's wall and an eye free to lengthen (docs/scleral_buckling.md, "A living
eye's wall"): the tension-only fibre law (forms/hyperelastic.py, TangentialFibres) against
its closed forms, and the optic nerve's end on a spring (problems/scleral_buckling/terms.py,
OpticNerveSpring) on the coarse eye against the clamped eye's recorded numbers."""

from __future__ import annotations

import json
from pathlib import Path

import dolfinx
import dolfinx.fem
import pytest
import ufl
from mpi4py import MPI

from eyemech.forms import NeoHooke, Yeoh
from eyemech.forms.hyperelastic import TangentialFibres, meridian_and_latitude
from eyemech.problems import scleral_buckling as sb
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError

C10, C4 = 0.0833, 255.0
# two fibre families in the x-y plane (the coat's tangent plane), z its normal
IN_PLANE = (ufl.as_vector((1.0, 0.0, 0.0)), ufl.as_vector((0.0, 1.0, 0.0)))


@pytest.fixture(scope="module")
def cube():
    return dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1)


def _value(expression, mesh) -> float:
    """The cube's integral of a constant expression: its value."""
    return dolfinx.fem.assemble_scalar(dolfinx.fem.form(expression * ufl.dx(domain=mesh)))


def _stretch(l1: float, l2: float):
    """The incompressible homogeneous stretch diag(λ1, λ2, 1/(λ1 λ2)), as a ufl variable."""
    return ufl.variable(ufl.as_matrix([[l1, 0, 0], [0, l2, 0], [0, 0, 1.0 / (l1 * l2)]]))


@pytest.mark.parametrize("l1, l2", [(0.9, 0.9), (0.95, 0.8), (0.97, 1.0)])
def test_fibres_carry_no_compression(cube, l1, l2):
    """Shortened in both in-plane directions (or one shortened, the other at rest), the
    fibres store no energy and carry no stress: the coat is its neo-Hookean matrix, to
    round-off (Yeoh's c20 (Ī1 − 3)² would add its full share: checked)."""
    F = _stretch(l1, l2)
    fibres, matrix = TangentialFibres(C10, C4, IN_PLANE), NeoHooke(C10)
    assert abs(_value(fibres.strain_energy(F), cube) - _value(matrix.strain_energy(F), cube)) < 1e-15
    stress = ufl.diff(fibres.strain_energy(F) - matrix.strain_energy(F), F)
    assert _value(ufl.inner(stress, stress), cube) < 1e-28
    yeoh = Yeoh(C10, C4 / 4.5)
    assert _value(yeoh.strain_energy(F) - matrix.strain_energy(F), cube) > 1e-6


def test_a_stretched_fibre_stores_its_quartic(cube):
    """Uniaxial incompressible stretch λ along the first family: the second family is
    shortened (λ^-1/2) and silent, so W = c10 (λ² + 2/λ − 3) + c4 (λ² − 1)⁴ exactly."""
    lam = 1.06
    F = ufl.as_matrix([[lam, 0, 0], [0, lam**-0.5, 0], [0, 0, lam**-0.5]])
    exact = C10 * (lam**2 + 2 / lam - 3) + C4 * (lam**2 - 1) ** 4
    energy = _value(TangentialFibres(C10, C4, IN_PLANE).strain_energy(F), cube)
    assert energy == pytest.approx(exact, rel=1e-12)


def test_fibres_store_yeohs_energy_in_inflation(cube):
    """Equibiaxial in-plane stretch 1 + ε (inflation): two families with c4 = 4.5 c20 store
    the Yeoh coat's stiffening energy to leading order in ε. Exactly, Ī4 − 1 = 2ε + ε² and
    Ī1 − 3 = 12 ε² − 20 ε³ + O(ε⁴), so their ratio is 1 + 16/3 ε + O(ε²): 1.0053 at
    ε = 0.1 %, 1.054 at 1 % (the sclera's strain at 15 mmHg)."""
    c20 = C4 / 4.5
    for eps in (1e-4, 1e-3, 1e-2):
        F = _stretch(1 + eps, 1 + eps)
        fibre = _value(TangentialFibres(0.0, C4, IN_PLANE).strain_energy(F), cube)
        yeoh = _value(Yeoh(0.0, c20).strain_energy(F), cube)
        # the slope (ratio − 1)/ε: 5.334, 5.344, 5.441 (exact from the invariants)
        assert (fibre / yeoh - 1) / eps == pytest.approx(16 / 3, rel=0.025), eps


def test_the_eyes_fibres_lie_along_meridians_and_circles_of_latitude(cube):
    """At a point of the wall the two directions are unit, orthogonal to each other and to
    the radius (tangent to a sphere about the origin), the second one about the z axis."""
    X = ufl.as_vector((3.0, 4.0, -2.0))
    along, around = meridian_and_latitude(X)
    for a in (along, around):
        assert _value(ufl.dot(a, a), cube) == pytest.approx(1.0, rel=1e-12)
        assert abs(_value(ufl.dot(a, X), cube)) < 1e-12
    assert abs(_value(ufl.dot(along, around), cube)) < 1e-12
    assert abs(_value(around[2], cube)) < 1e-15


def test_bad_fibre_and_spring_input_is_refused():
    with pytest.raises(ParameterError, match="c4_sclera.*material=fibres"):
        sb.Parameters(material="table-1", c4_sclera=100.0).validate()
    with pytest.raises(ParameterError, match="c20_sclera.*material=calibrated"):
        sb.Parameters(material="fibres", c20_sclera=10.0).validate()
    with pytest.raises(ParameterError, match="c4_cornea"):
        sb.Parameters(material="fibres", c4_cornea=-1.0).validate()
    with pytest.raises(ParameterError, match="optic_nerve_end_spring"):
        sb.Parameters(optic_nerve_end_spring=-0.001).validate()


RECORDED = Path(__file__).parent / "data" / "scleral_buckling_coarse_paper.json"


@pytest.fixture(scope="module")
def free_eye():
    """The coarse eye of the paper's operation (Table 1's wall, 2.0 mm of rigid travel),
    its optic nerve's end on a soft spring (the default living eye's spring)."""
    params = sb.Parameters(resolution="coarse", **{**sb.PAPER_OPERATION,
                                                   "optic_nerve_end_spring": 0.001})
    return sb.run(params, comm=MPI.COMM_SELF, options=RunOptions(fields=False, pictures=False))


def test_an_eye_free_to_lengthen_lengthens_behind_the_band(free_eye):
    """With the nerve's end on a spring of 0.001 MPa/mm (instead of clamped) the buckle rides
    on the globe: the retina's posterior pole moves back (measured −0.51 mm from the eye
    before surgery to the settled eye, against the clamped eye's −0.05 mm on the default
    mesh) and the settled ΔAL doubles (measured +0.983 mm against the clamped coarse eye's
    recorded +0.45 mm); the spring carries a small force (measured 0.011 N, whole eye,
    against the tire's 1.2 N) and the tear stays closed."""
    q = free_eye.quantities
    clamped = json.loads(RECORDED.read_text())["quantities"]["after_settling"]
    before, settled = q["after_iop"], q["after_settling"]
    pole_shift = settled["posterior_pole_axial_displacement_mm"] \
        - before["posterior_pole_axial_displacement_mm"]
    assert pole_shift < -0.3, pole_shift
    assert settled["axial_length_change_mm"] > clamped["axial_length_change_mm"] + 0.3
    assert settled["refraction_change_D"] < clamped["refraction_change_D"]
    assert 0.0 < settled["optic_nerve_end_force_N"] < 0.05 * settled["tire_contact_force_N"]
    assert settled["tear_closed_nts"] is True
