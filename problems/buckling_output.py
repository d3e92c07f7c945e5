"""Fields and pictures of the scleral-buckling scene: VTX for ParaView, a pyvista
series, and per step a view of the half eye coloured by von Mises stress and a
section through the buckle on the symmetry plane (which passes through the tear)."""

from __future__ import annotations

import math

import numpy as np

from eyemech.problems.run.output import (
    add_legend,
    gather_grid,
    region_data,
    render_png,
)

STAGE_NAMES = {0: "reference", 1: "IOP", 2: "buckling", 3: "suturing", 4: "settled"}


class Writer:
    def __init__(self, model, ctx):
        self.model, self.ctx = model, ctx
        folder = ctx.field_dir
        model.u.name = "displacement"
        # a resumed run starts a new VTX file (the old one keeps the steps before the
        # checkpoint: VTX cannot append); the .pvd series continues (docs/restart.md)
        resumed = ctx.checkpoints.resumed_from
        stem = "fields" if resumed is None else f"fields_from_{resumed.name}"
        self.earlier = sorted(p.name for p in folder.glob("fields*.bp")) \
            if resumed is not None and folder is not None else []
        self.vtx = ctx.field_writer([model.u], stem=stem, pvd=False)  # VTX on request
        self.series = ctx.pyvista_series()
        self.pictures = ctx.pictures
        ctx.checkpoints.value("pyvista_series", lambda: self.series.entries,
                              lambda saved: self.series.entries.__setitem__(
                                  slice(None), [tuple(e) for e in saved]))

    def state(self, load: float, stage: int, picture: bool = False) -> None:
        if self.ctx.field_dir is None and not self.pictures:  # --no-fields --no-pictures
            return
        with self.ctx.timings("output"):
            self.vtx.write(load)
            model = self.model
            model.von_mises.update()
            mesh = model.eye.mesh
            cells = mesh.topology.index_map(3).size_local
            dofmap = model.von_mises.field.function_space.dofmap.list[:cells, 0]
            grid = gather_grid(model.u, cell_data={
                "von_mises": model.von_mises.field.x.array[dofmap],
                "c": model.stiffness.x.array[dofmap],
                "tissue": region_data(model.eye.cell_tags, cells)})
            add_legend(grid, model.eye.names, mesh.topology.dim)
            self.series.write(load, grid)
            if picture and self.pictures:
                # the outline reads distributed unknowns (collective): every rank computes
                # it, only rank 0 (which holds the gathered grid) draws
                outline = _buckle_outline(model)
                if grid is not None:
                    self._pictures(grid, stage, outline)

    def _pictures(self, grid, stage: int, outline) -> None:
        name = STAGE_NAMES[stage]
        out = self.ctx.out
        whole = out / f"step{stage}_{name}_von_mises.png"
        render_png(grid, whole, scalars="von_mises", warp="displacement", camera=(0.6, 1.0, 0.35),
                   title=f"step {stage} ({name}): von Mises stress (MPa)", show_undeformed=False,
                   cmap="inferno")
        section = out / f"step{stage}_{name}_section.png"
        self._section(grid, section, f"step {stage} ({name}): section through the tear", outline)
        self.ctx.result.pictures += [whole.name, section.name]

    def _section(self, grid, path, title: str, outline) -> None:
        """The symmetry plane x = 0 seen from −x, zoomed on the buckle, with the
        buckle's outline drawn at its current position."""
        import pyvista

        from eyemech.problems.run.output import quiet_vtk

        quiet_vtk()
        model = self.model
        # a slice just inside the symmetry plane: the layers, the subretinal gap, the tear
        section = grid.slice(normal=(1.0, 0.0, 0.0), origin=(0.02, 0.0, 0.0))
        warped = section.warp_by_vector("displacement")
        plotter = pyvista.Plotter(off_screen=True, window_size=(1000, 800))
        plotter.add_mesh(warped, scalars="c", show_edges=True, cmap="tab10", log_scale=True,
                         scalar_bar_args={"title": "tissue c (MPa)"})
        if outline is not None:
            plotter.add_lines(outline, color="red", width=4)
        centre_y = model.geometry.sclera_radius * math.sin(math.radians(model.buckle_angle))
        plotter.camera.focal_point = (0.0, centre_y, model.axial_position)
        plotter.camera.position = (-30.0, centre_y, model.axial_position)
        plotter.camera.up = (0.0, 0.0, 1.0)
        plotter.camera.parallel_projection = True
        plotter.camera.parallel_scale = 6.0
        plotter.add_text(title, font_size=11)
        plotter.screenshot(str(path))
        plotter.close()

    def close(self) -> None:
        self.vtx.close()
        self.ctx.result.fields = self.earlier + self.vtx.files + self.series.files


def _buckle_outline(model):
    """The buckle's cross-section in the symmetry plane (x = −0.01, in front of the
    mesh), as a closed polyline; None before the buckle is placed. Collective: the
    tire's travel is a distributed unknown, so every rank must call it."""
    base = float(model.base_radius.value) - float(model.indentation.value)
    if base > 1.5 * model.geometry.sclera_radius:
        return None
    shape = model.params.buckle_shape()
    if shape.radial:
        return _radial_tire_outline(model, shape)
    z0 = model.axial_position
    polygons = []
    if shape.on_tire(0.0):  # the tire at the tear (at its own travel), the band over it
        tire = float(model.base_radius.value) - model.tire_travel_value()
        polygons.append([(tire, -shape.tire_width / 2), (tire + shape.tire_height, -shape.tire_width / 2),
                         (tire + shape.tire_height, shape.tire_width / 2), (tire, shape.tire_width / 2)])
        bottom = max(base, tire + shape.tire_height)
    else:
        bottom = base
    if shape.has_band:
        polygons.append([(bottom, -shape.band_width / 2),
                         (bottom + shape.band_thickness, -shape.band_width / 2),
                         (bottom + shape.band_thickness, shape.band_width / 2),
                         (bottom, shape.band_width / 2)])
    points = []
    for polygon in polygons:
        closed = polygon + polygon[:1]
        for a, b in zip(closed[:-1], closed[1:]):
            points += [(-0.01, a[0], z0 + a[1]), (-0.01, b[0], z0 + b[1])]
    return np.array(points)


def _radial_tire_outline(model, shape, segments: int = 24):
    """A radial tire's section in the symmetry plane: the annular sector between its
    inner face (at its travel) and its outer one, over its length along the meridian."""
    inner = float(model.base_radius.value) - model.tire_travel_value()
    angles = math.radians(model.buckle_angle) + shape.half_arc * np.linspace(-1.0, 1.0, segments + 1)
    ring = [(inner, t) for t in angles] + [(inner + shape.tire_height, t) for t in angles[::-1]]
    closed = ring + ring[:1]
    points = []
    for (ra, ta), (rb, tb) in zip(closed[:-1], closed[1:]):
        points += [(-0.01, ra * math.sin(ta), ra * math.cos(ta)), (-0.01, rb * math.sin(tb), rb * math.cos(tb))]
    return np.array(points)
