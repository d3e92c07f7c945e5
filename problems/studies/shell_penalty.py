"""Where the C0 interior-penalty shell fails, and what P3 buys over P2.

- Penalty sweep on the clamped plate (linear, P2): centre deflection error against
  α in γ = α p(p+1) D/h, and the condition number of the bending stiffness (free
  transverse degrees of freedom, 1-norm estimate). Too small an α loses coercivity (the
  consistency term wins: erratic, non-conforming answers); too large an α forces the
  slopes to be continuous with P2 (C1 locking: too stiff) and grows the condition
  number like α.
- Degree: P2 against P3 on refined meshes, error against unknowns and against wall
  time (assembly + solve; form compilation excluded — it is cached once per degree).
(The large-deflection plate curve is the study ``shell-plate-nonlinear``.)
"""

from __future__ import annotations

from pathlib import Path

import dolfinx.fem
import dolfinx.fem.petsc
import numpy as np
import scipy.sparse
import scipy.sparse.linalg
import ufl
from mpi4py import MPI

from eyemech.meshes.surface import mapped_surface, tag_boundary
from eyemech.problems import plate_clamped
from eyemech.problems.run.context import RunOptions
from eyemech.problems.shell.model import Shell
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import failed_row, mark_failed, save_chart, write_csv

QUIET = RunOptions(fields=False, pictures=False)


def _deflection_error(**overrides) -> tuple[float, int, float]:
    result = plate_clamped.run(plate_clamped.Parameters(**overrides), comm=MPI.COMM_SELF, options=QUIET)
    seconds = result.timings["assembly"] + result.timings["solve"]
    return result.quantities["center_deflection_error"], result.quantities["dofs"], seconds


def _condition_number(divisions: int, penalty_factor: float) -> float:
    """1-norm condition estimate of the clamped plate's bending stiffness: the block of
    the free transverse (w) dofs. (The linear plate's membrane block is decoupled and
    does not see the penalty; with it the condition number would be dominated by the
    membrane/bending stiffness ratio E h / (D/h²) instead.)"""
    params = plate_clamped.Parameters(divisions=divisions, penalty_factor=penalty_factor)
    L = params.length
    mesh = mapped_surface(lambda s, t: np.column_stack([L * s, L * t, 0 * s]), divisions, divisions,
                          params.diagonal, MPI.COMM_SELF)
    on_edge = (lambda x: np.isclose(x[0], 0) | np.isclose(x[0], L) | np.isclose(x[1], 0)
               | np.isclose(x[1], L))
    tagged = tag_boundary(mesh, {"edge": on_edge})
    shell = Shell(tagged, params, lambda x: np.tile([0.0, 0.0, 1.0], (len(x), 1)), clamped=("edge",))
    residual = ufl.derivative(shell.energy("linear"), shell.u, shell.v)
    jacobian = ufl.derivative(residual, shell.u, ufl.TrialFunction(shell.V))
    A = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(jacobian))
    A.assemble()
    indptr, indices, data = A.getValuesCSR()
    matrix = scipy.sparse.csr_matrix((data, indices, indptr), shape=A.getSize())
    fixed = np.concatenate([bc.dof_indices()[0] for bc in shell.fix("edge")])
    transverse = np.arange(2, matrix.shape[0], 3)  # blocked layout: 3 node + component
    free = np.setdiff1d(transverse, fixed)
    K = matrix[free][:, free].tocsc()
    lu = scipy.sparse.linalg.splu(K)
    inverse = scipy.sparse.linalg.LinearOperator(K.shape, matvec=lu.solve, rmatvec=lambda b: lu.solve(b, "T"))
    return float(scipy.sparse.linalg.onenormest(K) * scipy.sparse.linalg.onenormest(inverse))


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    if comm.rank != 0:  # serial studies: rank 0 does the work
        return []
    out.mkdir(parents=True, exist_ok=True)
    divisions = 8 if quick else 16
    factors = [0.1, 1.0, 10.0] if quick else list(np.logspace(-1.5, 3.0, 19))
    # a case whose solve fails is a row with status failed (``eyemech study`` exits 4)
    penalty_rows = []
    for alpha in factors:
        case = {"penalty_factor": float(alpha)}
        try:
            error, dofs, _ = _deflection_error(divisions=divisions, penalty_factor=float(alpha))
        except SolveFailure as failure:
            penalty_rows.append(failed_row(case, failure))
            continue
        penalty_rows.append(case | {"status": "ok", "center_deflection_error": error,
                                    "condition_number": _condition_number(divisions, float(alpha)),
                                    "dofs": dofs})
    degree_runs = {2: [8] if quick else [8, 16, 24, 32, 48], 3: [4] if quick else [4, 8, 12, 16]}
    degree_rows = []
    for degree, sequence in degree_runs.items():
        for n in sequence:
            case = {"degree": degree, "divisions": n}
            try:
                error, dofs, seconds = _deflection_error(divisions=n, degree=degree)
            except SolveFailure as failure:
                degree_rows.append(failed_row(case, failure))
                continue
            degree_rows.append(case | {"status": "ok", "dofs": dofs, "center_deflection_error": error,
                                       "seconds": seconds})
    files = [write_csv(out / "shell_penalty.csv", penalty_rows),
             write_csv(out / "shell_degree.csv", degree_rows)]
    files += _charts(out, divisions, penalty_rows, degree_rows)
    return files


def _charts(out: Path, divisions: int, penalty_rows: list[dict], degree_rows: list[dict]) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    columns = ("penalty_factor", "center_deflection_error", "condition_number")
    penalty = np.array([[r[k] for k in columns] for r in penalty_rows if r["status"] == "ok"],
                       dtype=float).reshape(-1, len(columns))
    failed_factors = [r["penalty_factor"] for r in penalty_rows if r["status"] != "ok"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    left.loglog(penalty[:, 0], np.abs(penalty[:, 1]) * 100, "o-")
    for alpha, error in penalty[:, :2]:
        if error > 0:  # too soft: mark the sign, which the log axis hides
            left.annotate("+", (alpha, abs(error) * 100), textcoords="offset points", xytext=(4, 4))
    left.set_xscale("log")
    mark_failed(left, failed_factors, "solve failed")
    left.axhline(0.3, color="grey", ls=":", label="0.3 % target")
    left.set(xlabel="penalty factor α", ylabel="|centre deflection error| (%)",
             title=f"clamped plate, P2, crossed {divisions}×{divisions} (+: too soft)")
    left.legend()
    right.loglog(penalty[:, 0], penalty[:, 2], "s-", color="C3")
    right.set_xscale("log")
    mark_failed(right, failed_factors, "solve failed")
    right.set(xlabel="penalty factor α", ylabel="condition number (1-norm estimate)",
              title="bending stiffness conditioning (free w dofs)")
    penalty_png = out / "shell_penalty.png"
    save_chart(fig, penalty_png, dpi=110, rect=(0, 0.04, 1, 1))

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    columns = ("divisions", "dofs", "center_deflection_error", "seconds")
    for degree, marker in ((2, "o-"), (3, "s-")):
        rows = np.array([[r[k] for k in columns] for r in degree_rows
                         if r["degree"] == degree and r["status"] == "ok"], dtype=float).reshape(-1, 4)
        left.loglog(rows[:, 1], np.abs(rows[:, 2]) * 100, marker, label=f"P{degree}")
        right.loglog(rows[:, 3], np.abs(rows[:, 2]) * 100, marker, label=f"P{degree}")
        for n, dofs, error, seconds in rows:
            right.annotate(f"{int(n)}", (seconds, abs(error) * 100), fontsize=7,
                           textcoords="offset points", xytext=(3, 3))
    failed = [r for r in degree_rows if r["status"] != "ok"]
    if failed:  # no unknowns or time to place them at: named on the chart
        left.text(0.02, 0.02, "✗ solve failed: " + "; ".join(f"P{r['degree']}, {r['divisions']} div."
                                                           for r in failed),
                  transform=left.transAxes, fontsize=7, color="tab:red")
    for axis, label in ((left, "unknowns"), (right, "assembly + solve (s)")):
        axis.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())  # no crowded labels
        axis.axhline(0.3, color="grey", ls=":")
        axis.set(xlabel=label, ylabel="|centre deflection error| (%)")
        axis.legend()
    left.set_title("clamped plate, crossed meshes, α = 1")
    right.set_title("accuracy against time (labels: divisions)")
    degree_png = out / "shell_degree.png"
    save_chart(fig, degree_png, dpi=110, rect=(0, 0.04, 1, 1))
    return [penalty_png, degree_png]


STUDY = Study(name="shell-penalty", summary="C0-IP shell: penalty sweep (accuracy, conditioning) and "
              "P2 vs P3 accuracy against time on the clamped plate", run=run)
