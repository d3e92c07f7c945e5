"""What a run leaves behind: ``results.json`` written atomically, timings, versions."""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import json
import os
import platform
import resource
import socket
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


def stamp() -> str:
    """One line for a chart footer and a CSV comment: what measured this, where, when."""
    v = versions()
    return (f"{datetime.date.today().isoformat()} · {platform.node()} ({platform.machine()}, "
            f"{os.cpu_count()} cpus) · eyemech {v.get('eyemech', '?')} · "
            f"DOLFINx {v.get('dolfinx', '?')} · PETSc {v.get('petsc', '?')}")


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
    krylov_iterations: int = 0         # Krylov iterations (0 for a direct solve's preonly)
    # PETSc's reallocations of the Jacobian's storage (MatGetInfo "mallocs", summed over
    # ranks): one per insertion outside the preallocated pattern, e.g. a new contact pair
    matrix_mallocs: int = 0
    # solves stopped at a flat residual and accepted by their Newton correction
    # (NewtonOptions.increment_tolerance); each cost one more Jacobian and factorisation,
    # counted above
    flat_residual_acceptances: int = 0

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

# the stopping tests of the Newton solvers built in this process, in order, each a dict
# (solver, rtol, atol, norm): results.json's ``newton_tolerances`` lists the distinct ones
# of its run, so a result states the accuracy it was converged to
STOPPING_CRITERIA: list[dict[str, Any]] = []


def record_stopping_criterion(solver: str, rtol: float, atol: float, norm: str,
                              stol: float = 0.0) -> None:
    """Newton stops at ‖F‖ ≤ max(atol, rtol ‖F_ref‖) in ``norm`` (called by each solver),
    or, where ``stol`` > 0, at an update ‖δu‖ ≤ stol ‖u‖ (recorded only then)."""
    criterion = {"solver": solver, "rtol": float(rtol), "atol": float(atol), "norm": norm}
    if stol > 0.0:
        criterion["stol"] = float(stol)
    STOPPING_CRITERIA.append(criterion)


@dataclasses.dataclass
class Result:
    """The outcome of one scene run; ``as_json`` is what ``results.json`` holds."""

    scene: str
    parameters: dict[str, Any]
    # the run's identity: a hash of the scene and its parameters (problems/run/identity.py),
    # also in run.json and in every checkpoint
    run_id: str = ""
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
        if not self.run_id:
            from eyemech.problems.run.identity import run_id

            self.run_id = run_id(self.scene, self.parameters)
        self._counts_at_start = SOLVER_COUNTS.copy()
        self._criteria_at_start = len(STOPPING_CRITERIA)

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

    def stopping_criteria(self) -> list[dict[str, Any]]:
        """The distinct Newton stopping tests of the solvers this run built."""
        distinct: list[dict[str, Any]] = []
        for criterion in STOPPING_CRITERIA[getattr(self, "_criteria_at_start", 0):]:
            if criterion not in distinct:
                distinct.append(criterion)
        return distinct

    def as_json(self) -> dict[str, Any]:
        counts = self.counts()
        data = {"schema_version": SCHEMA_VERSION, **dataclasses.asdict(self)}
        data["solver_counts"] = counts
        data["newton_tolerances"] = self.stopping_criteria()
        data["versions"] = versions()
        data["machine"] = machine()
        return to_jsonable(data)


# results.json's layout: problems/run/results.schema.json (a JSON Schema) describes it;
# this number changes with it, so a reader can tell which layout a file has
SCHEMA_VERSION = 1
SCHEMA_PATH = Path(__file__).with_name("results.schema.json")
# a staged scene (scleral-buckling) reports each stage's quantities as a group
# ``quantities["after_<stage>"]``; the top-level quantities are the last stage's
STAGE_PREFIX = "after_"


def stage_groups(quantities: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The per-stage quantity groups of a result, in order (empty for unstaged scenes)."""
    return {key: value for key, value in quantities.items()
            if key.startswith(STAGE_PREFIX) and isinstance(value, dict)}


def schema() -> dict[str, Any]:
    return json.loads(SCHEMA_PATH.read_text())


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


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _temporary(path: Path) -> tuple[int, str]:
    """A temporary file beside ``path`` with the permissions an ordinary ``open`` would
    give it (``mkstemp`` makes it 0600: others of the group could not read the result)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.fchmod(fd, 0o666 & ~_umask())
    return fd, tmp


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """``data`` in ``path``, whole or not at all (a temporary file beside it, renamed); an
    error (a full disk) names ``path`` and leaves no temporary file."""
    path = Path(path)
    fd, tmp = _temporary(path)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(err, OSError) and err.filename is None:
            raise OSError(err.errno, err.strerror, str(path)) from err
        raise


def write_json_atomic(path: str | Path, data: Any) -> None:
    """Write JSON so that readers see the old file or the whole new one, never a part."""
    write_text_atomic(path, json.dumps(data, indent=2) + "\n", sync=True)


def write_text_atomic(path: str | Path, text: str, sync: bool = False) -> None:
    """Write ``text`` so that readers see the old file or the whole new one; an error
    (a full disk) names ``path`` and leaves no temporary file."""
    path = Path(path)
    fd, tmp = _temporary(path)
    try:
        with os.fdopen(fd, "w") as handle:
            handle.write(text)
            if sync:
                handle.flush()
                os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(err, OSError) and err.filename is None:
            raise OSError(err.errno, err.strerror, str(path)) from err
        raise


LOCK_NAME = ".eyemech.lock"


class OutputFolder:
    """A run's (or a sweep's) hold on its output folder.

    :meth:`acquire` (collective) makes the folder, checks that it can be written, and
    creates ``.eyemech.lock`` there holding the process id, the host and the start time;
    a second run on the same folder is refused with exit code 2 (its files would mix
    with the first one's, and its checkpoint writes would delete the first one's
    temporary checkpoint). A lock left by a process that no longer runs on this host is
    taken over; one from another host must be removed by hand. :meth:`release` on rank 0
    removes it."""

    def __init__(self, folder: str | Path, comm, key: str = "--out"):
        self.folder, self.comm, self.key = Path(folder), comm, key
        self.lock = self.folder / LOCK_NAME
        self.held = False
        self.created = False
        self.made: list[Path] = []

    def acquire(self) -> "OutputFolder":
        from eyemech.problems.run.parameters import ParameterError

        error = None
        if self.comm.rank == 0:
            try:
                self._acquire()
            except ValueError as err:
                error = str(err)
        error = self.comm.bcast(error, root=0)
        if error:
            raise ParameterError(self.key, error)
        return self

    def _acquire(self) -> None:
        folder = self.folder
        try:
            for parent in (folder, *folder.parents):
                if parent.exists() and not parent.is_dir():
                    where = "is a file" if parent == folder else f"is under the file {parent}"
                    raise ValueError(f"{folder} {where}; the output goes to a folder")
            # the folders this run makes (the folder and missing parents, innermost first):
            # bad input found later removes them again
            self.made = [p for p in (folder, *folder.parents) if not p.exists()]
        except OSError as err:  # e.g. a name too long for the file system
            raise ValueError(f"cannot use {folder}: {err.strerror or err}") from None
        self.created = bool(self.made)
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise ValueError(f"cannot create {folder}: {err.strerror or err}") from None
        if not os.access(folder, os.W_OK | os.X_OK):
            raise ValueError(f"cannot write in {folder} (permission denied)")
        mine = f"{os.getpid()} {socket.gethostname()} " \
            f"{time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}\n"
        for _ in range(2):
            try:
                fd = os.open(self.lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
            except FileExistsError:
                pid, host, since = _lock_owner(self.lock)
                if host == socket.gethostname() and pid == os.getpid():
                    return  # this process holds it already (a run inside a run): not ours to remove
                if host == socket.gethostname() and pid is not None and not _alive(pid):
                    with contextlib.suppress(FileNotFoundError):
                        os.unlink(self.lock)  # left by a run that was killed
                    continue
                raise ValueError(f"{folder} is in use by another eyemech run (process {pid} "
                                 f"on {host} since {since}); wait for it to end or choose "
                                 f"another folder (remove {self.lock} if no run uses it)") \
                    from None
            except OSError as err:
                raise ValueError(f"cannot write in {folder}: {err.strerror or err}") from None
            with os.fdopen(fd, "w") as handle:
                handle.write(mine)
            self.held = True
            return
        raise ValueError(f"cannot take the lock {self.lock}")

    def release(self, remove_if_empty: bool = False) -> None:
        """Remove the lock (rank 0); with ``remove_if_empty`` also the folder when
        :meth:`acquire` made it and nothing else was written there."""
        if self.held and self.comm.rank == 0:
            with contextlib.suppress(OSError):
                if _lock_owner(self.lock)[0] == os.getpid():
                    os.unlink(self.lock)
            if remove_if_empty and self.created:
                with contextlib.suppress(OSError):
                    for made in self.made:
                        made.rmdir()  # fails, as it should, when anything is in it
        self.held = False


def _lock_owner(lock: Path) -> tuple[int | None, str, str]:
    try:
        words = lock.read_text().split()
    except OSError:
        return None, "?", "?"
    pid = int(words[0]) if words and words[0].isdigit() else None
    return pid, (words[1] if len(words) > 1 else "?"), (words[2] if len(words) > 2 else "?")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
