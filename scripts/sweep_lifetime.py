"""How a long sweep process holds up: MPI communicators and memory before and after many
cases of one scene in one process (docs/parallel.md, "Long processes").

    mpiexec -n 2 python -m eyemech.scripts.sweep_lifetime SCENE --cases 1000 \
        --vary KEY=LOW:HIGH [--set KEY=VALUE ...] --out DIR [--ranks-per-case 2]

runs ``eyemech sweep SCENE --grid KEY=<CASES values from LOW to HIGH> --set ... --out DIR
--ranks-per-case R --no-fields --no-pictures --quiet`` through the command line's ``main``
in this process (the code path of ``eyemech sweep``), and prints one JSON line (rank 0):
the communicators still free before and after (the fewest over the ranks; MPICH has
2,048 a process), the resident memory before and after and the peak (the most over the
ranks, MB), the wall time and how many cases ended ``ok``. ``--record FILE`` appends the
result as a Markdown table row. The exit code is the sweep's; 1 if a case did not end
``ok``.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import platform
import resource
import sys
import time
from pathlib import Path

# isort: off
from mpi4py import MPI  # first: it loads the libmpi DOLFINx's extension links against
# isort: on


def free_communicators(limit: int = 4096) -> int:
    """How many more communicators this process can make (up to ``limit``): the count
    falls by what the process holds on to."""
    made = []
    try:
        while len(made) < limit:
            made.append(MPI.COMM_SELF.Dup())
    except MPI.Exception:
        pass
    for comm in made:
        comm.Free()
    return len(made)


def resident_mb() -> float:
    """This process's resident memory now (MB)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def peak_resident_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def grid_values(vary: str, cases: int) -> tuple[str, str]:
    """``KEY=LOW:HIGH`` as (KEY, ``cases`` values evenly from LOW to HIGH, comma-separated)."""
    key, bounds = vary.split("=", 1)
    low, high = (float(v) for v in bounds.split(":"))
    step = (high - low) / max(cases - 1, 1)
    return key, ",".join(f"{low + i * step:.12g}" for i in range(cases))


def measure(scene: str, cases: int, vary: str, sets: list[str], out: Path,
            ranks_per_case: int) -> dict:
    from eyemech.problems.solve import driver  # noqa: F401  (PETSc's logging: made once)
    from eyemech.scripts.cli import main as eyemech

    comm = MPI.COMM_WORLD
    key, values = grid_values(vary, cases)
    arguments = ["sweep", scene, "--grid", f"{key}={values}", *sum((["--set", s] for s in sets), []),
                 "--out", str(out), "--ranks-per-case", str(ranks_per_case), "--no-fields",
                 "--no-pictures", "--quiet"]
    before = comm.allreduce(free_communicators(), op=MPI.MIN)
    memory_before = comm.allreduce(resident_mb(), op=MPI.MAX)
    start = time.perf_counter()
    code = eyemech(arguments)
    wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    after = comm.allreduce(free_communicators(), op=MPI.MIN)
    ok = 0
    if comm.rank == 0 and (out / "sweep.csv").exists():
        with (out / "sweep.csv").open() as table:
            ok = sum(1 for row in csv.DictReader(table) if row.get("status") == "ok")
    memory_after = comm.allreduce(resident_mb(), op=MPI.MAX)
    peak = comm.allreduce(max(peak_resident_mb(), resident_mb()), op=MPI.MAX)
    return {"scene": scene, "cases": cases, "ok_cases": comm.bcast(ok), "exit_code": code,
            "ranks": comm.size, "ranks_per_case": ranks_per_case, "grid": key,
            "settings": sets, "free_communicators_before": before,
            "free_communicators_after": after,
            "resident_mb_before": round(memory_before, 1),
            "resident_mb_after": round(memory_after, 1), "peak_resident_mb": round(peak, 1),
            "wall_s": round(wall, 1), "seconds_per_case": round(wall / cases, 3)}


def record(path: Path, row: dict, load: str) -> None:
    """Append ``row`` to the Markdown table in ``path`` (its header when new)."""
    title = ("# Benchmark: a long sweep process\n\n`make bench-sweep` (scripts/sweep_lifetime.py): "
             "`eyemech sweep` of many cases in one process; MPI communicators still free "
             "(fewest over the ranks; MPICH has 2,048 a process) and resident memory (most "
             "over the ranks) before and after the sweep (docs/parallel.md, \"Long "
             "processes\"). Wall times on a shared machine: see the load.\n\n")
    header = ("| date | machine | load (1 min at start; 1 / 5 / 15 min at end) | scene | settings "
              "| cases (ok) | ranks (per case) "
              "| free communicators before → after | resident MB before → after (peak) "
              "| wall s (per case) |\n|---|---|---|---|---|---|---|---|---|---|\n")
    line = (f"| {datetime.date.today()} | {platform.node()} ({platform.machine()}, {os.cpu_count()} cpus) "
            f"| {load} "
            f"| {row['scene']} | {' '.join(row['settings'])}, {row['grid']} varied "
            f"| {row['cases']} ({row['ok_cases']}) | {row['ranks']} ({row['ranks_per_case']}) "
            f"| {row['free_communicators_before']} → {row['free_communicators_after']} "
            f"| {row['resident_mb_before']:.0f} → {row['resident_mb_after']:.0f} "
            f"({row['peak_resident_mb']:.0f}) | {row['wall_s']:.0f} ({row['seconds_per_case']:.2f}) |\n")
    new = not path.exists()
    with path.open("a") as table:
        table.write(title + header if new else "")
        table.write(line)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("--cases", type=int, required=True)
    parser.add_argument("--vary", required=True, help="KEY=LOW:HIGH, the grid's parameter")
    parser.add_argument("--set", action="append", default=[], dest="sets")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--ranks-per-case", type=int, default=MPI.COMM_WORLD.size)
    parser.add_argument("--record", type=Path, help="append a Markdown row to this file")
    args = parser.parse_args(argv)
    load_start = Path("/proc/loadavg").read_text().split()[0]
    row = measure(args.scene, args.cases, args.vary, args.sets, args.out, args.ranks_per_case)
    if MPI.COMM_WORLD.rank == 0:
        # the 1-minute load as the sweep starts; the 1-, 5- and 15-minute loads as it ends
        load = f"{load_start}; {' / '.join(Path('/proc/loadavg').read_text().split()[:3])}"
        row["load"] = load
        print(json.dumps(row), flush=True)
        if args.record is not None:
            record(args.record, row, load)
    if row["exit_code"]:
        return row["exit_code"]
    return 0 if row["ok_cases"] == row["cases"] else 1


if __name__ == "__main__":
    sys.exit(main())
