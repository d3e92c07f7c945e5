"""Strong-scaling and refinement benchmark of the linear solvers (issue 10).

    python -m eyemech.scripts.scaling run --ranks 1,2 --cases sb-coarse,sb-default \
        --solvers direct,iterative --out docs/scaling
    python -m eyemech.scripts.scaling report --out docs/scaling
    python -m eyemech.scripts.scaling probe --cells 8,12,17 --element Q1P0 --until 1 \
        --petsc fieldsplit_u_pc_gamg_threshold=0.05 --out docs/scaling

``run`` launches ``mpiexec -n N eyemech run SCENE ... --json`` for every case, rank
count and solver (one after the other: timings need the machine), and appends one row
per run to ``OUT/scaling.csv``; ``report`` writes ``OUT/scaling.png`` (time per Newton
step and Krylov iterations per solve) and prints the Markdown table. Ready for any N:
on a cluster pass ``--ranks 1,4,16,64`` (and ``--mpiexec`` for the site's launcher).

``probe`` is the refinement check of the iterative solver on the eye: it runs
scleral-buckling in-process (serial) with any number of cells per cube edge (the
scene's resolutions are 8, 12 and 26) along the first part of the load path only
(``--until 1``: the IOP step; 2: and the buckle), with the iterative solver and
optional PETSc overrides, and appends Newton/Krylov counts to ``OUT/refinement.csv``.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import math
import os
import platform
import shlex
import subprocess
import sys
from pathlib import Path

BIN = Path(sys.executable).parent

# name: (scene, overrides, refinement level) -- levels of one scene refine the same mesh
CASES: dict[str, tuple[str, dict[str, str], int]] = {
    "sb-coarse": ("scleral-buckling", {"resolution": "coarse"}, 0),
    "sb-default": ("scleral-buckling", {"resolution": "default"}, 1),
    "sb-paper": ("scleral-buckling", {"resolution": "paper"}, 2),
    # keratotomy: 8 incisions, a short creep (IOP step + 3 creep steps) keeps it minutes
    "kt-default": ("keratotomy", {"t_end": "600", "first_dt": "200", "dt_growth": "1"}, 0),
    "kt-fine": ("keratotomy", {"t_end": "600", "first_dt": "200", "dt_growth": "1",
                               "mesh_size": "0.7", "azimuthal_divisions": "32"}, 1),
}

COLUMNS = ("date", "machine", "load", "case", "scene", "level", "solver", "ranks", "dofs",
           "status", "newton_iterations", "krylov_iterations", "krylov_per_solve",
           "assembly_s", "solve_s", "total_s", "s_per_newton", "solve_s_per_newton",
           "peak_memory_mb_per_rank")


def run_case(case: str, ranks: int, solver: str, out: Path, mpiexec: str) -> dict:
    scene, overrides, level = CASES[case]
    folder = out / "runs" / f"{case}-{solver}-{ranks}ranks"
    sets = sum((["--set", f"{k}={v}"] for k, v in {**overrides, "solver": solver}.items()), [])
    command = [str(BIN / "eyemech"), "run", scene, *sets, "--out", str(folder), "--no-fields",
               "--no-pictures", "--json"]
    if ranks > 1 or mpiexec != str(BIN / "mpiexec"):
        command = [*shlex.split(mpiexec), "-n", str(ranks), *command]
    load = os.getloadavg()[0]
    proc = subprocess.run(command, capture_output=True, text=True)
    results = folder / "results.json"
    if not results.exists():
        raise RuntimeError(f"{' '.join(command)} failed:\n{proc.stderr[-2000:]}")
    data = json.loads(results.read_text())
    steps, timings = data["steps"], data["timings"]
    newton = sum(s.get("newton_iterations", 0) for s in steps)
    krylov = sum(s.get("krylov_iterations", 0) for s in steps)
    work = timings["assembly"] + timings["solve"]
    q = data["quantities"]
    dofs = q.get("dofs", "")
    return {"date": datetime.date.today().isoformat(),
            "machine": f"{platform.node()} ({os.cpu_count()} cpus)", "load": round(load, 1),
            "case": case, "scene": scene, "level": level, "solver": solver, "ranks": ranks,
            "dofs": dofs, "status": data["status"], "newton_iterations": newton,
            "krylov_iterations": krylov,
            "krylov_per_solve": round(krylov / max(newton, 1), 1),
            "assembly_s": round(timings["assembly"], 2), "solve_s": round(timings["solve"], 2),
            "total_s": round(timings["total"], 2),
            "s_per_newton": round(work / max(newton, 1), 3),
            "solve_s_per_newton": round(timings["solve"] / max(newton, 1), 3),
            "peak_memory_mb_per_rank": round(data["peak_memory_mb"], 1)}


def append(out: Path, row: dict, name: str = "scaling.csv",
           columns: tuple[str, ...] = COLUMNS) -> None:
    table = out / name
    rows = list(csv.DictReader(table.open())) if table.exists() else []
    rows.append({k: row[k] for k in columns})
    with table.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)


PROBE_COLUMNS = ("date", "machine", "load", "element", "cells_per_edge", "until", "dofs", "status",
                 "newton_iterations", "krylov_iterations", "krylov_per_solve", "max_krylov_per_solve",
                 "solve_s_per_newton", "options")


def probe(cells: int, element: str, until: float, petsc: dict[str, str]) -> dict:
    """Serial scleral-buckling with ``cells`` per cube edge, solver=iterative, along
    the load path to the end of the stage ``until`` lies in (1: the IOP stage)."""
    import dataclasses

    from eyemech.problems import scleral_buckling as sb
    from eyemech.problems.run.context import RunContext, RunOptions
    from eyemech.problems.run.parameters import build
    from eyemech.problems.scleral_buckling.stages import operation as stages_of
    from eyemech.problems.solve.driver import NewtonOptions

    @dataclasses.dataclass(frozen=True)
    class Refined(sb.Parameters):
        def geometry(self):
            return dataclasses.replace(super().geometry(), cells_per_edge=cells)

    params = build(Refined, {"element": element, "solver": "iterative"})
    options = RunOptions(fields=False, pictures=False, newton=NewtonOptions(petsc=petsc))
    load = os.getloadavg()[0]
    status = "ok"
    with RunContext(sb.SCENE.name, params, None, None, options) as ctx:
        model = sb.BucklingModel(params, ctx)
        writer = sb.Writer(model, ctx)
        stages = stages_of(params)[:max(1, math.ceil(until))]  # the first stages of the operation
        try:
            sb.Operation(model, ctx, writer, stages).follow(label="probe")
        except sb.SolveFailure as err:
            status = f"failed: {err}"[:80]
        finally:
            writer.close()
        dofs = sum(f.function_space.dofmap.index_map.size_global
                   * f.function_space.dofmap.index_map_bs for f in model.fields)
        steps, solve_s = ctx.result.steps, ctx.timings.as_dict().get("solve", 0.0)
    newton = sum(s["newton_iterations"] for s in steps)
    krylov = sum(s["krylov_iterations"] for s in steps)
    return {"date": datetime.date.today().isoformat(),
            "machine": f"{platform.node()} ({os.cpu_count()} cpus)", "load": round(load, 1),
            "element": element, "cells_per_edge": cells, "until": until, "dofs": dofs,
            "status": status, "newton_iterations": newton, "krylov_iterations": krylov,
            "krylov_per_solve": round(krylov / max(newton, 1), 1),
            "max_krylov_per_solve": max((round(s["krylov_iterations"] / s["newton_iterations"])
                                         for s in steps if s["newton_iterations"]), default=0),
            "solve_s_per_newton": round(solve_s / max(newton, 1), 3),
            "options": " ".join(f"{k}={v}" for k, v in petsc.items())}


def markdown(rows: list[dict]) -> str:
    keys = ("case", "solver", "ranks", "dofs", "status", "newton_iterations", "krylov_per_solve",
            "s_per_newton", "solve_s_per_newton", "assembly_s", "solve_s", "total_s",
            "peak_memory_mb_per_rank", "load")
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(str(r[k]) for k in keys) + " |" for r in rows]
    return "\n".join(lines)


def chart(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from eyemech.problems.studies._common import stamp

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for case in dict.fromkeys(r["case"] for r in rows):
        for solver, style in (("direct", "o-"), ("iterative", "s--")):
            pick = sorted((r for r in rows if r["case"] == case and r["solver"] == solver
                           and r["status"] == "ok"), key=lambda r: int(r["ranks"]))
            if pick:
                left.plot([int(r["ranks"]) for r in pick], [float(r["s_per_newton"]) for r in pick],
                          style, label=f"{case} {solver} ({pick[0]['dofs']} dofs)")
    left.set_xlabel("MPI ranks")
    left.set_ylabel("s per Newton step (assembly + linear solve)")
    left.set_xscale("log", base=2)
    left.set_yscale("log")
    left.set_title("strong scaling")
    left.legend(fontsize=7)
    for scene in dict.fromkeys(r["scene"] for r in rows):
        pick = sorted((r for r in rows if r["scene"] == scene and r["solver"] == "iterative"
                       and r["status"] == "ok" and int(r["ranks"]) == 1),
                      key=lambda r: int(r["level"]))
        if pick:
            right.plot([int(r["dofs"]) for r in pick], [float(r["krylov_per_solve"]) for r in pick],
                       "s-", label=scene)
    right.set_xscale("log")
    right.set_xlabel("dofs (mesh refinement)")
    right.set_ylabel("Krylov iterations per Newton step")
    right.set_title("iterative: refinement (1 rank)")
    right.legend(fontsize=8)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    fig.text(0.01, 0.01, stamp(), fontsize=7, color="0.4")
    fig.savefig(path, dpi=120)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("command", choices=("run", "report", "probe"))
    parser.add_argument("--cases", default="sb-coarse,sb-default")
    parser.add_argument("--ranks", default="1,2")
    parser.add_argument("--solvers", default="direct,iterative")
    parser.add_argument("--out", default="docs/scaling")
    parser.add_argument("--mpiexec", default=str(BIN / "mpiexec"))
    parser.add_argument("--cells", default="8,12", help="probe: cells per cube edge")
    parser.add_argument("--element", default="Q1P0", help="probe: Q1P0 or Q2P1")
    parser.add_argument("--until", type=float, default=1.0, help="probe: end of the load path")
    parser.add_argument("--petsc", action="append", default=[], help="probe: OPTION=VALUE")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.command == "probe":
        petsc = dict(item.split("=", 1) for item in args.petsc)
        for cells in (int(n) for n in args.cells.split(",")):
            row = probe(cells, args.element, args.until, petsc)
            append(out, row, "refinement.csv", PROBE_COLUMNS)
            print(json.dumps(row), flush=True)
        return 0
    if args.command == "run":
        for case in args.cases.split(","):
            for ranks in (int(n) for n in args.ranks.split(",")):
                for solver in args.solvers.split(","):
                    row = run_case(case, ranks, solver, out, args.mpiexec)
                    append(out, row)
                    print(json.dumps(row), flush=True)
        return 0
    rows = list(csv.DictReader((out / "scaling.csv").open()))
    chart(rows, out / "scaling.png")
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
