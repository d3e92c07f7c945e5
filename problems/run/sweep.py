"""Parameter studies: the Cartesian product of ``--grid`` values, cases run side by
side on split communicators, one CSV row per case (failures recorded, not fatal)."""

from __future__ import annotations

import csv
import dataclasses
import io
import itertools
import json
import logging
import traceback
from pathlib import Path
from typing import Any

from mpi4py import MPI

from eyemech.problems.run.checkpoint import Interrupted, latest
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.faults import abort_if_stranding
from eyemech.problems.run.newton import SolveFailure
from eyemech.problems.run.parameters import ParameterError, build
from eyemech.problems.run.progress import case_ended, case_started
from eyemech.problems.run.results import OutputFolder, stage_groups, write_text_atomic

log = logging.getLogger("eyemech")

def parse_grid(entries: list[str]) -> dict[str, list[str]]:
    grid: dict[str, list[str]] = {}
    for entry in entries:
        if "=" not in entry:
            raise ParameterError(entry, "a --grid entry is key=v1,v2,...")
        key, values = entry.split("=", 1)
        items = [v.strip() for v in values.split(",") if v.strip()]
        if not items:
            raise ParameterError(key, "--grid needs at least one value")
        grid[key.strip()] = items
    return grid


def cases(scene, base: dict[str, Any], grid: dict[str, list[str]]) -> list[dict[str, Any]]:
    """Every combination, each validated now so that a bad value stops the sweep
    before any case runs."""
    keys = list(grid)
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
    folder = OutputFolder(out, comm).acquire()  # made, writable, and this sweep's alone
    try:
        return _run_cases(scene, all_cases, grid, Path(out), ranks_per_case, options, resume,
                          comm)
    finally:
        folder.release()


def _run_cases(scene, all_cases, grid, out: Path, ranks_per_case: int,
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
        previous = _finished(case_dir) if resume else None
        if previous is not None:
            if sub.rank == 0:
                rows.append({**row, **previous})
            continue
        params = build(scene.parameters, overrides)
        quiet = sub.rank != 0 or (options.quiet if options is not None else True)
        started = case_started(index, len(all_cases), {k: overrides[k] for k in grid}, quiet)
        try:
            result = scene.run(params, comm=sub, out=case_dir,
                               options=_case_options(options, case_dir, resume))
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


def _case_options(options: RunOptions | None, case_dir: Path, resume: bool) -> RunOptions | None:
    """With --resume, an interrupted case continues from its last checkpoint."""
    if not resume or latest(case_dir) is None:
        return options
    options = options or RunOptions()
    return dataclasses.replace(options, checkpoint=dataclasses.replace(options.checkpoint,
                                                                       resume=case_dir))


def _finished(case_dir: Path) -> dict[str, Any] | None:
    """The row of a case whose results.json says ``ok``; None (run it again) for a
    missing, unreadable or unfinished one."""
    path = case_dir / "results.json"
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except (OSError, ValueError) as err:
        log.warning("%s is unreadable (%s): the case runs again", path, err)
        return None
    if not isinstance(data, dict) or data.get("status") != "ok":
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
