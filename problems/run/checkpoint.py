"""Checkpoint and restart of stepped runs; see docs/restart.md.

A scene registers the state that the path follower cannot see -- DOLFINx Functions
(unknowns, quadrature-space internal variables such as ``Cv_n``), Constants (the cavity's
``P_ini``/``V_ini``) and plain values (a dict of time series, contact memory) -- with
``ctx.checkpoints``; :func:`eyemech.problems.solve.driver.follow_path` adds its own (the path,
the load or time, the step size, the step records) and the run's results so far, and
writes a checkpoint every N steps or T minutes, and when SIGINT/SIGTERM asks the run to
stop.

Format (a folder per checkpoint, ``OUT/checkpoints/ckpt_SSSSSS`` with S the number of
converged steps of the run so far):

- ``meta.json`` (rank 0): scene, parameters, rank count, the path state, the registered
  Constants and values, ``result`` (quantities, steps, fields, pictures so far), and per
  Function its element and a fingerprint of its mesh.
- ``rank_RRRR.npz`` (one per writing rank): per Function ``NAME.cells`` (the original
  cell index of every owned cell, i.e. the cell's number in the mesh generator's input,
  independent of the partition) and ``NAME.values`` (the cell's dof values in the
  element's own order). Reading looks every local cell (owned and ghost) up by its
  original index, so a checkpoint written on N ranks restarts on M ranks. This needs
  the same mesh input (checked by the fingerprint) and elements without dof
  transformations (Lagrange up to degree 2, DG, quadrature and Real spaces; refused
  otherwise).

Why not adios4dolfinx/io4dolfinx: they need ADIOS2's Python bindings built with MPI
(or h5py with parallel HDF5); the ``dolfinx-solver-real`` wheel ships ADIOS2's C++
libraries only, and the ``adios2`` wheel on PyPI is a serial build of the same sonames
(loading both into one process risks symbol clashes). Plain NumPy files keyed by the
original cell index need nothing new and keep N-to-M restart.

Atomicity: everything is written into ``.tmp_ckpt_SSSSSS``; after a barrier rank 0
renames it to ``ckpt_SSSSSS`` (one ``rename``, atomic on POSIX file systems). A kill
before the rename leaves only a ``.tmp_`` folder that readers ignore; the last good
checkpoint is untouched. After the rename the run's older checkpoints beyond ``keep``
and any other run's are deleted (``meta.json`` names the run: its scene and the hash of
its parameters, problems/run/identity.py).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import os
import re
import shutil
import signal
import sys
import time
import zipfile
from pathlib import Path
from typing import Any, Callable

import numpy as np
from mpi4py import MPI

from eyemech.problems.run import signals
from eyemech.problems.run.faults import (  # noqa: F401
    KILL_ENV,
    parse_divergence,
    parse_kill,
    plant_divergence,
)
from eyemech.problems.run.lockstep import Lockstep, label_code

PETSC_ERR_USER = 83  # PETSc's error code for an error raised by user code

log = logging.getLogger("eyemech")

FORMAT = "eyemech-checkpoint-1"
NAME = re.compile(r"^ckpt_(\d{6,})$")


class Interrupted(Exception):
    """SIGINT/SIGTERM stopped the run at the end of a step, after a checkpoint."""

    def __init__(self, signum: int, step: int, checkpoint: Path | None):
        self.signum, self.step, self.checkpoint = signum, step, checkpoint
        where = f"; checkpoint {checkpoint}" if checkpoint else " (no output folder: no checkpoint)"
        super().__init__(f"stopped by {signal.Signals(signum).name} after step {step}{where}")


class CheckpointError(ValueError):
    """A checkpoint that does not fit this run (other scene, parameters, mesh, state)."""


@dataclasses.dataclass
class CheckpointOptions:
    """When to write checkpoints and where to restart from."""

    every_steps: int = 0          # 0: not by step count
    every_minutes: float = 10.0   # 0: not by time
    keep: int = 2                 # checkpoints kept (the newest)
    resume: Path | None = None    # a run folder (or its checkpoints/) to continue from

    @staticmethod
    def parse_every(text: str) -> tuple[int, float]:
        """``"5"`` -> every 5 steps; ``"10m"`` / ``"10min"`` -> every 10 minutes; ``"0"`` off."""
        text = text.strip().lower()
        match = re.fullmatch(r"(\d+(?:\.\d+)?)\s*(m|min)", text)
        if match:
            return 0, float(match.group(1))
        if text.isdigit():
            return int(text), 0.0
        raise ValueError(f"'{text}' is neither a step count (5) nor minutes (10m)")


@dataclasses.dataclass
class _Entry:
    kind: str               # function | constant | value
    obj: Any = None
    get: Callable[[], Any] | None = None
    set: Callable[[Any], None] | None = None


def latest(folder: str | Path) -> Path | None:
    """The newest complete checkpoint under ``folder`` (a run folder or its
    ``checkpoints/``), or None."""
    folder = Path(folder)
    if (folder / "checkpoints").is_dir():
        folder = folder / "checkpoints"
    if not folder.is_dir():
        return None
    found = [(int(m.group(1)), p) for p in folder.iterdir()
             if (m := NAME.match(p.name)) and (p / "meta.json").is_file()]
    return max(found)[1] if found else None


def newest_readable(folder: str | Path, warn: bool = True, run: str | None = None) \
        -> tuple[Path | None, dict[str, Any] | None]:
    """The newest checkpoint under ``folder`` whose ``meta.json`` and rank files all read
    whole, with its meta; older ones are tried when the newest is damaged (truncated by
    a full disk, emptied by a crash of the file system), each skipped one logged. With
    ``run`` (a run id) only that run's checkpoints count. (None, None) when there is no
    checkpoint; :class:`CheckpointError` when none is readable."""
    folder = Path(folder)
    if (folder / "checkpoints").is_dir():
        folder = folder / "checkpoints"
    if not folder.is_dir():
        return None, None
    found = sorted(((int(m.group(1)), p) for p in folder.iterdir()
                    if (m := NAME.match(p.name)) and (p / "meta.json").is_file()), reverse=True)
    if run is not None:
        from eyemech.problems.run.identity import checkpoints_in

        others = {c.path.name for c in checkpoints_in(folder.parent)
                  if c.run_id is not None and c.run_id != run}
        found = [(step, p) for step, p in found if p.name not in others]
    problems = []
    for _, candidate in found:
        try:
            meta = read_meta(candidate)
            _check_rank_files(candidate, meta)
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as err:
            problems.append(f"{candidate.name}: {err}")
            if warn:
                log.warning("checkpoint %s is unreadable (%s)%s", candidate, err,
                            "" if candidate == found[-1][1] else "; trying the one before it")
            continue
        return candidate, meta
    if problems:
        raise CheckpointError(f"no readable checkpoint in {folder} ({'; '.join(problems)})")
    return None, None


def _check_rank_files(checkpoint: Path, meta: dict[str, Any]) -> None:
    """Every rank file is there and every array in it reads whole."""
    parts = sorted(checkpoint.glob("rank_*.npz"))
    if len(parts) != meta.get("mpi_size"):
        raise CheckpointError(f"{len(parts)} rank files of {meta.get('mpi_size')}")
    for part in parts:
        try:
            with np.load(part) as arrays:
                for key in arrays.files:
                    arrays[key]
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
            raise CheckpointError(f"{part.name} is damaged ({type(err).__name__}: {err})") \
                from None


def read_meta(checkpoint: Path) -> dict[str, Any]:
    meta = json.loads((checkpoint / "meta.json").read_bytes().decode("utf-8"))
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise CheckpointError(f"{checkpoint} is not an {FORMAT} checkpoint")
    return meta


class Checkpoints:
    """The registry of a run's state, the writer and the reader (collective on ``comm``)."""

    def __init__(self, scene: str, parameters: dict[str, Any], result, comm: MPI.Comm,
                 out: Path | None, options: CheckpointOptions | None = None,
                 run_id: str | None = None):
        from eyemech.problems.run.identity import run_id as identity

        self.scene, self.parameters, self.result = scene, parameters, result
        self.run_id = run_id or identity(scene, parameters)
        self.comm, self.options = comm, options or CheckpointOptions()
        self.folder = out / "checkpoints" if out is not None else None
        self.entries: dict[str, _Entry] = {}
        self.steps_done = 0           # converged steps of the run so far (all paths)
        self.written = 0              # checkpoints written by this process
        self.completed_paths: list[list[dict]] = []
        self.path_index = -1
        self.last: Path | None = None
        self.write_seconds: list[float] = []
        self._last_write = time.monotonic()
        self._listening = False
        self._kill = parse_kill()
        self._diverge = parse_divergence()
        self._watching: tuple[Any, Callable] | None = None  # (solver, hook) of the test hook
        self.resume_meta: dict[str, Any] | None = None
        self.resumed_from: Path | None = None
        self.restore_seconds = 0.0
        if self.options.resume is not None:
            self._load_meta(Path(self.options.resume))
        # made last: close() frees them (collective, like their creation)
        self._hang_comm = comm.Dup() if self._diverge[0] == "hang" else None  # test hook
        # every rank at every step's end with the same decision, or an error (lockstep.py)
        self.lockstep = Lockstep(comm)

    # -- registration ---------------------------------------------------------------
    def function(self, name: str, f) -> None:
        """A dolfinx Function: its dof values, by original cell (N-to-M safe)."""
        if f.function_space.element.needs_dof_transformations:
            raise CheckpointError(f"'{name}': elements with dof transformations are not supported")
        self._add(name, _Entry("function", f))

    def constant(self, name: str, c) -> None:
        """A dolfinx Constant (same value on every rank)."""
        self._add(name, _Entry("constant", c))

    def value(self, name: str, get: Callable[[], Any], set: Callable[[Any], None]) -> None:
        """Any state that is the same on every rank: ``get()`` returns JSON-able data
        (NumPy arrays allowed), ``set(data)`` puts it back."""
        self._add(name, _Entry("value", get=get, set=set))

    def series(self, name: str, lists: dict[str, list]) -> None:
        """A dict of lists (time series), restored in place: callers keep their references."""
        def put(saved: dict[str, list]) -> None:
            for key, values in saved.items():
                lists.setdefault(key, [])[:] = values
        self.value(name, lambda: lists, put)

    def _add(self, name: str, entry: _Entry) -> None:
        if name in self.entries:
            raise CheckpointError(f"state '{name}' is registered twice")
        self.entries[name] = entry

    @property
    def enabled(self) -> bool:
        return self.folder is not None

    # -- the path follower's side -----------------------------------------------------
    def enter_path(self, label: str) -> dict[str, Any] | None:
        """Called when ``follow_path`` starts. Returns None for a fresh path, or, when
        resuming, ``{"skip": records}`` for a path finished before the checkpoint or
        the saved path state for the path the checkpoint is in (state then restored)."""
        self._listen()
        self.path_index += 1
        meta = self.resume_meta
        if meta is None:
            return None
        saved = meta["path"]
        if self.path_index < saved["index"]:
            return {"skip": meta["completed_paths"][self.path_index]}
        if self.path_index == saved["index"]:
            if saved["label"] != label:
                raise CheckpointError(f"checkpoint is in path '{saved['label']}', the run "
                                      f"reached path '{label}' at the same position")
            self._restore(meta)
            self.resume_meta = None
            return saved
        raise CheckpointError("the run has more paths before the checkpoint's than it had")

    def leave_path(self, records: list[dict]) -> None:
        self.completed_paths.append(records)

    def watch_step(self, solver) -> None:
        """Test hook: a kill (or SIGTERM, or a hang) inside Newton of the step about to be
        solved."""
        kind, step, rank = self._kill
        if self._diverge[0] in ("hang", "petsc"):
            kind, step, rank = self._diverge
        if kind not in ("step", "sigterm", "hang", "petsc") or self.steps_done + 1 != step:
            return
        calls = []

        def hook(_x, _b):
            calls.append(1)
            if len(calls) == 2:  # after Newton's first update: the unknowns are mid-step
                if kind == "step":
                    os.kill(os.getpid(), signal.SIGKILL)
                elif kind == "hang" and rank == self.comm.rank:
                    print(f"EYEMECH_TEST_DIVERGE: rank {rank} hangs in step {step}",
                          file=sys.stderr, flush=True)
                    self._hang_comm.Barrier()  # no other rank calls it: stuck in C
                elif kind == "petsc" and rank == self.comm.rank:
                    from petsc4py import PETSc

                    print(f"EYEMECH_TEST_DIVERGE: rank {rank} raises a PETSc error in step "
                          f"{step}", file=sys.stderr, flush=True)
                    raise PETSc.Error(PETSC_ERR_USER)  # SNES fails on this rank only
                elif kind == "sigterm" and (rank is None or rank == self.comm.rank):
                    os.kill(os.getpid(), signal.SIGTERM)
        solver.residual_hooks.append(hook)
        self._watching = (solver, hook)

    def step_done(self, path_state: dict[str, Any]) -> None:
        """After a converged step: check that every rank is in step (the same step and
        decision, problems/run/lockstep.py), write a checkpoint when due, stop when
        asked to."""
        self.steps_done += 1
        if self._watching is not None:
            solver, hook = self._watching
            solver.residual_hooks.remove(hook)
            self._watching = None
        records = path_state.get("records") or [{}]
        decision = [float(self.path_index), label_code(str(path_state.get("label", ""))),
                    float(self.steps_done), float(path_state.get("step", 0)),
                    float(path_state.get("value", 0.0)), float(path_state.get("increment", 0.0)),
                    float(records[-1].get("iterations", 0)), float(records[-1].get("cuts", 0))]
        plant_divergence(self.comm, self.steps_done, decision)
        self.lockstep.check(f"the end of step {self.steps_done} (path "
                            f"'{path_state.get('label', '')}')", tuple(decision))
        stop = self.comm.allreduce(signals.requested(), op=MPI.MAX)
        due = self.comm.bcast(self._due() if self.comm.rank == 0 else None, root=0)
        if self.enabled and (due or stop):
            self.write(path_state)
        if stop:
            raise Interrupted(stop, self.steps_done, self.last if self.enabled else None)

    def _due(self) -> bool:
        opts = self.options
        by_steps = opts.every_steps > 0 and self.steps_done % opts.every_steps == 0
        by_time = opts.every_minutes > 0 and \
            time.monotonic() - self._last_write >= 60.0 * opts.every_minutes
        return by_steps or by_time

    # -- writing ------------------------------------------------------------------------
    def write(self, path_state: dict[str, Any]) -> Path:
        start = time.perf_counter()
        name = f"ckpt_{self.steps_done:06d}"
        final, tmp = self.folder / name, self.folder / f".tmp_{name}"
        if self.comm.rank == 0:
            self.folder.mkdir(parents=True, exist_ok=True)
            for stale in self.folder.glob(".tmp_ckpt_*"):
                shutil.rmtree(stale, ignore_errors=True)
            tmp.mkdir()
        self.comm.Barrier()
        arrays, functions = {}, {}
        for key, entry in self.entries.items():
            if entry.kind == "function":
                cells, values = _cell_values(entry.obj)
                arrays[f"{key}.cells"], arrays[f"{key}.values"] = cells, values
                functions[key] = _describe(entry.obj)
        _save_npz(tmp / f"rank_{self.comm.rank:04d}.npz", arrays)
        meta = self._meta(path_state, functions)  # collective (fingerprints)
        if self.comm.rank == 0:
            _write_text(tmp / "meta.json", json.dumps(meta, default=_encode))
        self.comm.Barrier()
        self.written += 1
        if self._kill[0] == "checkpoint" and self.written == self._kill[1]:
            os.kill(os.getpid(), signal.SIGKILL)  # test hook: the write is not committed
        if self.comm.rank == 0:
            if final.exists():  # a checkpoint of the same step from an earlier attempt
                shutil.rmtree(final)
            os.rename(tmp, final)
            _fsync_dir(self.folder)
            self._prune(self.steps_done)
        self.comm.Barrier()
        self.last = final
        self._last_write = time.monotonic()
        self.write_seconds.append(time.perf_counter() - start)
        return final

    def _meta(self, path_state: dict[str, Any], functions: dict[str, dict]) -> dict[str, Any]:
        for key, entry in self.entries.items():
            if entry.kind == "function":
                functions[key]["mesh"] = _fingerprint(entry.obj.function_space.mesh)
        meta = {"format": FORMAT, "scene": self.scene, "run_id": self.run_id,
                "parameters": self.parameters,
                "mpi_size": self.comm.size, "steps_done": self.steps_done,
                "path": {"index": self.path_index, **path_state},
                "completed_paths": self.completed_paths, "functions": functions,
                "constants": {k: np.asarray(e.obj.value).tolist()
                              for k, e in self.entries.items() if e.kind == "constant"},
                "values": {k: e.get() for k, e in self.entries.items() if e.kind == "value"},
                "result": {"quantities": self.result.quantities, "steps": self.result.steps,
                           "fields": self.result.fields, "pictures": self.result.pictures},
                "written": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        return meta

    def _prune(self, newest: int) -> None:
        """Keep the newest ``keep`` checkpoints of this run, up to the one just written
        (``newest``); remove the rest: this run's older ones, its later ones from before
        a resume (they describe steps this run is computing again) and other runs' (a
        new run starts only where those ended, identity.check_fresh_start)."""
        from eyemech.problems.run.identity import checkpoints_in

        found = checkpoints_in(self.folder.parent)
        own = [c for c in found if c.run_id == self.run_id and c.step <= newest]
        kept = {c.path for c in own[-max(self.options.keep, 1):]}
        for checkpoint in found:
            if checkpoint.path not in kept:
                shutil.rmtree(checkpoint.path, ignore_errors=True)

    # -- reading ------------------------------------------------------------------------
    def _load_meta(self, folder: Path) -> None:
        meta, error = None, None
        if self.comm.rank == 0:
            try:
                found, meta = newest_readable(folder, run=self.run_id)
                if meta is not None:
                    meta["_folder"] = str(found)
            except (OSError, ValueError) as err:
                error = str(err)
        meta, error = self.comm.bcast((meta, error), root=0)
        if error:
            raise CheckpointError(error)
        if meta is None:
            return  # nothing to resume from: a fresh start
        if meta["scene"] != self.scene:
            raise CheckpointError(f"checkpoint {meta['_folder']} is of scene '{meta['scene']}'")
        changed = sorted(k for k in set(meta["parameters"]) | set(self.parameters)
                         if _canonical(meta["parameters"].get(k)) != _canonical(self.parameters.get(k)))
        if changed:
            raise CheckpointError(f"checkpoint {meta['_folder']} was written with other values of "
                                  f"{', '.join(changed)}")
        self.resume_meta = meta
        self.resumed_from = Path(meta["_folder"])

    def _restore(self, meta: dict[str, Any]) -> None:
        start = time.perf_counter()
        folder = Path(meta["_folder"])
        saved = set(meta["functions"]) | set(meta["constants"]) | set(meta["values"])
        if saved != set(self.entries):
            raise CheckpointError(f"checkpoint state {sorted(saved ^ set(self.entries))} does not "
                                  "match what this run registers")
        parts = [np.load(p) for p in sorted(folder.glob("rank_*.npz"))]
        if len(parts) != meta["mpi_size"]:
            raise CheckpointError(f"{folder} has {len(parts)} rank files of {meta['mpi_size']}")
        for key, entry in self.entries.items():
            if entry.kind == "function":
                _check_function(key, entry.obj, meta["functions"][key])
                _set_cell_values(entry.obj, np.concatenate([p[f"{key}.cells"] for p in parts]),
                                 np.concatenate([p[f"{key}.values"] for p in parts]), key)
            elif entry.kind == "constant":
                entry.obj.value = np.asarray(meta["constants"][key]).reshape(
                    np.shape(entry.obj.value))
            else:
                entry.set(_decode(meta["values"][key]))
        result = meta["result"]
        self.result.quantities.clear()
        self.result.quantities.update(result["quantities"])
        self.result.steps[:] = result["steps"]
        self.result.fields[:] = result["fields"]
        self.result.pictures[:] = result["pictures"]
        self.steps_done = meta["steps_done"]
        self.completed_paths = [list(p) for p in meta["completed_paths"]]
        self.restore_seconds = time.perf_counter() - start

    # -- signals and the end of the run ---------------------------------------------------
    def _listen(self) -> None:
        """SIGINT/SIGTERM: finish the step, checkpoint, stop (a second one: at once;
        problems/run/signals.py)."""
        if not self._listening:
            signals.listen()
            self._listening = True

    def restore_signal_handlers(self) -> None:
        if self._listening:
            signals.unlisten()
            self._listening = False

    def close(self) -> None:
        """The run ends (collective: every rank, as ``RunContext.__exit__``)."""
        self.restore_signal_handlers()
        if self.lockstep.comm is not None:  # the longest wait of any rank, for results.json
            self.lockstep.longest_wait = self.lockstep.comm.allreduce(
                self.lockstep.longest_wait, op=MPI.MAX)
        self.lockstep.free()
        if self._hang_comm is not None:
            self._hang_comm.Free()
            self._hang_comm = None

    def summary(self) -> dict[str, Any]:
        """What results.json says about checkpoints."""
        out: dict[str, Any] = {"written": self.written}
        if self.last is not None:
            out["last"] = str(self.last)
        if self.write_seconds:
            out["write_seconds_max"] = round(max(self.write_seconds), 4)
            out["write_seconds_total"] = round(sum(self.write_seconds), 4)
        if self.resumed_from is not None:
            out["resumed_from"] = str(self.resumed_from)
            out["restore_seconds"] = round(self.restore_seconds, 4)
        if self.lockstep.checks:  # the longest wait of any rank for the others at a step's end
            out["lockstep_checks"] = self.lockstep.checks
            out["lockstep_wait_max_s"] = round(self.lockstep.longest_wait, 4)
        return out


# -- Function values by original cell ------------------------------------------------------
def _cell_values(f) -> tuple[np.ndarray, np.ndarray]:
    V = f.function_space
    mesh = V.mesh
    owned = mesh.topology.index_map(mesh.topology.dim).size_local
    bs = V.dofmap.bs
    dofs = V.dofmap.list[:owned]
    values = f.x.array.reshape(-1, bs)[dofs].reshape(owned, -1)
    cells = np.asarray(mesh.topology.original_cell_index[:owned], dtype=np.int64)
    return cells, values


def _set_cell_values(f, cells: np.ndarray, values: np.ndarray, name: str) -> None:
    V = f.function_space
    mesh = V.mesh
    local = np.asarray(mesh.topology.original_cell_index, dtype=np.int64)  # owned + ghosts
    if len(cells) == 0:
        raise CheckpointError(f"'{name}': the checkpoint has no cells")
    order = np.argsort(cells)
    cells, values = cells[order], values[order]
    at = np.minimum(np.searchsorted(cells, local), len(cells) - 1)
    bs = V.dofmap.bs
    dofs = V.dofmap.list[:len(local)]
    problem = None
    if not np.array_equal(cells[at], local):
        problem = f"'{name}': the checkpoint lacks cells of this mesh"
    else:
        try:
            rows = values[at].reshape(len(local), dofs.shape[1], bs)
        except ValueError as err:
            problem = f"'{name}': the checkpoint's values do not fit this space ({err})"
    # what one rank finds, every rank raises: none may be left in scatter_forward
    problems = [p for p in mesh.comm.allgather(problem) if p is not None]
    if problems:
        raise CheckpointError(problems[0])
    f.x.array.reshape(-1, bs)[dofs] = rows
    f.x.scatter_forward()


def _describe(f) -> dict[str, Any]:
    V = f.function_space
    return {"element": repr(V.ufl_element()), "dofs": V.dofmap.index_map.size_global * V.dofmap.bs}


def _check_function(name: str, f, saved: dict[str, Any]) -> None:
    mine = _describe(f)
    if mine["element"] != saved["element"] or mine["dofs"] != saved["dofs"]:
        raise CheckpointError(f"'{name}': saved as {saved['element']} with {saved['dofs']} dofs, "
                              f"this run has {mine['element']} with {mine['dofs']}")
    here, there = _fingerprint(f.function_space.mesh), saved["mesh"]
    if here[0] != there[0] or not np.allclose(here[1:], there[1:], rtol=1e-9, atol=1e-12):
        raise CheckpointError(f"'{name}': the mesh differs from the checkpoint's "
                              "(other mesh parameters or mesh generator)")


def _fingerprint(mesh) -> list[float]:
    """Global cell count and the sums of cell midpoints weighted by the original cell
    index: equal for the same mesh input on any number of ranks (up to round-off)."""
    tdim = mesh.topology.dim
    owned = mesh.topology.index_map(tdim).size_local
    x = mesh.geometry.x[mesh.geometry.dofmaps[0][:owned]].mean(axis=1)
    weight = (np.asarray(mesh.topology.original_cell_index[:owned]) % 997 + 1.0)[:, None]
    local = np.concatenate([[float(owned)], (weight * x).sum(axis=0)])
    return mesh.comm.allreduce(local, op=MPI.SUM).tolist()


# -- files ---------------------------------------------------------------------------------
@contextlib.contextmanager
def _naming(path: Path):
    """An OSError of the write (a full disk) names the file it was writing."""
    try:
        yield
    except OSError as err:
        if err.filename is None:
            raise OSError(err.errno, err.strerror, str(path)) from err
        raise


def _save_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    with _naming(path), open(path, "wb") as handle:
        np.savez(handle, **arrays)
        handle.flush()
        os.fsync(handle.fileno())


def _write_text(path: Path, text: str) -> None:
    with _naming(path), open(path, "w") as handle:
        handle.write(text)
        handle.flush()
        os.fsync(handle.fileno())


def _fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _encode(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return {"__ndarray__": value.tolist(), "dtype": str(value.dtype)}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot checkpoint a {type(value).__name__}")


def _decode(value: Any) -> Any:
    if isinstance(value, dict):
        if "__ndarray__" in value:
            return np.array(value["__ndarray__"], dtype=value["dtype"])
        return {k: _decode(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_decode(v) for v in value]
    return value


def _canonical(value: Any) -> Any:
    """Parameters compared as JSON sees them (tuples and lists alike)."""
    return json.loads(json.dumps(value, default=_encode))

