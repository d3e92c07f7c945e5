"""PNG frames and ``.vtu`` series of the P1 lens scenes (``iol-fold`` and ``iol-injection`` with
``model=p1-rotation-free``): the P2 scenes' pictures (``model.render_grid``, the same camera and
walls) and frames (``<stem>.pvd`` + one ``.vtu`` per frame, what notebooks read with
``pyvista.read``), drawn from the P1 vertices and triangles. Each frame holds the displacement
per vertex and, per triangle, the thickness, the part (1 optic, 0 haptic) and the largest
surface strain (``fast_injection.cell_surface_strain``), the P2 frames' fields."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from eyemech.problems.lens.model import render_grid, write_animation
from eyemech.problems.lens.rotation_free import FastLens


def lens_grid(lens: FastLens, u: np.ndarray, surface_strain: np.ndarray):
    """The P1 lens in its reference position as a pyvista grid with the frame's fields."""
    import pyvista

    tri = lens.shell.tri
    cells = np.hstack([np.full((len(tri), 1), 3), tri]).ravel()
    grid = pyvista.UnstructuredGrid(cells, np.full(len(tri), pyvista.CellType.TRIANGLE, dtype=np.uint8),
                                    lens.shell.X.copy())
    grid.point_data["displacement"] = u.reshape(-1, 3)
    part = np.zeros(len(tri))
    part[lens.optic_triangles] = 1.0
    grid.cell_data["thickness (mm)"] = lens.shell.thickness
    grid.cell_data["optic"] = part
    grid.cell_data["surface strain"] = surface_strain
    return grid


class FrameWriter:
    """The frames of one P1 run: a ``.vtu`` per frame under ``ctx``'s field folder (none under
    ``--no-fields``) and a PNG per frame in the output folder (none under ``--no-pictures``)."""

    def __init__(self, ctx, lens: FastLens, stem: str, picture_stem: str):
        self.ctx, self.lens, self.picture_stem = ctx, lens, picture_stem
        self.series = ctx.pyvista_series(stem=stem)
        self.pictures = ctx.out if ctx.pictures and ctx.rank0 else None
        self.frames: list[Path] = []
        self.seconds = 0.0  # wall time spent drawing and writing frames

    @property
    def active(self) -> bool:
        return self.series.out is not None or self.pictures is not None

    def write(self, at: float, u: np.ndarray, title: str, obstacles: dict) -> None:
        """The frame at simulated time ``at``: the lens at displacement u, the rigid ``obstacles``
        drawn as wireframes."""
        if not self.active:
            return
        from eyemech.problems.lens.fast_injection import cell_surface_strain

        begin = time.perf_counter()
        strain = cell_surface_strain(self.lens, u, np.arange(len(self.lens.shell.tri)))
        grid = lens_grid(self.lens, u, strain)
        with self.ctx.timings("output"):
            self.series.write(at, grid)
            if self.pictures is not None:
                path = self.pictures / f"{self.picture_stem}_{len(self.frames):03d}.png"
                render_grid(grid.warp_by_vector("displacement"), path, title, obstacles)
                self.frames.append(path)
        self.seconds += time.perf_counter() - begin

    def finish(self, gif: str) -> None:
        """The series' index among the result's fields, the PNGs and their animation ``gif``
        among its pictures."""
        result = self.ctx.result
        result.fields.extend(self.series.files)
        if self.frames:
            result.pictures += [p.name for p in self.frames]
            animation = write_animation(self.frames, self.ctx.out / gif)
            if animation:
                result.pictures.append(animation)
