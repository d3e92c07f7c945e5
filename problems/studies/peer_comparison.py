"""eyemech against a plain DOLFINx script on the same problem: ``sphere-inflation`` at its
defaults (P2P1 on tetrahedra, Q2P1 on hexahedra) timed side by side with
:mod:`eyemech.problems.reference.plain_dolfinx_sphere`, which solves the same discrete
problem (same mesh, same elements, Newton with MUMPS LU, relative residual 1e-9, the
whole load in one step), so the errors match and the wall times compare. eyemech runs at
its defaults, which factor the P2P1 Jacobian with MUMPS LDLᵀ (docs/atlas/peer-comparison.md,
"Symmetric factorisation").

Wall time is that of the whole process, as a user meets it: ``eyemech run ... --no-fields
--no-pictures`` against ``python -m ...plain_dolfinx_sphere``, start-up and imports
included, with Python's bytecode cache on (a folder of the study's). Every case runs once
untimed first (compiled forms and bytecode in their caches, files in the page cache), then ``repeats`` times
alternating the two, one process at a time; the median is reported, of the wall time and of the CPU time
(user + system, the work done: less disturbed by other jobs on a shared machine). Each row records the
1-minute load average before and after its runs (the machine is shared) and the number of files in FFCx's
JIT cache folder: FFCx 0.11 lists that folder for every form it looks up (35 ms at 13,000 files), which
eyemech's run contract avoids (problems/run/jit_cache.py) and the plain script, as the DOLFINx demos
write it, pays once per form.
"""

from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mpi4py import MPI

from eyemech.problems import scenes
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import mark_failed, save_chart, with_units, write_csv

CASES = [("P2P1", 1.0), ("Q2P1", 1.0)]
QUICK_CASES = [("P2P1", 3.0)]


def _environment(bytecode: Path) -> dict[str, str]:
    """The processes' environment: Python's bytecode cache on, in ``bytecode``, as in a
    user's installation (with PYTHONDONTWRITEBYTECODE set, every import of a module that was
    not byte-compiled at installation, eyemech's editable sources among them, compiles it
    from source: 0.04 s more CPU for eyemech's imports, measured). Both processes alike."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = str(bytecode)
    return env


def _timed(command: list[str], env: dict[str, str]) -> tuple[float, float, dict]:
    """(wall seconds, CPU seconds (user + system), last JSON line) of one process. The CPU
    time is the work done, which the other jobs on a shared machine change less than the
    wall time (they take turns on the cores)."""
    cpu_before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, check=True, env=env)
    wall = time.perf_counter() - start
    cpu_after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (cpu_after.ru_utime - cpu_before.ru_utime) + (cpu_after.ru_stime - cpu_before.ru_stime)
    return wall, cpu, json.loads(done.stdout.strip().splitlines()[-1])


def _eyemech(element: str, mesh_size: float, out: Path, env: dict[str, str]) -> tuple[float, float, dict]:
    command = [str(Path(sys.executable).parent / "eyemech"), "run", "sphere-inflation",
               "--set", f"element={element}", "--set", f"mesh_size={mesh_size}", "--out", str(out),
               "--no-fields", "--no-pictures", "--quiet", "--checkpoint-every", "0", "--json"]
    wall, cpu, result = _timed(command, env)
    return wall, cpu, {"error": result["quantities"]["inner_radius_error"],
                       "newton": sum(step["newton_iterations"] for step in result["steps"])}


def _plain(element: str, mesh_size: float, env: dict[str, str]) -> tuple[float, float, dict]:
    command = [sys.executable, "-m", "eyemech.problems.reference.plain_dolfinx_sphere",
               "--element", element, "--mesh-size", str(mesh_size)]
    wall, cpu, result = _timed(command, env)
    return wall, cpu, {"error": result["inner_radius_error"], "newton": result["newton_iterations"],
                       "unknowns": result["unknowns"]}


def _jit_cache_files() -> int:
    folder = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "fenics"
    return sum(1 for _ in folder.iterdir()) if folder.is_dir() else 0


def _failed(case: dict, failure: subprocess.CalledProcessError) -> dict:
    """The row of a case whose process stopped with an error: status ``failed`` where its
    Newton gave up (eyemech: "solve failed", exit 3; the plain script: "SNES did not
    converge"), ``error`` otherwise, with the process's last line of stderr."""
    stderr = failure.stderr or ""
    solve = (failure.returncode == 3 and "solve failed" in stderr) or "SNES did not converge" in stderr
    last = next((line for line in reversed(stderr.splitlines()) if line.strip()), str(failure))
    who = "plain script" if "eyemech.problems.reference.plain_dolfinx_sphere" in failure.cmd \
        else "eyemech run"
    return {**case, "status": "failed" if solve else "error", "error": f"{who}: {last.strip()}"[:300]}


def compare(element: str, mesh_size: float, repeats: int) -> dict:
    """One case's row: status ok with the two processes' medians, or the row of
    :func:`_failed` (``eyemech study`` exits 4)."""
    load_before = os.getloadavg()[0]
    case = {"element": element, "mesh_size": mesh_size}
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder)
        env = _environment(out / "bytecode")
        try:
            _eyemech(element, mesh_size, out / "warm", env)
            _plain(element, mesh_size, env)
            ours, theirs = [], []
            for k in range(repeats):
                ours.append(_eyemech(element, mesh_size, out / f"run{k}", env))
                theirs.append(_plain(element, mesh_size, env))
        except subprocess.CalledProcessError as failure:
            return _failed(case, failure)
    wall_ours = statistics.median(w for w, _, _ in ours)
    wall_theirs = statistics.median(w for w, _, _ in theirs)
    cpu_ours = statistics.median(c for _, c, _ in ours)
    cpu_theirs = statistics.median(c for _, c, _ in theirs)
    return case | {"status": "ok", "unknowns": theirs[0][2]["unknowns"],
                   "error_eyemech": ours[0][2]["error"], "error_plain": theirs[0][2]["error"],
                   "newton_eyemech": ours[0][2]["newton"], "newton_plain": theirs[0][2]["newton"],
                   "wall_eyemech_s": round(wall_ours, 3), "wall_plain_s": round(wall_theirs, 3),
                   "ratio": round(wall_ours / wall_theirs, 3),
                   "cpu_eyemech_s": round(cpu_ours, 3), "cpu_plain_s": round(cpu_theirs, 3),
                   "cpu_ratio": round(cpu_ours / cpu_theirs, 3), "repeats": repeats,
                   "load_before": round(load_before, 2), "load_after": round(os.getloadavg()[0], 2),
                   "jit_cache_files": _jit_cache_files()}


def run(out: Path, quick: bool = False, comm=MPI.COMM_WORLD) -> list[Path]:
    if comm.size > 1:
        raise ValueError("peer-comparison times single processes: run it on one rank")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cases, repeats = (QUICK_CASES, 1) if quick else (CASES, 5)
    rows = [compare(element, h, repeats) for element, h in cases]
    # the scene's parameters looked up, not imported: _common.settings counts a study's scene
    # imports, and this table records none (sphere-inflation runs as a process)
    named = with_units(rows, scenes()["sphere-inflation"].parameters)
    csv = write_csv(out / "peer_comparison.csv", named,
                    f"sphere-inflation vs plain DOLFINx, process wall and CPU time, median of {repeats}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.2))
    labels = [f"{r['element']} h={r['mesh_size']:g}" for r in rows]
    x = range(len(rows))
    ok = [i for i in x if rows[i]["status"] == "ok"]
    ax.bar([i - 0.2 for i in ok], [rows[i]["wall_eyemech_s"] for i in ok], 0.4, label="eyemech run")
    ax.bar([i + 0.2 for i in ok], [rows[i]["wall_plain_s"] for i in ok], 0.4, label="plain DOLFINx script")
    mark_failed(ax, [i for i in x if i not in ok], "case failed")
    ax.set_xticks(list(x), labels)
    ax.set_ylabel("process wall time (s)")
    ax.set_title("sphere-inflation, same mesh and error")
    ax.legend(fontsize=8)
    chart = out / "peer_comparison.png"
    save_chart(fig, chart)
    return [csv, chart]


STUDY = Study(name="peer-comparison",
              summary="sphere-inflation wall time against a plain DOLFINx script on the same "
                      "mesh (matched error), P2P1 and Q2P1",
              run=run)
