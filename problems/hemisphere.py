"""``hemisphere``: the pinched hemisphere with an 18° hole of the shell obstacle course
(MacNeal & Harder 1985): radius 10, h = 0.04, E = 6.825e7, ν = 0.3, free edges, four
radial point loads on the equator, outward at ±x and inward at ±y. Reference radial
displacement under the loads ≈ 0.093 (MacNeal & Harder give 0.094; converged thin-shell
values are 0.0924–0.093). Load 2 per point on the whole shell (= 1 on the usual quarter).

The whole hemisphere is meshed. The rigid motions are removed by conditions that the
symmetric loading satisfies anyway: u_x = 0 on the plane x = 0, u_y = 0 on y = 0, and
u_z = 0 at one node of the equator.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from mpi4py import MPI

from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.scene import Scene
from eyemech.problems.shell.hemisphere import (
    REFERENCE,
    HemisphereParameters,
    run_hemisphere,
)

__all__ = ["REFERENCE", "Parameters", "SCENE", "run"]


@dataclasses.dataclass(frozen=True)
class Parameters(HemisphereParameters):
    """The linear benchmark's parameters (:class:`eyemech.problems.shell.hemisphere.HemisphereParameters`)."""


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    return run_hemisphere(SCENE.name, params, comm, out, options, rerun=run)


SCENE = Scene(name="hemisphere", kind="benchmark", parameters=Parameters, run=run,
              summary="pinched hemisphere with an 18° hole, four radial point loads (reference 0.093)")
