"""``iol-fold``: the lens folded into the cartridge (the fold itself:
:mod:`eyemech.problems.lens.fold`); its smallest self distance is reported and the folded
state is saved to ``folded_state.npz`` for ``iol-injection``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from mpi4py import MPI

from eyemech.problems.lens.fold import FoldParameters, fold, self_contact_kind
from eyemech.problems.lens.model import LensShell, save_state, write_animation
from eyemech.problems.lens.models import MODELS, Model
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.parameters import GEOMETRY, field
from eyemech.problems.run.scene import Scene


@dataclasses.dataclass(frozen=True)
class Parameters(FoldParameters):
    """The fold's parameters (:class:`eyemech.problems.lens.fold.FoldParameters`) and the model."""

    model: Model = field("p2-c0ip", "the lens model: " + " | ".join(MODELS) + " (the rotation-free P1 "
                                    "triangle of iol-speed: the same roll, chamber and ipctk self-contact on "
                                    "its vertices and triangles, the same pictures and .vtu frames)",
                         group=GEOMETRY)


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        if params.model == "p1-rotation-free":
            _run_rotation_free(ctx, params)
            return ctx.result
        with ctx.timings("mesh"):
            shell = LensShell(params, ctx.comm)
        pictures = ctx.out if ctx.pictures else None
        history = fold(params, ctx, shell, pictures)
        q = ctx.result.quantities
        distances = [d for d in history["self_distance"] if np.isfinite(d)]
        q.update(steps=history["steps"], steps_per_second=history["steps"] / history["wall"],
                 max_penetration_mm=float(max(history["penetration"], default=0.0)),
                 haptic_max_strain=float(max(history["strain"], default=0.0)),
                 min_self_distance_mm=float(min(distances)) if distances else None,
                 self_intersecting=bool(any(history["intersecting"])),
                 self_contact_forces=self_contact_kind(params), contact_seconds=history["contact_seconds"],
                 self_contact_seconds=getattr(history["self_contact"], "seconds", 0.0),
                 ccd_limited_updates=len(getattr(history["self_contact"], "step_limits", [])),
                 triangles=shell.mesh.topology.index_map(2).size_global,
                 nodes=shell.mesh.geometry.index_map().size_global, dofs=shell.dofs(),
                 **history["time_error"])
        if ctx.out is not None:
            save_state(ctx.out / "folded_state.npz", shell, ctx.comm)
            ctx.result.fields.append("folded_state.npz")
            ctx.result.fields.extend(history["series"].files)
            if pictures is not None and ctx.rank0 and history["frames"]:
                ctx.result.pictures += [p.name for p in history["frames"]]
                gif = write_animation(history["frames"], ctx.out / "fold.gif")
                if gif:
                    ctx.result.pictures.append(gif)
    return ctx.result


def _run_rotation_free(ctx: RunContext, params: Parameters) -> None:
    """The fold on the P1 lens; its folded_state.npz (the vertices') starts
    ``iol-injection --set model=p1-rotation-free``."""
    from eyemech.problems.lens import fast_injection
    from eyemech.problems.lens.fast_frames import FrameWriter

    lens = fast_injection.fast_lens(ctx, params)
    frames = FrameWriter(ctx, lens, stem="fold", picture_stem="fold")
    with ctx.timings("time_stepping"):
        folded, history = fast_injection.fold(params, lens, ctx.record_step, frames)
    ctx.result.quantities.update(model=params.model, **fast_injection.quantities(history, params),
                                 triangles=len(lens.shell.tri), nodes=len(lens.shell.X),
                                 dofs=lens.shell.n_dofs)
    if ctx.out is not None and ctx.rank0:
        fast_injection.save_state(ctx.out / "folded_state.npz", lens, folded)
        ctx.result.fields.append("folded_state.npz")
        frames.finish("fold.gif")


SCENE = Scene(name="iol-fold", kind="scene", parameters=Parameters, run=run,
              summary="intra-ocular lens rolled about the injector axis while the loading chamber "
                      "closes on its haptics (damped quasi-static, saves the folded state)")
