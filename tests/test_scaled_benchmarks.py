"""Each benchmark holds its stated accuracy away from its default parameters (issue 27).

Every case runs a benchmark with geometry scaled ×0.2 or ×5, moduli ×0.1 or ×10, or a
load within the model's range, and asserts the bound its default test asserts, against
the reference computed for those parameters:

- exact solutions take the parameters (sphere inflation, liquid sphere, Hertz, the
  viscoelastic point ODE and standard linear solid, the rolled cantilever's circle, the
  Euler–Bernoulli period);
- the tabulated shell references scale by dimensional analysis of linear elasticity,
  stated at each case (for a plate w = c q L⁴/D, D = E h³/12(1 − ν²); for the Scordelis–Lo
  roof and the pinched hemisphere, with every length scaled by s, the displacement is
  w ∝ q L / E · Φ(shape) and w ∝ F/(E h) · Φ(shape));
- Cook's membrane has no closed form: a neo-Hookean body loaded by F with modulus μ
  deforms alike for the same F/μ, so (μ, F) × 0.1 and × 10 must give the 6.9 mm tip.

Meshes: the defaults, or coarser where the default-parameter bound still holds there
(each benchmark's first case, ``default``, checks the bound on that mesh). Cases longer
than ~30 s here are marked ``slow`` and run only with ``EYEMECH_SCALED_SLOW=1``.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from eyemech.problems import (
    cantilever_rolling,
    cantilever_vibration,
    cook_membrane,
    hemisphere,
    hertz,
    liquid_sphere,
    plate_clamped,
    plate_simply_supported,
    scordelis_lo,
    sls_creep,
    sphere_inflation,
    uniaxial_relaxation,
)
from eyemech.problems.reference import analytic
from eyemech.problems.reference import viscoelastic as visco
from eyemech.problems.run.context import RunOptions

QUIET = RunOptions(fields=False, pictures=False)
SLOW = pytest.mark.skipif(not os.environ.get("EYEMECH_SCALED_SLOW"),
                          reason="longer than ~20 s here: EYEMECH_SCALED_SLOW=1 runs it")


def _run(module, **overrides):
    params = module.Parameters(**overrides)
    return params, module.run(params, options=QUIET).quantities


def _slow(case):
    return pytest.param(*case, marks=[SLOW, pytest.mark.slow])


# -- sphere inflation: exact thick sphere, bound 0.5 % (tests/test_sphere_inflation.py) ----
SPHERE = dict(inner_radius=10.0, outer_radius=12.0, c10=0.05, pressure=0.01)


@pytest.mark.parametrize("label, scale", [
    ("default", {}),
    ("geometry x0.2", dict(inner_radius=2.0, outer_radius=2.4)),
    ("geometry x5", dict(inner_radius=50.0, outer_radius=60.0)),
    ("moduli x0.1, pressure x0.1", dict(c10=0.005, pressure=0.001)),
    ("moduli x10", dict(c10=0.5)),
    ("pressure x2 (p/c10 = 0.4, limit point at ≈ 0.46)", dict(pressure=0.02)),
])
def test_sphere_inflation(label, scale):
    case = {**SPHERE, **scale}
    # one cell across the wall: the coarsest mesh derived from the wall thickness
    _, q = _run(sphere_inflation, **case, cells_across_wall=1.0)
    exact = analytic.sphere_inner_radius(case["pressure"], case["inner_radius"], case["outer_radius"],
                                         case["c10"])
    assert q["inner_radius_deformed"] == pytest.approx(exact, rel=5e-3)
    # the displacement itself, not only the radius
    assert q["inner_radius_deformed"] - case["inner_radius"] == pytest.approx(
        exact - case["inner_radius"], rel=5e-2)


# -- liquid sphere: exact, bound 0.5 % (tests/test_liquid_cavity.py) -------------------------
LIQUID = dict(inner_radius=10.0, outer_radius=12.0, c10=0.05, bulk_modulus=0.2,
              initial_pressure=0.002, external_pressure=0.05)


@pytest.mark.parametrize("label, scale", [
    ("default", {}),
    ("geometry x0.2", dict(inner_radius=2.0, outer_radius=2.4)),
    ("geometry x5", dict(inner_radius=50.0, outer_radius=60.0)),
    ("moduli x0.1, pressures x0.1", dict(c10=0.005, bulk_modulus=0.02, initial_pressure=0.0002,
                                         external_pressure=0.005)),
    ("moduli x10", dict(c10=0.5, bulk_modulus=2.0)),
    ("external pressure x0.5", dict(external_pressure=0.025)),
])
def test_liquid_sphere(label, scale):
    case = {**LIQUID, **scale}
    _, q = _run(liquid_sphere, **case)
    a, pressure = analytic.liquid_sphere(case["inner_radius"], case["outer_radius"], case["c10"],
                                         case["bulk_modulus"], case["initial_pressure"],
                                         case["external_pressure"])
    assert q["cavity_pressure"] == pytest.approx(pressure, rel=5e-3)
    assert q["inner_radius_deformed"] == pytest.approx(a, rel=5e-3)
    assert q["inner_radius_deformed"] - case["inner_radius"] == pytest.approx(
        a - case["inner_radius"], rel=5e-3)


# -- Cook's membrane: 6.9 mm within 1 % at Q2P1, 8 per side (tests/test_cook_membrane.py) ---
@pytest.mark.parametrize("label, factor", [("default", 1.0), ("modulus and load x0.1", 0.1),
                                           ("modulus and load x10", 10.0)])
def test_cook_membrane(label, factor):
    base = cook_membrane.Parameters()
    _, q = _run(cook_membrane, shear_modulus=base.shear_modulus * factor, load=base.load * factor,
                element="Q2P1", elements_per_side=8)
    assert q["tip_displacement"] == pytest.approx(cook_membrane.REFERENCE_TIP_DISPLACEMENT, rel=0.01)


# -- Hertz: force within 3 %, contact radius within 5 % (tests/test_contact.py) --------------
@pytest.mark.parametrize("label, case", [
    ("default", {}),
    ("geometry x0.2", dict(radius=0.2, indentation=0.0002)),
    ("geometry x5", dict(radius=5.0, indentation=0.005)),
    ("modulus x0.1", dict(youngs_modulus=0.1)),
    ("modulus x10", dict(youngs_modulus=10.0)),
    ("ball x5 pressed to d/R = 0.005", dict(radius=5.0, indentation=0.025)),
])
def test_hertz(label, case):
    params, q = _run(hertz, **case)
    exact = hertz.hertz_force(params, params.indentation)  # 4/3 E* R^½ d^{3/2}
    assert q["contact_force"] == pytest.approx(exact, rel=0.03)
    assert q["contact_radius"] == pytest.approx(np.sqrt(params.radius * params.indentation), rel=0.05)
    # every mesh length is a multiple of a = √(R d): about the default mesh (1 619 cells)
    # whatever the geometry, and the estimate made before meshing is within its stated
    # −40 % … +25 %
    assert 1000 < q["cells"] < 2500
    assert 0.6 < q["estimated_cells"] / q["cells"] < 1.25


# -- uniaxial relaxation: 0.5 % against the point ODE (tests/test_viscoelastic.py) ----------
@pytest.mark.parametrize("label, case", [
    ("default", {}),
    ("geometry x0.2", dict(length=0.2)),
    ("geometry x5", dict(length=5.0)),
    ("moduli x0.1", dict(mu_inf=0.005, mu_v=0.005)),
    ("moduli x10", dict(mu_inf=0.5, mu_v=0.5)),
    ("time scale x0.1", dict(tau=10.0, t_end=30.0, ramp_time=1.0)),
    ("stretch 1.5", dict(stretch=1.5)),
    ("compression 0.8", dict(stretch=0.8)),
    # 1 767 adaptive steps, 0.093 % (fixed dt = 1 s: 0.70 %, past the bound), 12 s warm
    _slow(("stretch 1.5, mu_v/mu_inf = 10", dict(stretch=1.5, mu_inf=0.005))),
])
def test_uniaxial_relaxation(label, case):
    params, q = _run(uniaxial_relaxation, **case)
    times = np.asarray(q["times"])
    reference = visco.relaxation(times, params.stretch_at, params.mu_inf, params.mu_v, params.tau,
                                 breaks=(params.ramp_time,))
    error = np.abs(np.asarray(q["cauchy_stress"]) / reference - 1).max()
    assert error < 5e-3
    # the time-discretisation estimate bounds the error and stays within the tolerance
    assert error <= q["time_error_estimate"] <= params.time_tolerance


# -- creep: 1 % against the small-strain standard linear solid (tests/test_viscoelastic.py) --
@pytest.mark.parametrize("label, case", [
    ("default", {}),
    ("geometry x0.2", dict(length=0.2)),
    ("geometry x5", dict(length=5.0)),
    ("moduli and stress x0.1", dict(mu_inf=0.005, mu_v=0.005, stress=0.0003)),
    ("moduli x10", dict(mu_inf=0.5, mu_v=0.5)),
    ("time scale x10", dict(tau=1000.0, t_end=8000.0, dt=20.0)),
    ("stress x-1 (compression)", dict(stress=-0.003)),
])
def test_sls_creep(label, case):
    params, q = _run(sls_creep, **case)
    times = np.asarray(q["times"])
    sls = visco.sls_creep_strain(times, params.stress, params.mu_inf, params.mu_v, params.tau)
    assert np.abs(np.asarray(q["axial_strain"]) / sls - 1).max() < 1e-2
    assert q["time_error_estimate"] <= params.time_tolerance


# -- plates: Timoshenko's w = c q L⁴/D within 0.3 % (tests/test_shell.py) ---------------------
PLATE = dict(q=1.0, youngs_modulus=1.092e6, length=10.0, thickness=0.1)


def _plate_cases():
    cases = [("default", {}), ("geometry x0.2", dict(length=2.0, thickness=0.02)),
             ("geometry x5", dict(length=50.0, thickness=0.5)),
             ("modulus x0.1", dict(youngs_modulus=1.092e5)), ("modulus x10", dict(youngs_modulus=1.092e7)),
             ("thickness x0.2", dict(thickness=0.02))]
    return [(module, coefficient, label, scale)
            for module, coefficient in ((plate_clamped, 0.00126532), (plate_simply_supported, 0.00406235))
            for label, scale in cases]


@pytest.mark.parametrize("module, coefficient, label, scale", _plate_cases())
def test_plates(module, coefficient, label, scale):
    case = {**PLATE, **scale}
    _, q = _run(module, **case)
    D = case["youngs_modulus"] * case["thickness"] ** 3 / (12 * (1 - 0.3**2))
    reference = coefficient * case["q"] * case["length"] ** 4 / D  # Kirchhoff plate: exact scaling
    assert abs(q["center_deflection"]) == pytest.approx(reference, rel=3e-3)


# -- Scordelis–Lo: 0.3024 within 2 % (tests/test_shell.py) ------------------------------------
ROOF = dict(radius=25.0, length=50.0, thickness=0.25, youngs_modulus=4.32e8, gravity_load=90.0)


@pytest.mark.parametrize("label, scale, factor", [
    ("default", {}, 1.0),
    # all lengths × s: w ∝ q L/E · Φ(R/L, h/L, angle, ν) → × s
    ("geometry x0.2", dict(radius=5.0, length=10.0, thickness=0.05), 0.2),
    ("geometry x5", dict(radius=125.0, length=250.0, thickness=1.25), 5.0),
    ("modulus x0.1", dict(youngs_modulus=4.32e7), 10.0),  # w ∝ 1/E
    ("modulus x10", dict(youngs_modulus=4.32e9), 0.1),
])
def test_scordelis_lo(label, scale, factor):
    _, q = _run(scordelis_lo, **{**ROOF, **scale})
    assert abs(q["edge_deflection"]) == pytest.approx(0.3024 * factor, rel=0.02)


# -- pinched hemisphere: 0.093 within 2 % (tests/test_shell.py) -------------------------------
BALL = dict(radius=10.0, thickness=0.04, youngs_modulus=6.825e7, force=2.0)


@pytest.mark.parametrize("label, scale, factor", [
    ("default", {}, 1.0),
    # all lengths × s: w ∝ F/(E h) · Φ(R/h, hole, ν) → × 1/s
    ("geometry x0.2", dict(radius=2.0, thickness=0.008), 5.0),
    ("geometry x5", dict(radius=50.0, thickness=0.2), 0.2),
    ("modulus x0.1", dict(youngs_modulus=6.825e6), 10.0),
    ("modulus x10", dict(youngs_modulus=6.825e8), 0.1),
])
def test_hemisphere(label, scale, factor):
    _, q = _run(hemisphere, **{**BALL, **scale})
    reference = 0.093 * factor  # the default force 2 gives 0.093
    assert abs(q["radial_displacement_x"]) == pytest.approx(reference, rel=0.02)
    assert abs(q["radial_displacement_y"]) == pytest.approx(reference, rel=0.02)


# -- rolled cantilever: the tip on the exact circle within 1 % of L (tests/test_shell.py) -----
STRIP = dict(length=12.0, width=1.0, thickness=0.1, youngs_modulus=1.2e6)


@pytest.mark.parametrize("label, scale", [
    ("default", {}),
    # a scaled strip compiles its shell forms anew (the thickness enters them as a number):
    # ~2 min here with a cold FFCx cache, 4.4 s warm
    _slow(("geometry x0.2", dict(length=2.4, width=0.2, thickness=0.02))),
    _slow(("geometry x5", dict(length=60.0, width=5.0, thickness=0.5))),
    ("modulus x0.1", dict(youngs_modulus=1.2e5)),
    ("modulus x10", dict(youngs_modulus=1.2e7)),
    ("half the moment", dict(moment_fraction=0.5)),
])
def test_cantilever_rolling(label, scale):
    params, q = _run(cantilever_rolling, **{**STRIP, **scale})
    exact_u, exact_w = cantilever_rolling.exact_tip(params)  # circle of radius E I / M
    assert np.hypot(q["tip_u"] - exact_u, q["tip_w"] - exact_w) < 0.01 * params.length


# -- vibrating cantilever: the first period within 0.5 % (tests/test_shell_dynamics.py) -------
BEAM = dict(length=6.0, width=1.0, thickness=0.13, youngs_modulus=1.0)


@pytest.mark.parametrize("label, scale", [
    ("default", {}),
    ("geometry x0.2", dict(length=1.2, width=0.2, thickness=0.026)),
    ("geometry x5", dict(length=30.0, width=5.0, thickness=0.65)),
    ("modulus x0.1", dict(youngs_modulus=0.1)),
    ("modulus x10", dict(youngs_modulus=10.0)),
    ("amplitude x0.5", dict(amplitude=0.005)),
])
def test_cantilever_vibration(label, scale):
    params, q = _run(cantilever_vibration, **{**BEAM, **scale})
    # Euler–Bernoulli: ω₁ = 1.8751² √(E I / (ρ A L⁴)), I/A = h²/12
    omega = 1.87510407**2 * np.sqrt(params.youngs_modulus * params.thickness**2 / 12
                                    / (params.density * params.length**4))
    assert q["omega_exact"] == pytest.approx(omega, rel=1e-6)
    assert q["period"] == pytest.approx(q["period_exact"], rel=5e-3)
    assert abs(q["period_error"]) < 5e-3  # against the time scheme's own oscillator


# -- contact patch: segment-to-segment contact (the default method) passes the patch test to
# round-off on the default blocks (stress spread 1e-12, tests/test_contact.py); the bound here
# is the issue's 1 %. The blocks' element sizes are absolute parameters, scaled with the
# width; gmsh does not mesh the scaled blocks as the scaled mesh (834 and 837 cells against
# 867), which the mortar integration does not care about (node-to-surface two-pass did: 9.8 %
# and 12.2 % there, against 5-7 % on the default blocks) -----------------------------------
@pytest.mark.parametrize("label, scale", [
    ("default", {}),
    ("geometry x0.2", dict(width=0.2, master_size=0.05, slave_size=0.034)),
    ("geometry x5", dict(width=5.0, master_size=1.25, slave_size=0.85)),
    ("modulus x0.1, pressure x0.1", dict(youngs_modulus=0.1, pressure=0.001)),
    ("modulus x10", dict(youngs_modulus=10.0)),
    ("pressure x3", dict(pressure=0.03)),
])
def test_contact_patch(label, scale):
    from eyemech.problems import contact_patch

    _, q = _run(contact_patch, method="segment-to-segment", **scale)
    for block in ("lower", "upper"):
        assert q[f"stress_spread_{block}"] < 0.01
