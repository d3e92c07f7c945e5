"""The nonlinear pinched hemisphere (``hemisphere-nonlinear``) against the load–deflection
table of Sze, Liu & Lo, Finite Elem. Anal. Des. 40 (2004) 1551–1569, problem 3.4:
radial displacement of the point pulled outward and of the point pushed inward for
P = 0 … 400 (each point load on the whole shell), on two meshes, P2.

The P2 faceted shell locks in membrane on coarse meshes (the linear hemisphere is
−23 % at 8 divisions, −2 % at 16): the chart shows how much of that survives at
large deflection.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from eyemech.problems import hemisphere_nonlinear as scene
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, save_chart, write_csv


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    if comm.rank != 0:  # serial study: rank 0 does the work
        return []
    meshes = [4] if quick else [8, 16]
    force = 40.0 if quick else scene.SZE_MAX_FORCE
    rows = []
    for divisions in meshes:
        params = scene.Parameters(divisions=divisions, force=force,
                                  load_steps=round(20 * force / scene.SZE_MAX_FORCE))
        result = scene.run(params, comm=MPI.COMM_SELF, options=QUIET)
        for step in result.steps:
            rows.append(dict(divisions=divisions, dofs=result.quantities["dofs"], force=step["force"],
                             outward=step["radial_displacement_x"], inward=step["radial_displacement_y"],
                             outward_sze=step["radial_displacement_x_sze"],
                             inward_sze=step["radial_displacement_y_sze"],
                             newton_iterations=step["newton_iterations"]))
    csv_path = write_csv(out / "shell_hemisphere_nonlinear.csv", rows,
                         "pinched hemisphere R 10, h 0.04, E 6.825e7, nu 0.3, P2 crossed, whole shell; "
                         "displacements radial, inward positive for the pushed point",
                         "reference: Sze, Liu & Lo (2004) problem 3.4 table")
    return [csv_path, _chart(out, rows)]


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
                                               "against Sze, Liu & Lo (2004), two meshes", run=run)
