"""``plate-clamped``: square Kirchhoff plate, all edges clamped, uniform load — the
shell paper's bending test (E = 1.092e6, ν = 0.3, L = 10, h = 0.1: w = 0.1265 q).
Linear reference w = 0.00126532 q L⁴/D (Timoshenko & Woinowsky-Krieger, Table 35);
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
    return run_plate(SCENE.name, "clamped", params, comm, out, options, rerun=run)


SCENE = Scene(name="plate-clamped", kind="benchmark", parameters=Parameters, run=run,
              summary="clamped square plate under uniform load, Kirchhoff-Love shell (Timoshenko)")
