"""Performance benchmarks: a scene at a stated size, timed phase by phase.

A scene module may define ``BENCHMARK`` (parameter overrides, e.g. the paper's
resolution) and ``bench_operation(params) -> str``, the row's ``operation``: what the
parameters amount to in words (the main job's defaults changed from Table 1's eye to a
living one, and a row's ``settings`` only lists what differs from the defaults of its day),
and ``bench_outcome(quantities) -> str``, the row's ``outcome``: what the run bought (the
main job's tear verdict, its axial and refractive change), so that a time is read beside
its result.
``eyemech bench NAME`` runs it once on the current communicator and appends one row to
``OUT/NAME.csv``; ``OUT/NAME.md`` is the table of all rows, with the machine and the method
stated, regenerated every time.
"""

from __future__ import annotations

import csv
import datetime
import importlib
import io
import platform
from pathlib import Path

from mpi4py import MPI

from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import build
from eyemech.problems.run.results import versions, write_text_atomic

PHASES = ("mesh", "form_compilation", "assembly", "solve", "contact_search", "output", "total")
COLUMNS = ("date", "machine", "ranks", "settings", "operation", "outcome", "dofs", "cells", *PHASES,
           "peak_memory_mb", "newton_iterations", "newton_iterations_all", "failed_newton_solves",
           "factorisations", "symbolic_factorisations", "krylov_iterations", "matrix_mallocs", "status")
# what the counts mean (the table's notes)
COUNTS = ("newton_iterations: of the converged solves (the steps' own); newton_iterations_all: "
          "of all solves, the failed attempts of cut steps included (failed_newton_solves of "
          "them); factorisations: numeric LU factorisations PETSc performed (its log events), "
          "symbolic_factorisations: its symbolic analyses (one per new matrix pattern); "
          "krylov_iterations: Krylov iterations of all solves (0 with LU alone; linear_reuse="
          "krylov: FGMRES on the kept factorisation, its failed attempts included); "
          "matrix_mallocs: PETSc's reallocations of the Jacobian's storage (entries outside "
          "its preallocated pattern)")


def run_benchmark(scene, out: Path, comm: MPI.Comm = MPI.COMM_WORLD, options: RunOptions | None = None,
                  overrides: dict | None = None):
    """One row: the scene at its ``BENCHMARK`` settings, updated by ``overrides``."""
    module = importlib.import_module(scene.run.__module__)
    benchmark = getattr(module, "BENCHMARK", {})
    extra = {key: value for key, value in (overrides or {}).items()
             if str(benchmark.get(key)) != str(value)}
    overrides = {**benchmark, **extra}
    params = build(scene.parameters, overrides)
    options = options or RunOptions(fields=False, pictures=False)
    # a row with settings of its own keeps its own results.json beside the benchmark's
    # one folder (a value that is a path, e.g. folded_state, must not nest folders)
    folder = f"{scene.name}-{comm.size}ranks" + "".join(
        f"-{key}={str(value).replace('/', '_')}" for key, value in extra.items())
    result = scene.run(params, comm=comm, out=Path(out) / folder, options=options)
    if comm.rank != 0:
        return None
    timings = result.timings
    row = {"date": datetime.date.today().isoformat(),
           "machine": f"{platform.node()} ({platform.machine()}, {__import__('os').cpu_count()} cpus)",
           "ranks": comm.size, "settings": _settings(overrides),
           "operation": getattr(module, "bench_operation", lambda _: "")(params),
           "outcome": getattr(module, "bench_outcome", lambda _: "")(result.quantities),
           "dofs": result.quantities.get("dofs"),
           "cells": result.quantities.get("cells"),
           **{k: round(timings.get(k, 0.0), 2) for k in PHASES},
           "peak_memory_mb": round(result.peak_memory_mb, 1),
           "newton_iterations": sum(s.get("newton_iterations", 0) for s in result.steps),
           "status": result.status}
    counts = result.counts()
    row.update({k: counts[k] for k in ("newton_iterations_all", "failed_newton_solves",
                                       "factorisations", "symbolic_factorisations",
                                       "krylov_iterations", "matrix_mallocs")})
    table = Path(out) / f"{scene.name}.csv"
    rows = list(csv.DictReader(table.open(), restval="")) if table.exists() else []
    rows.append({k: row[k] for k in COLUMNS})
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS)
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomic(table, buffer.getvalue())
    write_text_atomic(Path(out) / f"{scene.name}.md", _markdown(scene.name, benchmark, rows))
    return row


def _settings(overrides: dict) -> str:
    """The parameters a row ran with beyond the scene's defaults."""
    return " ".join(f"{key}={value}" for key, value in overrides.items()) or "defaults"


def _markdown(name: str, benchmark: dict, rows: list[dict]) -> str:
    v = versions()
    lines = [f"# Benchmark `{name}`", "",
             f"Settings: each row's `settings` (beyond the scene's defaults; this version's "
             f"benchmark: `{_settings(benchmark)}`); "
             f"SNES Newton with MUMPS LU; DOLFINx {v.get('dolfinx', '?')}, PETSc {v.get('petsc', '?')}. "
             "Seconds per phase (form compilation is a first-run cost: FFCx caches it); "
             "peak memory is the largest resident set of any rank. "
             f"Counts: {COUNTS}; empty where a row predates them.", "",
             "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join("" if r.get(c) is None else str(r[c]) for c in COLUMNS) + " |"
              for r in rows]
    return "\n".join(lines) + "\n"
