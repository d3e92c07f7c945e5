"""Fields and pictures of the scleral-buckling scene: VTX for ParaView, a pyvista
series, and at each stage's end a view of the half eye coloured by von Mises stress and
a section through the buckle on the symmetry plane (which passes through the tear), with
the buckle's outline (:meth:`eyemech.forms.buckle.Buckle.outline`)."""

from __future__ import annotations

import math

from eyemech.problems.run.output import (
    add_legend,
    gather_grid,
    region_data,
    render_png,
    save_screenshot,
)


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

    def state(self, load: float, stage: int, name: str = "reference", picture: bool = False) -> None:
        """The state at path value ``load``, stage number ``stage`` (0: before any), named
        ``name`` in its pictures (drawn when ``picture``)."""
        if self.ctx.field_dir is None and not self.pictures:  # --no-fields --no-pictures
            return
        with self.ctx.timings("output"):
            self.vtx.write(load)
            tissues = self.model.tissues
            tissues.von_mises.update()
            mesh = self.model.eye.mesh
            cells = mesh.topology.index_map(3).size_local
            dofmap = tissues.von_mises.field.function_space.dofmap.list[:cells, 0]
            grid = gather_grid(self.model.u, cell_data={
                "von_mises (MPa)": tissues.von_mises.field.x.array[dofmap],
                "c": tissues.stiffness.x.array[dofmap],
                "tissue": region_data(self.model.eye.cell_tags, cells)})
            add_legend(grid, self.model.eye.names, mesh.topology.dim)
            self.series.write(load, grid)
            if picture and self.pictures:
                # the outline reads distributed unknowns (collective): every rank computes
                # it, only rank 0 (which holds the gathered grid) draws
                outline = self.model.buckle.outline()
                whole, section = self._picture_paths(stage, name)
                if grid is not None:
                    self._pictures(grid, stage, name, outline)
                # the names on every rank: the ranks' results agree (docs/parallel.md)
                self.ctx.result.pictures += [whole.name, section.name]

    def _picture_paths(self, stage: int, name: str):
        out = self.ctx.out
        return out / f"step{stage}_{name}_von_mises.png", out / f"step{stage}_{name}_section.png"

    def _pictures(self, grid, stage: int, name: str, outline) -> None:
        whole, section = self._picture_paths(stage, name)
        render_png(grid, whole, scalars="von_mises (MPa)", warp="displacement", camera=(0.6, 1.0, 0.35),
                   title=f"step {stage} ({name}): von Mises stress (MPa)", show_undeformed=False,
                   cmap="inferno")
        self._section(grid, section, f"step {stage} ({name}): section through the tear", outline)

    def _section(self, grid, path, title: str, outline) -> None:
        """The symmetry plane x = 0 seen from −x, zoomed on the buckle, with the
        buckle's outline drawn at its current position."""
        import pyvista

        from eyemech.problems.run.output import quiet_vtk

        quiet_vtk()
        buckle = self.model.buckle
        # a slice just inside the symmetry plane: the layers, the subretinal gap, the tear
        section = grid.slice(normal=(1.0, 0.0, 0.0), origin=(0.02, 0.0, 0.0))
        warped = section.warp_by_vector("displacement")
        plotter = pyvista.Plotter(off_screen=True, window_size=(1000, 800))
        plotter.add_mesh(warped, scalars="c", show_edges=True, cmap="tab10", log_scale=True,
                         scalar_bar_args={"title": "tissue c (MPa)"})
        if outline is not None:
            plotter.add_lines(outline, color="red", width=4)
        centre_y = self.model.geometry.sclera_radius * math.sin(math.radians(buckle.angle))
        plotter.camera.focal_point = (0.0, centre_y, buckle.axial_position)
        plotter.camera.position = (-30.0, centre_y, buckle.axial_position)
        plotter.camera.up = (0.0, 0.0, 1.0)
        plotter.camera.parallel_projection = True
        plotter.camera.parallel_scale = 6.0
        plotter.add_text(title, font_size=11)
        try:  # whole or not at all; a full disk names the picture
            save_screenshot(plotter, path)
        finally:
            plotter.close()

    def close(self) -> None:
        self.vtx.close()
        self.ctx.result.fields = self.earlier + self.vtx.files + self.series.files

