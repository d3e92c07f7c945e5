"""Newton with the exact Jacobian and a kept factorisation (``linear_reuse = "krylov"``,
problems/solve/stale_factorisation.py): each Newton direction solves the current Jacobian
by FGMRES preconditioned with the last LU factorisation, refactorised only when FGMRES
needs more than ``krylov_max_it`` iterations.

On the small problem (tests/krylov_problem.py): Newton's convergence is the full Newton
method's (quadratic), with fewer factorisations than iterations; a Krylov solve that does
not converge on the kept factorisation, or is predicted after a few iterations not to,
refactorises and solves again, never failing the Newton solve; modified Newton on the
kept factorisation assembles fewer Jacobians; the counts are PETSc's events and the iterations FGMRES did; 2
ranks give 1 rank's answer. On the coarse eye: the reference method's quantities with fewer
factorisations.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from eye_methods import REFERENCE_METHOD, assert_same_eye
from krylov_problem import solve

from eyemech.problems import scleral_buckling
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError
from eyemech.problems.solve.driver import NewtonOptions

BIN = Path(sys.executable).parent
PROBLEM = Path(__file__).parent / "krylov_problem.py"


@pytest.fixture(scope="module")
def direct():
    return solve("none")


@pytest.fixture(scope="module")
def krylov():
    return solve("krylov")


def test_krylov_on_a_kept_factorisation_keeps_newtons_quadratic_convergence(direct, krylov):
    """The same residual histories as full Newton with LU, iteration by iteration (FGMRES
    to 1e-8 relative leaves ‖F‖ where the exact direction does, measured to 2e-3 relative
    down to 1e-12), and quadratic: ‖F_k+1‖ ≤ ‖F_k‖² once ‖F_k‖ < 1e-2 (measured constants
    0.06–0.36; linear convergence at any rate ≥ 1e-4 would break it at ‖F_k‖ ~ 1e-6), with 2
    factorisations for 18 Newton iterations and 202 FGMRES iterations (measured)."""
    assert all(krylov["converged"]) and all(direct["converged"])
    for exact, kept in zip(direct["histories"], krylov["histories"]):
        assert len(kept) == len(exact)
        for a, b in zip(exact, kept):
            if a > 1e-12:
                assert b == pytest.approx(a, rel=1e-2)
        for before, after in zip(kept, kept[1:]):
            if before < 1e-2 and after > 1e-13:  # above round-off
                assert after <= before**2
    counts = krylov["counts"]
    assert counts["newton_iterations"] == direct["counts"]["newton_iterations"] == 18
    assert counts["factorisations"] <= 3 < counts["newton_iterations"]
    assert direct["counts"]["factorisations"] == 18  # one per iteration with LU
    assert counts["krylov_iterations"] > counts["newton_iterations"]
    assert direct["counts"]["krylov_iterations"] == 0  # preonly is no Krylov method
    assert krylov["u_squared"] == pytest.approx(direct["u_squared"], rel=1e-10)


def test_counts_are_petscs_events_and_the_iterations_done(krylov):
    """Every refresh of the kept factorisation is one numeric factorisation PETSc logged
    (the first with the symbolic analysis); every Newton iteration assembles a Jacobian."""
    counts = krylov["counts"]
    assert counts["factorisations"] == krylov["refreshes"]
    assert counts["symbolic_factorisations"] == 1
    assert counts["jacobians"] == counts["newton_iterations_all"] == 18


def test_a_krylov_failure_on_the_kept_factorisation_refactorises():
    """With one FGMRES iteration allowed, every solve on a kept factorisation of an earlier
    Jacobian fails (measured: 16 of the 17) and is repeated on a fresh one; Newton never
    sees the failure: all four solves converge to the same solution, and the FGMRES
    iterations of the failed attempts are counted."""
    one = solve("krylov", krylov_max_it=1)
    assert all(one["converged"])
    assert one["refreshes_after_failure"] >= 5
    assert one["counts"]["factorisations"] == one["refreshes"]
    assert one["counts"]["failed_newton_solves"] == 0
    # each Newton iteration: 1, or 1 failed + 1 on the fresh factorisation
    assert one["counts"]["krylov_iterations"] == 18 + one["refreshes_after_failure"]
    assert one["u_squared"] == pytest.approx(solve("none")["u_squared"], rel=1e-10)


def test_an_early_refresh_stops_a_slow_krylov_solve_and_counts_its_iterations(krylov):
    """``krylov_predict_after`` = 5: a solve on a kept factorisation whose first 5 FGMRES
    iterations contract too slowly to reach 1e-8 within 20 is stopped there and repeated on
    a fresh factorisation. Measured: one early refresh (in the third load step's first
    Newton iteration, where the 20 without the prediction ran out: one refresh after failure
    either way), 2 factorisations as without it, 146 FGMRES iterations instead of 202. The
    stopped solve's 5 iterations are in the counts (SNES's linear iterations are the sum of
    every attempt's), and the answer is the same."""
    early = solve("krylov", krylov_max_it=20, krylov_predict_after=5)
    assert all(early["converged"])
    assert early["early_refreshes"] == 1 == krylov["refreshes_after_failure"]
    assert early["early_iterations"] == 5 * early["early_refreshes"]
    counts = early["counts"]
    assert counts["factorisations"] == krylov["counts"]["factorisations"] == 2
    assert counts["krylov_iterations"] == early["fgmres_iterations"]
    assert (counts["krylov_iterations"]
            <= krylov["counts"]["krylov_iterations"] - 15 * early["early_refreshes"])
    assert [len(h) for h in early["histories"]] == [len(h) for h in krylov["histories"]]
    assert early["u_squared"] == pytest.approx(krylov["u_squared"], rel=1e-10)


def test_early_refreshes_with_a_short_krylov_budget(direct):
    """With 8 FGMRES iterations allowed and the prediction after 2, every refresh after
    failure is an early one (measured 4 of 4; 5 factorisations, 88 FGMRES iterations), each
    stopped solve counting its 2 iterations; Newton's iterations and answer are full
    Newton's."""
    short = solve("krylov", krylov_max_it=8, krylov_predict_after=2)
    assert all(short["converged"])
    assert short["early_refreshes"] == short["refreshes_after_failure"] >= 3
    assert short["early_iterations"] == 2 * short["early_refreshes"]
    assert short["counts"]["krylov_iterations"] == short["fgmres_iterations"]
    assert short["counts"]["factorisations"] == short["refreshes"] < direct["counts"]["factorisations"]
    assert short["counts"]["newton_iterations"] == direct["counts"]["newton_iterations"]
    assert short["u_squared"] == pytest.approx(direct["u_squared"], rel=1e-10)


def test_modified_newton_on_the_kept_factorisation_assembles_fewer_jacobians(direct):
    """``reuse_contraction`` = 0.5 with ``linear_reuse=krylov``: the assembled Jacobian is
    kept while Newton contracts by 0.5 or better below 1 % of ‖F_0‖ (FGMRES then solves the
    kept operator). Measured: 11 Jacobians for 27 Newton iterations (full Newton: 18 for
    18), 2 factorisations; the answer to 3e-12 relative (measured; bound 1e-8 from
    Newton's tolerance, 1e-9 relative on ‖F‖)."""
    kept = solve("krylov", reuse_contraction=0.5)
    assert all(kept["converged"])
    counts = kept["counts"]
    assert counts["jacobians"] < counts["newton_iterations_all"]
    assert counts["jacobians"] < direct["counts"]["jacobians"] == 18
    assert counts["factorisations"] <= 3
    assert kept["u_squared"] == pytest.approx(direct["u_squared"], rel=1e-8)


def test_two_ranks_give_one_ranks_answer(krylov):
    """MUMPS distributed on 2 ranks with the Krylov solve on the kept factorisation: the
    same solution (measured to 1e-15) and the same counts of Newton iterations and
    factorisations."""
    command = [str(BIN / "mpiexec"), "-n", "2", sys.executable, str(PROBLEM), "krylov", "20"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    two = json.loads([line for line in done.stdout.splitlines() if line.startswith("{")][-1])
    assert all(two["converged"])
    assert two["u_squared"] == pytest.approx(krylov["u_squared"], rel=1e-10)
    for key in ("newton_iterations", "factorisations", "jacobians"):
        assert two["counts"][key] == krylov["counts"][key], key


def test_krylov_reuse_refuses_what_it_cannot_do():
    with pytest.raises(ParameterError) as refused:
        NewtonOptions(linear_reuse="krylov", krylov_predict_after=20)
    assert refused.value.key == "krylov_predict_after"
    with pytest.raises(ParameterError) as refused:
        scleral_buckling.Parameters(resolution="coarse", linear_reuse="krylov",
                                    krylov_jacobian_reuse=1.0).validate()
    assert refused.value.key == "krylov_jacobian_reuse"
    with pytest.raises(ParameterError) as refused:
        NewtonOptions(linear_reuse="krylov", krylov_max_it=0)
    assert refused.value.key == "krylov_max_it"
    with pytest.raises(ParameterError) as refused:
        scleral_buckling.Parameters(resolution="coarse", linear_reuse="krylov",
                                    krylov_rtol=1.0).validate()
    assert refused.value.key == "krylov_rtol"
    with pytest.raises(ParameterError) as refused:
        scleral_buckling.Parameters(resolution="coarse", linear_reuse="krylov",
                                    solver="iterative").validate()
    assert refused.value.key == "linear_reuse"


# the coarse eye, steps 1-3 (the settling step only lengthens the test)
# measured on the paper's operation (docs/scleral_buckling.md, Krylov on a kept factorisation)
COARSE_EYE = {"resolution": "coarse", "settle": False, **scleral_buckling.PAPER_OPERATION}


def test_coarse_eye_with_krylov_reuse_matches_the_reference_method_with_fewer_factorisations():
    """Steps 1-3 on the coarse eye with linear_reuse=krylov (the scene's other defaults)
    against the reference method: the quantities of interest after buckling and after
    suturing within 1 % (measured: 3e-10 relative), the tear rim's gap within 0.005 mm
    (measured 1e-12 mm), with a fifth of the reference's factorisations or fewer (measured
    14 against 190), a Jacobian assembled at every Newton iteration (measured 62 for 61:
    one solve with step 3's cp line search assembled one more than it iterated)."""
    options = RunOptions(fields=False, pictures=False, quiet=True)
    krylov = scleral_buckling.run(scleral_buckling.Parameters(**COARSE_EYE, linear_reuse="krylov"),
                                  options=options)
    reference = scleral_buckling.run(scleral_buckling.Parameters(**COARSE_EYE, **REFERENCE_METHOD),
                                     options=options)
    assert krylov.status == reference.status == "ok"
    assert_same_eye(reference, krylov, rim_gap_tolerance=0.005)
    counts, reference_counts = krylov.counts(), reference.counts()
    assert counts["krylov_iterations"] > 0 == reference_counts["krylov_iterations"]
    assert 5 * counts["factorisations"] <= reference_counts["factorisations"]
    assert (counts["newton_iterations_all"] <= counts["jacobians"]
            <= counts["newton_iterations_all"] + counts["newton_solves"])
