"""The nonlinear pinched hemisphere (``hemisphere-nonlinear``) against the load–deflection
table of Sze, Liu & Lo, Finite Elem. Anal. Des. 40 (2004) 1551–1569, problem 3.4:
radial displacement of the point pulled outward and of the point pushed inward for
P = 0 … 400 (each point load on the whole shell), on 8 and 16 divisions, P2. The default
mesh (``cells_per_bending_length`` 1.6: 32 divisions, 125,000 unknowns) takes over 40 min
for the path here and is left out.

The P2 faceted shell locks in membrane on coarse meshes (the linear hemisphere is
−23 % at 8 divisions, −2 % at 16): the chart shows how much of that survives at
large deflection.

A second thickness, h = 0.2 (R/h = 50; Sze's table is for h = 0.04 alone), at
P = 12,500 (Sze's P = 100 × (0.2/0.04)³: the bending-scaled load of a quarter of the
path), on a sequence of cells per bending length (× 1.5), against the Richardson value
of the three (observed order): the same model's mesh-converged answer.

A path that reaches its last load gives its steps as rows with status ok; one whose solve
fails gives one row (its divisions, the load it was to reach as ``force_N``) with status
failed and the message as ``error``, crossed at the chart's origin, and ``eyemech study``
exits 4; a thick case that fails is a failed row of the second table.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from eyemech.problems import hemisphere_nonlinear as scene
from eyemech.problems.run.error_estimate import extrapolate
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import (
    QUIET,
    failed_row,
    save_chart,
    with_units,
    write_csv,
)

SZE_DIVISIONS = (8, 16)
THICK = 0.2
THICK_FORCE = 100.0 * (THICK / 0.04) ** 3
THICK_RESOLUTIONS = (1.6 / 1.5, 1.6, 1.6 * 1.5)
THICK_LOAD_STEPS = 4
QUICK_THICK_RESOLUTIONS = (0.5, 0.75)


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    if comm.rank != 0:  # serial study: rank 0 does the work
        return []
    meshes = [4] if quick else SZE_DIVISIONS
    force = 40.0 if quick else scene.SZE_MAX_FORCE
    rows = []
    for divisions in meshes:
        params = scene.Parameters(divisions=divisions, force=force,
                                  load_steps=round(20 * force / scene.SZE_MAX_FORCE))
        try:
            result = scene.run(params, comm=MPI.COMM_SELF, options=QUIET)
        except SolveFailure as failure:  # a path that did not reach P: one row that says so (exit 4)
            rows.append(failed_row(dict(divisions=divisions, force=force), failure))
            continue
        for step in result.steps:  # a path that reached P: its load steps, a row each
            rows.append(dict(divisions=divisions, force=step["force"], status="ok",
                             dofs=result.quantities["dofs"],
                             outward=step["radial_displacement_x"], inward=step["radial_displacement_y"],
                             outward_sze=step["radial_displacement_x_sze"],
                             inward_sze=step["radial_displacement_y_sze"],
                             newton_iterations=step["newton_iterations"]))
    csv_path = write_csv(out / "shell_hemisphere_nonlinear.csv", with_units(rows, scene.Parameters),
                         "pinched hemisphere R 10, h 0.04, E 6.825e7, nu 0.3, P2 crossed, whole shell; "
                         "displacements radial, inward positive for the pushed point",
                         "reference: Sze, Liu & Lo (2004) problem 3.4 table")
    thick = thick_rows(QUICK_THICK_RESOLUTIONS if quick else THICK_RESOLUTIONS)
    thick_path = write_csv(out / "shell_hemisphere_thick.csv", with_units(thick, scene.Parameters),
                           f"h = {THICK}, P = {THICK_FORCE:g} in {THICK_LOAD_STEPS} load steps; "
                           "reference: Richardson from the three resolutions (observed order)")
    return [csv_path, thick_path, _chart(out, rows)]


def thick_rows(resolutions) -> list[dict]:
    """The thick shell on each resolution, and every row's error against the Richardson
    value of the finest three (:func:`richardson_references`)."""
    rows = []
    for resolution in resolutions:
        params = scene.Parameters(thickness=THICK, force=THICK_FORCE, load_steps=THICK_LOAD_STEPS,
                                  cells_per_bending_length=resolution)
        try:
            result = scene.run(params, comm=MPI.COMM_SELF, options=QUIET)
        except SolveFailure as failure:
            rows.append(failed_row(dict(cells_per_bending_length=resolution), failure))
            continue
        q = result.quantities
        rows.append(dict(cells_per_bending_length=resolution, status="ok", divisions=q["divisions"],
                         dofs=q["dofs"], outward=q["radial_displacement_x"],
                         inward=q["radial_displacement_y"],
                         newton_iterations=result.solver_counts["newton_iterations_all"]))
    richardson_references(rows, ("outward", "inward"))
    return rows


def richardson_references(rows: list[dict], keys) -> None:
    """For each quantity: the value extrapolated from the finest three rows (sizes ∝
    1/divisions, :func:`extrapolate`), and every row's error against it
    (``<key>_reference``, ``<key>_order``, ``<key>_error``)."""
    ok = [r for r in rows if r["status"] == "ok"]
    if len(ok) < 2:
        return
    for key in keys:
        reference, order = extrapolate([r[key] for r in ok], [1.0 / r["divisions"] for r in ok])
        for row in ok:
            row |= {f"{key}_reference": reference, f"{key}_order": order,
                    f"{key}_error": row[key] / reference - 1.0}


def _chart(out: Path, rows: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axis = plt.subplots(figsize=(6.4, 4.6))
    fractions = np.array(scene.SZE_LOAD_FRACTION)
    axis.plot(scene.SZE_OUTWARD, fractions * scene.SZE_MAX_FORCE, "ks", mfc="none",
              label="Sze et al. 2004, pulled point (outward)")
    axis.plot(scene.SZE_INWARD, fractions * scene.SZE_MAX_FORCE, "k^", mfc="none",
              label="Sze et al. 2004, pushed point (inward)")
    for divisions in sorted({r["divisions"] for r in rows}):
        mine = [r for r in rows if r["divisions"] == divisions]
        if mine[0]["status"] != "ok":  # its path did not reach P: a cross at the origin
            axis.plot([0], [0], "x", color="tab:red", ms=10, mew=2, clip_on=False,
                      label=f"P2, {divisions} div.: solve failed")
            continue
        force = [0.0] + [r["force"] for r in mine]
        dofs = mine[0]["dofs"]
        line, = axis.plot([0.0] + [r["outward"] for r in mine], force, "-",
                          label=f"P2, {divisions} div. ({dofs} dofs), outward")
        axis.plot([0.0] + [r["inward"] for r in mine], force, "--", color=line.get_color(),
                  label=f"P2, {divisions} div., inward")
    linear = np.array([0.0, 4.5])
    axis.plot(linear, linear / 0.0465, ":", color="grey", label="linear shell (0.0465 P)")
    axis.set(xlabel="radial displacement at the load (mm)", ylabel="P, each point load (N)",
             title="pinched hemisphere, large deflection", ylim=(0, 420), xlim=(0, 9))
    axis.legend(fontsize=7, loc="lower right")
    path = out / "shell_hemisphere_nonlinear.png"
    save_chart(fig, path, dpi=110)
    return path


STUDY = Study(name="shell-hemisphere", summary="nonlinear pinched hemisphere: load–deflection curve "
                                               "against Sze, Liu & Lo (2004) on three meshes; a second "
                                               "thickness against its converged value", run=run)
