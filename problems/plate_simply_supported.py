"""``plate-simply-supported``: square Kirchhoff plate, simply supported (w = 0,
rotation free, immovable in-plane), uniform load.
Linear reference w = 0.00406235 q L⁴/D (Timoshenko & Woinowsky-Krieger, Table 8);
``kinematics=nonlinear`` adds membrane stiffening at deflections beyond ~h/2."""

from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.scene import Scene
from eyemech.problems.shell.model import PlateParameters, run_plate

Parameters = PlateParameters


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    return run_plate(SCENE.name, "simply-supported", params, comm, out, options, rerun=run)


SCENE = Scene(name="plate-simply-supported", kind="benchmark", parameters=Parameters, run=run,
              summary="simply supported square plate under uniform load, "
                      "Kirchhoff-Love shell (Timoshenko)")
