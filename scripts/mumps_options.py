"""MUMPS option sets timed on Jacobians dumped from a scene's run (issue 22; the measurement
is docs/scleral_buckling.md, "MUMPS's options at the paper's resolution").

    python -m eyemech.scripts.mumps_options dump --every 12 --dir /tmp/jac -- \
        scleral-buckling --set resolution=paper --set settle=false --out /tmp/run
    mpiexec -n 2 python -m eyemech.scripts.mumps_options time /tmp/jac/J132_*.bin \
        --sets default,scotch,blr-1e-10 --rounds 2 --repeats 2

``dump`` runs the scene through the CLI and writes every ``--every``-th Jacobian the Newton
solver assembles (after all its hooks: contact, zonules, cavity) in PETSc binary, named by
its count and the count of Newton solves so far. ``time`` factors each matrix with
MUMPS LU for every option set, round-robin (``--rounds``: A, B, …, A, B, … so that a shared
machine's load falls on all sets alike): the analysis once per set and round, then
``--repeats`` numeric factorisations (the analysis reused, as in a Newton solve) and solves
against b = A x for a random x; it prints per set the fastest numeric factorisation and
solve, MUMPS's factor entries (INFOG(29); INFOG(35) with block low-rank compression),
operations (RINFOG(3)), working memory (INFOG(22), MB over all ranks), the ordering used
(INFOG(7)), and the solution's relative residual and error. The set ``ldlt`` factors the
symmetric part (A + Aᵀ)/2 by MUMPS LDLᵀ instead (PCCHOLESKY, sym = 2): the price of a
symmetric factorisation on the same pattern, not a solve of A.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

SYMMETRIC = "ldlt"  # an option set's key (not a PETSc option): factor (A + Aᵀ)/2 by LDLᵀ
# MUMPS options on top of the code's own (NewtonOptions.as_petsc: ICNTL(14) = 100)
OPTION_SETS: dict[str, dict[str, str]] = {
    "default": {},
    "amd": {"mat_mumps_icntl_7": "0"},
    "amf": {"mat_mumps_icntl_7": "2"},
    "scotch": {"mat_mumps_icntl_7": "3"},
    "pord": {"mat_mumps_icntl_7": "4"},
    "metis": {"mat_mumps_icntl_7": "5"},
    "qamd": {"mat_mumps_icntl_7": "6"},
    "ptscotch": {"mat_mumps_icntl_28": "2", "mat_mumps_icntl_29": "1"},
    "scaling-none": {"mat_mumps_icntl_8": "0"},
    "scaling-7": {"mat_mumps_icntl_8": "7"},
    "scaling-77": {"mat_mumps_icntl_8": "77"},
    "perm-none": {"mat_mumps_icntl_6": "0"},
    "perm-5": {"mat_mumps_icntl_6": "5"},
    **{f"blr-{eps}": {"mat_mumps_icntl_35": "1", "mat_mumps_cntl_7": eps}
       for eps in ("1e-12", "1e-10", "1e-8")},
    "blr2-1e-10": {"mat_mumps_icntl_35": "2", "mat_mumps_cntl_7": "1e-10"},
    # MUMPS LDLᵀ (PCCHOLESKY on AIJ: sym = 2, the upper triangle read), timed on the
    # symmetric part (A + Aᵀ)/2: the eye's Real rows are not symmetric (docs/scleral_buckling.md,
    # "Symmetric factorisation: measured, not an option"), so this prices the factorisation only
    "ldlt": {SYMMETRIC: "1"},
}

BASE = {"mat_mumps_icntl_14": "100"}


@dataclasses.dataclass
class Timing:
    """One option set on one matrix: seconds are the fastest over repeats and rounds."""
    matrix: str
    option_set: str
    analysis_and_factorisation: float
    factorisation: float
    solve: float
    factor_entries: float  # INFOG(29)
    compressed_entries: float  # INFOG(35): INFOG(29) unless block low-rank compresses
    flops: float  # RINFOG(3)
    memory_mb: int  # INFOG(22), all ranks
    ordering: int  # INFOG(7)
    residual: float  # ‖b − A x‖ / ‖b‖
    error: float  # ‖x − x_true‖ / ‖x_true‖

    def row(self) -> str:
        return (f"{self.matrix} {self.option_set:12s} analysis+factor {self.analysis_and_factorisation:.2f} s"
                f"  factor {self.factorisation:.3f} s  solve {self.solve:.3f} s"
                f"  entries {self.factor_entries:.3g} ({self.compressed_entries:.3g})"
                f"  flops {self.flops:.3g}  memory {self.memory_mb} MB  ordering {self.ordering}"
                f"  residual {self.residual:.1e}  error {self.error:.1e}")


def _entries(value: int) -> float:
    """MUMPS's INFOG entry counts: negative means millions."""
    return float(value) if value >= 0 else -1e6 * value


def load_matrix(path: str, comm):
    from petsc4py import PETSc
    A = PETSc.Mat().create(comm)
    A.setType("aij")
    viewer = PETSc.Viewer().createBinary(path, "r", comm=comm)
    A.load(viewer)
    viewer.destroy()
    return A


def time_option_set(A, b, x_true, name: str, options: dict[str, str], prefix: str,
                    repeats: int) -> Timing:
    """Analysis and first factorisation, then ``repeats`` numeric factorisations (the
    matrix's state increased so that PCSetUp refactors, keeping the analysis) and solves."""
    from petsc4py import PETSc
    symmetric = SYMMETRIC in options
    options = {k: v for k, v in options.items() if k != SYMMETRIC}
    if symmetric:
        A = _symmetric_part(A)
        b = A.createVecLeft()
        A.mult(x_true, b)
    database = PETSc.Options()
    for key, value in {**BASE, **options}.items():
        database[prefix + key] = value
    ksp = PETSc.KSP().create(A.comm)
    ksp.setOptionsPrefix(prefix)
    ksp.setType("preonly")
    ksp.getPC().setType("cholesky" if symmetric else "lu")
    ksp.getPC().setFactorSolverType("mumps")
    ksp.setOperators(A)
    ksp.setFromOptions()
    x = b.duplicate()
    comm = A.comm.tompi4py()

    def timed(call) -> float:
        comm.barrier()
        start = time.perf_counter()
        call()
        comm.barrier()
        return time.perf_counter() - start

    first = timed(ksp.setUp)
    factorisations, solves = [], []
    for _ in range(repeats):
        A.stateIncrease()
        factorisations.append(timed(ksp.getPC().setUp))
        solves.append(timed(lambda: ksp.solve(b, x)))
    F = ksp.getPC().getFactorMatrix()
    r = b.duplicate()
    A.mult(x, r)
    r.aypx(-1.0, b)
    x.axpy(-1.0, x_true)
    timing = Timing(matrix=Path(A.getName() or "A").name, option_set=name,
                    analysis_and_factorisation=first, factorisation=min(factorisations),
                    solve=min(solves), factor_entries=_entries(F.getMumpsInfog(29)),
                    compressed_entries=_entries(F.getMumpsInfog(35)),
                    flops=F.getMumpsRinfog(3), memory_mb=F.getMumpsInfog(22),
                    ordering=F.getMumpsInfog(7), residual=r.norm() / b.norm(),
                    error=x.norm() / x_true.norm())
    ksp.destroy()
    for key in {**BASE, **options}:
        database.delValue(prefix + key)
    return timing


def _symmetric_part(A):
    """(A + Aᵀ)/2, named as A."""
    from petsc4py import PETSc
    S = A.transpose()
    S.axpy(1.0, A, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    S.scale(0.5)
    S.setName(A.getName())
    return S


def time_matrices(paths: list[str], sets: list[str], rounds: int, repeats: int,
                  seed: int = 1) -> list[Timing]:
    """Every option set on every matrix, round-robin; the fastest of the rounds kept."""
    import numpy as np
    from petsc4py import PETSc
    comm = PETSc.COMM_WORLD
    best: dict[tuple[str, str], Timing] = {}
    calls = 0
    for path in paths:
        A = load_matrix(path, comm)
        A.setName(Path(path).stem)
        x_true = A.createVecRight()
        rng = np.random.default_rng(seed + comm.rank)
        x_true.setArray(rng.standard_normal(x_true.getLocalSize()))
        b = A.createVecLeft()
        A.mult(x_true, b)
        for _ in range(rounds):
            for name in sets:
                calls += 1
                t = time_option_set(A, b, x_true, name, OPTION_SETS[name], f"mo{calls}_", repeats)
                if comm.rank == 0:
                    print(t.row(), flush=True)
                kept = best.get((path, name))
                if kept is None or t.factorisation < kept.factorisation:
                    best[(path, name)] = t
        A.destroy()
    return list(best.values())


def dump_jacobians(scene_args: list[str], directory: Path, every: int) -> int:
    """Run a scene through the CLI with a last Jacobian hook writing every ``every``-th
    Jacobian (the first included) as ``J{count}_solve{n}.bin``: its count and the count of
    Newton solves (load steps, cut steps and retries) so far."""
    from petsc4py import PETSc

    from eyemech.problems.solve import driver
    from eyemech.scripts.cli import main
    directory.mkdir(parents=True, exist_ok=True)
    state = {"count": 0, "solves": 0}
    real_solve = driver.NonlinearSolver.solve

    def dump(x, mat) -> None:
        state["count"] += 1
        if state["count"] == 1 or state["count"] % every == 0:
            mat.assemble()
            name = directory / f"J{state['count']:03d}_solve{state['solves']:03d}.bin"
            viewer = PETSc.Viewer().createBinary(str(name), "w", comm=mat.comm)
            mat.view(viewer)
            viewer.destroy()

    def solve(self, *args, **kwargs):
        # the hook goes last, after the scene's own (contact, zonules, cavity)
        if dump not in self.jacobian_hooks:
            self.jacobian_hooks.append(dump)
        state["solves"] += 1
        return real_solve(self, *args, **kwargs)

    driver.NonlinearSolver.solve = solve
    try:
        return main(scene_args)
    finally:
        driver.NonlinearSolver.solve = real_solve


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m eyemech.scripts.mumps_options")
    sub = parser.add_subparsers(dest="command", required=True)
    d = sub.add_parser("dump", help="run a scene, writing its Jacobians in PETSc binary")
    d.add_argument("--every", type=int, default=12)
    d.add_argument("--dir", type=Path, required=True)
    d.add_argument("scene_args", nargs=argparse.REMAINDER, help="after --: `eyemech run` arguments")
    t = sub.add_parser("time", help="time MUMPS option sets on dumped Jacobians")
    t.add_argument("matrices", nargs="+")
    t.add_argument("--sets", default=",".join(OPTION_SETS),
                   help="comma-separated, of: " + ", ".join(OPTION_SETS))
    t.add_argument("--rounds", type=int, default=2)
    t.add_argument("--repeats", type=int, default=2)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from mpi4py import MPI  # noqa: F401  (loads MPI before petsc4py)
    if args.command == "dump":
        scene_args = args.scene_args[1:] if args.scene_args[:1] == ["--"] else args.scene_args
        return dump_jacobians(["run", *scene_args], args.dir, args.every)
    sets = args.sets.split(",")
    unknown = [s for s in sets if s not in OPTION_SETS]
    if unknown:
        raise SystemExit(f"--sets: unknown {', '.join(unknown)}; known: {', '.join(OPTION_SETS)}")
    time_matrices(args.matrices, sets, args.rounds, args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
