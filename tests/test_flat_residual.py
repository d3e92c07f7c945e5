"""A Newton solve stopped at a flat residual, accepted by its Newton correction
(``NewtonOptions.increment_tolerance``; the eye's use: docs/scleral_buckling.md, "A flat
residual accepted by its Newton correction").

The nonlinear Poisson problem of tests/test_newton_counts.py asked for a residual below
round-off (rtol = atol = 1e-30) cannot converge by its residual: Newton reaches the
solution in a few iterations and then stops at a round-off floor. Its correction there is
round-off too, so the displacement criterion accepts the state; a solve stopped after one
iteration, far from the solution, is refused by the residual's limit or by the correction."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from test_newton_counts import PetscLog, _nonlinear_poisson, assert_counts_are_petscs

from eyemech.problems.solve.driver import NewtonOptions

UNREACHABLE = NewtonOptions(line_search="bt", rtol=1e-30, atol=1e-30, max_it=12)


def _solve(options: NewtonOptions):
    problem = _nonlinear_poisson(options)
    problem["load"].value = 1.0
    with PetscLog() as log:
        converged, _ = problem["solver"].solve()
    return problem, converged, log


# in a process of its own: a test before it in the same process may have left PETSc's SNES
# events begun by an error (tests/test_newton_counts.py, ERROR_IN_A_HOOK), and PETSc then
# counts none of them again
ACCEPTED = """
import dataclasses, json
from test_flat_residual import UNREACHABLE, _solve
problem, converged, log = _solve(dataclasses.replace(UNREACHABLE, increment_tolerance=1e-10))
solver = problem["solver"]
print(json.dumps({"converged": bool(converged), "acceptance": solver.flat_acceptance,
                  "counts": solver.last_counts.as_dict(), "events": log.counts,
                  "snes_iterations": solver.snes.getIterationNumber(),
                  "u": problem["u"].x.array.tolist()}))
"""


def test_a_round_off_floor_is_accepted_by_its_correction_and_counted():
    """Accepted: the residual at round-off (≤ 1e-12 of the load's 20), the correction ≤ 1e-10;
    the state is the converged one (the same u as a solve to rtol = 1e-12). The check's
    Jacobian, factorisation and linear solve are counted as one more Newton iteration, as
    PETSc logs them."""
    proc = subprocess.run([sys.executable, "-c", ACCEPTED], capture_output=True, text=True,
                          cwd=Path(__file__).parent, timeout=300)
    assert proc.returncode == 0, proc.stderr
    measured = json.loads(proc.stdout.strip().splitlines()[-1])
    assert measured["converged"]
    residual, correction = measured["acceptance"]
    assert residual < 1e-12 and correction <= 1e-10
    counts = measured["counts"]
    assert counts["flat_residual_acceptances"] == 1 and counts["failed_newton_solves"] == 0
    assert counts["newton_iterations_all"] >= measured["snes_iterations"] + 1
    log = PetscLog()
    log.counts = measured["events"]
    assert_counts_are_petscs(counts, log)
    reference, converged_reference, _ = _solve(NewtonOptions(line_search="bt", rtol=1e-12))
    assert converged_reference
    assert np.allclose(measured["u"], reference["u"].x.array, rtol=0, atol=1e-12)


def test_without_the_tolerance_the_same_solve_fails():
    _problem, converged, _log = _solve(UNREACHABLE)
    assert not converged


def test_a_solve_far_from_the_solution_is_not_accepted():
    """One iteration from u = 0 leaves the residual at ~1e-1: above the residual's limit;
    with the limit raised, its correction (~1e-2) is above the tolerance."""
    one = dataclasses.replace(UNREACHABLE, max_it=1, increment_tolerance=1e-6)
    problem, converged, _ = _solve(one)
    assert not converged and problem["solver"].flat_acceptance is None
    problem, converged, _ = _solve(dataclasses.replace(one, flat_residual_limit=1e3))
    assert not converged and problem["solver"].flat_acceptance is None
    counts = problem["solver"].last_counts.as_dict()
    assert counts["flat_residual_acceptances"] == 0 and counts["failed_newton_solves"] == 1
    # the check's Jacobian and factorisation, counted as a Newton iteration begun
    assert counts["newton_iterations_all"] == counts["jacobians"] == counts["factorisations"] == 2
