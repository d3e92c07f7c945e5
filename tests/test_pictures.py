"""Pictures a reader can trust: every colour bar names its unit and a magnitude's starts
at zero; the tonometer is drawn; and every scene picture in docs/img was made at the
scene's defaults, so that its caption's values are the defaults (the PNG records the scene
and parameters it was made with: problems/run/output.py, tag_picture)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from eyemech.problems import scenes
from eyemech.problems.run.output import picture_record, render_png

DOCS = Path(__file__).resolve().parents[1] / "docs"
# the scenes' pictures the README and the docs show (docs/iol's are the lens scenes'
# animation frames, of runs up to 44 min, some at the paper's resolution: no record)
IMAGES = [DOCS / "img", DOCS / "shell"]
# the lens and zonules' section is a view drawn outside the scene's writer: it carries no record
UNRECORDED = {"buckling-lens-section.png"}
DOCS_PICTURES = sorted(p for folder in IMAGES for p in folder.glob("*.png") if p.name not in UNRECORDED)


@pytest.mark.parametrize("path", DOCS_PICTURES, ids=[p.stem for p in DOCS_PICTURES])
def test_a_docs_picture_shows_the_scenes_defaults(path):
    record = picture_record(path)
    assert record is not None, f"{path.name} carries no record of how it was made: run the scene"
    defaults = dataclasses.asdict(scenes()[record["scene"]].parameters())
    made = {k: record["parameters"].get(k) for k in defaults}
    different = {k: (made[k], v) for k, v in defaults.items()
                 if json.dumps(made[k], default=str) != json.dumps(v, default=str)}
    assert not different, f"{path.name} ({record['caption']!r}) was made with {different}"


def test_the_readmes_von_mises_picture_shows_the_buckle_and_sutures():
    """The README's von Mises picture is drawn as the scene draws it now (its record lists
    the buckle, the sutures and the scale), and its caption's bar is the picture's."""
    record = picture_record(DOCS / "img" / "buckling-von-mises.png")
    drawn = record["drawn"]
    assert {"silicone tire", "encircling band", "sutures", "tear (beneath)"} <= set(drawn["extras"])
    assert drawn["scale_bar_mm"] == 5.0 and drawn["bar"]["title"] == "von Mises stress (MPa)"
    low, high = drawn["bar"]["range"]
    readme = (DOCS.parent / "README.md").read_text()
    assert low == 0.0 and f"the bar from 0 to {high:.3f} MPa" in readme


def _grid():
    import pyvista as pv

    grid = pv.ImageData(dimensions=(3, 3, 3)).cast_to_unstructured_grid()
    grid.point_data["displacement"] = np.zeros((grid.n_points, 3))
    grid.point_data["displacement (mm)"] = 1e-18 + np.linspace(0.0, 0.4, grid.n_points)
    grid.point_data["p (MPa)"] = np.linspace(-0.2, 0.4, grid.n_points)
    grid.point_data["p"] = np.linspace(-0.2, 0.4, grid.n_points)
    grid.point_data["w (mm)"] = np.linspace(-3.7e-7, 0.126, grid.n_points)  # an edge's ripple
    return grid


def _bars(monkeypatch) -> list[dict]:
    import pyvista as pv

    seen: list[dict] = []
    add_mesh = pv.Plotter.add_mesh

    def spy(self, mesh, **kw):
        if kw.get("scalars"):
            seen.append(kw)
        return add_mesh(self, mesh, **kw)

    monkeypatch.setattr(pv.Plotter, "add_mesh", spy)
    return seen


def test_a_magnitudes_bar_starts_at_zero(tmp_path, monkeypatch):
    bars = _bars(monkeypatch)
    render_png(_grid(), tmp_path / "a.png", scalars="displacement (mm)")
    render_png(_grid(), tmp_path / "b.png", scalars="p (MPa)")
    render_png(_grid(), tmp_path / "w.png", scalars="w (mm)")
    assert bars[0]["clim"] == (0.0, pytest.approx(0.4))
    assert bars[0]["scalar_bar_args"]["title"] == "displacement (mm)"
    assert bars[1]["clim"] is None  # a signed field keeps its range
    assert bars[2]["clim"] == (0.0, pytest.approx(0.126))  # round-off below zero: from zero


def test_a_bar_without_a_unit_is_refused(tmp_path):
    with pytest.raises(ValueError, match="names no unit"):
        render_png(_grid(), tmp_path / "c.png", scalars="p")


def test_the_tonometer_is_drawn():
    from eyemech.problems.tonometry import PRISM_DIAMETER, _tonometer

    grid = _grid()
    (prism, _), (rim, style) = _tonometer(grid, 3.06)
    top = float((grid.points[:, 2] + grid["displacement"][:, 2]).max())
    assert prism.bounds[4] == pytest.approx(top)
    assert prism.bounds[1] == pytest.approx(PRISM_DIAMETER / 2, rel=1e-3)
    radius = np.linalg.norm(rim.points[:, :2], axis=1)
    assert np.allclose(radius, 3.06 / 2) and style["color"] == "red"


def test_a_scene_picture_records_its_parameters(tmp_path):
    from eyemech.problems import sphere_inflation as si
    from eyemech.problems.run.context import RunOptions

    si.run(si.Parameters(mesh_size=3.0), out=tmp_path, options=RunOptions(fields=False))
    record = picture_record(tmp_path / "deformed.png")
    assert record["scene"] == "sphere-inflation" and record["parameters"]["mesh_size"] == 3.0
    assert record["caption"] == "sphere-inflation, p = 0.01 MPa"


def test_the_eyes_section_names_its_stage_gap_scale_and_directions(monkeypatch):
    """What a surgeon reads off the eye's section besides the tissues' legend: the stage
    and the rim gap with its verdict and the IOP in the title, a 2 mm scale bar, and
    arrows naming anterior (+z) and outside (+y)."""
    import pyvista as pv

    from eyemech.problems.scleral_buckling.output import _scale_and_directions, _section_title

    title = _section_title(3, "suturing", {"tear_rim_gap_max_mm": 0.014, "tear_rim_margin_mm": 0.036,
                                           "iop_mmHg": 79.2})
    assert title == "step 3 (suturing): section through the tear\n" \
                    "rim gap 0.014 mm (closed by 0.036 mm), IOP 79 mmHg"
    assert "open by 0.020 mm" in _section_title(4, "settling", {"tear_rim_gap_max_mm": 0.07,
                                                                 "tear_rim_margin_mm": -0.02})
    labels, lines, arrows = [], [], []
    monkeypatch.setattr(pv.Plotter, "add_point_labels",
                        lambda self, points, texts, **kw: labels.extend(zip(texts, np.asarray(points))))
    monkeypatch.setattr(pv.Plotter, "add_lines", lambda self, points, **kw: lines.append(np.asarray(points)))
    add_mesh = pv.Plotter.add_mesh
    monkeypatch.setattr(pv.Plotter, "add_mesh",
                        lambda self, mesh, **kw: (arrows.append(mesh), add_mesh(self, mesh, **kw))[1])
    plotter = pv.Plotter(off_screen=True)
    try:
        _scale_and_directions(plotter, (-1.0, 5.0, -3.0))
    finally:
        plotter.close()
    (bar,) = lines
    assert np.linalg.norm(bar[1] - bar[0]) == pytest.approx(2.0)
    named = dict(labels)
    assert set(named) == {"2 mm", "anterior", "outside"}
    assert len(arrows) == 2
    corner = np.array([-1.0, 5.0, -3.0]) + (0.0, -3.0, 0.8)  # where the arrows start
    assert named["anterior"][2] > corner[2] and named["outside"][1] > corner[1]


def test_a_picture_records_what_it_draws(tmp_path, monkeypatch):
    """render_png returns, and writes into the PNG, the bar's title and range, the extras'
    names, the scale bar and the arrows; the bar is a line of its length across the view
    (perpendicular to the direction the camera looks along), which is parallel."""
    import pyvista as pv

    from eyemech.problems.run.output import PointLabels

    lines, cameras = [], []
    add_mesh, screenshot = pv.Plotter.add_mesh, pv.Plotter.screenshot

    def spy(self, mesh, **kw):
        if kw.get("color") == "black" and isinstance(mesh, pv.PolyData) and mesh.n_lines:
            lines.append(np.asarray(mesh.points))
        return add_mesh(self, mesh, **kw)

    def shot(self, *args, **kw):
        cameras.append((np.subtract(self.camera.position, self.camera.focal_point),
                        self.camera.parallel_projection))
        return screenshot(self, *args, **kw)

    monkeypatch.setattr(pv.Plotter, "add_mesh", spy)
    monkeypatch.setattr(pv.Plotter, "screenshot", shot)
    extras = [(pv.Sphere(radius=0.2), {"color": "grey", "opacity": 0.4, "label": "instrument"}),
              (pv.Sphere(radius=0.1), {"color": "red"}),  # unnamed: drawn, not listed
              PointLabels(np.zeros((1, 3)), ["here"])]
    drawn = render_png(_grid(), tmp_path / "d.png", scalars="displacement (mm)", warp="displacement",
                       camera=(0.6, 1.0, 0.35), extras=extras, legend=True, scale_bar_mm=0.5,
                       directions={"anterior": (0, 0, 1)}, scene="sphere-inflation", title="t")
    assert drawn == {"bar": {"title": "displacement (mm)", "range": [0.0, pytest.approx(0.4)]},
                     "extras": ["instrument", "here"], "scale_bar_mm": 0.5, "directions": ["anterior"]}
    assert picture_record(tmp_path / "d.png")["drawn"] == drawn
    (bar,) = lines
    (view, parallel), = cameras
    assert np.linalg.norm(bar[1] - bar[0]) == pytest.approx(0.5)
    assert np.dot(bar[1] - bar[0], view) == pytest.approx(0.0, abs=1e-9) and parallel
    # a signed field's bar keeps its range, and says so
    assert render_png(_grid(), tmp_path / "e.png", scalars="p (MPa)")["bar"]["range"] == \
        [pytest.approx(-0.2), pytest.approx(0.4)]


@pytest.mark.parametrize("kind, orientation, arc", [
    ("encircling+segmental", "circumferential", 90.0), ("encircling+segmental", "circumferential", 360.0),
    ("encircling", "circumferential", 90.0), ("segmental", "circumferential", 90.0),
    ("segmental", "radial", 90.0)])
def test_the_buckle_is_drawn_where_the_scene_puts_it(kind, orientation, arc):
    """The von Mises picture's buckle over the half model (x >= 0): band and tire swept from
    their sections in the symmetry plane (the section picture's outline) at their travels
    -- the tire's inner face at base - tire travel, the band's on the tire over its arc and
    at base - band travel beyond it, each as wide as it is along the axis; a radial tire
    extruded across the meridian to half its width."""
    import math

    from eyemech.forms.buckle import Buckle, BuckleShape
    from eyemech.problems.scleral_buckling.output import buckle_surfaces

    shape = BuckleShape(kind=kind, orientation=orientation, tire_arc_deg=arc)
    base, band, tire, axial = 12.2, 0.8, 0.9, -3.0
    buckle = Buckle(shape, axial, base, band, tire, polar_angle=math.radians(105.0))
    surfaces = {style["label"]: body for body, style in buckle_surfaces(buckle, tire)}
    assert set(surfaces) == {name for name, has in (("silicone tire", shape.has_tire),
                                                    ("encircling band", shape.has_band)) if has}
    for body in surfaces.values():
        assert body.is_manifold and body.bounds[0] == pytest.approx(0.0, abs=1e-9)
    if "encircling band" in surfaces:
        points = surfaces["encircling band"].points
        rho = np.hypot(points[:, 0], points[:, 1])
        azimuth = np.degrees(np.arctan2(np.abs(points[:, 0]), points[:, 1]))
        assert np.ptp(points[:, 2]) == pytest.approx(shape.band_width, rel=1e-5)
        edge = arc / 2 if shape.has_tire else 0.0
        over, beyond = azimuth < edge - 1e-3, azimuth > edge + 1e-3
        if beyond.any():  # beyond the tire: at its own travel
            assert rho[beyond].min() == pytest.approx(base - band, rel=1e-5)
        if over.any():  # over the tire: on its top
            assert rho[over].min() == pytest.approx(base - tire + shape.tire_height, rel=1e-5)
        assert azimuth.max() == pytest.approx(180.0, rel=1e-5)
    if "silicone tire" in surfaces:
        points = surfaces["silicone tire"].points
        if orientation == "radial":  # a ring about x, w/2 across the meridian
            assert points[:, 0].max() == pytest.approx(shape.tire_width / 2, rel=1e-5)
            assert np.hypot(points[:, 1], points[:, 2]).min() == pytest.approx(base - tire, rel=1e-5)
        else:
            rho = np.hypot(points[:, 0], points[:, 1])
            assert rho.min() == pytest.approx(base - tire, rel=1e-5)
            assert rho.max() == pytest.approx(base - tire + shape.tire_height, rel=1e-5)
            assert np.ptp(points[:, 2]) == pytest.approx(shape.tire_width, rel=1e-5)
            assert np.degrees(np.arctan2(np.abs(points[:, 0]), points[:, 1])).max() == \
                pytest.approx(min(arc / 2, 180.0), rel=1e-5)
