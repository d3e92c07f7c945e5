"""Fields and pictures of the scleral-buckling scene: VTX for ParaView, a pyvista
series, and at each stage's end a view of the half eye coloured by von Mises stress, with
the buckle's band and tire (translucent, at their travels), the sutures, where the tear
lies, a 5 mm scale and the anterior and outside directions; and a section through the
buckle on the symmetry plane (which passes through the tear), with the buckle's outline
(:meth:`eyemech.forms.buckle.Buckle.outline`)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from eyemech.forms.buckle import Buckle
from eyemech.problems.run.output import (
    PointLabels,
    add_legend,
    gather_grid,
    region_data,
    render_png,
    save_screenshot,
)
from eyemech.problems.scleral_buckling.error_estimate import RIM_GAP
from eyemech.problems.scleral_buckling.measures import rim_verdict


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

    def state(self, load: float, stage: int, name: str = "reference", picture: bool = False,
              measured: dict | None = None) -> None:
        """The state at path value ``load``, stage number ``stage`` (0: before any), named
        ``name`` in its pictures (drawn when ``picture``; ``measured``: the stage's
        measurements, whose rim gap and IOP the section's title states)."""
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
                "von_mises": tissues.von_mises.field.x.array[dofmap],
                "c": tissues.stiffness.x.array[dofmap],
                "tissue": region_data(self.model.eye.cell_tags, cells)})
            add_legend(grid, self.model.eye.names, mesh.topology.dim)
            self.series.write(load, grid)
            if picture and self.pictures:
                # the buckle's travels are distributed unknowns and the sutures' anchors
                # read them (collective): every rank computes them, only rank 0 (which
                # holds the gathered grid) draws
                placed = self.model.buckle.at_travel()
                outline = None if placed is None else placed[0].outline(placed[1])
                marks = self._marks() | {"buckle": placed}
                whole, section = self._picture_paths(stage, name)
                if grid is not None:
                    self._pictures(grid, stage, name, outline, marks, measured or {})
                # the names on every rank: the ranks' results agree (docs/parallel.md)
                self.ctx.result.pictures += [whole.name, section.name]

    def _picture_paths(self, stage: int, name: str):
        out = self.ctx.out
        return out / f"step{stage}_{name}_von_mises.png", out / f"step{stage}_{name}_section.png"

    def _marks(self) -> dict:
        """What the pictures mark, from values every rank holds (collective): the tear
        rim's nodes (global numbers); every suture's bites (azimuth, side, centre) and
        where each leaves the buckle (``sutures``); and, on the section's meridian, those
        bites' centres and anchors."""
        sutures = self.model.sutures
        anchors = np.asarray(sutures.anchors()).reshape(-1, 3)
        in_plane = [k for k, bite in enumerate(sutures.bites) if abs(bite[0]) < 1e-9]
        gaps = self.model.gaps
        rim = gaps.rim_nodes() if gaps.pairing is not None else np.zeros(0, dtype=np.int64)
        return {"rim": rim, "bites": np.array([sutures.bites[k][2] for k in in_plane]).reshape(-1, 3),
                "anchors": anchors[in_plane], "sutures": (list(sutures.bites), anchors)}

    def _pictures(self, grid, stage: int, name: str, outline, marks: dict, measured: dict) -> None:
        whole, section = self._picture_paths(stage, name)
        parameters = dataclasses.asdict(self.model.params)
        # the picture's bar names the quantity and its unit; the fields keep the name
        # notebooks read
        grid.cell_data[VON_MISES_BAR] = grid.cell_data["von_mises"]
        title = f"step {stage} ({name}): von Mises stress (MPa)"
        render_png(grid, whole, scalars=VON_MISES_BAR, warp="displacement", camera=(0.6, 1.0, 0.35),
                   title=title, show_undeformed=False, cmap="inferno", scene=SCENE_NAME,
                   parameters=parameters, extras=_eye_extras(grid, marks), legend=True,
                   scale_bar_mm=5.0, directions=DIRECTIONS)
        self._section(grid, section, _section_title(stage, name, measured), outline, marks, parameters)

    def _section(self, grid, path, title: str, outline, marks: dict, parameters: dict) -> None:
        """The symmetry plane x = 0 (the tear's meridian) seen from −x, zoomed on the
        buckle: the tissues by name, the buckle's outline, the tear's rim, the sutures
        that lie in the plane, a 2 mm scale and which way is anterior and outside."""
        import pyvista

        from eyemech.problems.run.output import quiet_vtk, tag_picture

        quiet_vtk()
        buckle = self.model.buckle
        # a slice just inside the symmetry plane: the layers, the subretinal gap, the tear
        section = grid.slice(normal=(1.0, 0.0, 0.0), origin=(0.02, 0.0, 0.0))
        warped = section.warp_by_vector("displacement")
        names = dict(zip(grid.field_data["tissue_tags"].tolist(), grid.field_data["tissue_names"].tolist()))
        shown = sorted(set(np.asarray(warped.cell_data["tissue"]).tolist()) & set(names))
        # tissues as categories: each tag its colour and its name in the legend
        warped.cell_data["tissue_index"] = np.searchsorted(shown, warped.cell_data["tissue"])
        plotter = pyvista.Plotter(off_screen=True, window_size=(1000, 800))
        plotter.add_mesh(warped, scalars="tissue_index", show_edges=True, cmap="tab10",
                         n_colors=max(len(shown), 1), show_scalar_bar=False)
        plotter.add_legend([(names[tag].replace("_", " "), color) for tag, color in
                            zip(shown, _category_colors(len(shown)))], bcolor="white",
                           size=(0.2, 0.035 * len(shown) + 0.02), loc="lower left")
        if outline is not None:
            plotter.add_lines(outline, color="red", width=4, label="buckle")
        moved = grid.points + grid.point_data["displacement"]
        in_front = -1.0  # overlays between the camera (at x = −30) and the section
        rim = moved[marks["rim"]]
        rim = rim[np.abs(grid.points[marks["rim"], 0]) < 0.3]  # the rim's nodes on the section
        if len(rim):
            plotter.add_points(_onto(rim, in_front), color="yellow", point_size=14,
                               render_points_as_spheres=True)
            plotter.add_point_labels(_onto(rim[:1], in_front), ["tear's rim"], font_size=14,
                                     shape_opacity=0.6, always_visible=True)
        if len(marks["bites"]):
            nearest = np.argmin(np.linalg.norm(grid.points[None] - marks["bites"][:, None], axis=2), axis=1)
            bites = _onto(moved[nearest], in_front)
            plotter.add_points(bites, color="limegreen", point_size=12, render_points_as_spheres=True)
            for bite, anchor in zip(bites, _onto(marks["anchors"], in_front)):
                plotter.add_lines(np.array([bite, anchor]), color="limegreen", width=3)
            plotter.add_point_labels(bites[:1], ["suture"], font_size=14, shape_opacity=0.6,
                                     always_visible=True)
        centre_y = self.model.geometry.sclera_radius * math.sin(math.radians(buckle.angle))
        _scale_and_directions(plotter, (in_front, centre_y - 3.5, buckle.axial_position - 5.3))
        plotter.camera.focal_point = (0.0, centre_y, buckle.axial_position)
        plotter.camera.position = (-30.0, centre_y, buckle.axial_position)
        plotter.camera.up = (0.0, 0.0, 1.0)
        plotter.camera.parallel_projection = True
        plotter.camera.parallel_scale = 6.0
        plotter.add_text(title, font_size=11)
        try:
            save_screenshot(plotter, Path(path),
                            lambda tmp: tag_picture(tmp, SCENE_NAME, parameters, title))
        finally:
            plotter.close()

    def close(self) -> None:
        self.vtx.close()
        self.ctx.result.fields = self.earlier + self.vtx.files + self.series.files



SCENE_NAME = "scleral-buckling"
VON_MISES_BAR = "von Mises stress (MPa)"
# the von Mises picture's arrows: the optic axis towards the cornea, and the way the tear's
# meridian leaves it (the section's "outside")
DIRECTIONS = {"anterior": (0.0, 0.0, 1.0), "outside (at the tear)": (0.0, 1.0, 0.0)}
BAND_STYLE = {"color": "gray", "opacity": 0.45, "label": "encircling band"}
TIRE_STYLE = {"color": "lightslategray", "opacity": 0.55, "label": "silicone tire"}
SUTURE_COLOR = "limegreen"


def buckle_surfaces(buckle: Buckle, tire_travel: float, resolution: int = 72) -> list:
    """The buckle's elements over the half model (x >= 0) as closed pyvista surfaces,
    (surface, add_mesh keywords) pairs, at their travels: each element's cross-section
    in the symmetry plane (``section``, the section picture's outline) swept as the
    element is -- band and circumferential tire revolved about the optic axis over their
    azimuths (the band over the tire's arc at the tire's top, beyond it at its own
    travel), a radial tire (a ring about x) extruded across the meridian to x = w/2."""
    import pyvista

    def polygon(segments) -> pyvista.PolyData:
        points = np.array(segments[::2], dtype=float)  # each segment's start: the vertices
        points[:, 0] = 0.0  # on the symmetry plane itself
        return pyvista.PolyData(points, faces=np.r_[len(points), np.arange(len(points))])

    def revolved(section, start: float, stop: float) -> pyvista.PolyData:
        """``section`` (at azimuth 0, +y) swept from ``start`` to ``stop`` (rad, towards +x)."""
        swept = polygon(section).extrude_rotate(resolution=max(int(resolution * (stop - start) / math.pi), 2),
                                                angle=math.degrees(stop - start), capping=True,
                                                rotation_axis=(0.0, 0.0, -1.0))
        return swept.rotate_z(-math.degrees(start), inplace=False) if start else swept

    surfaces, tire_arc, tire_top = [], 0.0, -math.inf
    for part in buckle.parts:  # the tire first
        if part.is_tire:
            section, tire_top = part.section(tire_travel, -math.inf)
            if part.axis == 0:  # radial: a ring about x
                body = polygon(section).extrude((0.5 * part.width, 0.0, 0.0), capping=True)
            else:
                tire_arc = min(part.shape.half_arc, math.pi)
                body = revolved(section, 0.0, tire_arc)
            surfaces.append((body, TIRE_STYLE))
        else:  # the band, over the tire where it lies
            pieces = []
            if tire_arc > 0.0:
                pieces.append(revolved(part.section(tire_travel, tire_top)[0], 0.0, tire_arc))
            if tire_arc < math.pi:
                pieces.append(revolved(part.section(tire_travel, -math.inf)[0], tire_arc, math.pi))
            surfaces.append((pieces[0].append_polydata(*pieces[1:]), BAND_STYLE))
    return surfaces


def _eye_extras(grid, marks: dict) -> list:
    """What the von Mises picture draws on the deformed half eye besides the stress
    (:func:`render_png`'s extras): the buckle (:func:`buckle_surfaces`; none before it is
    placed), each suture's bites as green beads on the sclera joined over the buckle
    through where they leave it, a label where the tear lies (under the buckle), and the
    cornea and the optic nerve named."""
    import pyvista

    moved = grid.points + grid.point_data["displacement"]
    placed = marks.get("buckle")
    buckle = buckle_surfaces(*placed) if placed is not None else []
    extras: list = list(buckle)
    bites, anchors = marks["sutures"]
    if placed is not None and len(bites):
        centres = np.array([bite[2] for bite in bites], dtype=float)
        # the bites on the deformed sclera: their nearest nodes, moved
        nearest = np.argmin(np.linalg.norm(grid.points[None] - centres[:, None], axis=2), axis=1)
        beads = moved[nearest]
        lines = []
        k = 0
        while k < len(bites):  # a suture's two bites (sides -1, +1) at one azimuth: one loop
            if k + 1 < len(bites) and bites[k][0] == bites[k + 1][0] and bites[k][1] == -bites[k + 1][1]:
                lines.append([beads[k], anchors[k], anchors[k + 1], beads[k + 1]])
                k += 2
            else:
                lines.append([beads[k], anchors[k]])
                k += 1
        starts = np.cumsum([0] + [len(line) for line in lines])
        threads = pyvista.PolyData(np.concatenate(lines), lines=np.concatenate(
            [np.r_[len(line), start + np.arange(len(line))] for line, start in zip(lines, starts)]))
        extras.append((pyvista.PolyData(beads), {"color": SUTURE_COLOR, "point_size": 14,
                                                 "render_points_as_spheres": True, "label": "sutures"}))
        extras.append((threads, {"color": SUTURE_COLOR, "line_width": 4}))
    rim = marks["rim"]
    if len(rim):
        # the tear lies inside, under the buckle: its label outside the eye, over the rim
        centre = moved[rim].mean(axis=0)
        outer = max([float(np.linalg.norm(moved, axis=1).max())]
                    + [float(np.linalg.norm(surface.points, axis=1).max()) for surface, _ in buckle])
        over = centre / np.linalg.norm(centre) * (outer + 0.5)
        extras.append((pyvista.lines_from_points(np.array([centre, over])), {"color": "yellow",
                                                                              "line_width": 4}))
        extras.append(PointLabels(over[None], ["tear (beneath)"], {"point_color": "yellow",
                                                                    "point_size": 12}))
    extras += _tissue_labels(grid, moved)
    return extras


def _tissue_labels(grid, moved) -> list:
    """The cornea named at its apex and the optic nerve at its end (the most anterior and
    the most posterior points of their cells), when the grid has them."""
    if "tissue_names" not in grid.field_data:
        return []
    names = dict(zip(grid.field_data["tissue_names"].tolist(), grid.field_data["tissue_tags"].tolist()))
    points, texts = [], []
    for name, text, pick in (("cornea", "cornea", np.argmax), ("optic_nerve", "optic nerve", np.argmin)):
        if name not in names:
            continue
        cells = np.flatnonzero(np.asarray(grid.cell_data["tissue"]) == names[name])
        if not len(cells):
            continue
        nodes = grid.extract_cells(cells).point_data["vtkOriginalPointIds"]
        points.append(moved[nodes[pick(moved[nodes, 2])]])
        texts.append(text)
    return [PointLabels(np.array(points), texts)] if texts else []


def _section_title(stage: int, name: str, measured: dict) -> str:
    """The stage, and what a surgeon reads off the section: the tear's rim gap, closed or
    open by its margin against the closure tolerance (measures.rim_margin), and the IOP."""
    title = f"step {stage} ({name}): section through the tear"
    if "tear_rim_gap_max_mm" in measured and np.isfinite(measured["tear_rim_gap_max_mm"]):
        margin = measured["tear_rim_margin_mm"]
        title += (f"\nrim gap {measured['tear_rim_gap_max_mm']:.3f} mm "
                  f"({rim_verdict(margin)} by {abs(margin):.3f} mm)")
        if "iop_mmHg" in measured:
            title += f", IOP {measured['iop_mmHg']:.0f} mmHg"
    return title


def _onto(points: np.ndarray, x: float) -> np.ndarray:
    """``points`` moved onto the plane x = ``x`` (in front of the section, towards the camera)."""
    points = np.array(points, dtype=float).reshape(-1, 3)
    points[:, 0] = x
    return points


def _category_colors(count: int) -> list:
    """The colours pyvista gives ``count`` categories of the tab10 map (for the legend)."""
    import matplotlib

    cmap = matplotlib.colormaps["tab10"].resampled(max(count, 1))
    return [cmap(k)[:3] for k in range(count)]


def _scale_and_directions(plotter, corner) -> None:
    """A 2 mm scale bar from ``corner`` and arrows to anterior (+z) and outside (+y: the
    section's meridian leaves the axis that way; seen from −x it points left)."""
    import pyvista

    corner = np.asarray(corner, dtype=float)
    bar = np.array([corner, corner + (0.0, -2.0, 0.0)])
    plotter.add_lines(bar, color="black", width=5)
    # a label's text starts at its point and runs to the right of the picture (−y here): the
    # bar's under its middle, the outside arrow's ending at its tip, so no text crosses a line
    plotter.add_point_labels((bar.mean(axis=0) + (0.0, 0.45, -0.55))[None], ["2 mm"], font_size=14,
                             shape_opacity=0.0, show_points=False, always_visible=True)
    origin = corner + (0.0, -3.0, 0.8)
    for direction, label, shift in (((0.0, 0.0, 1.5), "anterior", (0.0, 0.0, 0.3)),
                                    ((0.0, 1.5, 0.0), "outside", (0.0, 1.4, 0.25))):
        plotter.add_mesh(pyvista.Arrow(start=origin, direction=direction, scale=1.5), color="black")
        plotter.add_point_labels((origin + np.array(direction) + shift)[None], [label], font_size=13,
                                 shape_opacity=0.0, show_points=False, always_visible=True)


def headline(quantities: dict) -> list[str]:
    """What the operation did, in a surgeon's terms, ahead of the run's table: the tear
    after suturing and settled (its verdict and margin, measures.rim_verdict; with
    ``error_estimate`` the verdict reads the margin against the rim gap's estimated
    discretisation error, shown as ±), then the last stage's axial and refractive change,
    the operation's peak IOP and the liquid vented."""
    stages = _stages(quantities)
    sutured = [name for name in ("after_suturing", "after_settling") if name in stages]
    tear, estimated = [], False
    for name in sutured:
        stage = stages[name]
        margin = stage.get("tear_rim_margin_mm", math.nan)
        verdict = _verdict(stage)
        if verdict is None:  # no tear
            continue
        error = stage.get(f"{RIM_GAP}_error_estimate")
        estimated |= error is not None
        band = f" ± {error:.3f}" if error is not None else ""
        tear.append(f"{verdict} {name.replace('_', ' ')} (margin {margin:+.3f}{band} mm)")
    lines = []
    if tear:
        lines.append("the tear: " + ", ".join(tear) + ("" if estimated else
                     "; the margin's discretisation error not estimated (--set error_estimate=true)"))
    if sutured:
        name, last = sutured[-1], stages[sutured[-1]]
        peak = _peak_iop(stages)
        outcome = [*_changes(last),
                   f"peak IOP {peak:.0f} mmHg" if math.isfinite(peak) else "",
                   f"vented {last['vented_volume_uL']:.0f} µL ({last.get('venting_route', '?')})"
                   if last.get("vented_volume_uL") else "nothing vented"]
        lines.append(f"{name.replace('_', ' ')}: " + ", ".join(item for item in outcome if item))
    settled = stages.get("after_settling", {})
    if "subretinal_pump_from_iop_mmHg" in settled:  # subretinal_pump_mmHg on
        started = settled["subretinal_pump_from_iop_mmHg"]
        lines.append("the pigment epithelium's pump: "
                     + (f"from {started:.0f} mmHg, where the break sealed"
                        if started is not None and math.isfinite(started)
                        else "never started, the break did not seal"))
    return lines


def bench_outcome(quantities: dict) -> str:
    """A benchmark row's outcome, so that its time stands beside what it bought: the tear's
    rim gap and verdict after suturing / settled, the last stage's ΔAL and ΔSE, the peak
    IOP and the liquid vented (empty where the run measured nothing)."""
    every_stage = _stages(quantities)
    stages = {name: every_stage[name] for name in ("after_suturing", "after_settling")
              if name in every_stage}
    if not stages:
        return ""
    rims = []
    for stage in stages.values():
        gap, verdict = stage.get("tear_rim_gap_max_mm"), _verdict(stage)
        if gap is not None and verdict is not None:
            rims.append(f"{gap:.3f} mm {verdict}".replace("-", "−"))
    labels = [name.removeprefix("after_").replace("suturing", "sutured").replace("settling", "settled")
              for name in stages]
    parts = [f"rim {' / '.join(rims)} ({' / '.join(labels)})"] if rims else []
    last = list(stages.values())[-1]
    changes = _changes(last)
    if changes:
        parts.append(", ".join(changes).replace("-", "−") + f" ({labels[-1]})")
    peak = _peak_iop(every_stage)
    if math.isfinite(peak):
        vented = last.get("vented_volume_uL") or 0.0
        parts.append(f"peak IOP {peak:.0f} mmHg, vented {vented:.0f} µL")
    return "; ".join(parts)


def _stages(quantities: dict) -> dict:
    """The run's per-stage groups (``after_iop``, ``after_buckling``, ...)."""
    return {name: group for name, group in quantities.items()
            if name.startswith("after_") and isinstance(group, dict)}


def _changes(stage: dict) -> list[str]:
    """The stage's axial and refractive change, those it reports."""
    return ([f"ΔAL {stage['axial_length_change_mm']:+.2f} mm"] if "axial_length_change_mm" in stage else []) \
        + ([f"ΔSE {stage['refraction_change_D']:+.2f} D"] if "refraction_change_D" in stage else [])


def _verdict(stage: dict) -> str | None:
    """The stage's tear verdict: the error estimate's where it ran, else the margin's."""
    return stage.get("tear_verdict") or rim_verdict(stage.get("tear_rim_margin_mm", math.nan))


def _peak_iop(stages: dict) -> float:
    """The highest IOP any stage reached (-inf: none reported)."""
    return max((group.get("peak_iop_mmHg", -math.inf) for group in stages.values()),
               default=-math.inf)
