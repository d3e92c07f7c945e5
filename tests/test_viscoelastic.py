"""The finite-strain viscoelastic model (issue 6, seed 003 after Le Tallec, Rahier & Kaiss
1993): uniaxial relaxation and creep of a bar against references.

Point-ODE reference, derived here independently of the code under test
----------------------------------------------------------------------
Evolution law (forms/viscoelastic.py, eq. E):  τ Ċv = C̄ − ⅓ tr(C̄ Cv⁻¹) Cv.
Incompressible homogeneous uniaxial tension: F = diag(λ, λ^-½, λ^-½), J = 1, C̄ = C =
diag(λ², λ⁻¹, λ⁻¹). Starting from Cv = I, (E) keeps Cv diagonal with equal lateral entries
and det Cv = 1, so Cv = diag(a, a^-½, a^-½). Then

    tr(C̄ Cv⁻¹) = λ²/a + 2 a^½/λ,
    11-component:  τ ȧ = λ² − ⅓ (λ²/a + 2a^½/λ) a = ⅔ (λ² − a^(3/2)/λ),
    22-component:  τ d(a^-½)/dt = −½ a^(-3/2) τ ȧ = ⅓ (1/λ − λ² a^(-3/2))   (the same ODE).

Stress: σ = μ∞ dev(b̄) + μv dev(F̄ Cv⁻¹ F̄ᵀ) + p I with σ22 = 0 (free lateral faces):

    σ11 = μ∞ (λ² − λ⁻¹) + μv (λ²/a − a^½/λ).

Small strain (λ = 1 + ε, a = 1 + 2εv): τ ε̇v = ε − εv, σ = 3μ∞ ε + 3μv (ε − εv): after a
step strain σ/ε = 3(μ∞ + μv e^(−t/τ)) (issue 6); under a step stress the standard linear
solid of the seed §2.3.1 (E = 3μ): ε(t) = σ/(3μ∞) − (σ/(3μ∞) − σ/(3(μ∞+μv))) e^(−t/τc),
τc = τ (μ∞+μv)/μ∞.

Tolerances. Backward Euler is first order: the viscous stress after n steps of size h = Δt/τ
carries a relative error ≈ (t/τ)(h/2) e^(−t/τ) of the viscous part, largest (≈ h/4 of
the total for μv = μ∞) during the ramp; the defaults (h = 0.01) give 0.28 % measured, the
issue's bound is 0.5 %. The small-strain laws hold to O(ε²) (the O(ε) term of λ² − 1/λ
vanishes), far inside 1 %.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import last_json, run_cli
from scipy.integrate import solve_ivp

from eyemech.problems import sls_creep, uniaxial_relaxation
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError, build
from eyemech.problems.solid.viscous_bar import TooManySteps, UnstableIntegration
from eyemech.problems.solve.driver import NonlinearSolver, SolveFailure

QUIET = RunOptions(fields=False, pictures=False)


# -- the reference, written here --------------------------------------------------------
def point_relaxation(times, stretch_at, ramp_time, mu_inf, mu_v, tau):
    """σ11(t) from the scalar ODE above, solve_ivp at rtol 1e-10, split at the ramp's kink."""
    rate = lambda t, y: [2 / 3 * (stretch_at(t) ** 2 - y[0] ** 1.5 / stretch_at(t)) / tau]
    edges = [0.0] + ([ramp_time] if 0 < ramp_time < max(times) else []) + [max(times)]
    pieces, a0 = [], 1.0
    for start, end in zip(edges[:-1], edges[1:]):
        sol = solve_ivp(rate, (start, end), [a0], method="DOP853", rtol=1e-10, atol=1e-13,
                        dense_output=True)
        pieces.append((start, end, sol.sol))
        a0 = sol.y[0, -1]
    a = np.array([next(s for lo, hi, s in pieces if lo <= t <= hi)(t)[0] for t in times])
    lam = np.array([stretch_at(t) for t in times])
    return mu_inf * (lam**2 - 1 / lam) + mu_v * (lam**2 / a - np.sqrt(a) / lam)


def tensor_rate(Cbar, Cv, tau):
    """Law (E) in full 3×3 form (numpy), to check the scalar reduction."""
    return (Cbar - np.trace(Cbar @ np.linalg.inv(Cv)) / 3 * Cv) / tau


def test_scalar_ode_is_the_tensor_law():
    """The 9-component law (E) under a stretch history stays diag(a, a^-½, a^-½), keeps
    det Cv = 1, and its a(t) is the scalar ODE's."""
    tau, stretch_at = 2.0, (lambda t: 1 + 0.4 * min(t, 1.0))
    C = lambda t: np.diag([stretch_at(t) ** 2, 1 / stretch_at(t), 1 / stretch_at(t)])
    full = solve_ivp(lambda t, y: tensor_rate(C(t), y.reshape(3, 3), tau).ravel(), (0, 3),
                     np.eye(3).ravel(), rtol=1e-11, atol=1e-13, t_eval=[0.5, 1.0, 3.0])
    scalar = solve_ivp(lambda t, y: [2 / 3 * (stretch_at(t) ** 2 - y[0] ** 1.5 / stretch_at(t)) / tau],
                       (0, 3), [1.0], rtol=1e-11, atol=1e-13, t_eval=[0.5, 1.0, 3.0])
    for k in range(3):
        Cv = full.y[:, k].reshape(3, 3)
        a = scalar.y[0, k]
        assert np.allclose(Cv, np.diag([a, a**-0.5, a**-0.5]), rtol=1e-8, atol=1e-10)
        assert np.linalg.det(Cv) == pytest.approx(1.0, abs=1e-8)


def test_ufl_updates_are_the_law():
    """forms/viscoelastic.py evaluated by DOLFINx on constant tensors equals (E) in numpy:
    the rate, forward Euler, and the backward-Euler closed form X/det(X)^⅓, which solves
    Cv − Cv_n = Δt (C̄ − λ Cv)/τ with det Cv = 1 for a scalar multiplier λ."""
    import dolfinx
    import ufl
    from mpi4py import MPI

    from eyemech.forms import viscoelastic as ve

    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1, dolfinx.mesh.CellType.hexahedron)
    rng = np.random.default_rng(6)
    M = rng.normal(size=(3, 3)) * 0.2 + np.eye(3)
    Cbar = M.T @ M / np.linalg.det(M) ** (2 / 3)
    N = rng.normal(size=(3, 3)) * 0.1 + np.eye(3)
    Cv_n = N.T @ N / np.linalg.det(N) ** (2 / 3)
    dt, tau = 0.7, 2.0
    c = lambda A: dolfinx.fem.Constant(mesh, A)
    exprs = ufl.as_tensor([ve.evolution_rate(c(Cbar), c(Cv_n), tau),
                           ve.forward_euler(c(Cbar), c(Cv_n), dt, tau),
                           ve.backward_euler(c(Cbar), c(Cv_n), dt, tau)])
    values = dolfinx.fem.Expression(exprs, np.zeros((1, 3))).eval(mesh, np.array([0], np.int32))
    rate, forward, backward = values.reshape(3, 3, 3)
    assert np.allclose(rate, tensor_rate(Cbar, Cv_n, tau), rtol=1e-12, atol=1e-14)
    assert np.allclose(forward, Cv_n + dt * tensor_rate(Cbar, Cv_n, tau), rtol=1e-12, atol=1e-14)
    assert np.linalg.det(backward) == pytest.approx(1.0, rel=1e-12)
    # the implicit equation with its multiplier: (Cv_n + Δt/τ C̄ − Cv) ∥ Cv
    multiplier = (Cv_n + dt / tau * Cbar - backward) / (dt / tau) / backward
    assert np.allclose(multiplier, multiplier[0, 0], rtol=1e-10)


# -- uniaxial relaxation --------------------------------------------------------------
@pytest.fixture(scope="module")
def relaxation_default():
    params = uniaxial_relaxation.Parameters()
    return params, uniaxial_relaxation.run(params, options=QUIET)


def _relaxation_error(params, result):
    times = np.array(result.quantities["times"])
    stress = np.array(result.quantities["cauchy_stress"])
    reference = point_relaxation(times, params.stretch_at, params.ramp_time, params.mu_inf,
                                 params.mu_v, params.tau)
    return np.abs(stress / reference - 1)


def test_relaxation_matches_point_ode(relaxation_default):
    """Adaptive steps (the default, time_tolerance 1e-2): 337 steps, 3.3e-3 measured
    (fixed dt = 1 s: 300 steps, 2.8e-3). The estimate bounds the error it reports on
    and stays within the tolerance."""
    params, result = relaxation_default
    assert result.quantities["times"][-1] == pytest.approx(params.t_end)
    error = _relaxation_error(params, result)
    assert error.max() < 5e-3, f"max relative error {error.max():.3e}"
    estimate = result.quantities["time_error_estimate"]
    assert error.max() <= estimate <= params.time_tolerance
    # it relaxes: the end stress is well below the stress at the end of the ramp
    stress = result.quantities["cauchy_stress"]
    assert stress[-1] < 0.8 * max(stress)


def test_newton_converges_quadratically():
    """The consistent tangent (UFL derivative through Cv(u)): ≤ 4 iterations per step,
    and during the ramp the contraction factor of the residual itself shrinks fast
    (≈ 1e-2, 3e-4, 1e-7 measured), where a frozen-Cv tangent would converge linearly.
    (In the hold phase only p changes and one iteration suffices.)"""
    params = uniaxial_relaxation.Parameters(t_end=12.0, time_stepping="fixed")  # dt = 1 s
    steps = uniaxial_relaxation.run(params, options=QUIET).steps
    assert max(s["newton_iterations"] for s in steps) <= 4
    r = steps[4]["residuals"]  # t = 5 s, in the ramp
    assert len(r) >= 4
    assert r[-1] / r[-2] < 0.1 * (r[-2] / r[-3]) and r[-2] / r[-3] < 0.1 * (r[-3] / r[-4])


def test_small_stretch_follows_linear_relaxation_modulus():
    params = uniaxial_relaxation.Parameters(stretch=1.001, ramp_time=0.0, t_end=200.0)
    result = uniaxial_relaxation.run(params, options=QUIET)
    times = np.array(result.quantities["times"])
    modulus = np.array(result.quantities["cauchy_stress"]) / (params.stretch - 1)
    linear = 3 * (params.mu_inf + params.mu_v * np.exp(-times / params.tau))
    assert times[0] == 0.0 and modulus[0] == pytest.approx(3 * (params.mu_inf + params.mu_v), rel=1e-3)
    assert np.abs(modulus / linear - 1).max() < 1e-2  # measured 1.2e-3


@pytest.mark.parametrize("stepping", ["fixed", "adaptive"])
def test_cut_steps_leave_the_history_intact(monkeypatch, stepping):
    """Every fourth Newton solve is reported failed after it has changed u: the path
    follower restores u and cuts, and Cv_n — written only after a converged step — must
    not remember the failed attempt (a double relaxation would show as an O(1 %) error
    that accumulates)."""
    real_solve, calls = NonlinearSolver.solve, {"n": 0}

    def flaky(self):
        converged, iterations = real_solve(self)
        calls["n"] += 1
        return (False, iterations) if calls["n"] % 4 == 0 else (converged, iterations)

    monkeypatch.setattr(NonlinearSolver, "solve", flaky)
    params = uniaxial_relaxation.Parameters(t_end=60.0, time_stepping=stepping)
    result = uniaxial_relaxation.run(params, options=QUIET)
    assert sum(s["cuts"] for s in result.steps) >= 10
    assert _relaxation_error(params, result).max() < 5e-3


def test_taylor_hood_tetrahedra_agree():
    params = uniaxial_relaxation.Parameters(element="P2P1", t_end=30.0)
    result = uniaxial_relaxation.run(params, options=QUIET)
    assert _relaxation_error(params, result).max() < 5e-3


def test_fixed_steps_report_the_error_they_make_where_they_miss_the_bound():
    """λ = 1.5, μ∞ = 0.005, μv = 0.5 (the viscous branch 100× stiffer): the fixed dt = 1 s
    is 0.79 % off the point ODE (measured), past the 0.5 % bound; the time-error estimate
    (12.9 % measured, conservative: it lets errors decay at the retardation rate only)
    says so, and exceeds the default tolerance."""
    params = uniaxial_relaxation.Parameters(stretch=1.5, mu_inf=0.005, mu_v=0.5, time_stepping="fixed")
    result = uniaxial_relaxation.run(params, options=QUIET)
    error = _relaxation_error(params, result).max()
    assert error > 5e-3
    assert result.quantities["time_error_estimate"] > max(error, params.time_tolerance)


def test_adaptive_steps_past_the_cap_stop_with_a_clear_error(tmp_path):
    params = uniaxial_relaxation.Parameters(max_steps=20, t_end=60.0)
    with pytest.raises(TooManySteps) as info:
        uniaxial_relaxation.run(params, out=tmp_path, options=QUIET)
    assert isinstance(info.value, SolveFailure)
    assert "max_steps = 20" in str(info.value) and "time_tolerance" in str(info.value)
    import json
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["status"] == "failed" and len(saved["quantities"]["times"]) == 20


# -- forward Euler ----------------------------------------------------------------------
def test_forward_euler_accurate_below_its_limit():
    params = uniaxial_relaxation.Parameters(time_scheme="forward-euler", t_end=60.0,
                                            time_stepping="fixed")
    result = uniaxial_relaxation.run(params, options=QUIET)
    assert _relaxation_error(params, result).max() < 5e-3


def test_forward_euler_blows_up_beyond_its_limit(tmp_path):
    """Linearised, the error is multiplied by (1 − Δt/τ) per step: Δt = 2.5 τ diverges."""
    params = uniaxial_relaxation.Parameters(time_scheme="forward-euler", ramp_time=0.0, dt=250.0,
                                            time_stepping="fixed",
                                            t_end=5000.0)
    with pytest.raises(UnstableIntegration) as info:
        uniaxial_relaxation.run(params, out=tmp_path, options=QUIET)
    assert isinstance(info.value, SolveFailure)
    assert "unstable" in str(info.value) and info.value.time < params.t_end
    import json
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["status"] == "failed" and len(saved["quantities"]["times"]) >= 2


def test_backward_euler_bounded_at_huge_steps():
    params = uniaxial_relaxation.Parameters(ramp_time=0.0, dt=1000.0, t_end=5000.0,
                                            time_stepping="fixed")
    result = uniaxial_relaxation.run(params, options=QUIET)
    relaxed = params.mu_inf * (params.stretch**2 - 1 / params.stretch)
    assert result.quantities["cauchy_stress"][-1] == pytest.approx(relaxed, rel=1e-3)


# -- creep ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def creep_default():
    params = sls_creep.Parameters()
    return params, sls_creep.run(params, options=QUIET)


def test_creep_matches_standard_linear_solid(creep_default):
    params, result = creep_default
    times = np.array(result.quantities["times"])
    strain = np.array(result.quantities["axial_strain"])
    glassy = params.stress / (3 * (params.mu_inf + params.mu_v))
    relaxed = params.stress / (3 * params.mu_inf)
    retardation = params.tau * (params.mu_inf + params.mu_v) / params.mu_inf
    sls = relaxed - (relaxed - glassy) * np.exp(-times / retardation)
    # adaptive steps (68): 2.4e-3 measured (fixed dt = 2 s, 400 steps: 1.1e-3), the
    # small-strain law's own error at this 2 % strain included
    assert np.abs(strain / sls - 1).max() < 1e-2
    assert result.quantities["time_error_estimate"] <= params.time_tolerance
    assert strain[-1] > 1.9 * strain[0]  # creeps from the glassy towards twice that
    # the follower traction keeps the true stress constant while the section shrinks
    assert np.allclose(result.quantities["cauchy_stress"], params.stress, rtol=1e-6)


def test_creep_at_finite_strain_matches_point_ode():
    """σ = 0.03 MPa (10 % glassy strain; the small-strain law is off by 1.6 % here):
    against (E) at one point, λ(t) from σ11(λ, a) = σ at every instant."""
    from scipy.optimize import brentq

    params = sls_creep.Parameters(stress=0.03, t_end=300.0)
    result = sls_creep.run(params, options=QUIET)
    mu_inf, mu_v, tau, sigma = params.mu_inf, params.mu_v, params.tau, params.stress
    stretch_of = lambda a: brentq(lambda s: mu_inf * (s * s - 1 / s) + mu_v * (s * s / a - a**0.5 / s)
                                  - sigma, 0.5, 3.0, xtol=1e-14)
    times = np.array(result.quantities["times"])
    ode = solve_ivp(lambda t, y: [2 / 3 * (stretch_of(y[0]) ** 2 - y[0] ** 1.5 / stretch_of(y[0])) / tau],
                    (0, times[-1]), [1.0], rtol=1e-10, atol=1e-13, t_eval=times)
    reference = np.array([stretch_of(a) for a in ode.y[0]]) - 1
    strain = np.array(result.quantities["axial_strain"])
    assert np.abs(strain / reference - 1).max() < 5e-3  # measured 1.1e-3


# -- parallel and bad input ---------------------------------------------------------------
@pytest.mark.mpi
def test_two_ranks_give_the_same_numbers(tmp_path, relaxation_default):
    _, serial = relaxation_default
    code, out, err = run_cli("run", "uniaxial-relaxation", "--set", "t_end=40", "--set",
                             "mesh_divisions=2", "--out", str(tmp_path), "--json", "--no-pictures",
                             "--no-fields", ranks=2)
    assert code == 0, err
    parallel = last_json(out)
    assert parallel["mpi_size"] == 2
    # the adaptive steps do not depend on t_end: the same steps up to the last (cut at
    # 40 s), to round-off in the error estimate (8e-7 relative measured on 2×2×2 cells)
    count = len(parallel["quantities"]["times"]) - 1
    assert count >= 10 and parallel["quantities"]["times"][-1] == pytest.approx(40.0)
    assert parallel["quantities"]["times"][:count] == pytest.approx(serial.quantities["times"][:count],
                                                                     rel=1e-5)
    assert parallel["quantities"]["cauchy_stress"][:count] == pytest.approx(
        serial.quantities["cauchy_stress"][:count], rel=1e-5)


@pytest.mark.parametrize("key, value", [("tau", "0"), ("tau", "-1"), ("dt", "0"), ("dt", "-0.5"),
                                        ("mu_inf", "0"), ("mu_v", "-0.01"),
                                        ("time_scheme", "crank-nicolson")])
def test_bad_input_is_one_clear_error(key, value):
    for scene in (uniaxial_relaxation, sls_creep):
        with pytest.raises(ParameterError) as info:
            build(scene.Parameters, {key: value})
        assert info.value.key == key and key in str(info.value)


def test_bad_input_on_the_command_line(tmp_path):
    code, _, err = run_cli("run", "sls-creep", "--set", "tau=0", "--out", str(tmp_path))
    assert code == 2 and "tau" in err and "> 0" in err
    assert not (tmp_path / "results.json").exists()


# -- the stability study (quick mode) ------------------------------------------------------
def test_stability_study_quick(tmp_path):
    import csv

    from mpi4py import MPI

    from eyemech.problems.studies import studies

    files = studies()["viscoelastic-stability"].run(out=tmp_path, quick=True, comm=MPI.COMM_WORLD)
    assert {f.suffix for f in files} == {".csv", ".png"}
    lines = [l for l in files[0].read_text().splitlines() if not l.startswith("#")]
    rows = {(r["scheme"], float(r["dt_over_tau"])): r for r in csv.DictReader(lines)}
    backward = [float(rows[("backward-euler", h)]["max_error"]) for h in (0.1, 0.5, 2.5)]
    assert all(np.isfinite(backward)) and max(backward) < 0.2  # bounded at dt = 2.5 τ
    assert 3.0 < backward[1] / backward[0] < 6.0  # first order: ×5 in dt, ≈ ×4.4 measured
    assert rows[("forward-euler", 2.5)]["status"] == "blew up"
    assert rows[("forward-euler", 0.1)]["status"] == "ok"
