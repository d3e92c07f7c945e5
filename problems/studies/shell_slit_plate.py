"""The slit annular plate (``slit-annular-plate``) off its defaults: Sze, Liu & Lo's plate
(h = 0.03) to q_max on three meshes against their table at every load level, and a
second thickness with another load against the same model's mesh-converged answer.

- **sze**: 32 × 4 and 48 × 6 (the default) squares, P2 crossed, the load path landing on
  the table's levels q/q_max = 0.025 … 1; per level the deflections of the loaded edge's
  inner (A) and outer (B) points, Sze's values, and the value extrapolated from the two
  meshes (order 2). The full path on 72 × 9 costs ≈ 15 min here and is left out.
- **thick**: h = 0.06 at q = 3.2 (Sze's 0.4 × (0.06/0.03)³: the bending-scaled load of
  half the path; no published curve for this plate) on 32 × 4, 48 × 6 and 72 × 9 (× 1.5),
  against their Richardson value (observed order).

Sze et al. (2004) table 4 as copied in Project Chrono's demo (see the scene).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from eyemech.problems import slit_annular_plate as scene
from eyemech.problems.run.error_estimate import extrapolate
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, save_chart, with_units, write_csv

MESHES = ((32, 4), (48, 6), (72, 9))
SZE_MESHES = MESHES[:2]
THICK = 0.06
THICK_LINE_LOAD = 0.4 * (THICK / 0.03) ** 3
THICK_LOAD_STEPS = 8
QUICK_MESHES = ((8, 1), (12, 2))
QUICK_LINE_LOAD = 0.08


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    if comm.rank != 0:  # serial study: rank 0 does the work
        return []
    line_load = QUICK_LINE_LOAD if quick else scene.SZE_MAX_LINE_LOAD
    sze = sze_rows(QUICK_MESHES if quick else SZE_MESHES, line_load)
    thick = thick_rows(QUICK_MESHES if quick else MESHES)
    files = [write_csv(out / "shell_slit_plate.csv", with_units(sze, scene.Parameters),
                       "slit annular plate, Sze's h = 0.03; deflection_a inner, deflection_b outer point",
                       "reference: Sze, Liu & Lo (2004) table 4; extrapolated: Richardson of the meshes"),
             write_csv(out / "shell_slit_plate_thick.csv", with_units(thick, scene.Parameters),
                       f"h = {THICK}, q = {THICK_LINE_LOAD:g} in {THICK_LOAD_STEPS} load steps; "
                       "reference: Richardson from the meshes (observed order)")]
    files.append(_chart(out / "shell_slit_plate.png", sze))
    return files


def _solve(**changes):
    try:
        return scene.run(scene.Parameters(**changes), comm=MPI.COMM_SELF, options=QUIET), None
    except SolveFailure as failure:
        return None, str(failure)[:200]


def sze_rows(meshes, line_load: float) -> list[dict]:
    rows = []
    for around, across in meshes:
        result, failure = _solve(divisions=around, radial_divisions=across, line_load=line_load)
        if result is None:
            rows.append(dict(divisions=around, radial_divisions=across, status="failed", error=failure))
            continue
        for step in result.steps:
            rows.append(dict(divisions=around, radial_divisions=across, status="ok",
                             dofs=result.quantities["dofs"], line_load=step["line_load"],
                             deflection_a=step["deflection_a"], deflection_b=step["deflection_b"],
                             deflection_a_sze=step["deflection_a_sze"],
                             deflection_b_sze=step["deflection_b_sze"],
                             newton_iterations=step["newton_iterations"]))
    _extrapolate_levels(rows)
    return rows


def _extrapolate_levels(rows: list[dict]) -> None:
    """At every load level reached by all meshes: the extrapolated deflections."""
    ok = [r for r in rows if r["status"] == "ok"]
    meshes = {r["divisions"] for r in ok}
    for load in {round(r["line_load"], 9) for r in ok}:
        level = [r for r in ok if round(r["line_load"], 9) == load]
        if len(level) != len(meshes) or len(level) < 2:
            continue
        for key in ("deflection_a", "deflection_b"):
            value, _ = extrapolate([r[key] for r in level], [1.0 / r["divisions"] for r in level])
            for row in level:
                row[f"{key}_extrapolated"] = value


def thick_rows(meshes) -> list[dict]:
    rows = []
    for around, across in meshes:
        result, failure = _solve(divisions=around, radial_divisions=across, thickness=THICK,
                                 line_load=THICK_LINE_LOAD, load_steps=THICK_LOAD_STEPS)
        if result is None:
            rows.append(dict(divisions=around, radial_divisions=across, status="failed", error=failure))
            continue
        q = result.quantities
        rows.append(dict(divisions=around, radial_divisions=across, status="ok", dofs=q["dofs"],
                         deflection_a=q["deflection_a"], deflection_b=q["deflection_b"],
                         newton_iterations=result.solver_counts["newton_iterations_all"]))
    ok = [r for r in rows if r["status"] == "ok"]
    if len(ok) >= 2:
        for key in ("deflection_a", "deflection_b"):
            reference, order = extrapolate([r[key] for r in ok], [1.0 / r["divisions"] for r in ok])
            for row in ok:
                row |= {f"{key}_reference": reference, f"{key}_order": order,
                        f"{key}_error": row[key] / reference - 1.0}
    return rows


def _chart(path: Path, rows: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axis = plt.subplots(figsize=(6.4, 4.6))
    fractions = np.array(scene.SZE_LOAD_FRACTION) * scene.SZE_MAX_LINE_LOAD
    axis.plot(scene.SZE_W_A, fractions, "ks", mfc="none", label="Sze et al. 2004, W_A (inner)")
    axis.plot(scene.SZE_W_B, fractions, "k^", mfc="none", label="Sze et al. 2004, W_B (outer)")
    for around in sorted({r["divisions"] for r in rows if r["status"] == "ok"}):
        mine = [r for r in rows if r["divisions"] == around and r["status"] == "ok"]
        load = [0.0] + [r["line_load"] for r in mine]
        line, = axis.plot([0.0] + [r["deflection_a"] for r in mine], load, "-",
                          label=f"P2, {around} × {mine[0]['radial_divisions']} ({mine[0]['dofs']} dofs), W_A")
        axis.plot([0.0] + [r["deflection_b"] for r in mine], load, "--", color=line.get_color(),
                  label=f"{around} × {mine[0]['radial_divisions']}, W_B")
    axis.set(xlabel="vertical deflection (mm)", ylabel="line load q (N/mm)",
             title="slit annular plate, large deflection")
    axis.legend(fontsize=7, loc="lower right")
    save_chart(fig, path, dpi=110)
    return path


STUDY = Study(name="shell-slit-plate",
              summary="slit annular plate: load-deflection against Sze, Liu & Lo (2004) on two meshes; "
                      "a second thickness against its converged value", run=run)
