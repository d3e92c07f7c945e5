"""What every scene's ``run`` shares: options, timings, output folder, the Result,
and the guarantee that ``results.json`` is written whole (also on failure)."""

from __future__ import annotations

import dataclasses
import logging
import traceback
from pathlib import Path
from typing import Any

from mpi4py import MPI

from eyemech.forms import ordering  # noqa: F401  (UFL's operand order: forms/ordering.py)
from eyemech.meshes import MeshError
from eyemech.problems.run import identity, jit_cache
from eyemech.problems.run.checkpoint import CheckpointOptions, Checkpoints, Interrupted
from eyemech.problems.run.faults import abort_if_stranding, output_error
from eyemech.problems.run.identity import run_id
from eyemech.problems.run.newton import NewtonOptions, SolveFailure, close_solvers, hold_solvers
from eyemech.problems.run.output import FieldWriter, PyvistaSeries
from eyemech.problems.run.parameters import ParameterError, SceneParameters, check
from eyemech.problems.run.petsc_lifetime import release_run_objects, start_run
from eyemech.problems.run.petsc_output import confined
from eyemech.problems.run.results import (
    OutputFolder,
    Result,
    Timings,
    peak_memory_mb,
    write_json_atomic,
)

log = logging.getLogger("eyemech")


@dataclasses.dataclass
class RunOptions:
    """How to run, as opposed to what to model (the scene's parameters)."""

    quiet: bool = True            # no progress bar
    fields: bool = True           # write fields (.vtu + .pvd)
    vtx: bool = False             # write them as ADIOS2 VTX (.bp) too (ParaView with ADIOS2)
    pictures: bool = True         # write PNG pictures (pyvista, rank 0)
    newton: NewtonOptions = dataclasses.field(default_factory=NewtonOptions)
    checkpoint: CheckpointOptions = dataclasses.field(default_factory=CheckpointOptions)


class RunContext:
    """``with RunContext(...) as ctx:`` around a scene's work.

    On leaving, ``results.json`` is written atomically by rank 0 with status ``ok``,
    or ``failed`` and the message when a :class:`SolveFailure` escapes (the failure
    is then re-raised for the caller or the command line to report), or ``interrupted``
    when SIGINT/SIGTERM stopped the run after a checkpoint (:class:`Interrupted`).

    ``ctx.checkpoints`` is where a stepped scene registers its state for checkpoints
    (see :mod:`eyemech.problems.run.checkpoint`); pass it to ``follow_path``.
    """

    def __init__(self, scene: str, params: SceneParameters, comm: MPI.Comm | None,
                 out: str | Path | None, options: RunOptions | None):
        check(params)  # bad input stops here, before anything is created or solved
        jit_cache.install()  # a cached form found by its file name (problems/run/jit_cache.py)
        self.comm = comm if comm is not None else MPI.COMM_WORLD
        self.out = Path(out) if out is not None else None
        options = options or RunOptions()
        # files of --petsc viewers go to this run's folder (problems/run/petsc_output.py)
        newton = dataclasses.replace(options.newton,
                                     petsc=confined(options.newton.petsc, self.out))
        self.options = dataclasses.replace(options, newton=newton)
        self.timings = Timings()
        parameters = params.as_dict()
        self.result = Result(scene=scene, parameters=parameters, mpi_size=self.comm.size,
                             run_id=run_id(scene, parameters))
        # the folder is made, checked and locked (all ranks raise alike when it cannot be)
        self.folder = OutputFolder(self.out, self.comm).acquire() if self.out is not None \
            else None
        self._fresh = False  # this run replaces the folder's previous one (not a resume)
        self._resuming_here = False  # --resume names this run's own --out folder
        self._previous_outputs: set[str] = set()
        self._previous_run_file: bytes | None = None
        try:
            self.checkpoints = Checkpoints(scene, self.result.parameters, self.result, self.comm,
                                           self.out, self.options.checkpoint,
                                           run_id=self.result.run_id)
        except BaseException:
            self._release()
            raise
        try:
            self._take_folder()
        except BaseException:
            self.checkpoints.close()
            self._release()
            raise
        self._field_writers: list[FieldWriter] = []
        # the run's parallel solvers are kept until it closes them, and its other parallel
        # PETSc objects destroyed as it ends (problems/run/petsc_lifetime.py)
        self._solvers_before = hold_solvers()
        self._first_petsc_object = start_run(self.comm)  # last: it freezes the collector

    def _close_field_writers(self, error: BaseException | None) -> None:
        """The writers a scene left open (an error before its ``finally``), closed on every
        rank in the order they were made: an ADIOS2 writer left to the garbage collector
        flushes in its destructor, and on a full disk that aborts the process. A close that
        fails retires its writer (output.py); the run's own error is the one reported."""
        for writer in self._field_writers:
            try:
                writer.close()
            except OSError:
                if error is None:
                    raise
        self._field_writers = []

    def _release(self, remove_if_empty: bool = False) -> None:
        if self.folder is not None:
            self.folder.release(remove_if_empty=remove_if_empty)

    def _take_folder(self) -> None:
        """The folder becomes this run's (collective): refused while it holds an unfinished
        run's checkpoints (a resume continues its own), ``run.json`` names this run, and
        the previous run's outputs are listed to be cleared when this run ends
        (problems/run/identity.py)."""
        if self.out is None:
            return
        # a resume continues its own folder; any other folder is this run's to take
        resume = self.options.checkpoint.resume
        self._resuming_here = resume is not None and Path(resume).resolve() == self.out.resolve()
        self._fresh = self.checkpoints.resume_meta is None or not self._resuming_here
        error, previous = None, (set(), None)
        if self.rank0:
            try:
                previous = self._take_folder_here()
            except ValueError as err:
                error = str(err)
            except OSError as err:
                error = f"cannot write in {self.out}: {err.strerror or err}"
        error = self.comm.bcast(error, root=0)
        if error:
            raise ParameterError("--resume" if self._resuming_here else "--out", error)
        self._previous_outputs, self._previous_run_file = previous

    def _take_folder_here(self) -> tuple[set[str], bytes | None]:
        record = identity.read_folder(self.out)
        resume = self.options.checkpoint.resume
        if resume is not None and record.finished() and record.run_id == self.result.run_id \
                and Path(resume).resolve() == self.out.resolve():
            raise ValueError(f"the run in {self.out} has finished (its results.json says ok): "
                             "nothing to resume")
        if not self._fresh:
            before = identity.write_run_file(self.out, self.result.scene, self.result.parameters,
                                             self.result.run_id, self.comm.size)
            return set(), before
        if self._resuming_here:  # and no checkpoint of this run found
            identity.refuse_other_runs_checkpoints(self.out, self.result.parameters)
        identity.check_fresh_start(self.out, self.result.scene)
        previous = identity.outputs(self.out, record.results)
        before = identity.write_run_file(self.out, self.result.scene, self.result.parameters,
                                         self.result.run_id, self.comm.size)
        return previous, before

    def __enter__(self) -> "RunContext":
        return self

    def __exit__(self, kind, error, tb) -> bool:
        # an exception on this rank alone: the other ranks wait in a collective call
        abort_if_stranding(self.comm, error)
        # every rank is here (or the error was this rank's alone and the job is ended)
        try:
            self._close_field_writers(error)
        finally:
            release_run_objects(self.comm, self._first_petsc_object,
                                lambda: close_solvers(created_after=self._solvers_before))
            self.checkpoints.close()
        if isinstance(error, Interrupted):
            self.result.status = "interrupted"
            self.result.message = str(error)
        elif isinstance(error, SolveFailure):
            self.result.status = "failed"
            if error.failed_step is not None:  # its work is in the totals: the steps sum to them
                self.result.steps.append(named_like(error.failed_step, self.result.steps,
                                                     error.quantity))
            kept = f" Converged steps are in {self.out}: {', '.join(self.result.fields)}." \
                if self.out is not None and self.result.fields else ""
            self.result.message = str(error) + kept
        elif error is not None:
            self.result.status = "error"
            self.result.message = "".join(traceback.format_exception_only(kind, error)).strip()
        if error is None and self.checkpoints.resume_meta is not None:
            # the scene never reached the checkpoint's path: its numbers are not a resume
            self.result.status = "error"
            self.result.message = (f"resumed from {self.checkpoints.resumed_from}, but the run "
                                   "never reached the checkpoint's path (does the scene pass "
                                   "ctx.checkpoints to follow_path?)")
        if self.checkpoints.write_seconds:
            self.timings.add("checkpoint", sum(self.checkpoints.write_seconds))
        self.result.timings = self.timings.as_dict()
        self.result.checkpoints = self.checkpoints.summary()
        # all ranks are here
        collective = error is None or isinstance(error, (SolveFailure, Interrupted))
        memory = peak_memory_mb()
        self.result.peak_memory_mb = self.comm.allreduce(memory, op=MPI.MAX) if collective else memory
        # bad input found only once the mesh exists (an obstacle inside the body, a mesh
        # the scene cannot use) is bad input all the same: no results.json, and the
        # folder goes again if this run made it and nothing else is in it (exit 2)
        late_bad_input = isinstance(error, (ParameterError, MeshError))
        # a resume refused before it reached its checkpoint (another layout of the scene's
        # state, a checkpoint that does not fit) leaves the folder as it found it
        refused_resume = error is not None and self.checkpoints.resume_meta is not None
        try:
            if late_bad_input or refused_resume:
                self._give_folder_back()
            elif not (error is not None and self.checkpoints.resume_meta is not None):
                try:
                    self.write()
                except OSError as failed:
                    # a full disk that stopped the run cannot take results.json either:
                    # the first failure is the one to report
                    if not (output_error(failed) and output_error(error)):
                        raise
                else:
                    self._clear_previous()
            # a resume that failed before it reached the checkpoint keeps the folder's
            # results.json (say "interrupted"): it still describes the run
        finally:
            self._release(remove_if_empty=late_bad_input)
        if self.result.status == "error" and error is None:
            from eyemech.problems.run.checkpoint import CheckpointError

            raise CheckpointError(self.result.message)
        return False

    @property
    def rank0(self) -> bool:
        return self.comm.rank == 0

    def path(self, name: str) -> Path | None:
        return None if self.out is None else self.out / name

    # -- output the scenes share ------------------------------------------------------
    @property
    def field_dir(self) -> Path | None:
        """Where fields go: the output folder, or None (nothing written) under ``--no-fields``."""
        return self.out if self.options.fields else None

    @property
    def pictures(self) -> bool:
        """Whether PNG pictures are drawn (an output folder and no ``--no-pictures``)."""
        return self.options.pictures and self.out is not None

    def field_writer(self, functions: list, stem: str = "fields", pvd: bool = True) -> FieldWriter:
        """``functions`` as a ``.pvd`` series (``pvd=False``: a scene with a series of its
        own), and as ADIOS2 VTX under ``--vtx``; a no-op writer under ``--no-fields``."""
        writer = FieldWriter(self.field_dir, self.comm, functions, stem=stem,
                             vtx=self.options.vtx, pvd=pvd)
        self._field_writers.append(writer)
        return writer

    def pyvista_series(self, stem: str = "state") -> PyvistaSeries:
        """``<stem>.pvd`` + one gathered ``.vtu`` per frame for pyvista (no-op under ``--no-fields``)."""
        return PyvistaSeries(self.field_dir, self.comm, stem=stem)

    def record_step(self, **values: Any) -> None:
        self.result.steps.append(values)

    def write(self) -> None:
        if self.out is not None and self.rank0:
            write_json_atomic(self.out / "results.json", self.result.as_json())

    def _clear_previous(self) -> None:
        """A new run in a used folder: the previous run's outputs it did not write again
        and the checkpoints of other runs go (rank 0, after results.json is written)."""
        if self.out is None or not self._fresh or not self.rank0:
            return
        kept = identity.written_outputs(self.out, self.result.fields, self.result.pictures)
        removed = identity.clear_previous(self.out, self._previous_outputs, kept,
                                          self.result.run_id)
        if removed:
            log.info("removed the previous run's %s from %s", ", ".join(removed), self.out)

    def _give_folder_back(self) -> None:
        """Bad input found after meshing, or a resume refused before its checkpoint:
        run.json as it was before this run."""
        if self.out is not None and self.rank0:
            identity.restore_run_file(self.out, self._previous_run_file)


# what a scene calls the position along its path in its step records (the driver's "load")
PATH_POSITION_KEYS = ("load", "load_factor", "time", "depth_mm")


def named_like(failed_step: dict, steps: list[dict], quantity: str = "") -> dict:
    """The driver's record of a failed step (its position as ``load``) with the position
    under the name the scene's own records give it (``time`` for a time-stepped scene,
    ``load_factor``, ...), so that every step of ``results.json`` reads alike; before any
    record, the name of the path's ``quantity`` (the failure's)."""
    first = {"time": "time", "load factor": "load_factor"}.get(quantity, "load")
    name = next((key for key in PATH_POSITION_KEYS if steps and key in steps[-1]), first)
    return {name if key == "load" else key: value for key, value in failed_step.items()}

