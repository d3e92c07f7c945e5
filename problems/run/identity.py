"""A run owns its output folder (docs/cli.md, "A run owns its folder").

A run's identity is its scene and a hash of its full parameters (:func:`run_id`: the
same on every rank and in every new process). It is written to ``DIR/run.json`` when the
run starts, to ``results.json`` and to every checkpoint's ``meta.json``, so that what a
folder holds can always be told apart:

- a new run into a folder that holds checkpoints of a run that has not ended (no
  ``results.json`` of that run says ``ok``, ``failed`` or ``error``) is refused: they are
  the only copy of interrupted work (:func:`check_fresh_start`);
- a new run replaces the folder's previous run: when it ends, the previous run's outputs
  that it did not write again (extra ``state_NNNN.vtu``, pictures, VTX folders) and the
  checkpoints of runs that had ended are removed (:func:`clear_previous`);
- ``--resume DIR`` continues the run that ``run.json`` names, from its own checkpoints
  only (:func:`resume_plan`).

Everything here reads and writes on the calling rank: callers run it on rank 0 and
broadcast the outcome.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import re
import shutil
import time
from pathlib import Path
from typing import Any

RUN_FILE = "run.json"
FORMAT = "eyemech-run-1"
CHECKPOINT_NAME = re.compile(r"^ckpt_(\d{6,})$")
ENDED = ("ok", "failed", "error")  # results.json statuses of a run that ended


def _encode(value: Any) -> Any:
    if hasattr(value, "tolist"):  # NumPy arrays and scalars
        return value.tolist()
    return str(value)  # paths, and anything else by its text


def run_id(scene: str, parameters: dict[str, Any]) -> str:
    """16 hex digits of the SHA-256 of the scene and its parameters as canonical JSON
    (sorted keys, floats as Python writes them: the same in every new process and on every
    rank; tuples and lists alike)."""
    text = json.dumps({"scene": scene, "parameters": parameters}, sort_keys=True,
                      separators=(",", ":"), default=_encode)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _json(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _id_of(data: dict[str, Any] | None) -> str | None:
    """The run id a record states, or the one of its scene and parameters (records
    written before run ids; a non-finite parameter was stored as null there)."""
    if data is None:
        return None
    if isinstance(data.get("run_id"), str):
        return data["run_id"]
    if isinstance(data.get("scene"), str) and isinstance(data.get("parameters"), dict):
        return run_id(data["scene"], data["parameters"])
    return None


@dataclasses.dataclass
class Checkpoint:
    path: Path
    step: int
    run_id: str | None  # None: meta.json unreadable
    scene: str | None


@dataclasses.dataclass
class FolderRecord:
    """What an output folder holds, as far as eyemech's files tell."""

    folder: Path
    run: dict[str, Any] | None          # run.json
    results: dict[str, Any] | None      # results.json
    checkpoints: list[Checkpoint]

    @property
    def run_id(self) -> str | None:
        """The folder's current run: run.json's, else results.json's."""
        return _id_of(self.run) or _id_of(self.results)

    @property
    def scene(self) -> str | None:
        for data in (self.run, self.results):
            if data is not None and isinstance(data.get("scene"), str):
                return data["scene"]
        return next((c.scene for c in self.checkpoints if c.scene), None)

    @property
    def parameters(self) -> dict[str, Any] | None:
        for data in (self.run, self.results):
            if data is not None and isinstance(data.get("parameters"), dict):
                return data["parameters"]
        return None

    def ended(self) -> set[str]:
        """Ids of runs the folder's results.json records as ended."""
        if self.results is not None and self.results.get("status") in ENDED:
            found = _id_of(self.results)
            return {found} if found else set()
        return set()

    def finished(self) -> bool:
        """The folder's current run finished: its results.json says ok."""
        return self.results is not None and self.results.get("status") == "ok" \
            and _id_of(self.results) == self.run_id

    def unfinished_checkpoints(self) -> list[Checkpoint]:
        """Checkpoints of runs that have not ended (or whose meta.json is unreadable)."""
        ended = self.ended()
        return [c for c in self.checkpoints if c.run_id is None or c.run_id not in ended]

    def own_checkpoints(self, run: str) -> list[Checkpoint]:
        return [c for c in self.checkpoints if c.run_id == run]

    def empty(self) -> bool:
        return self.run is None and self.results is None and not self.checkpoints


def checkpoints_in(folder: Path) -> list[Checkpoint]:
    """The committed checkpoints under ``folder/checkpoints``, oldest first."""
    where = folder / "checkpoints"
    if not where.is_dir():
        return []
    found = []
    for path in where.iterdir():
        match = CHECKPOINT_NAME.match(path.name)
        if not match or not path.is_dir():
            continue
        meta = _json(path / "meta.json")
        found.append(Checkpoint(path, int(match.group(1)), _id_of(meta),
                                meta.get("scene") if meta else None))
    return sorted(found, key=lambda c: c.step)


def read_folder(folder: str | Path) -> FolderRecord:
    folder = Path(folder)
    return FolderRecord(folder, _json(folder / RUN_FILE), _json(folder / "results.json"),
                        checkpoints_in(folder))


def describe_checkpoints(checkpoints: list[Checkpoint]) -> str:
    names = ", ".join(c.path.name for c in checkpoints)
    runs = sorted({f"{c.scene or '?'} run {c.run_id or '(unreadable)'}" for c in checkpoints})
    return f"{names} ({'; '.join(runs)})"


def check_fresh_start(folder: Path, scene: str) -> None:
    """A new run into ``folder``: refused (ValueError) while it holds checkpoints of a run
    that has not ended."""
    record = read_folder(folder)
    unfinished = record.unfinished_checkpoints()
    if not unfinished:
        return
    resume = f"continue it with 'eyemech run {unfinished[-1].scene} --resume {folder}', " \
        if unfinished[-1].scene else ""
    raise ValueError(f"{folder} holds checkpoints of a run that has not ended: "
                     f"{describe_checkpoints(unfinished)}; {resume}remove {folder / 'checkpoints'}, "
                     f"or choose another folder")


def refuse_other_runs_checkpoints(folder: Path, parameters: dict[str, Any]) -> None:
    """``--resume folder`` found no checkpoint of its run (scene and parameters as this
    version reads them) while the folder holds an unfinished run's: refused (ValueError)
    naming the parameters in which they differ (a checkpoint written before the scene had
    a parameter lacks it)."""
    unfinished = read_folder(folder).unfinished_checkpoints()
    if not unfinished:
        return
    saved = (_json(unfinished[-1].path / "meta.json") or {}).get("parameters") or {}

    def canonical(value: Any) -> str:
        return json.dumps(value, sort_keys=True, default=_encode)

    absent = sorted(k for k in parameters if k not in saved)
    other = sorted(k for k in parameters if k in saved
                   and canonical(saved[k]) != canonical(parameters[k]))
    why = "; ".join(part for part in (
        f"it has no value of {', '.join(absent)}" if absent else "",
        f"other values of {', '.join(other)}" if other else "") if part) \
        or "other parameters"
    raise ValueError(f"the checkpoints in {folder} ({describe_checkpoints(unfinished)}) were "
                     f"written by a run this version cannot continue ({why}): start the run "
                     f"again in another folder, or remove {folder / 'checkpoints'}")


def write_run_file(folder: Path, scene: str, parameters: dict[str, Any], run: str,
                   mpi_size: int) -> bytes | None:
    """``folder/run.json`` naming this run; returns the previous file's bytes (None: none)."""
    from eyemech.problems.run.results import write_text_atomic

    path = folder / RUN_FILE
    previous = None
    with contextlib.suppress(OSError):
        previous = path.read_bytes()
    text = json.dumps({"format": FORMAT, "scene": scene, "run_id": run, "mpi_size": mpi_size,
                       "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                       "parameters": parameters}, indent=2, default=_encode)
    write_text_atomic(path, text + "\n")
    return previous


def restore_run_file(folder: Path, previous: bytes | None) -> None:
    """Put back the run.json a run replaced (a run refused as bad input after meshing)."""
    from eyemech.problems.run.results import write_text_atomic

    path = folder / RUN_FILE
    with contextlib.suppress(OSError):
        if previous is None:
            path.unlink()
        else:
            write_text_atomic(path, previous.decode("utf-8"))


# -- the previous run's outputs ---------------------------------------------------------
def series_frames(pvd: Path) -> list[str]:
    """The files a ``.pvd`` index lists."""
    with contextlib.suppress(OSError):
        return re.findall(r'file="([^"]+)"', pvd.read_text())
    return []


def outputs(folder: Path, results: dict[str, Any] | None) -> set[str]:
    """The output files of the run whose ``results`` (its results.json) describe it, and
    every ``.pvd`` series in ``folder`` with its frames (a run killed before results.json
    leaves its series)."""
    names: set[str] = set()
    if results is not None:
        for key in ("fields", "pictures"):
            entries = results.get(key)
            if isinstance(entries, list):
                names.update(e for e in entries if isinstance(e, str))
    for pvd in folder.glob("*.pvd"):
        names.add(pvd.name)
        names.update(series_frames(pvd))
    return {n for n in names if _inside(folder, n)}


def _inside(folder: Path, name: str) -> bool:
    """A plain name of ``folder`` (no separator, no '..'): what we may remove."""
    return bool(name) and "/" not in name and name not in (".", "..") \
        and name not in (RUN_FILE, "results.json", "checkpoints")


def clear_previous(folder: Path, previous: set[str], kept: set[str], run: str) -> list[str]:
    """Remove the previous run's outputs in ``previous`` that this run did not write
    (``kept``), and every checkpoint not of this run. Returns what was removed."""
    removed = []
    for name in sorted(previous - kept):
        path = folder / name
        with contextlib.suppress(OSError):
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            elif path.exists() or path.is_symlink():
                path.unlink()
            else:
                continue
            removed.append(name)
    for checkpoint in checkpoints_in(folder):
        if checkpoint.run_id != run:
            shutil.rmtree(checkpoint.path, ignore_errors=True)
            removed.append(f"checkpoints/{checkpoint.path.name}")
    return removed


def written_outputs(folder: Path, fields: list[str], pictures: list[str]) -> set[str]:
    """What this run wrote: its fields and pictures, and the frames of its series."""
    names = set(fields) | set(pictures)
    for name in list(names):
        if name.endswith(".pvd"):
            names.update(series_frames(folder / name))
    return names


# -- resume -----------------------------------------------------------------------------
@dataclasses.dataclass
class ResumePlan:
    """What ``--resume DIR`` does: continue (``parameters`` of the run, from its
    checkpoint or from the start) or report the finished run (``finished``)."""

    scene: str
    parameters: dict[str, Any]
    run_id: str
    finished: dict[str, Any] | None = None  # results.json of a run that finished
    from_checkpoint: bool = False


def resume_plan(folder: Path) -> ResumePlan:
    """The run ``--resume folder`` continues (ValueError when there is none)."""
    if not folder.exists():
        raise ValueError(f"{folder}: no such folder")
    if not folder.is_dir():
        raise ValueError(f"{folder}: not a folder (give the run's output folder)")
    record = read_folder(folder)
    current = record.run_id
    if current is None:  # a folder of checkpoints only
        readable = [c for c in record.checkpoints if c.run_id]
        current = readable[-1].run_id if readable else None
    if current is None:
        raise ValueError(f"{folder} holds no run to resume (no {RUN_FILE}, results.json or "
                         "readable checkpoint)")
    if record.finished():
        return ResumePlan(record.scene, record.parameters or {}, current,
                          finished=record.results)
    own = record.own_checkpoints(current)
    if own:
        meta = _json(own[-1].path / "meta.json") or {}
        return ResumePlan(meta.get("scene") or record.scene, meta.get("parameters") or {},
                          current, from_checkpoint=True)
    if record.parameters is None or record.scene is None:
        raise ValueError(f"{folder}: its run's parameters are not recorded")
    return ResumePlan(record.scene, record.parameters, current)


def finite_parameters(parameters: dict[str, Any]) -> dict[str, Any]:
    """results.json stores a non-finite number as null: such a parameter is left to its
    default when a run is restarted from that record (run.json keeps them)."""
    return {k: v for k, v in parameters.items()
            if v is not None and not (isinstance(v, float) and not math.isfinite(v))}
