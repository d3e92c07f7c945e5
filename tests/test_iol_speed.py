"""The lens speed benchmark (issue 8 §4) at a tiny size: its counts and time split are
consistent, and the faster solution methods solve the same equations.

No wall-clock assertions (the machine is shared): only counts, sums and solutions.

References
- Modified Newton (lagged Jacobian) and Newton–Krylov (finite-difference Jacobian action,
  Knoll & Keyes, J. Comput. Phys. 193, 2004) converge to the same discrete solution as
  Newton when all three stop at the same relative residual: the histories agree to the
  solver tolerance (rtol 1e-8 of residuals ~1e-4 N on a lens whose tangent stiffness is
  ≳ 1e-3 N/mm: ≲ 1e-6 mm; 1e-5 mm asserted).
- The linearised step is one Newton iteration of the same implicit step: its first
  iteration count is 1 by definition and its deviation from Newton is first order in Δt
  (not asserted: only that it stays finite and near).
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from eyemech.problems import iol_speed
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError

QUIET = RunOptions(fields=False, pictures=False)
TINY = {"mesh_scale": 3.0, "steps": 3, "rtol": 1e-8}


def _run(**overrides):
    params = iol_speed.Parameters(**{**TINY, **overrides})
    return iol_speed.run(params, comm=MPI.COMM_SELF, options=QUIET).quantities


@pytest.fixture(scope="module")
def runs():
    return {name: _run(**kw) for name, kw in {
        "newton": {},
        "lagged": {"jacobian": "lagged"},
        "krylov": {"jacobian": "matrix-free", "krylov_rtol": 1e-6},
        "linearised": {"method": "linearised"},
        "contact": {"method": "linearised", "contact": True, "repeats": 2},
    }.items()}


def test_counts_and_time_split_are_consistent(runs):
    for name, q in runs.items():
        steps = q["steps"]
        assert len(q["tip_history"]) == len(q["optic_history"]) == len(q["time"]) == steps
        assert sum(q["newton_iterations"]) == q["iterations"], name
        phases = q["seconds_per_step"]
        assert set(phases) == set(iol_speed.PHASES)
        assert all(v >= 0.0 for k, v in phases.items() if k != "other"), name
        # the phases (with "other" the remainder) add up to the measured time of the best run
        assert sum(phases.values()) * steps == pytest.approx(steps / q["steps_per_second"], rel=1e-9)
        assert q["steps_per_second_cpu"] > 0 and len(q["steps_per_second_all"]) == q["repeats"]
        assert q["factorisations"] == q["jacobians"]
    newton = runs["newton"]
    # full Newton: one residual per iteration plus the first of each step, one Jacobian per iteration
    assert newton["residuals"] == newton["iterations"] + newton["steps"]
    assert newton["jacobians"] == newton["iterations"]
    linearised = runs["linearised"]
    assert (linearised["iterations"] == linearised["residuals"] == linearised["jacobians"]
            == linearised["steps"])
    assert runs["lagged"]["jacobians"] < runs["lagged"]["iterations"]
    krylov = runs["krylov"]
    # every GMRES product is one residual assembly
    assert krylov["residuals"] == krylov["iterations"] + krylov["steps"] + krylov["krylov_iterations"]
    assert runs["contact"]["seconds_per_step"]["contact"] > 0.0
    assert runs["newton"]["seconds_per_step"]["contact"] == 0.0


def test_lagged_and_matrix_free_newton_give_newtons_solution(runs):
    reference = np.asarray(runs["newton"]["tip_history"])
    assert np.max(np.abs(reference[-1] - reference[0])) > 1e-3  # the lens does move
    for name in ("lagged", "krylov"):
        for key in ("tip_history", "optic_history"):
            assert np.allclose(runs[name][key], runs["newton"][key], atol=1e-5, rtol=0), (name, key)
    linearised = np.asarray(runs["linearised"]["tip_history"])
    assert np.all(np.isfinite(linearised)) and np.max(np.abs(linearised - reference)) < 0.2


def test_bad_method_is_refused():
    with pytest.raises(ParameterError, match="method"):
        iol_speed.Parameters(method="explicit").validate()
    with pytest.raises(ParameterError, match="jacobian"):
        iol_speed.Parameters(jacobian="numeric").validate()
    with pytest.raises(ParameterError, match="roll_radius"):
        iol_speed.Parameters(roll_radius=1.0).validate()


def test_explicit_jacobian_equals_ufls_derivative():
    """``shell_jacobian`` (forms/shell.py, written out by hand for a smaller kernel) is the
    exact second variation of the shell energy: on the rolled lens its matrix equals UFL's
    derivative of the residual up to round-off (3e-16 measured; 1e-12 asserted)."""
    import dolfinx.fem
    import dolfinx.fem.petsc
    import ufl

    params = iol_speed.Parameters(**TINY)
    shell = iol_speed._lens(params)
    shell.u.x.array[:] = iol_speed.initial_roll(shell, params.roll_radius)
    shell.u.x.scatter_forward()
    matrices = []
    for jacobian in (shell.jacobian(), ufl.derivative(shell.residual(), shell.u)):
        A = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(jacobian))
        A.assemble()
        matrices.append(A)
    explicit, reference = matrices
    explicit.axpy(-1.0, reference)
    assert explicit.norm() <= 1e-12 * reference.norm()


def test_bad_tangent_is_refused():
    with pytest.raises(ParameterError) as err:
        iol_speed.Parameters(tangent="symbolic").validate()
    assert err.value.key == "tangent"
