"""Newton's work counted and PETSc options that reach the objects that read them.

- Every Newton iteration, Jacobian, numeric factorisation and symbolic analysis is counted,
  a cut step's failed attempts included: per step (``attempts``, ``newton_iterations_all``,
  ``jacobians``, ``factorisations``, ``symbolic_factorisations``) and per run
  (``solver_counts`` at the top of ``results.json``). Factorisations are PETSc's own log
  events, so they count what PETSc did, not what the driver expects it to do.
- MUMPS reads its ICNTLs when PETSc sets up the factor matrix, during a solve (and again
  on a new factor matrix when the matrix pattern changes): the options must still be in
  PETSc's options database then. Before the fix ICNTL(14) read back 20 (MUMPS's default)
  instead of the 100 the code sets, and ``--petsc mat_mumps_icntl_33=1`` read back 0.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import dolfinx
import dolfinx.fem
import dolfinx.mesh
import numpy as np
import pytest
import ufl
from eye_methods import REFERENCE_METHOD, assert_same_eye
from mpi4py import MPI
from petsc4py import PETSc

from eyemech.problems import cook_membrane, scleral_buckling, sphere_inflation
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.results import SOLVER_COUNTS, SolverCounts
from eyemech.problems.solve import driver
from eyemech.problems.solve.driver import NewtonOptions, NonlinearSolver, Stepping, follow_path

TINY = {"mesh_size": 4.0}  # the thick sphere in 3 load steps, ~1 s
STEP_KEYS = ("attempts", "newton_iterations_all", "jacobians", "factorisations",
             "symbolic_factorisations")


@pytest.fixture
def factors(monkeypatch):
    """What the factor matrix of every solver closed while the test runs held as it was
    closed (the run contract destroys a run's solvers as the run ends)."""
    seen: list[dict | None] = []
    close = NonlinearSolver.close

    def spy(self):
        factor = self.factor_matrix()
        if factor is None or factor.getType() != "mumps":
            seen.append(None)
        else:
            seen.append({"icntl": {k: factor.getMumpsIcntl(k) for k in (12, 14, 33)},
                         "entries": factor.getMumpsInfog(29),
                         "pc": self.snes.getKSP().getPC().getType()})
        close(self)

    monkeypatch.setattr(NonlinearSolver, "close", spy)
    return seen


def code_icntl_14() -> int:
    return int(NewtonOptions().as_petsc()["mat_mumps_icntl_14"])


def test_mumps_options_of_the_code_and_of_petsc_reach_the_factor_matrix(factors, tmp_path):
    """A run through the command line's own entry point (``--petsc`` as a user gives it):
    after the solve the factored matrix holds the code's ICNTL(14) and the user's ICNTL(33)
    (MUMPS's defaults: 20 and 0)."""
    from eyemech.scripts.cli import main

    code = main(["run", "sphere-inflation", "--set", "mesh_size=4.0", "--petsc",
                 "mat_mumps_icntl_33=1", "--out", str(tmp_path), "--no-fields", "--no-pictures",
                 "--quiet"])
    assert code == 0
    assert len(factors) == 1
    factor = factors[0]
    assert factor is not None, "no MUMPS factorisation"
    assert code_icntl_14() == 100
    assert factor["icntl"][14] == code_icntl_14()
    assert factor["icntl"][33] == 1
    # the run's numbers are counted in its results.json
    saved = json.loads((tmp_path / "results.json").read_text())
    check_counts(saved)


def check_counts(saved: dict) -> None:
    """The totals agree with the steps, and each step's counts with its cuts."""
    totals, steps = saved["solver_counts"], saved["steps"]
    for step in steps:
        assert all(key in step for key in STEP_KEYS), step
        # a failed run's last step: every attempt failed, each one cut the step
        failed = step.get("status") == "failed"
        assert step["attempts"] == step["cuts"] + (0 if failed else 1)
        assert step["newton_iterations_all"] >= step["newton_iterations"]
        # SNES Newton with LU: one Jacobian and one factorisation per iteration
        assert step["factorisations"] == step["jacobians"] == step["newton_iterations_all"]
    assert totals["newton_solves"] == sum(s["attempts"] for s in steps)
    assert totals["failed_newton_solves"] == sum(s["cuts"] for s in steps)
    assert totals["newton_iterations"] == sum(s["newton_iterations"] for s in steps)
    for key in ("newton_iterations_all", "jacobians", "factorisations", "symbolic_factorisations"):
        assert totals[key] == sum(s[key] for s in steps), key
    # one pattern (no contact): one symbolic analysis, in the first step
    assert totals["symbolic_factorisations"] == 1 == steps[0]["symbolic_factorisations"]



def test_options_are_read_by_the_factor_matrix_made_for_a_new_pattern():
    """A Jacobian hook that adds an entry outside the finite-element pattern (as contact
    does when pairs change) makes PETSc analyse the matrix again on a new factor matrix;
    that one reads the options too. Between solves the options are out of the database."""
    problem = _nonlinear_poisson(NewtonOptions(petsc={"mat_mumps_icntl_33": "1"}))
    solver, u = problem["solver"], problem["u"]
    first, last = 0, problem["size"] - 1  # not coupled by a P1 Laplacian on this mesh
    calls = [0]

    def grow_pattern(_x, matrix):
        calls[0] += 1
        if calls[0] == 2:  # from the second Jacobian on
            matrix.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        if calls[0] >= 2:
            matrix.setValue(first, last, 0.0, addv=PETSc.InsertMode.ADD_VALUES)
            matrix.assemble()

    solver.jacobian_hooks.append(grow_pattern)
    problem["load"].value = 1.0
    if not PETSc.Log.isActive():
        PETSc.Log.begin()
    symbolic = PETSc.Log.Event("MatLUFactorSym")
    before = symbolic.getPerfInfo()["count"]
    converged, iterations = solver.solve()
    assert converged and iterations >= 3
    # the first pattern, then the grown one on a new factor matrix
    assert symbolic.getPerfInfo()["count"] - before == 2
    assert solver.last_counts.symbolic_factorisations == 2
    assert solver.last_counts.factorisations == iterations
    factor = solver.factor_matrix()
    assert factor.getMumpsIcntl(14) == code_icntl_14()
    assert factor.getMumpsIcntl(33) == 1
    assert np.isfinite(u.x.array).all()
    prefix = solver.snes.getOptionsPrefix()
    assert not PETSc.Options().hasName(f"{prefix}mat_mumps_icntl_14")


def test_failed_attempts_are_counted():
    """A first attempt that runs out of Newton iterations is cut: the step reports both
    attempts, and the process's totals grow by the work of both."""
    problem = _nonlinear_poisson(NewtonOptions(max_it=4))
    solver = problem["solver"]
    before = SOLVER_COUNTS.copy()
    records = follow_path(solver, lambda value, _increment: setattr(problem["load"], "value", value),
                          Stepping(0.0, 1.0, initial_step=1.0, max_step=1.0), quiet=True)
    assert records[0].cuts >= 1, "the full load was meant to fail in 4 iterations"
    first = records[0]
    assert first.attempts == first.cuts + 1
    assert first.iterations_all > first.iterations
    assert first.factorisations == first.jacobians == first.iterations_all
    work = SOLVER_COUNTS - before
    assert work == solver.counts
    assert work.newton_solves == sum(r.attempts for r in records)
    assert work.failed_newton_solves == sum(r.cuts for r in records)
    assert work.newton_iterations == sum(r.iterations for r in records)
    assert work.newton_iterations_all == sum(r.iterations_all for r in records)
    assert work.factorisations == sum(r.factorisations for r in records)
    # failed attempts: max_it iterations each, all factorised
    failed = work.newton_iterations_all - work.newton_iterations
    assert failed == 4 * work.failed_newton_solves


class PetscLog:
    """PETSc's own log events counted over a ``with`` block (the driver turns PETSc's
    logging on at import): SNES solves, linear solves, Jacobian evaluations (kept ones
    included), numeric and symbolic factorisations (LU, and LDLᵀ as PETSc's Cholesky)."""

    EVENTS = ("SNESSolve", "KSPSolve", "SNESJacobianEval", "MatLUFactorNum", "MatLUFactorSym",
              "MatCholFctrNum", "MatCholFctrSym")

    def __enter__(self) -> "PetscLog":
        self._before = self._now()
        return self

    def __exit__(self, *_exc) -> None:
        now = self._now()
        self.counts = {name: now[name] - self._before[name] for name in self.EVENTS}

    def _now(self) -> dict[str, int]:
        return {name: int(PETSc.Log.Event(name).getPerfInfo()["count"]) for name in self.EVENTS}


def assert_counts_are_petscs(counts: dict, log: PetscLog) -> None:
    """Full Newton with a direct solver: a Newton iteration is one linear solve and one
    Jacobian, each Jacobian one numeric factorisation (MUMPS LU or LDLᵀ)."""
    events = log.counts
    assert counts["newton_solves"] == events["SNESSolve"]
    assert counts["newton_iterations_all"] == events["KSPSolve"] == events["SNESJacobianEval"]
    assert counts["jacobians"] == events["SNESJacobianEval"]
    assert counts["factorisations"] == events["MatLUFactorNum"] + events["MatCholFctrNum"]
    assert counts["symbolic_factorisations"] == \
        events["MatLUFactorSym"] + events["MatCholFctrSym"]


def _nan_in_the_line_search() -> NonlinearSolver:
    """ln u = 0 from u = e³ with backtracking allowed no step below 1/2: the full step
    makes u negative, ln u NaN (DIVERGED_FUNCTION_NANORINF in the first iteration's line
    search, after its linear solve)."""
    mesh = dolfinx.mesh.create_unit_interval(MPI.COMM_SELF, 1)
    V = dolfinx.fem.functionspace(mesh, ("DG", 0))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    u.x.array[:] = np.exp(3.0)
    options = NewtonOptions(line_search="bt", petsc={"snes_linesearch_minlambda": "0.5"})
    return driver.NonlinearSolver(ufl.ln(u) * v * ufl.dx, u, options=options)


def _error_in_a_residual_hook() -> NonlinearSolver:
    """The nonlinear Poisson problem whose residual hook raises at its third call: in the
    line search of the second Newton iteration, after its linear solve."""
    problem = _nonlinear_poisson(NewtonOptions())
    problem["load"].value = 1.0
    calls = [0]

    def hook(_x, _vec):
        calls[0] += 1
        if calls[0] == 3:
            raise RuntimeError("a hook's error")

    problem["solver"].residual_hooks.append(hook)
    return problem["solver"]


def test_the_iteration_a_solve_fails_in_is_counted_as_petsc_logs_it():
    """An attempt that ends inside a Newton iteration (here a NaN residual in its line
    search, after the linear solve) did that iteration's Jacobian, linear solve and
    factorisation: ``newton_iterations_all`` counts it (SNES's iteration number does not),
    and every count equals PETSc's log events of the solve."""
    solver = _nan_in_the_line_search()
    with PetscLog() as log:
        converged, _ = solver.solve()
    assert not converged and solver.reason() == "DIVERGED_FUNCTION_NANORINF"
    counts = solver.last_counts.as_dict()
    assert counts["newton_iterations_all"] == 1 > solver.snes.getIterationNumber()
    assert_counts_are_petscs(counts, log)


# run in a process of its own: the error leaves PETSc's events around it (SNESSolve, the
# line search, the residual's evaluation) begun and never ended, and PETSc counts an event
# when its outermost begin ends, so the process's log would count none of them again
ERROR_IN_A_HOOK = """
import json
from test_newton_counts import PetscLog, _error_in_a_residual_hook
solver = _error_in_a_residual_hook()
with PetscLog() as log:
    try:
        solver.solve()
    except RuntimeError as error:
        assert str(error) == "a hook's error"
print(json.dumps({"counts": solver.last_counts.as_dict(), "events": log.counts,
                  "snes_iterations": solver.snes.getIterationNumber()}))
"""


def test_the_iteration_a_hook_raises_in_is_counted_as_petsc_logs_it():
    """An exception in a residual hook in the second iteration's line search (after its
    linear solve and factorisation): both iterations are counted, as PETSc's log counts
    their linear solves, Jacobians and factorisations (the events the error left closed)."""
    proc = subprocess.run([sys.executable, "-c", ERROR_IN_A_HOOK], capture_output=True,
                          text=True, cwd=Path(__file__).parent, timeout=300)
    assert proc.returncode == 0, proc.stderr
    measured = json.loads(proc.stdout.strip().splitlines()[-1])
    counts, events = measured["counts"], measured["events"]
    assert counts["newton_iterations_all"] == 2 > measured["snes_iterations"]
    assert counts["newton_iterations_all"] == events["KSPSolve"] == events["SNESJacobianEval"]
    assert counts["jacobians"] == events["SNESJacobianEval"]
    assert counts["factorisations"] == events["MatLUFactorNum"] == 2
    assert counts["symbolic_factorisations"] == events["MatLUFactorSym"] == 1


def test_a_path_with_nan_attempts_counts_what_petsc_logs():
    """The NaN-cut path (``_log_path``: full steps, a NaN residual cuts the load step at
    once): the solver's totals equal PETSc's log events over the path, and the steps' counts
    sum to the totals (measured: 29 linear solves; the 3 NaN attempts' iterations were
    the ones SNES's iteration number leaves out)."""
    with PetscLog() as log:
        solver, records, _u = _log_path(cut_on_nan=True)
    counts = solver.counts.as_dict()
    assert solver.counts.failed_newton_solves >= 2
    assert_counts_are_petscs(counts, log)
    assert counts["newton_iterations_all"] == sum(r.iterations_all for r in records)
    for record in records:  # one iteration, Jacobian and factorisation per NaN attempt
        assert record.iterations_all == record.jacobians == record.factorisations
        assert record.iterations_all == record.iterations + record.cuts


def test_a_failed_run_records_its_failed_step_and_counts_what_petsc_logs(tmp_path):
    """The thick sphere past its limit pressure (neo-Hookean inflation has a pressure
    maximum, ≈ 0.45 of 0.05 MPa here): steps converge until the step is cut below its
    smallest length. ``results.json`` (status failed) records the last, failed step
    (status failed, its attempts' work), the totals equal the sum over the steps, and
    they equal PETSc's log events over the run (measured: 8 steps, 130 factorisations, the
    failed step's 6 among them)."""
    from eyemech.scripts.cli import main

    with PetscLog() as log:
        code = main(["run", "sphere-inflation", "--set", "mesh_size=4.0", "--set",
                     "pressure=0.05", "--out", str(tmp_path), "--no-fields", "--no-pictures",
                     "--quiet"])
    assert code == 3
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["status"] == "failed"
    steps, totals = saved["steps"], saved["solver_counts"]
    assert [s.get("status") for s in steps[:-1]] == [None] * (len(steps) - 1)
    last = steps[-1]
    assert last["status"] == "failed" and last["newton_iterations"] == 0
    assert last["factorisations"] > 0 and last["attempts"] == last["cuts"] >= 1
    # the failed step's position under the scene's own name for it, as every other step's
    assert last["step"] == len(steps) and last["load_factor"] > steps[-2]["load_factor"]
    assert "load" not in last
    check_counts(saved)
    assert totals["newton_iterations_all"] == sum(s["newton_iterations_all"] for s in steps)
    assert_counts_are_petscs(totals, log)


def test_factorisations_are_counted_where_petsc_performs_them():
    """With the preconditioner lagged (the LU of every second Jacobian preconditions
    GMRES) PETSc factorises half as often as Newton iterates: the count follows PETSc,
    not an assumption of one factorisation per iteration."""
    problem = _nonlinear_poisson(NewtonOptions(petsc={"snes_lag_preconditioner": "2",
                                                      "ksp_type": "gmres", "ksp_rtol": "1e-12"}))
    solver = problem["solver"]
    problem["load"].value = 1.0
    converged, iterations = solver.solve()
    assert converged and iterations >= 4
    counts = solver.last_counts
    assert counts.jacobians == counts.newton_iterations_all == iterations
    assert counts.factorisations == (iterations + 1) // 2  # iterations 0, 2, 4, ...
    assert counts.symbolic_factorisations == 1


def test_results_json_reports_totals_of_a_scene_run():
    result = sphere_inflation.run(sphere_inflation.Parameters(**TINY),
                                  options=RunOptions(fields=False, pictures=False))
    data = result.as_json()
    check_counts(data)
    assert data["solver_counts"]["newton_iterations"] == \
        sum(s["newton_iterations"] for s in data["steps"])
    # frozen at the end of the run: later solves elsewhere do not change it
    _nonlinear_poisson(NewtonOptions())["solver"].solve()
    assert result.as_json()["solver_counts"] == data["solver_counts"]


def _nonlinear_poisson(options: NewtonOptions) -> dict:
    """-div((1 + u²) grad u) = 20·load on the unit square, u = 0 on its boundary (P1, 4×4)."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 4)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    load = dolfinx.fem.Constant(mesh, 0.0)
    residual = ((1 + u**2) * ufl.inner(ufl.grad(u), ufl.grad(v)) - 20.0 * load * v) * ufl.dx
    mesh.topology.create_connectivity(1, 2)
    facets = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    dofs = dolfinx.fem.locate_dofs_topological(V, 1, facets)
    bc = dolfinx.fem.dirichletbc(0.0, dofs, V)
    solver = driver.NonlinearSolver(residual, u, [bc], options=options)
    return {"solver": solver, "u": u, "load": load, "size": V.dofmap.index_map.size_global}


def test_bench_rows_carry_the_counts(tmp_path, monkeypatch):
    """``eyemech bench`` adds the counts as columns; rows of an older table keep theirs
    and show the new columns empty."""
    from eyemech import problems
    from eyemech.problems.run import bench

    monkeypatch.setattr(sphere_inflation, "BENCHMARK", TINY, raising=False)
    old = ("date,machine,ranks,dofs,cells,mesh,form_compilation,assembly,solve,contact_search,"
           "output,total,peak_memory_mb,newton_iterations,status\n"
           "2026-11-22,vm,1,39879,8120,0.2,0.3,113,230,2.4,0.0,344,502,205,ok\n")
    (tmp_path / "sphere-inflation.csv").write_text(old)
    row = bench.run_benchmark(problems.get("sphere-inflation"), tmp_path)
    assert row["newton_iterations_all"] >= row["newton_iterations"] > 0
    assert row["factorisations"] == row["newton_iterations_all"]
    assert row["symbolic_factorisations"] == 1 and row["failed_newton_solves"] == 0
    table = (tmp_path / "sphere-inflation.md").read_text().splitlines()
    assert "| 205 |  |  |  |  |  |  | ok |" in table[-2]
    assert table[-1].startswith(f"| {row['date']} | {row['machine']} | 1 | mesh_size=4.0 |")
    # LU alone: no Krylov iteration; no reallocation of the Jacobian
    assert table[-1].endswith(f"| {row['newton_iterations']} | {row['newton_iterations_all']} | 0 "
                              f"| {row['factorisations']} | 1 | 0 | 0 | ok |")


def test_the_main_jobs_bench_row_names_what_it_bought():
    """A bench row of ``scleral-buckling`` states its outcome beside its time: the tear's
    rim and verdict after suturing / settled, the settled ΔAL and ΔSE, the peak IOP and the
    liquid vented, read from the run's quantities (here the coarse eye's recorded run,
    tests/data/scleral_buckling_coarse.json); a run that measured no stage has none."""
    record = json.loads((Path(__file__).parent / "data" / "scleral_buckling_coarse.json").read_text())
    assert scleral_buckling.bench_outcome(record["quantities"]) == (
        "rim −0.000 mm closed / −0.000 mm closed (sutured / settled); ΔAL +0.65 mm, "
        "ΔSE −2.37 D (settled); peak IOP 79 mmHg, vented 194 µL")
    sutured = {"after_suturing": record["quantities"]["after_suturing"]}
    assert scleral_buckling.bench_outcome(sutured).startswith("rim −0.000 mm closed (sutured); ΔAL +0.76 mm")
    assert scleral_buckling.bench_outcome({"dofs": 4242}) == ""


def test_bench_overrides_are_run_and_named_in_the_row(tmp_path, monkeypatch):
    """``eyemech bench NAME --set k=v`` runs the benchmark settings updated by the overrides;
    the row's settings column names both."""
    from eyemech import problems
    from eyemech.problems.run import bench

    monkeypatch.setattr(sphere_inflation, "BENCHMARK", TINY, raising=False)
    row = bench.run_benchmark(problems.get("sphere-inflation"), tmp_path,
                              overrides={"load_steps": "2"})
    assert row["settings"] == "mesh_size=4.0 load_steps=2"
    # its own folder: the benchmark's own results.json is not overwritten
    result = json.loads((tmp_path / "sphere-inflation-1ranks-load_steps=2" / "results.json")
                        .read_text())
    assert result["parameters"]["load_steps"] == 2 and len(result["steps"]) == 2
    # the table names the benchmark's settings, not the last row's
    assert "this version's benchmark: `mesh_size=4.0`" in (tmp_path / "sphere-inflation.md").read_text()


def test_modified_newton_and_predictor_reach_full_newtons_solution_with_fewer_factorisations():
    """The nonlinear Poisson problem in 5 load steps: the secant predictor and modified
    Newton (a kept factorisation while the residual contracts by 0.5 or better, below 1 %
    of the first) land on full Newton's solution, every iteration and factorisation counted:
    factorisations = Jacobians < iterations."""
    def solve(options: NewtonOptions, predictor: str) -> tuple[np.ndarray, SolverCounts]:
        problem = _nonlinear_poisson(options)
        follow_path(problem["solver"], lambda value, _inc: setattr(problem["load"], "value", value),
                    Stepping(initial_step=0.2, max_step=0.2, predictor=predictor), quiet=True)
        return problem["u"].x.array.copy(), problem["solver"].counts

    full, full_counts = solve(NewtonOptions(), "none")
    budget, counts = solve(NewtonOptions(reuse_contraction=0.5), "secant")
    assert np.allclose(budget, full, rtol=1e-7, atol=1e-9)
    assert counts.factorisations == counts.jacobians < counts.newton_iterations_all
    assert counts.factorisations < full_counts.factorisations
    assert full_counts.factorisations == full_counts.newton_iterations_all


def test_a_failed_full_step_solve_is_repeated_with_the_fallback_line_search():
    """atan(u) = 0 from u = 2 (uniform on the unit interval, ∫ atan(u) v dx): full Newton
    steps overshoot ever further (u ← u − (1 + u²) atan u diverges for |u| > 1.39), the
    fallback's backtracking converges to 0. Both solves are counted, and the solver's line
    search is the full step again afterwards."""
    mesh = dolfinx.mesh.create_unit_interval(MPI.COMM_SELF, 4)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    u.x.array[:] = 2.0
    options = NewtonOptions(line_search="basic", max_it=8, fallback_line_search="bt")
    solver = driver.NonlinearSolver(ufl.atan(u) * v * ufl.dx, u, options=options)
    converged, iterations = solver.solve()
    assert converged
    assert np.allclose(u.x.array, 0.0, atol=1e-9)
    counts = solver.last_counts
    assert solver.counts.newton_solves == 2 and solver.counts.failed_newton_solves == 1
    assert counts.newton_iterations == iterations
    assert solver.counts.factorisations == solver.counts.newton_iterations_all
    assert solver.snes.getLineSearch().getType() == "basic"
    # without the fallback the same start fails
    u.x.array[:] = 2.0
    plain = driver.NonlinearSolver(ufl.atan(u) * v * ufl.dx, u,
                                   options=NewtonOptions(line_search="basic", max_it=8))
    assert plain.solve()[0] is False and plain.counts.newton_solves == 1


def _log_path(cut_on_nan: bool) -> tuple[NonlinearSolver, list, np.ndarray]:
    """ln u = 3 (1 − load) on one DG0 dof, followed from u = e³ (load 0) to u = 1 (load 1)
    in one load step if it converges: Newton's full step u ← u (1 − ln u + 3 (1 − load))
    leaves u > 0 only while ln u − 3 (1 − load) < 1, so at load 1 and at 0.5 it makes u
    negative and ln u NaN (DIVERGED_FUNCTION_NANORINF), as an inverted element does."""
    mesh = dolfinx.mesh.create_unit_interval(MPI.COMM_SELF, 1)
    V = dolfinx.fem.functionspace(mesh, ("DG", 0))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    u.x.array[:] = np.exp(3.0)
    level = dolfinx.fem.Constant(mesh, 3.0)
    options = NewtonOptions(line_search="basic", fallback_line_search="bt", cut_on_nan=cut_on_nan)
    solver = driver.NonlinearSolver((ufl.ln(u) - level) * v * ufl.dx, u, options=options)
    records = follow_path(solver, lambda value, _increment: setattr(level, "value", 3.0 * (1 - value)),
                          Stepping(0.0, 1.0, initial_step=1.0, max_step=1.0), quiet=True)
    return solver, records, u.x.array


def test_a_full_step_that_makes_the_residual_nan_cuts_the_load_step():
    """``cut_on_nan``: a full-step solve that fails with a NaN residual is not repeated with
    the fallback line search; its load step is cut at once (at load 1 and 0.5: 2 cuts), each
    failed attempt counted (one factorisation each, no converged iteration). Without it the
    same NaN is repeated with bt, which converges from load 0 to 1 in one step (5
    iterations, 6 factorisations in all, measured): on this smooth problem the retry is the
    cheaper one; on the eye at the paper's resolution bt crawled at its 0.1 floor across
    the contact's kink (docs/scleral_buckling.md, "A NaN cuts the load step")."""
    retried, retried_records, retried_u = _log_path(cut_on_nan=False)
    assert len(retried_records) == 1 and retried_records[0].cuts == 0
    assert retried.counts.newton_solves == 2 and retried.counts.failed_newton_solves == 1
    assert np.allclose(retried_u, 1.0, atol=1e-9)

    cut, records, u = _log_path(cut_on_nan=True)
    assert np.allclose(u, 1.0, atol=1e-9)
    assert records[0].cuts == 2 and records[0].increment == pytest.approx(0.25)
    # one solve per attempt: no bt solve behind a NaN (measured: 8 solves, 3 failed)
    assert cut.counts.newton_solves == sum(r.attempts for r in records)
    assert cut.counts.failed_newton_solves == sum(r.cuts for r in records) >= 2
    # the failed attempts' factorisations are counted: one each (measured 8 = 6 + 2)
    assert records[0].factorisations == records[0].jacobians == records[0].iterations + 2
    assert cut.snes.getLineSearch().getType() == "basic"

    # a failure without NaN (atan's full steps overshoot ever further) is still retried
    mesh = dolfinx.mesh.create_unit_interval(MPI.COMM_SELF, 4)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    w, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    w.x.array[:] = 2.0
    options = NewtonOptions(line_search="basic", max_it=8, fallback_line_search="bt",
                            cut_on_nan=True)
    overshoot = driver.NonlinearSolver(ufl.atan(w) * v * ufl.dx, w, options=options)
    assert overshoot.solve()[0] and overshoot.counts.newton_solves == 2


# the coarse eye without the settling step (its 4th stage only lengthens the test)
# the budget measured on the paper's operation (docs/scleral_buckling.md, Newton's budget)
BUDGET_EYE = {"resolution": "coarse", "settle": False, **scleral_buckling.PAPER_OPERATION}


@pytest.fixture(scope="module")
def budget_eye_and_log():
    """The coarse eye with the scene's defaults, and PETSc's log events over its run."""
    options = RunOptions(fields=False, pictures=False, quiet=True)
    with PetscLog() as log:
        result = scleral_buckling.run(scleral_buckling.Parameters(**BUDGET_EYE), options=options)
    return result, log


@pytest.fixture(scope="module")
def budget_eye(budget_eye_and_log):
    """The coarse eye with the scene's defaults (one run shared by the tests below)."""
    return budget_eye_and_log[0]


def assert_eye_counts_are_petscs(result, log: PetscLog) -> None:
    """The eye's totals against PETSc's log events over its run, and the sum over its steps
    against the totals. With modified Newton an iteration on a kept Jacobian is a linear
    solve and a Jacobian request (``SNESJacobianEval``) but no assembly and no
    factorisation: Jacobians assembled = numeric factorisations ≤ requests."""
    data = result.as_json()
    counts, events, steps = data["solver_counts"], log.counts, data["steps"]
    assert counts["newton_solves"] == events["SNESSolve"]
    assert counts["newton_iterations_all"] == events["KSPSolve"] == events["SNESJacobianEval"]
    assert counts["factorisations"] == events["MatLUFactorNum"] + events["MatCholFctrNum"]
    assert counts["symbolic_factorisations"] == \
        events["MatLUFactorSym"] + events["MatCholFctrSym"]
    assert counts["jacobians"] <= events["SNESJacobianEval"]
    for key in STEP_KEYS:
        assert counts["newton_solves" if key == "attempts" else key] == \
            sum(s[key] for s in steps), key


def test_the_coarse_eyes_counts_are_petscs(budget_eye_and_log):
    """The default coarse eye (no settling): every count as PETSc's log counts it."""
    assert_eye_counts_are_petscs(*budget_eye_and_log)


def test_scleral_buckling_budget_matches_the_reference_method_with_fewer_factorisations(
        budget_eye):
    """The scene's defaults (secant predictor, modified Newton, 0.2 mm buckle steps,
    load steps sized by factorisations, full Newton steps while the buckle moves in) against
    the reference method on the coarse eye: the quantities of interest after buckling and
    after suturing within 1 % (measured: ≤ 1.5e-6 relative after buckling and after
    suturing), the tear rim's gap within 0.01 mm (1 % of its 1.04 mm after step 1; measured
    0.00026 mm after buckling, 0.00021 mm after suturing), with at most half the numeric
    factorisations (measured: 50 in 20 load steps against 177 in 24; 0.28, so the bound
    leaves room for the solver's counts to move)."""
    options = RunOptions(fields=False, pictures=False, quiet=True)
    with PetscLog() as log:
        reference = scleral_buckling.run(
            scleral_buckling.Parameters(**BUDGET_EYE, **REFERENCE_METHOD), options=options)
    assert_eye_counts_are_petscs(reference, log)
    budget = budget_eye
    assert_same_eye(reference, budget, rim_gap_tolerance=0.01)
    ref_counts = reference.as_json()["solver_counts"]
    counts = budget.as_json()["solver_counts"]
    assert counts["factorisations"] <= 0.5 * ref_counts["factorisations"]
    # modified Newton: iterations on kept factorisations, all of them counted
    assert counts["factorisations"] == counts["jacobians"] < counts["newton_iterations_all"]


def test_the_first_jacobian_fills_the_preallocated_pattern(budget_eye):
    """The eye's Jacobian is assembled into the pattern DOLFINx preallocated: only entries
    outside it (the zonule bars' couplings, retina pairs) make PETSc reallocate. A final
    assembly of the bars' zeros before the first Jacobian squeezes the unused pattern out,
    and the first Jacobian then grows row by row: 18,337 reallocations on the coarse eye
    (4,242 unknowns), about 200 s of one rank's first Jacobian at the paper's resolution
    (docs/scleral_buckling.md, "The Jacobian's preallocation"). With the flush assembly of
    ZonuleBars.allow_new_nonzeros: 124 in the first load step (the bars' rows), 217 in the
    run; the bound is a tenth of the unknowns."""
    steps = budget_eye.as_json()["steps"]
    unknowns = budget_eye.quantities["dofs"]
    assert 0 < steps[0]["matrix_mallocs"] < unknowns / 10
    assert budget_eye.as_json()["solver_counts"]["matrix_mallocs"] == sum(
        s["matrix_mallocs"] for s in steps)


def test_the_retina_contact_pattern_is_preallocated(budget_eye):
    """The retina's contact pairs enter the matrix's pattern before they form: those
    within half an element of the nearest master triangle at set-up
    (NodeToSurfaceContact.allow_new_nonzeros), and at each solve's start those about to
    form (grow_pattern). The pattern, and so MUMPS's symbolic analysis, then stays fixed:
    one analysis in the coarse eye's three steps (measured 1; 4, in load steps 1, 13, 14
    and 15, when PETSc grew the matrix as pairs formed; docs/scleral_buckling.md, "The
    contact pattern, preallocated")."""
    steps = budget_eye.as_json()["steps"]
    assert budget_eye.as_json()["solver_counts"]["symbolic_factorisations"] <= 2
    assert all(step["symbolic_factorisations"] <= 1 for step in steps)


def test_segment_to_segment_retina_contact_gives_the_node_to_surface_eye(budget_eye):
    """The retina–choroid pair by segment-to-segment contact (mortar integration; it passes
    the patch test, tests/test_contact.py) against the default node-to-surface pair on the
    coarse eye: the quantities after buckling and suturing within 1 % (measured: to 1e-4)
    and the rim gap within 0.01 mm (measured 0.0164 / 0.0141 against 0.0145 / 0.0063 mm),
    at more factorisations (measured 70 against 50; docs/scleral_buckling.md,
    "Segment-to-segment retina contact")."""
    options = RunOptions(fields=False, pictures=False, quiet=True)
    mortar = scleral_buckling.run(scleral_buckling.Parameters(
        **BUDGET_EYE, retina_contact_method="segment-to-segment"), options=options)
    assert_same_eye(budget_eye, mortar, rim_gap_tolerance=0.01)
    assert mortar.quantities["after_suturing"]["tear_closed_nts"]


def test_full_steps_while_the_buckle_moves_reach_the_reference_eye(budget_eye):
    """``line_search``: full Newton steps in step 2 (the default) against backtracking (bt)
    on the coarse eye: the same solution (measured: the quantities to 1.1e-12 relative, the
    rim gap to 1e-5 mm printed). What full steps cost depends on the operation and the mesh:
    at the defaults (13.0 mm, 2.0 mm of travel) they take 50 factorisations against bt's 61
    on the coarse eye; with the buckle at 12.5 mm and 1.5 mm of travel 43 against 41 there
    and 42 against 41 in step 2 on the default mesh; with the rim on grid lines they saved
    (default mesh 78 against 94, paper 125 against 177: docs/scleral_buckling.md, "Newton's
    budget")."""
    backtracking = scleral_buckling.run(
        scleral_buckling.Parameters(**BUDGET_EYE, line_search="bt"),
        options=RunOptions(fields=False, pictures=False, quiet=True))
    assert_same_eye(backtracking, budget_eye, rim_gap_tolerance=1e-6, relative=1e-6)
    counts = budget_eye.as_json()["solver_counts"]
    # within a tenth of bt's work (measured 50 against 61), and no failed solve
    assert counts["factorisations"] <= 1.1 * backtracking.as_json()["solver_counts"]["factorisations"]
    assert counts["failed_newton_solves"] == 0


@pytest.mark.parametrize("key, value", [("jacobian_reuse", 1.0), ("jacobian_reuse", -0.1),
                                        ("buckle_step", 0.5), ("buckle_step", 0.0),
                                        ("hard_step_effort", -1), ("stagnation_window", -1),
                                        ("cycle_max_period", -1), ("creep_window", -1),
                                        ("settle_step", 0.9), ("settle_step", -0.1),
                                        ("full_step_nan", "sometimes")])
def test_budget_parameters_out_of_range_are_refused(key, value):
    from eyemech.problems.run.parameters import ParameterError

    with pytest.raises(ParameterError) as refused:
        scleral_buckling.Parameters(resolution="coarse", **{key: value}).validate()
    assert refused.value.key == key


def test_load_steps_follow_the_effort_and_each_stage_limit():
    """Sized by factorisations: 20 iterations on 3 factorisations is an easy step (grown
    ×1.5), 12 factorisations a hard one (halved); at a stop the next stage's own limit
    caps the increment and its first step."""
    stepping = Stepping(0.0, 2.0, initial_step=0.25, max_step=0.5, stops=(1.0,),
                        stage_max_steps=(0.5, 0.1), effort="factorisations", hard_iterations=10)

    def record(factorisations: int) -> driver.StepRecord:
        return driver.StepRecord(step=1, load=0.5, increment=0.4, iterations=20, cuts=0,
                                 residuals=[], factorisations=factorisations)

    assert stepping.next_increment(0.4, record(3), 0.5) == pytest.approx(0.6)
    assert stepping.next_increment(0.8, record(3), 0.5) == pytest.approx(1.0)  # 0.5 of the span
    assert stepping.next_increment(0.4, record(12), 0.5) == pytest.approx(0.2)
    assert stepping.next_increment(0.4, record(8), 1.0) == pytest.approx(0.2)  # 0.1 of the span
    assert stepping.first_step(1.0) == pytest.approx(0.1)
    assert Stepping(initial_step=0.5, max_step=0.25).first_step(0.0) == 0.5  # no stage limits


def _stage_factorisations(result, stage: int) -> int:
    return sum(step["factorisations"] for step in result.as_json()["steps"]
               if step["stage"] == stage)


def test_full_steps_in_the_settling_step_save_factorisations():
    """``settle_line_search``: full Newton steps in step 4 (``basic``) against backtracking
    (bt, the default) on the coarse eye with the settling step, both from the last converged P
    with the other steps' load steps (``settle_start = converged``, ``settle_step = 0``;
    tests/test_settle.py for the default settling). The first
    settling load step starts from P's pinned row alone (‖F_0‖ ≈ 1.6e-3 on the default mesh): the full
    step's second-order remainder in the displacement rows is larger, bt clamps its step at 0.1 and the
    residual creeps × 0.9 per iteration (there 22 iterations, 21 factorisations) where full steps
    converge in 6. Measured on the coarse eye at the defaults: 68 factorisations in 25 load
    steps against 87 in 26, step 4's 18 against 37; the settled axial-length change 0.44977
    against 0.44851 mm (0.28 %), the refraction change −0.3155 against −0.3185 D (0.003 D),
    IOP 15 mmHg both."""
    options = RunOptions(fields=False, pictures=False, quiet=True)
    full, backtracking = (scleral_buckling.run(
        scleral_buckling.Parameters(resolution="coarse", settle_line_search=line_search,
                                    settle_start="converged", settle_step=0.0,
                                    stagnation_window=3, settle_reuse_test="residual",
                                    cycle_max_period=0, retina_step_depth=0.0,  # as measured
                                    **scleral_buckling.PAPER_OPERATION),
        options=options) for line_search in ("basic", "bt"))
    expected, actual = backtracking.quantities["after_settling"], full.quantities["after_settling"]
    for key in ("axial_length_change_mm", "iop_mmHg"):
        assert actual[key] == pytest.approx(expected[key], rel=0.01), key
    # the settled cornea's power change and the refraction (−0.32 D at the defaults) are
    # path-dependent at 0.01 D (measured 0.0064 and 0.0030 D apart): 0.02 D is 0.05 % of
    # the cornea's 41 D power
    for key in ("corneal_power_change_D", "refraction_change_D"):
        assert actual[key] == pytest.approx(expected[key], abs=0.02), key
    # 1 % of the rim's 1.04 mm gap after step 1 (measured −0.00003 mm both)
    assert actual["tear_rim_gap_max_mm"] == pytest.approx(expected["tear_rim_gap_max_mm"],
                                                          abs=0.01)
    # measured 18 against 37 (0.49); 0.75 leaves room for the solver's counts to move
    assert _stage_factorisations(full, 4) <= 0.75 * _stage_factorisations(backtracking, 4)
    assert full.as_json()["solver_counts"]["factorisations"] < \
        backtracking.as_json()["solver_counts"]["factorisations"]


def test_mumps_ldlt_gives_the_lu_answer_with_half_the_factor(factors, tmp_path):
    """The sphere's default (``--factorisation auto`` at P2P1) reaches MUMPS as LDLᵀ (PETSc's
    cholesky on the symmetric indefinite Jacobian, ‖A−Aᵀ‖/‖A‖ = 1.2e-16): the same Newton
    history and answer as ``--factorisation lu`` to round-off, with about half its factor
    entries (INFOG(29))."""
    from eyemech.scripts.cli import main

    def run(factorisation: str) -> tuple[dict, str, int]:
        out = tmp_path / factorisation
        code = main(["run", "sphere-inflation", "--set", "mesh_size=4.0", "--factorisation",
                     factorisation, "--out", str(out), "--no-fields", "--no-pictures", "--quiet"])
        assert code == 0
        factor = factors[-1]
        assert factor is not None, "no MUMPS factorisation"
        assert factor["icntl"][14] == code_icntl_14()
        assert factor["icntl"][12] == (2 if factorisation == "auto" else 1)
        return json.loads((out / "results.json").read_text()), factor["pc"], factor["entries"]

    lu, lu_pc, lu_entries = run("lu")
    ldlt, ldlt_pc, ldlt_entries = run("auto")
    assert (lu_pc, ldlt_pc) == ("lu", "cholesky")
    # one triangle of a symmetric ordering: 0.50 of LU's entries at h = 1 (4.18 M / 8.31 M)
    assert ldlt_entries < 0.6 * lu_entries, (ldlt_entries, lu_entries)
    (step_lu,), (step_ldlt,) = lu["steps"], ldlt["steps"]
    assert step_ldlt["newton_iterations"] == step_lu["newton_iterations"]
    # the last residual is round-off (1e-15): compare the ones above it
    np.testing.assert_allclose(step_ldlt["residuals"][:-1], step_lu["residuals"][:-1], rtol=1e-9)
    assert step_ldlt["inner_radius_deformed"] == pytest.approx(step_lu["inner_radius_deformed"],
                                                               rel=1e-12)
    check_counts(ldlt)


def test_factorisation_choice():
    """"auto" is the solver's scene choice (LDLᵀ at the sphere's and Cook's membrane's P2P1 and
    Q2P1, measured to halve LU's factor), LDLᵀ comes with MUMPS's [u, p]-pair ordering (ICNTL(12)
    = 2 with ICNTL(6) = 5: without it the sphere's Q2P1 factor took 1.5× LU's flops); an unknown
    name is a ParameterError naming it."""
    from eyemech.problems.run.parameters import ParameterError

    assert (sphere_inflation.auto_factorisation("P2P1"),
            sphere_inflation.auto_factorisation("Q2P1")) == ("ldlt", "ldlt")
    assert cook_membrane.auto_factorisation("Q2P1") == "ldlt"
    assert NewtonOptions().as_petsc(auto="ldlt")["pc_type"] == "cholesky"
    ldlt = NewtonOptions().as_petsc(auto="ldlt")
    assert (ldlt["mat_mumps_icntl_12"], ldlt["mat_mumps_icntl_6"]) == ("2", "5")
    assert "mat_mumps_icntl_12" not in NewtonOptions().as_petsc()
    assert NewtonOptions().as_petsc()["pc_type"] == "lu"
    assert NewtonOptions(factorisation="lu").as_petsc(auto="ldlt")["pc_type"] == "lu"
    assert NewtonOptions(factorisation="ldlt").as_petsc()["pc_type"] == "cholesky"
    with pytest.raises(ParameterError, match="factorisation"):
        NewtonOptions(factorisation="cholesky")


def test_results_state_the_newton_stopping_test():
    """results.json's ``newton_tolerances``: the stopping test the run's Newton solves used
    (a result states the accuracy it was converged to), here SNES's default
    ‖F‖ ≤ max(1e-10, 1e-9 ‖F_0‖), and ``--petsc snes_rtol`` is what it then states."""
    options = RunOptions(fields=False, pictures=False, quiet=True)
    params = sphere_inflation.Parameters(mesh_size=4.0)
    default = sphere_inflation.run(params, comm=MPI.COMM_SELF, options=options).as_json()
    assert default["newton_tolerances"] == [{"solver": "SNES Newton", "rtol": 1e-9, "atol": 1e-10,
                                             "norm": "l2 norm of the assembled residual"}]
    tighter = RunOptions(fields=False, pictures=False, quiet=True,
                         newton=NewtonOptions(petsc={"snes_rtol": "1e-11"}))
    stated = sphere_inflation.run(params, comm=MPI.COMM_SELF, options=tighter).as_json()
    assert [c["rtol"] for c in stated["newton_tolerances"]] == [1e-11]


def _penalised_bar(options: NewtonOptions) -> NonlinearSolver:
    """−u'' = 40 on the unit interval (P1, 32 cells), u = 0 at its ends, held below 1 by a
    penalty 10⁴ ⟨u − 1⟩₊ per unit length: from u = 0 the first Newton step, blind to the
    obstacle, lands far inside it, and backtracking on ‖F‖ creeps across the penalty's
    kink (λ ≈ 0.1, ‖F‖ × 0.9 per iteration), as on the eye's contact."""
    mesh = dolfinx.mesh.create_unit_interval(MPI.COMM_SELF, 32)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    residual = (ufl.inner(ufl.grad(u), ufl.grad(v)) - 40.0 * v
                + 1e4 * ufl.max_value(u - 1.0, 0.0) * v) * ufl.dx
    mesh.topology.create_connectivity(0, 1)
    ends = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    bc = dolfinx.fem.dirichletbc(0.0, dolfinx.fem.locate_dofs_topological(V, 0, ends), V)
    return driver.NonlinearSolver(residual, u, [bc], options=options)


def test_the_step_relative_contraction_test_keeps_the_factorisation_while_backtracking_creeps():
    """``reuse_step_relative``: after a step of length λ the Jacobian is kept when ‖F‖ fell
    to 1 − λ(1 − θ) of its last value or below (the linear model's 1 − λ, within θ). In the
    bar's creep (‖F‖ × 0.9 at λ ≈ 0.1) the residual-only test (‖F‖ ≤ θ ‖F_k−1‖) asks for a
    factorisation every iteration; the step-relative test keeps it. Both reach full
    Newton's answer (measured: to 3e-11), every iteration counted (measured: 26
    iterations on 26 factorisations, against 53 iterations on 8)."""
    def solve(step_relative: bool) -> tuple[np.ndarray, SolverCounts]:
        solver = _penalised_bar(NewtonOptions(
            line_search="bt", reuse_contraction=0.5, reuse_below=1.0, reuse_max_it=60,
            reuse_step_relative=step_relative))
        converged, _ = solver.solve()
        assert converged
        return solver.unknowns[0].x.array.copy(), solver.counts

    residual_test, residual_counts = solve(False)
    step_test, step_counts = solve(True)
    assert np.allclose(step_test, residual_test, rtol=0, atol=1e-8)
    assert residual_test.max() == pytest.approx(1.004, abs=1e-3)  # in the penalty's band
    # the creep: a fresh factorisation for every iteration under the residual-only test
    assert residual_counts.factorisations == residual_counts.newton_iterations_all >= 20
    assert step_counts.newton_solves == 1
    assert step_counts.factorisations <= 0.5 * residual_counts.factorisations
    assert step_counts.factorisations == step_counts.jacobians < step_counts.newton_iterations_all


def test_energy_line_search_in_the_suture_step_saves_factorisations():
    """``suture_line_search = cp`` (the default) against bt in step 3 on the default mesh
    (steps 1–3) with the buckle at 12.5 mm and 1.5 mm of travel, where bt creeps: the same
    eye after suturing within 1 % with fewer factorisations in step 3. bt rejects a step
    that raises ‖F‖ and creeps at its 0.1 floor; cp takes the step where the energy's
    directional derivative vanishes. Measured (the tear's rim on its circle, with
    settling): step 3's 19 factorisations against 27, 141 in all against 150; after
    suturing the axial-length change 1.5489 against 1.5499 mm, the rim gap 0.0327 against
    0.0332 mm. At the defaults (13.0 mm, 2.0 mm) neither creeps: both take 10 in step 3
    (63 in steps 1–3) to the same digits. The coarse eye is no proxy here: its step 3
    takes 7 either way."""
    options = RunOptions(fields=False, pictures=False, quiet=True)
    energy, backtracking = (scleral_buckling.run(
        scleral_buckling.Parameters(settle=False, buckle_position=12.5, indentation=1.5,
                                    suture_line_search=line_search,
                                    **scleral_buckling.PAPER_OPERATION),
        options=options) for line_search in ("cp", "bt"))
    expected, actual = backtracking.quantities["after_suturing"], energy.quantities["after_suturing"]
    for key in ("axial_length_change_mm", "iop_mmHg", "refraction_change_D"):
        assert actual[key] == pytest.approx(expected[key], rel=0.01), key
    # 1 % of the rim's ≈ 1 mm gap after step 1
    assert actual["tear_rim_gap_max_mm"] == pytest.approx(expected["tear_rim_gap_max_mm"], abs=0.01)
    assert _stage_factorisations(energy, 3) < _stage_factorisations(backtracking, 3)


def _scalar(residual, start: float, options: NewtonOptions) -> NonlinearSolver:
    """residual(u) = 0 on one DG0 dof from u = ``start``."""
    mesh = dolfinx.mesh.create_unit_interval(MPI.COMM_SELF, 1)
    V = dolfinx.fem.functionspace(mesh, ("DG", 0))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    u.x.array[:] = start
    return driver.NonlinearSolver(residual(u) * v * ufl.dx, u, options=options)


def test_a_stagnating_backtracking_solve_is_stopped_early():
    """``stagnation_window``: u² + 1 = 0 has no root; backtracking from u = 2 brings ‖F‖ to
    its floor 1 and stays (5, 1.56, 1.085, 1.011, 1.007, 1.0, …): the test stops it after 5
    iterations and 5 factorisations (counted as a failed solve) where PETSc's own test
    (DIVERGED_LOCAL_MIN) ends it after 7 iterations and 8 factorisations (measured). The
    price, shown by u³ − 2u + 2 = 0 from 0: backtracking sits at the local minimum of |F|
    (0.911) for three iterations and then escapes to the root in 9; the test stops it at 4.
    Hence a window of 3 on the eye, whose converged solves fall by 0.77 or less over any 3
    iterations (measured: default, coarse and paper meshes, docs/scleral_buckling.md)."""
    def no_root(u):
        return u**2 + 1

    plain = _scalar(no_root, 2.0, NewtonOptions(line_search="bt"))
    assert plain.solve()[0] is False and not plain.stagnated
    stopped = _scalar(no_root, 2.0, NewtonOptions(line_search="bt", stagnation_window=3))
    assert stopped.solve()[0] is False
    assert stopped.stagnated and stopped.reason().startswith("STAGNATED")
    assert stopped.residual_history[-1] > 0.9 * stopped.residual_history[-4]
    assert stopped.counts.failed_newton_solves == 1
    assert stopped.counts.factorisations == stopped.counts.newton_iterations_all == 5
    assert stopped.counts.factorisations < plain.counts.factorisations
    # full steps are not monotone in ‖F‖: the test leaves them alone
    full = _scalar(no_root, 2.0, NewtonOptions(line_search="basic", stagnation_window=3))
    assert full.solve()[0] is False and not full.stagnated

    def local_minimum(u):
        return u**3 - 2 * u + 2

    escapes = _scalar(local_minimum, 0.0, NewtonOptions(line_search="bt"))
    assert escapes.solve() == (True, 9)
    cut = _scalar(local_minimum, 0.0, NewtonOptions(line_search="bt", stagnation_window=3))
    assert cut.solve()[0] is False and cut.stagnated and cut.counts.newton_iterations_all == 4
    # a converging solve is not touched (its residual falls every iteration)
    problem = _nonlinear_poisson(NewtonOptions(line_search="bt", stagnation_window=3))
    problem["load"].value = 1.0
    assert problem["solver"].solve()[0] and not problem["solver"].stagnated
    assert problem["solver"].counts.newton_iterations >= 4  # the window was reached


def test_full_steps_that_cycle_are_stopped_early():
    """``cycle_max_period``: full Newton steps on u³ − 2u + 2 = 0 from 0 hop 0 → 1 → 0 → …
    for ever (‖F‖ = 2, 1, 2, 1, …, the textbook 2-cycle): without the test the solve runs to
    the iteration limit, a factorisation per iteration; with it the solve stops once the
    norms have repeated one period (4 norms, 3 iterations), counted as a failed solve, and
    the fallback line search (bt) then finds the root from the same start."""
    def two_cycle(u):
        return u**3 - 2 * u + 2

    plain = _scalar(two_cycle, 0.0, NewtonOptions(line_search="basic", max_it=20))
    assert plain.solve()[0] is False and not plain.cycled
    assert plain.counts.newton_iterations_all == 20
    stopped = _scalar(two_cycle, 0.0, NewtonOptions(line_search="basic", max_it=20,
                                                    cycle_max_period=8))
    assert stopped.solve()[0] is False
    assert stopped.cycled and stopped.reason().startswith("CYCLED")
    assert stopped.residual_history == pytest.approx([2.0, 1.0, 2.0, 1.0])
    assert stopped.counts.failed_newton_solves == 1
    assert stopped.counts.factorisations == stopped.counts.newton_iterations_all == 3
    retried = _scalar(two_cycle, 0.0, NewtonOptions(line_search="basic", max_it=20,
                                                    cycle_max_period=8, fallback_line_search="bt"))
    assert retried.solve()[0] is True
    assert retried.counts.failed_newton_solves == 1
    assert retried.counts.factorisations < plain.counts.factorisations
    # backtracking is monotone in ‖F‖ and never cycles: the test leaves it alone
    escapes = _scalar(two_cycle, 0.0, NewtonOptions(line_search="bt", cycle_max_period=8))
    assert escapes.solve() == (True, 9) and not escapes.cycled
    # a converging solve is not touched
    problem = _nonlinear_poisson(NewtonOptions(line_search="basic", cycle_max_period=8))
    problem["load"].value = 1.0
    assert problem["solver"].solve()[0] and not problem["solver"].cycled


def test_modified_newton_that_creeps_is_repeated_with_fresh_jacobians_at_once():
    """``reuse_creep_window``: u³ + u = 0 from u = 2 with modified Newton keeping its first
    Jacobian (13) while ‖F‖ contracts by 0.95 or better: near the root (J = 1) the kept
    matrix contracts ‖F‖ by only 1 − 1/13 ≈ 0.92 per iteration, so the solve creeps to the
    iteration limit (25) and is then repeated with fresh Jacobians, which converge in 6. The
    creep test stops the first attempt once 4 iterations have lowered ‖F‖ by less than half:
    after 8 (measured: ‖F‖ = 10, 3.10, 1.97, 1.44, 1.12, 0.91, 0.76, 0.65, 0.57; the last 4
    together × 0.505). The fresh retry is the same solve, to the last bit, so only the
    wasted iterations go."""
    def cubic(u):
        return u**3 + u

    def solve(window: int) -> NonlinearSolver:
        solver = _scalar(cubic, 2.0, NewtonOptions(line_search="basic", reuse_contraction=0.95,
                                                   reuse_below=1.0, reuse_creep_window=window))
        assert solver.solve() == (True, 6)
        return solver

    plain, stopped = solve(0), solve(4)
    assert plain.counts.newton_iterations_all == 25 + 6
    assert stopped.counts.newton_iterations_all == 8 + 6
    assert stopped.counts.failed_newton_solves == plain.counts.failed_newton_solves == 1
    assert stopped.unknowns[0].x.array[0] == plain.unknowns[0].x.array[0]
    # full Newton (no kept Jacobian) is never stopped by it: on the root of sign(u)|u|^0.55,
    # where |F| is not differentiable, it creeps × 0.9 per iteration to the iteration limit
    full = _scalar(lambda u: ufl.sign(u) * abs(u) ** 0.55, 1.0, NewtonOptions(line_search="basic"))
    assert full.solve()[0] is False and not full.crept
    assert full.counts.newton_iterations_all == full.options.max_it
    # nor is backtracking's creep on a kept factorisation (the penalised bar:
    # test_the_step_relative_contraction_test_keeps_the_factorisation_while_backtracking_creeps)


@pytest.mark.parametrize("norms, creeping", [
    ([1.0, 0.95, 0.9, 0.85, 0.8], True),     # × 0.95 per iteration
    ([1.0, 0.9, 0.8, 0.7, 0.6], True),       # 0.6 over 4: more than half left
    ([1.0, 0.8, 0.6, 0.45, 0.4], False),     # 0.4 over 4: contracting fast enough
    ([1.0, 0.95, 0.96, 0.9, 0.85], False),   # not monotone: a kink, not a creep
    ([1.0, 0.95, 0.9, 0.85], False),         # too short to tell
])
def test_a_creep_is_a_slow_monotone_fall(norms, creeping):
    assert driver.creeps(norms, 4, 0.5) is creeping


@pytest.mark.parametrize("period, norms, cycles", [
    (8, [2.0, 1.0, 2.0, 1.0], True),                          # period 2, one repeat
    (8, [1.0, 0.5, 0.5, 0.5], True),                          # period 1: three equal norms
    (8, [3.0, 5.0, 4.0, 6.0, 7.0, 5.0, 4.0, 6.0, 7.0], True),  # period 4
    (3, [3.0, 5.0, 4.0, 6.0, 7.0, 5.0, 4.0, 6.0, 7.0], False),  # ... beyond the longest asked
    (8, [2.0, 1.0, 2.0, 1.01], False),                        # 1 % apart: not a repeat
    (8, [1.0, 1e-2, 1e-5, 1e-10], False),                     # converging
    (8, [1.0, 0.5], False),                                   # too short to tell
])
def test_a_cycle_is_a_period_of_norms_repeated(period, norms, cycles):
    assert driver.repeats_a_cycle(norms, period, 1e-3) is cycles


def test_a_cut_step_restores_the_hooks_memory_of_its_start():
    """``memory_hooks``: a load step cut after a failed attempt, and a failed solve repeated
    with the fallback line search, start from what the hooks remembered at the start (a
    contact search's sticky triangles), not from the failed attempt's last iterate."""
    problem = _nonlinear_poisson(NewtonOptions(max_it=4))
    solver = problem["solver"]
    memory = {"value": 0}
    restored: list[int] = []

    def remember(_x, _b) -> None:  # each residual changes what the hook remembers
        memory["value"] += 1

    solver.residual_hooks.append(remember)
    solver.memory_hooks.append((lambda: memory["value"],
                                lambda saved: (restored.append(saved),
                                               memory.update(value=saved))))
    records = follow_path(solver, lambda value, _increment: setattr(problem["load"], "value", value),
                          Stepping(0.0, 1.0, initial_step=1.0, max_step=1.0), quiet=True)
    assert records[0].cuts >= 1
    # every cut of the first step put back the memory of its start (no residual yet: 0)
    assert restored[:records[0].cuts] == [0] * records[0].cuts


@pytest.mark.skipif(not os.environ.get("EYEMECH_BUDGET_DEFAULT"),
                    reason="two runs of make run's eye, ~70 s idle: EYEMECH_BUDGET_DEFAULT=1")
def test_stopping_stalled_backtracking_costs_the_default_eye_nothing():
    """``stagnation_window = 3`` against 0 on ``make run``'s eye: the load path
    and the quantities after every step stay the same, and the run takes no more
    factorisations. With the tear's rim on grid lines it stopped step 4's two failed bt
    attempts after 7 iterations instead of 15 and 24 (107 factorisations instead of 128);
    with the rim on its circle no bt solve stalls there and both take 141 (measured;
    docs/scleral_buckling.md, "Stalled backtracking"). The unit tests above show the stop
    itself."""
    options = RunOptions(fields=False, pictures=False, quiet=True)
    # the settling this was measured with: from the converged P, the other steps' load steps
    # (tests/test_settle.py for the default settling, which stops no solve)
    former = {"buckle_position": 12.5, "indentation": 1.5, "settle_start": "converged",
              "settle_step": 0.0, "settle_reuse_test": "residual", "settle_line_search": "bt",
              "cycle_max_period": 0, "retina_step_depth": 0.0,
              **scleral_buckling.PAPER_OPERATION}
    stopped, plain = (scleral_buckling.run(scleral_buckling.Parameters(
        stagnation_window=window, **former), options=options) for window in (3, 0))
    assert_same_eye(plain, stopped, rim_gap_tolerance=1e-5, relative=1e-4,
                    stages=("after_buckling", "after_suturing", "after_settling"))
    assert [s["load"] for s in stopped.as_json()["steps"]] == \
        [s["load"] for s in plain.as_json()["steps"]]
    assert stopped.as_json()["solver_counts"]["factorisations"] <= \
        plain.as_json()["solver_counts"]["factorisations"]


def _through_obstacle(predictor: str) -> tuple[NonlinearSolver, list]:
    """u = s on one dof, stepped from 0 to 1; a depth hook stands for a rigid obstacle
    0.3 thick whose contact face is at the last accepted state: a state that moved more
    than 0.15 (half its thickness) beyond it is reported as a point through it."""
    mesh = dolfinx.mesh.create_unit_interval(MPI.COMM_SELF, 1)
    V = dolfinx.fem.functionspace(mesh, ("DG", 0))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    load = dolfinx.fem.Constant(mesh, 0.0)
    solver = driver.NonlinearSolver((u - load) * v * ufl.dx, u, options=NewtonOptions())
    face = {"value": 0.0}
    solver.depth_hooks.append(lambda: (float(u.x.array[0]) - face["value"]) / 0.3)
    records = follow_path(solver, lambda value, _increment: setattr(load, "value", value),
                          Stepping(0.0, 1.0, initial_step=0.5, max_step=0.5, predictor=predictor),
                          on_converged=lambda _record: face.update(value=float(u.x.array[0])),
                          quiet=True)
    return solver, records


def test_a_step_through_an_obstacle_is_cut_and_counted():
    """``depth_hooks``: a converged state with a point deeper through an obstacle than
    ``Stepping.depth_limit`` (half its thickness) of it is refused and the step cut (the
    radial tire's tunnelling step, tests/test_buckle_radial.py): 0.5 (depth 1.67) and 0.25
    (0.83) are refused, 0.125 (0.42) accepted; the refused solves count as failed, their
    iterations in ``newton_iterations_all`` only."""
    solver, records = _through_obstacle("none")
    assert records[-1].load == pytest.approx(1.0)
    assert records[0].cuts == 2 and records[0].increment == pytest.approx(0.125)
    assert all(r.increment <= 0.15 + 1e-12 for r in records)
    work = solver.counts
    assert work.failed_newton_solves == sum(r.cuts for r in records) >= 3
    assert work.newton_iterations == sum(r.iterations for r in records)
    assert work.newton_iterations_all == sum(r.iterations_all for r in records) \
        == work.newton_iterations + work.failed_newton_solves  # one iteration each (linear)
    assert solver.rejected_predictions == 0


def test_a_predicted_start_through_an_obstacle_is_refused():
    """The secant's start (exact for u = s) at a grown step of 0.1875 lies 0.625 of the
    obstacle's thickness through it: refused (counted), the step starts unpredicted,
    converges there, and is cut as above; steps of 0.125 keep their predicted start."""
    solver, records = _through_obstacle("secant")
    assert records[-1].load == pytest.approx(1.0)
    assert solver.rejected_predictions >= 1
    assert all(r.increment <= 0.15 + 1e-12 for r in records)
    assert any(r.iterations == 0 for r in records)  # a predicted start kept (exact: no iteration)
