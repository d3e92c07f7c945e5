"""Every scene at its defaults on 1, 2 and 3 ranks: wall time and the largest relative
difference of its quantities from the serial run (``make bench-mpi``).

    python scripts/bench_mpi.py [--ranks 1,2,3] [--scenes a,b] [--out docs/bench]

Each run is ``mpiexec -n N eyemech run NAME --json --quiet`` with the scene's defaults
(fields and pictures on), timed from outside (interpreter start-up included). Writes
``OUT/mpi-scenes.csv`` (one row per scene and rank count) and ``OUT/mpi-scenes.md``
(the table docs/parallel.md shows); with ``--merge`` the rows measured now replace those of
the same scene and rank count in ``OUT/mpi-scenes.csv`` and the others are kept (a scene
measured apart from the hour-long whole, on a quieter machine). Left out:
``iol-injection`` (its default folds the lens first, 10–20 min serially; ``--scenes
iol-injection`` runs it); ``iol-speed`` measures one core and refuses more ranks (its row
records the refusal).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BIN = Path(sys.executable).parent
LEFT_OUT = {"iol-injection": "its default folds the lens first (10–20 min serially)"}
# Scenes whose serial path is itself sensitive at round-off: self-contact with friction,
# Newton updates cut by a collision-free fraction, adaptive time steps (docs/parallel.md,
# "Every scene on 1, 2 and 3 ranks"). A partition changes the last bits of the assembled
# sums, and that may be enough to take another path to nearly the same end. For these the
# serial run is repeated with the named parameter scaled by 1 + PERTURBATION, a change of
# the size of round-off; that run's distance from the serial end state is the reach of
# round-off on this path, and the N-rank runs are compared with the serial one by their end
# states too.
PATH_SENSITIVE = {"iol-fold": "youngs_modulus", "iol-injection": "youngs_modulus"}
PERTURBATION = 1e-12
COLUMNS = ("scene", "ranks", "exit_code", "wall_s", "load", "max_rel_diff", "worst_quantity",
           "effort_rel_diff", "effort_quantity", "lockstep_wait_max_s", "note", "date",
           "perturbed_rel_diff", "perturbed_quantity")


def flat(quantities: dict, prefix: str = "") -> dict[str, object]:
    out: dict[str, object] = {}
    for key, value in quantities.items():
        if isinstance(value, dict):
            out.update(flat(value, f"{prefix}{key}."))
        else:
            out[prefix + key] = value
    return out


def numbers(value) -> list[float]:
    if isinstance(value, bool) or value is None:
        return []
    if isinstance(value, (int, float)):
        return [float(value)]
    if isinstance(value, list):
        return [x for v in value for x in numbers(v)]
    return []


# quantities that are differences of other quantities (a contact patch's pressure spread,
# a benchmark's error, the eye's wall_inward_volume: its cavity's volume at the liquid's
# closing less the present one, -1e-11 uL at that moment against 4,663 mm3): their value
# is round-off when the solve is exact, so a relative difference of two round-offs says
# nothing; they are compared against the scale of the quantity they come from
DIFFERENCE_WORDS = ("spread", "error", "deviation", "residual", "inward")
# the solver's effort (Newton iterations, factorisations, the Jacobian's stored nonzeros,
# ...) is not a result: near the stopping test, round-off that differs between partitions
# can cost one iteration more, and a partition stores the couplings across its cut twice;
# an adaptive run's number of time steps, its cuts and step sizes follow from those
# iterations, and the lens' ccd_limited_updates counts the Newton updates its collision
# check shortened (on another path, other updates: 2 against 12-13 in the fold's last
# steps on 3 ranks). They are reported in their own column.
EFFORT_WORDS = ("iterations", "factorisations", "jacobians", "attempts", "load_steps",
                "solves", "krylov", "augmentations", "nonzeros", "mallocs", "limited_updates")
EFFORT_KEYS = ("steps", "time_steps", "fold_steps", "rejected_steps", "step_cuts", "cuts",
               "time_steps_s", "min_time_step_s", "max_time_step_s")


def is_effort(key: str) -> bool:
    return any(word in key for word in EFFORT_WORDS) or key.rsplit(".", 1)[-1] in EFFORT_KEYS


def describes_the_partition(key: str) -> bool:
    """A quantity that counts what the partition splits (retina-reattachment's contact
    pairs across ranks): 0 on one rank by definition, not a result to compare."""
    return "across_ranks" in key


def is_difference(key: str) -> bool:
    return any(word in key.rsplit(".", 1)[-1] for word in DIFFERENCE_WORDS)


def scale_of(key: str, quantities: dict[str, object]) -> float:
    """The magnitude a difference-quantity is measured against: the largest |value| of the
    plain quantities sharing its first word (``pressure_spread`` -> ``pressure_mean``, ...),
    else the largest |value| of any plain non-integer quantity of the run."""
    stem = key.rsplit(".", 1)[-1].split("_")[0]
    plain = {k: v for k, v in quantities.items() if not is_difference(k)}
    kin = [abs(x) for k, v in plain.items() if k.rsplit(".", 1)[-1].split("_")[0] == stem
           for x in numbers(v) if math.isfinite(x)]
    if kin:
        return max(kin)
    floats = [abs(x) for v in plain.values() if not isinstance(v, int)
              for x in numbers(v) if math.isfinite(x)]
    return max(floats, default=0.0)


def largest_difference(serial: dict, parallel: dict, effort: bool = False,
                       end_state: bool = False) -> tuple[float, str]:
    """The largest relative difference over the numeric quantities (wall-clock ones
    left out; the solver's effort only, or only the results, as ``effort`` says):
    |a − b| / max(|a|, |b|), or for a difference-quantity (a spread, an error)
    |a − b| / the scale of the quantity it comes from (``scale_of``); 0 where the scale is
    below 1e-14. Returns it and its key. Histories of different lengths (another number of
    adaptive steps) are an infinite difference, unless ``end_state``: then their last
    entries are compared (a path-sensitive scene's end, ``PATH_SENSITIVE``)."""
    worst, where = 0.0, ""
    ours, theirs = flat(serial), flat(parallel)
    for key, value in ours.items():
        if "seconds" in key or "per_second" in key or key not in theirs \
                or describes_the_partition(key) or is_effort(key) != effort:
            continue
        a, b = numbers(value), numbers(theirs[key])
        if len(a) != len(b) and end_state and a and b:
            a, b = a[-1:], b[-1:]
        elif len(a) != len(b):
            return math.inf, f"{key} (length {len(a)} vs {len(b)})"
        floor = scale_of(key, ours) if is_difference(key) else 0.0
        for x, y in zip(a, b):
            if math.isnan(x) and math.isnan(y):
                continue
            scale = max(abs(x), abs(y), floor)
            difference = 0.0 if scale < 1e-14 else abs(x - y) / scale
            if difference > worst:
                worst, where = difference, key
    return worst, where


def run(name: str, ranks: int, folder: Path,
        settings: tuple[str, ...] = ()) -> tuple[int, float, dict | None, str]:
    command = [str(BIN / "eyemech"), "run", name, "--out", str(folder), "--json", "--quiet",
               *[part for setting in settings for part in ("--set", setting)]]
    if ranks > 1:
        command = [str(BIN / "mpiexec"), "-n", str(ranks), *command]
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True,
                          env=dict(os.environ, OMP_NUM_THREADS="1"))
    seconds = time.perf_counter() - start
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    result = json.loads(lines[-1]) if done.returncode == 0 and lines else None
    said = done.stderr.strip().splitlines()
    return done.returncode, seconds, result, said[-1] if said and done.returncode else ""


def scene_names() -> list[str]:
    from eyemech.scripts.catalogue import scene_catalogue

    return [entry.name for entry in scene_catalogue()]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ranks", default="1,2,3")
    parser.add_argument("--scenes", default="", help="comma-separated (default: all but "
                        + ", ".join(LEFT_OUT) + ")")
    parser.add_argument("--out", default="docs/bench")
    parser.add_argument("--merge", action="store_true",
                        help="keep the rows of OUT/mpi-scenes.csv not measured now")
    parser.add_argument("--keep", default="",
                        help="write the runs into this folder and keep them (default: a "
                        "temporary folder, removed)")
    args = parser.parse_args()
    counts = [int(r) for r in args.ranks.split(",")]
    names = args.scenes.split(",") if args.scenes else \
        [n for n in scene_names() if n not in LEFT_OUT]
    rows = []
    kept = contextlib.nullcontext(args.keep) if args.keep else \
        tempfile.TemporaryDirectory(prefix="eyemech-bench-mpi-")
    with kept as scratch:
        for name in names:
            serial = None
            for ranks in counts:
                load_before = os.getloadavg()[0]
                code, seconds, result, said = run(name, ranks, Path(scratch) / f"{name}-{ranks}")
                # the machine's 1-minute load average around the run: a wall time is only
                # comparable with another measured at a similar load
                load = round((load_before + os.getloadavg()[0]) / 2, 1)
                # the longest any rank waited for the others at a step's end (scenes with
                # checkpoints; docs/parallel.md, "Ranks in step")
                waited = (result or {}).get("checkpoints", {}).get("lockstep_wait_max_s", "")
                row = {"scene": name, "ranks": ranks, "exit_code": code,
                       "wall_s": round(seconds, 1), "load": load, "max_rel_diff": "", "worst_quantity": "",
                       "effort_rel_diff": "", "effort_quantity": "",
                       "lockstep_wait_max_s": waited, "note": said[:160],
                       "date": time.strftime("%Y-%m-%d"), "perturbed_rel_diff": "",
                       "perturbed_quantity": ""}
                end_state = name in PATH_SENSITIVE
                if ranks == 1:
                    serial = result
                    if end_state and result is not None:
                        row.update(perturbed(name, result, Path(scratch)))
                elif result is not None and serial is not None:
                    worst, where = largest_difference(serial["quantities"], result["quantities"],
                                                      end_state=end_state)
                    row.update(max_rel_diff=f"{worst:.1e}", worst_quantity=where)
                    worst, where = largest_difference(serial["quantities"], result["quantities"],
                                                      effort=True)
                    row.update(effort_rel_diff=f"{worst:.1e}", effort_quantity=where)
                rows.append(row)
                print(" ".join(f"{k}={row[k]}" for k in COLUMNS), flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table = merged(read_rows(out / "mpi-scenes.csv"), rows) if args.merge else rows
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS)
    writer.writeheader()
    writer.writerows(table)
    (out / "mpi-scenes.csv").write_text(buffer.getvalue())
    shown = sorted({int(r["ranks"]) for r in table})
    (out / "mpi-scenes.md").write_text(markdown(table, shown))
    return 0 if all(r["exit_code"] == 0 or "measures one core" in r["note"] for r in rows) else 1


def perturbed(name: str, serial: dict, scratch: Path) -> dict[str, str]:
    """The serial run again with ``PATH_SENSITIVE[name]`` scaled by 1 + PERTURBATION: its
    largest relative difference from ``serial``'s end state (the reach of round-off on the
    serial path), as the 1-rank row's ``perturbed_*`` columns."""
    key = PATH_SENSITIVE[name]
    value = float(serial["parameters"][key]) * (1.0 + PERTURBATION)
    code, _, result, said = run(name, 1, scratch / f"{name}-1-perturbed", (f"{key}={value!r}",))
    if result is None:
        return {"perturbed_rel_diff": "", "perturbed_quantity": f"exit {code}: {said[:120]}"}
    worst, where = largest_difference(serial["quantities"], result["quantities"], end_state=True)
    return {"perturbed_rel_diff": f"{worst:.1e}", "perturbed_quantity": where}


def read_rows(path: Path) -> list[dict]:
    """The rows of an earlier table (none if it is missing); numbers as the CSV holds them."""
    if not path.exists():
        return []
    with path.open(newline="") as stream:
        rows = list(csv.DictReader(stream, restval=""))
    for row in rows:
        row["ranks"], row["exit_code"] = int(row["ranks"]), int(row["exit_code"])
        row["date"] = row.get("date") or ""
    return rows


def merged(earlier: list[dict], now: list[dict]) -> list[dict]:
    """Earlier rows with those measured now in their place (same scene and rank count);
    a scene new to the table goes after the others."""
    fresh = {(r["scene"], r["ranks"]): r for r in now}
    table = [fresh.pop((r["scene"], r["ranks"]), r) for r in earlier]
    table += [r for r in now if (r["scene"], r["ranks"]) in fresh]
    order = list(dict.fromkeys(r["scene"] for r in table))
    return sorted(table, key=lambda r: (order.index(r["scene"]), r["ranks"]))


def markdown(rows: list[dict], counts: list[int]) -> str:
    by_scene: dict[str, dict[int, dict]] = {}
    for row in rows:
        by_scene.setdefault(row["scene"], {})[row["ranks"]] = row
    head = ["scene", *[f"{r} rank{'s' * (r > 1)} (s)" for r in counts],
            *[f"max rel. diff. {r} ranks" for r in counts if r > 1],
            f"1 rank, E × (1 + {PERTURBATION:.0e})",
            *[f"effort {r} ranks" for r in counts if r > 1]]
    dates = sorted({str(r.get("date") or "") for r in rows} - {""}) or [time.strftime("%Y-%m-%d")]
    when = dates[0] if len(dates) == 1 else f"{dates[0]} to {dates[-1]}"
    lines = [f"Every scene at its defaults (`make bench-mpi`, {when}, "
             f"{platform.node()}, {os.cpu_count()} cpus): wall time of `mpiexec -n N eyemech "
             "run NAME` (start-up included) and the largest relative difference of any "
             "quantity from the serial run (a spread or an error against the scale of the "
             "quantity it comes from: scripts/bench_mpi.py, scale_of), and apart from it the "
             "largest relative difference in the solver's effort (Newton iterations, "
             "factorisations: round-off near the stopping test may cost an iteration); in brackets "
             "the machine's 1-minute load average "
             "during the run (other jobs included). The lens scenes' serial path is itself "
             "sensitive at round-off (self-contact with friction, collision-limited Newton "
             "updates, adaptive time steps): they are compared by their end states, and their "
             "serial run is repeated with the Young's modulus changed by a part in 10¹² — its "
             "distance from the serial run is how far round-off alone moves the result "
             "(docs/parallel.md, \"Every scene on 1, 2 and 3 ranks\").", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, runs in by_scene.items():
        cells = [f"`{name}`"]
        for r in counts:
            row = runs.get(r)
            cells.append("" if row is None else f"{row['wall_s']} ({row['load']})"
                         if int(row["exit_code"]) == 0 else f"exit {row['exit_code']}")
        for r in counts:
            if r > 1:
                row = runs.get(r, {})
                diff = row.get("max_rel_diff", "")
                cells.append(f"{diff} ({row['worst_quantity']})" if diff else "")
        serial = runs.get(1, {})
        diff = serial.get("perturbed_rel_diff", "")
        cells.append(f"{diff} ({serial['perturbed_quantity']})" if diff else
                     serial.get("perturbed_quantity", ""))
        for r in counts:
            if r > 1:
                row = runs.get(r, {})
                diff = row.get("effort_rel_diff", "")
                cells.append("same" if diff in ("0.0e+00",) else
                             f"{diff} ({row['effort_quantity']})" if diff else "")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
