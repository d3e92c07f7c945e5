"""What a run leaves behind: ``results.json`` written atomically, timings, versions."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import platform
import resource
import tempfile
import time
from collections import defaultdict
from importlib import metadata
from pathlib import Path
from typing import Any, Iterator

import numpy as np

TIMING_KEYS = ("mesh", "form_compilation", "assembly", "solve", "contact_search", "output")


class Timings:
    """Wall-clock seconds accumulated per phase; ``total`` is measured separately."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self._start = time.perf_counter()

    @contextlib.contextmanager
    def __call__(self, phase: str) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[phase] += time.perf_counter() - start

    def add(self, phase: str, seconds: float) -> None:
        self.seconds[phase] += seconds

    def as_dict(self) -> dict[str, float]:
        out = {key: round(self.seconds.get(key, 0.0), 6) for key in TIMING_KEYS}
        out.update({k: round(v, 6) for k, v in self.seconds.items() if k not in out})
        out["total"] = round(time.perf_counter() - self._start, 6)
        return out


def versions() -> dict[str, str]:
    """Versions of what produced the numbers (eyemech, DOLFINx, PETSc, Python)."""
    out = {"python": platform.python_version()}
    for dist in ("eyemech", "fenics-dolfinx", "dolfinx-solver-real", "fenics-ufl",
                 "fenics-basix", "fenics-ffcx", "gmsh"):
        with contextlib.suppress(metadata.PackageNotFoundError):
            out[dist] = metadata.version(dist)
    with contextlib.suppress(ImportError):
        import dolfinx

        out["dolfinx"] = dolfinx.__version__
    with contextlib.suppress(ImportError):
        from petsc4py import PETSc

        out["petsc"] = ".".join(str(v) for v in PETSc.Sys.getVersion())
    return out


def machine() -> dict[str, Any]:
    return {"node": platform.node(), "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(), "system": platform.system()}


def peak_memory_mb() -> float:
    """Peak resident memory of this process (MB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


@dataclasses.dataclass
class SolverCounts:
    """Work of Newton solves, a cut step's failed attempts included. Factorisations are
    counted where PETSc performs them (its log events ``MatLUFactorNum``/``MatCholFctrNum``
    and the symbolic ``MatLUFactorSym``/``MatCholFctrSym``/``MatILUFactorSym``/
    ``MatICCFactorSym``), whatever the preconditioner: MUMPS LU, or the sub-solvers of an
    iterative one (e.g. GAMG's coarse-grid LU)."""

    newton_solves: int = 0             # SNES solves started (attempts)
    failed_newton_solves: int = 0      # of which did not converge (the step was cut)
    newton_iterations: int = 0         # Newton iterations of the solves that converged
    newton_iterations_all: int = 0     # Newton iterations of all solves, failed ones included
    jacobians: int = 0                 # Jacobian assemblies
    factorisations: int = 0            # numeric factorisations
    symbolic_factorisations: int = 0   # symbolic analyses (a new matrix pattern needs one)

    def copy(self) -> "SolverCounts":
        return dataclasses.replace(self)

    def __add__(self, other: "SolverCounts") -> "SolverCounts":
        return SolverCounts(*(a + b for a, b in zip(self.values(), other.values())))

    def __sub__(self, other: "SolverCounts") -> "SolverCounts":
        return SolverCounts(*(a - b for a, b in zip(self.values(), other.values())))

    def add(self, other: "SolverCounts") -> None:
        """In place (the process-wide tally is one object that others hold)."""
        for name, value in dataclasses.asdict(other).items():
            setattr(self, name, getattr(self, name) + value)

    def values(self) -> tuple[int, ...]:
        return dataclasses.astuple(self)

    def as_dict(self) -> dict[str, int]:
        return dataclasses.asdict(self)


# Every Newton solve of this process adds its work here (NonlinearSolver.solve); a Result
# reports what was added while it ran.
SOLVER_COUNTS = SolverCounts()


@dataclasses.dataclass
class Result:
    """The outcome of one scene run; ``as_json`` is what ``results.json`` holds."""

    scene: str
    parameters: dict[str, Any]
    quantities: dict[str, Any] = dataclasses.field(default_factory=dict)
    steps: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    timings: dict[str, float] = dataclasses.field(default_factory=dict)
    status: str = "ok"
    message: str = ""
    mpi_size: int = 1
    fields: list[str] = dataclasses.field(default_factory=list)
    pictures: list[str] = dataclasses.field(default_factory=list)
    peak_memory_mb: float = 0.0
    checkpoints: dict[str, Any] = dataclasses.field(default_factory=dict)  # written, resumed_from
    # totals of SolverCounts over the run (every Newton solve of this process while the
    # run lasts, failed attempts included), fixed when the run ends (when its timings are
    # set). A resumed run counts the work since the resume; its steps keep the counts
    # they were converged with.
    solver_counts: dict[str, int] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        self._counts_at_start = SOLVER_COUNTS.copy()

    def __setattr__(self, name: str, value: Any) -> None:
        super().__setattr__(name, value)
        if name == "timings" and value and not self.solver_counts \
                and hasattr(self, "_counts_at_start"):
            super().__setattr__("solver_counts", self.counts())

    def counts(self) -> dict[str, int]:
        """The solver work of this run: at its end, or so far while it runs."""
        if self.solver_counts:
            return dict(self.solver_counts)
        return (SOLVER_COUNTS - self._counts_at_start).as_dict()

    def as_json(self) -> dict[str, Any]:
        counts = self.counts()
        data = dataclasses.asdict(self)
        data["solver_counts"] = counts
        data["versions"] = versions()
        data["machine"] = machine()
        return to_jsonable(data)


def to_jsonable(value: Any) -> Any:
    """Numpy scalars and arrays to plain JSON types; non-finite floats to None."""
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if np.isfinite(value) else None
    return value


def write_json_atomic(path: str | Path, data: Any) -> None:
    """Write JSON so that readers see the old file or the whole new one, never a part."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as handle:
            json.dump(data, handle, indent=2)
            handle.write("\n")
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_text_atomic(path: str | Path, text: str) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
