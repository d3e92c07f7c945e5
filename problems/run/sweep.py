"""Parameter studies: the Cartesian product of ``--grid`` values, cases run side by
side on split communicators, one CSV row per case (failures recorded, not fatal)."""

from __future__ import annotations

import csv
import dataclasses
import io
import itertools
import json
import logging
import re
import shutil
import traceback
from pathlib import Path
from typing import Any

from mpi4py import MPI

from eyemech.problems.run import identity
from eyemech.problems.run.checkpoint import Interrupted, latest
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.faults import abort_if_stranding
from eyemech.problems.run.identity import run_id
from eyemech.problems.run.newton import SolveFailure
from eyemech.problems.run.parameters import ParameterError, build
from eyemech.problems.run.progress import case_ended, case_started
from eyemech.problems.run.results import OutputFolder, stage_groups, write_text_atomic

log = logging.getLogger("eyemech")


def parse_grid(entries: list[str]) -> dict[str, list[str]]:
    """``--grid key=v1,v2`` entries; a key given twice is an error (its values belong in
    one entry: two would be read as a union by some and as the last by others)."""
    grid: dict[str, list[str]] = {}
    for entry in entries:
        if "=" not in entry:
            raise ParameterError(entry, "a --grid entry is key=v1,v2,...")
        key, values = entry.split("=", 1)
        key = key.strip()
        items = [v.strip() for v in values.split(",") if v.strip()]
        if not items:
            raise ParameterError(key, "--grid needs at least one value")
        if key in grid:
            raise ParameterError(key, f"--grid {key} is given twice ({','.join(grid[key])} "
                                 f"and {','.join(items)}); give all its values in one: "
                                 f"--grid {key}={','.join(grid[key] + items)}")
        grid[key] = items
    return grid


def cases(scene, base: dict[str, Any], grid: dict[str, list[str]]) -> list[dict[str, Any]]:
    """Every combination, each validated now so that a bad value stops the sweep
    before any case runs; two values of a key that are the same number (0.1 and 0.10)
    are refused (the cases are keyed by their parameters)."""
    keys = list(grid)
    for key in keys:
        typed = [build(scene.parameters, {**base, key: v}).as_dict()[key] for v in grid[key]]
        repeated = sorted({grid[key][i] for i, v in enumerate(typed) if typed.index(v) != i})
        if repeated:
            raise ParameterError(key, f"--grid {key} repeats the value {', '.join(repeated)}")
    combos = []
    for values in itertools.product(*(grid[k] for k in keys)):
        overrides = dict(base)
        overrides.update(zip(keys, values))
        build(scene.parameters, overrides)
        combos.append(overrides)
    return combos


def run_sweep(scene, base: dict[str, Any], grid: dict[str, list[str]], out: Path,
              ranks_per_case: int = 1, options: RunOptions | None = None,
              resume: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[dict[str, Any]]:
    all_cases = cases(scene, base, grid)
    if ranks_per_case < 1 or comm.size % ranks_per_case:
        raise ParameterError("--ranks-per-case", f"must divide the number of ranks ({comm.size})")
    ids = [run_id(scene.name, build(scene.parameters, c).as_dict()) for c in all_cases]
    folder = OutputFolder(out, comm).acquire()  # made, writable, and this sweep's alone
    try:
        error = None
        if comm.rank == 0:
            try:
                _take_sweep_folder(Path(out), scene.name, ids, resume)
            except ValueError as err:
                error = str(err)
        error = comm.bcast(error, root=0)
        if error:
            raise ParameterError("--out", error)
        return _run_cases(scene, all_cases, ids, grid, Path(out), ranks_per_case, options,
                          resume, comm)
    finally:
        folder.release()


CASE = re.compile(r"^case_(\d{4,})$")
OTHER_CASES = "other_cases"  # cases of this scene not in the current grid, kept for reuse


def _case_folders(out: Path) -> list[Path]:
    found = [p for p in out.glob("case_*") if p.is_dir() and CASE.match(p.name)]
    if (out / OTHER_CASES).is_dir():
        found += [p for p in (out / OTHER_CASES).iterdir() if p.is_dir()]
    return sorted(found)


def _take_sweep_folder(out: Path, scene: str, ids: list[str], resume: bool) -> None:
    """Rank 0, before the first case. Refuses a folder that holds a run, or cases of
    another scene, or (without ``resume``) a case that has not ended; with ``resume``
    moves every earlier case whose parameters are a case of this grid to that case's
    folder (``case_NNNN``, NNNN its place in this grid) and the others to
    ``other_cases/RUN_ID`` (reused when a later grid has them again)."""
    top = identity.read_folder(out)
    if top.run is not None or top.results is not None:
        raise ValueError(f"{out} holds a run of '{top.scene}' (its results.json or run.json), "
                         "not a sweep; choose another folder")
    found = {folder: identity.read_folder(folder) for folder in _case_folders(out)}
    for folder, record in found.items():
        if record.scene is not None and record.scene != scene:
            raise ValueError(f"{out} is a sweep of '{record.scene}' ({folder.name}), not of "
                             f"'{scene}'; choose another folder")
    if not resume:
        unfinished = [f"{folder.name}: {identity.describe_checkpoints(c)}"
                      for folder, record in found.items()
                      if (c := record.unfinished_checkpoints())]
        if unfinished:
            raise ValueError(f"{out} holds cases that have not ended ({'; '.join(unfinished)}); "
                             "continue them with --resume, or remove them")
        return
    _arrange(out, ids, found)


def _arrange(out: Path, ids: list[str], found: dict[Path, identity.FolderRecord]) -> None:
    wanted = {rid: out / f"case_{index:04d}" for index, rid in enumerate(ids)}
    destination: dict[Path, Path] = {}
    placed: set[str] = set()
    # a folder already where its case belongs stays; a finished copy beats another
    for folder, record in sorted(found.items(), key=lambda item: (
            wanted.get(item[1].run_id) != item[0], not item[1].finished())):
        rid = record.run_id
        if rid in wanted and rid not in placed:
            destination[folder] = wanted[rid]
            placed.add(rid)
        else:
            destination[folder] = out / OTHER_CASES / (rid or folder.name)
    moving = {f: d for f, d in destination.items() if f != d}
    if not moving:
        return
    staging = out / ".arranging"
    staging.mkdir(exist_ok=True)
    for index, folder in enumerate(moving):
        folder.rename(staging / str(index))
    for index, (folder, target) in enumerate(moving.items()):
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.exists():  # an older copy of the same run: the one found here replaces it
            shutil.rmtree(target)
        (staging / str(index)).rename(target)
        log.info("sweep: %s (run %s) is now %s", folder.relative_to(out),
                 found[folder].run_id, target.relative_to(out))
    staging.rmdir()


def _run_cases(scene, all_cases, ids, grid, out: Path, ranks_per_case: int,
               options: RunOptions | None, resume: bool, comm: MPI.Comm) -> list[dict[str, Any]]:
    groups = comm.size // ranks_per_case
    color = comm.rank // ranks_per_case
    sub = comm.Split(color, comm.rank)
    rows = []
    for index, overrides in enumerate(all_cases):
        if index % groups != color:
            continue
        case_dir = Path(out) / f"case_{index:04d}"
        row = {"case": index, **{k: overrides[k] for k in grid}}
        # read on the case's rank 0 and shared: whether the case runs, and from where, is
        # a collective choice (another rank could see the files otherwise, e.g. on NFS)
        previous, resume_from = sub.bcast(
            (_finished(case_dir, ids[index]) if resume else None,
             resume and latest(case_dir) is not None) if sub.rank == 0 else None, root=0)
        if previous is not None:
            if sub.rank == 0:
                rows.append({**row, **previous})
            continue
        params = build(scene.parameters, overrides)
        quiet = sub.rank != 0 or (options.quiet if options is not None else True)
        started = case_started(index, len(all_cases), {k: overrides[k] for k in grid}, quiet)
        try:
            result = scene.run(params, comm=sub, out=case_dir,
                               options=_case_options(options, case_dir, resume_from))
            row.update(status=result.status, **_scalars(result.quantities))
            row.update(_case_timings(result.timings))
        except Interrupted:
            raise  # SIGINT/SIGTERM stop the whole sweep; --resume continues it
        except SolveFailure as err:
            row.update(status="failed", error=str(err))
        except Exception as err:  # one case's error must not stop the others ...
            abort_if_stranding(sub, err)  # ... unless the case's other ranks wait for this one
            row.update(status="error", error="".join(traceback.format_exception_only(err)).strip())
        case_ended(index, len(all_cases), row["status"], started, quiet)
        if sub.rank == 0:
            rows.append(row)
    sub.Free()
    gathered = comm.gather(rows, root=0)
    if comm.rank != 0:
        return []
    table = sorted((r for part in gathered for r in part), key=lambda r: r["case"])
    write_text_atomic(Path(out) / "sweep.csv", _csv(table))
    return table


def _case_options(options: RunOptions | None, case_dir: Path,
                  resume_from: bool) -> RunOptions | None:
    """With --resume, an interrupted case (one with checkpoints: ``resume_from``) continues
    from its last checkpoint (its own: the case folders were arranged by run id)."""
    if not resume_from:
        return options
    options = options or RunOptions()
    return dataclasses.replace(options, checkpoint=dataclasses.replace(options.checkpoint,
                                                                       resume=case_dir))


def _finished(case_dir: Path, case_id: str) -> dict[str, Any] | None:
    """The row of a case whose results.json says ``ok`` for this case's parameters (its
    run id); None (run it again) for a missing, unreadable, unfinished or other one."""
    path = case_dir / "results.json"
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except (OSError, ValueError) as err:
        log.warning("%s is unreadable (%s): the case runs again", path, err)
        return None
    if not isinstance(data, dict) or data.get("status") != "ok" \
            or identity.read_folder(case_dir).run_id != case_id:
        return None
    return {"status": "ok", **_scalars(data.get("quantities", {})),
            **_case_timings(data.get("timings", {}))}


def _case_timings(timings: dict[str, float]) -> dict[str, float | None]:
    """A case's wall time and its form compilation (the run contract's
    ``form_compilation``: building the residual and Jacobian forms, FFCx/JIT included).
    The forms take every parameter as a Constant, so after a sweep's first case the JIT
    finds its kernels compiled and this is the UFL processing alone
    (tests/test_compile_once.py)."""
    return {"wall_time_s": timings.get("total"),
            "form_compilation_s": timings.get("form_compilation")}


def _scalars(quantities: dict[str, Any]) -> dict[str, Any]:
    """A case's CSV columns: its scalar quantities (a staged scene's are its last
    stage's), then one column group per stage, ``after_<stage>.<quantity>``."""
    row = {k: v for k, v in quantities.items() if isinstance(v, (int, float, bool, str))}
    for stage, group in stage_groups(quantities).items():
        row.update({f"{stage}.{k}": v for k, v in group.items()
                    if isinstance(v, (int, float, bool, str))})
    return row


def _csv(rows: list[dict[str, Any]]) -> str:
    columns: list[str] = []
    for row in rows:
        columns += [k for k in row if k not in columns]
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns)
    writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()
