"""Fields and pictures. By default a run's fields are gathered to rank 0 and written as
``.vtu`` files indexed by a ``.pvd`` series, which pyvista (``pv.get_reader``) and ParaView
both read; ADIOS2 VTX (``.bp``, written in parallel, for ParaView with ADIOS2) only on
request, as well (``--vtx``: the project's pyvista cannot read it). PNG pictures are rendered
off-screen by pyvista on rank 0 from the gathered grid."""

from __future__ import annotations

import contextlib
import dataclasses
import os
from pathlib import Path
from typing import Sequence

import dolfinx
import dolfinx.plot
import numpy as np
from mpi4py import MPI


class FieldWriter:
    """Time series of functions: when ``pvd``, a gathered ``<stem>.pvd`` series per element
    (``<stem>_<names>.pvd`` when there are several) with the functions as point data (a
    scene that writes its own series passes ``pvd=False``); with ``vtx`` also ADIOS2 VTX
    files (functions that share an element share a file)."""

    def __init__(self, out: Path | None, comm: MPI.Comm, functions: Sequence[dolfinx.fem.Function],
                 stem: str = "fields", vtx: bool = True, pvd: bool = True):
        self.files: list[str] = []
        self._writers = []
        self._series: list[tuple[list, PyvistaSeries]] = []
        self.comm = comm
        if out is None:
            return
        groups: dict[str, list] = {}
        for function in functions:
            key = function.function_space.element.signature
            groups.setdefault(key, []).append(function)
        for group in groups.values():
            names = "_".join(f.name for f in group)
            if vtx:
                name = f"{stem}_{names}.bp"
                self._writers.append(dolfinx.io.VTXWriter(comm, str(Path(out) / name), group,
                                                          engine="BP4"))
                self.files.append(name)
            if pvd:
                series_stem = stem if len(groups) == 1 else f"{stem}_{names}"
                self._series.append((group, PyvistaSeries(out, comm, stem=series_stem)))

    def write(self, time: float) -> None:
        for writer in self._writers:
            with self._failing(writer):
                writer.write(time)
        for group, series in self._series:  # collective: every rank gathers
            series.write(time, gather_grid(group[0], {f.name: f for f in group[1:]}))

    def close(self, error: BaseException | None = None) -> None:
        """Collective. Called in a ``finally`` (or ``__exit__``) while an exception raised
        on this rank alone propagates, it aborts the job instead: the other ranks are
        not here."""
        from eyemech.problems.run.faults import abort_if_stranding

        abort_if_stranding(self.comm, error)
        for _, series in self._series:
            self.files += [f for f in series.files if f not in self.files]
        self._series = []
        writers, self._writers = self._writers, []
        for writer in writers:
            with self._failing(writer):
                writer.close()

    @contextlib.contextmanager
    def _failing(self, writer):
        """ADIOS2 reports a write it cannot do (a full disk) as a RuntimeError, and its
        writer's destructor tries the same write again and throws, which ends the process
        with SIGABRT: such a writer is retired (kept alive to the end of the process, see
        :func:`_retire`) and the error raised as the OSError it is."""
        try:
            yield
        except RuntimeError as err:
            if writer in self._writers:
                self._writers.remove(writer)
            _retire(writer)
            raise _as_os_error(err) from None

    def __enter__(self):
        return self

    def __exit__(self, kind, error, tb):
        self.close(error)


# writers whose files could not be written: never destroyed (see FieldWriter._failing)
_RETIRED: list = []


def _retire(writer) -> None:
    """Keep ``writer``'s C++ object alive for good: one reference more than Python will
    ever release, so its destructor (which would repeat the failed write and abort) never
    runs, not even when the interpreter exits (tests/test_faults.py, full disk)."""
    import ctypes

    cpp = getattr(writer, "_cpp_object", writer)
    ctypes.pythonapi.Py_IncRef(ctypes.py_object(cpp))
    _RETIRED.append(cpp)


def _as_os_error(error: RuntimeError) -> Exception:
    """ADIOS2's "couldn't write to file F : errno = N: ..." as OSError(N, ..., F); one
    without a number ("couldn't close file F, in call to fstream close", also a full
    disk) as EIO. Other errors as they are."""
    import errno as errnos
    import re

    text = re.sub(r"\x1b\[[0-9;]*m", "", str(error))
    name = re.search(r"couldn't \w+(?: to)? file ([^\s,]+)", text)
    found = re.search(r"errno = (\d+)", text)
    if found:
        number = int(found.group(1))
        return OSError(number, os.strerror(number) if number in errnos.errorcode else text,
                       name.group(1) if name else None)
    if name:
        return OSError(errnos.EIO, "ADIOS2 could not write it (a full disk?)", name.group(1))
    return error


def region_data(cell_tags, cells: int) -> np.ndarray:
    """Each owned cell's region tag (0 where untagged), for ``gather_grid``'s ``cell_data``
    as ``"tissue"``; :func:`add_legend` names the tags."""
    tags = np.zeros(cells, dtype=np.int32)
    if cell_tags is not None:
        owned = cell_tags.indices < cells
        tags[cell_tags.indices[owned]] = cell_tags.values[owned]
    return tags


def add_legend(grid, names: dict[str, tuple[int, int]], dim: int, key: str = "tissue") -> None:
    """The names of ``key``'s tags as field data (``<key>_names``, ``<key>_tags``, same
    order), saved in the ``.vtu``: ``grid.field_data["tissue_names"]``."""
    if grid is None:
        return
    regions = sorted((tag, name) for name, (d, tag) in names.items() if d == dim)
    grid.field_data[f"{key}_tags"] = np.array([tag for tag, _ in regions], dtype=np.int32)
    grid.field_data[f"{key}_names"] = np.array([name for _, name in regions])


def gather_grid(function: dolfinx.fem.Function, point_data: dict[str, dolfinx.fem.Function] | None = None,
                cell_data: dict[str, np.ndarray] | None = None):
    """A pyvista grid of the whole mesh on rank 0 (None elsewhere), built on the
    degrees of freedom of ``function``'s (Lagrange) space, with ``function`` and the
    ``point_data`` functions (same space) attached.

    Each rank sends its owned cells, with their nodes in the global numbering, and its
    owned nodes: every node appears once, so the grid on N ranks is the serial grid
    (same points, connected across the partition boundaries)."""
    import pyvista

    space = function.function_space
    comm = space.mesh.comm
    topology, cell_types, geometry = dolfinx.plot.vtk_mesh(space)
    n_cells = space.mesh.topology.index_map(space.mesh.topology.dim).size_local
    index_map = space.dofmap.index_map
    owned = index_map.size_local
    to_global = index_map.local_to_global(np.arange(owned + index_map.num_ghosts, dtype=np.int32))
    # keep owned cells only so that each cell is drawn once
    nodes_per_cell = topology[0] + 1 if len(topology) else 0
    topology = topology[: n_cells * nodes_per_cell].reshape(-1, max(nodes_per_cell, 1)).astype(np.int64)
    topology[:, 1:] = to_global[topology[:, 1:]]
    cell_types = cell_types[:n_cells]
    values = {function.name: _point_values(function)[:owned]}
    for name, f in (point_data or {}).items():
        values[name] = _point_values(f)[:owned]
    cells_extra = {name: np.asarray(v)[:n_cells] for name, v in (cell_data or {}).items()}
    gathered = comm.gather((topology.ravel(), cell_types, geometry[:owned], values, cells_extra),
                           root=0)
    if comm.rank != 0:
        return None
    # the global node numbering is contiguous by rank: stacking owned nodes in rank order
    # puts every node at its global index
    grid = pyvista.UnstructuredGrid(np.concatenate([g[0] for g in gathered]),
                                    np.concatenate([g[1] for g in gathered]),
                                    np.vstack([g[2] for g in gathered]))
    for name in values:
        grid.point_data[name] = np.concatenate([g[3][name] for g in gathered])
    for name in cells_extra:
        grid.cell_data[name] = np.concatenate([g[4][name] for g in gathered])
    return grid


def displacement_grid(displacement: dolfinx.fem.Function):
    """The gathered grid (rank 0, None elsewhere) of a vector displacement on the mesh's
    corner nodes, with its magnitude as ``"displacement (mm)"`` for colouring.

    Interpolating to P1 first keeps pictures of P2/Q2 solids light and works for any
    geometry degree (pyvista draws linear cells)."""
    mesh = displacement.function_space.mesh
    nodal = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (mesh.geometry.dim,)))
    corner_displacement = dolfinx.fem.Function(nodal, name="displacement")
    corner_displacement.interpolate(displacement)
    grid = gather_grid(corner_displacement)
    if grid is not None:
        grid.point_data["displacement (mm)"] = np.linalg.norm(grid.point_data["displacement"], axis=1)
    return grid


def _point_values(function: dolfinx.fem.Function) -> np.ndarray:
    bs = function.function_space.dofmap.index_map_bs
    values = function.x.array.reshape(-1, bs) if bs > 1 else function.x.array.copy()
    if bs == 2:  # pyvista warps by 3-vectors
        values = np.hstack([values, np.zeros((values.shape[0], 1))])
    return values.copy()


def quiet_vtk() -> None:
    """VTK reports that there is no X display before it falls back to off-screen
    rendering; that is expected on clusters and in CI, so silence its warnings."""
    with contextlib.suppress(Exception):
        import vtk

        vtk.vtkObject.GlobalWarningDisplayOff()


@dataclasses.dataclass(frozen=True)
class PointLabels:
    """Texts at points, an extra for :func:`render_png` beside (dataset, keywords) pairs:
    ``style`` the keywords of pyvista's ``add_point_labels`` (the default: always visible,
    on a faint box)."""

    points: np.ndarray
    texts: Sequence[str]
    style: dict = dataclasses.field(default_factory=dict)


def render_png(grid, path: Path, *, scalars: str | None = None, warp: str | None = None,
               title: str = "", camera: str | Sequence = "iso", clim=None,
               show_undeformed: bool = True, cmap: str = "viridis", extras: Sequence = (),
               scene: str = "", parameters: dict | None = None, scale_bar_mm: float | None = None,
               directions: dict[str, Sequence[float]] | None = None, legend: bool = False) -> dict:
    """Off-screen pyvista picture of ``grid`` (rank 0 only: no collective call), coloured
    by ``scalars``: a name with its unit in brackets ("displacement (mm)"), the colour
    bar's title. A field that is nowhere negative (a magnitude) gets a bar from 0 to its
    largest value; so does one whose negative values are below 1e-4 of its largest (a
    clamped plate's w, -3.7e-7 mm of ripple at its edge against 0.126 mm: a bar from
    -3.69e-07 reads as noise).

    ``extras``: things drawn as well (an instrument, a buckle, sutures): (pyvista dataset,
    add_mesh keywords) pairs, whose ``label`` keyword names them, and :class:`PointLabels`;
    ``legend`` lists the labelled ones. ``scale_bar_mm``: a bar of that length (the mesh in
    mm) under the picture, across the view; the view is then a parallel projection, so
    that the bar measures anything in it. ``directions``: arrows named by their keys (e.g.
    "anterior": (0, 0, 1)) at the picture's lower right. ``scene`` and ``parameters`` are
    written into the PNG (:func:`tag_picture`) with what was drawn, the record this
    returns: the bar's title and range, the extras' names, the scale bar, the arrows."""
    import pyvista

    if scalars is not None and not scalars.rstrip().endswith(")"):
        raise ValueError(f"colour bar '{scalars}' names no unit: write it as 'name (unit)' "
                         "('(1)' for a ratio)")
    pyvista.OFF_SCREEN = True
    quiet_vtk()
    plotter = pyvista.Plotter(off_screen=True, window_size=(1000, 800))
    shown = grid.warp_by_vector(warp, factor=1.0) if warp else grid
    if show_undeformed and warp:
        plotter.add_mesh(grid, style="wireframe", color="grey", opacity=0.25)
    clim, bar = _bar(grid, scalars, clim)
    drawn: dict = {"bar": bar, "extras": [], "scale_bar_mm": None, "directions": []}
    plotter.add_mesh(shown, scalars=scalars, show_edges=True, cmap=cmap, clim=clim,
                     scalar_bar_args={"title": scalars or "", "fmt": "%.3g", "n_labels": 5})
    drawn["extras"] = _draw_extras(plotter, extras)
    if title:
        plotter.add_text(title, font_size=12)
    if camera == "iso":
        plotter.view_isometric()
    elif isinstance(camera, str):
        getattr(plotter, f"view_{camera}")()
    else:  # a direction to look from
        plotter.view_vector(camera)
    if scale_bar_mm or directions:
        # across and up the screen of the camera just set
        view = np.subtract(plotter.camera.position, plotter.camera.focal_point)
        drawn |= _scale_and_arrows(plotter, shown, view, plotter.camera.up, scale_bar_mm,
                                   directions or {})
    labelled = sum(1 for e in extras if not isinstance(e, PointLabels) and e[1].get("label"))
    if legend and labelled:
        size = (0.26, 0.035 * labelled)
        box = plotter.add_legend(bcolor="white", size=size, loc="upper right", face="rectangle")
        # in the upper right corner, under the title's line (pyvista's "upper right" puts
        # the box's corner at 0.85 whatever its size, and longer names run off the picture)
        box.SetPosition(0.98 - size[0], 0.94 - size[1])
    if scale_bar_mm:
        plotter.enable_parallel_projection()
    if scale_bar_mm or directions:
        plotter.reset_camera()  # the view takes in the bar and the arrows
    tag = (lambda tmp: tag_picture(tmp, scene, parameters or {}, title, drawn)) if scene else None
    try:
        save_screenshot(plotter, Path(path), tag)
    finally:
        plotter.close()
    return drawn


def _bar(grid, scalars: str | None, clim):
    """The colour range (from 0 for a magnitude, see :func:`render_png`) and the bar's
    record: its title and the range it shows (the data's, when ``clim`` stays None)."""
    if scalars is None:
        return clim, None
    values = np.asarray(grid[scalars], dtype=float)
    values = np.linalg.norm(values, axis=1) if values.ndim > 1 else values
    if clim is None and values.size and np.nanmin(values) >= -1e-4 * np.nanmax(np.abs(values)):
        clim = (0.0, float(np.nanmax(values)) or 1.0)
    shown = clim if clim is not None else \
        ((float(np.nanmin(values)), float(np.nanmax(values))) if values.size else None)
    return clim, {"title": scalars, "range": None if shown is None else [float(shown[0]), float(shown[1])]}


def _draw_extras(plotter, extras) -> list[str]:
    """:func:`render_png`'s extras drawn; the names of the labelled ones and the labels."""
    names: list[str] = []
    for extra in extras:
        if isinstance(extra, PointLabels):
            plotter.add_point_labels(np.asarray(extra.points, dtype=float).reshape(-1, 3),
                                     list(extra.texts), **({"font_size": 14, "shape_opacity": 0.5,
                                                            "always_visible": True} | extra.style))
            names += list(extra.texts)
        else:
            dataset, keywords = extra
            plotter.add_mesh(dataset, **keywords)
            if keywords.get("label"):
                names.append(keywords["label"])
    return names


def screen_axes(view, up) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors pointing right and up on the screen of a camera looking from
    ``view`` (towards the focal point) with ``up``."""
    back = np.asarray(view, dtype=float) / np.linalg.norm(view)
    upward = np.asarray(up, dtype=float) - np.dot(up, back) * back
    upward /= np.linalg.norm(upward)
    return np.cross(upward, back), upward


def _scale_and_arrows(plotter, shown, view, up, length: float | None, directions: dict) -> dict:
    """A scale bar of ``length`` (mm) across the view under ``shown``'s lower left, and
    arrows for ``directions`` at its lower right, in the plane through its centre
    that faces the camera."""
    import pyvista

    right, upward = screen_axes(view, up)
    points = np.asarray(shown.points, dtype=float)
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    across, height = (points - centre) @ right, (points - centre) @ upward
    size = max(float(np.ptp(across)), float(np.ptp(height)), 1e-12)
    below = centre + (height.min() - 0.08 * size) * upward
    drawn: dict = {}
    if length:
        start = below + across.min() * right
        bar = np.array([start, start + length * right])
        plotter.add_mesh(pyvista.lines_from_points(bar), color="black", line_width=6)
        plotter.add_point_labels((bar.mean(axis=0) - 0.04 * size * upward)[None], [f"{length:g} mm"],
                                 font_size=16, shape_opacity=0.0, always_visible=True,
                                 show_points=False)
        drawn["scale_bar_mm"] = float(length)
    arrow = 0.12 * size
    origin = below + (across.max() + arrow) * right  # right of the picture, clear of it
    for name, direction in directions.items():
        direction = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
        plotter.add_mesh(pyvista.Arrow(start=origin, direction=direction, scale=arrow), color="black")
        plotter.add_point_labels((origin + 1.25 * arrow * direction)[None], [name], font_size=14,
                                 shape_opacity=0.0, always_visible=True, show_points=False)
    drawn["directions"] = list(directions)
    return drawn


def save_screenshot(plotter, path: Path, before_rename=None) -> None:
    """``plotter``'s picture in ``path``, whole or not at all: written beside it (and
    ``before_rename(tmp)`` applied to it) and renamed; a failed write (a full disk) leaves
    no partial file and names ``path``."""
    tmp = path.with_suffix(".tmp.png")
    try:
        plotter.screenshot(str(tmp))
        if before_rename is not None:
            before_rename(tmp)
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(err, OSError) and err.filename is None:
            raise OSError(err.errno, err.strerror, str(path)) from err
        raise


def vtu_bytes(grid) -> bytes:
    """``grid`` as a ``.vtu`` file's bytes, as pyvista's ``save`` writes it (binary data,
    zlib-compressed), made in memory: VTK's XML writer that fails to write a file (a full
    disk) corrupts the heap (seen: "double free or corruption", SIGSEGV), so the bytes
    are written by Python, which raises an OSError naming the file instead."""
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter

    writer = vtkXMLUnstructuredGridWriter()
    writer.SetInputData(grid)
    writer.SetDataModeToBinary()
    writer.SetCompressorTypeToZLib()
    writer.WriteToOutputStringOn()
    if not writer.Write():
        raise RuntimeError("VTK could not serialise the grid")
    return writer.GetOutputStdString().encode("latin-1") \
        if hasattr(writer, "GetOutputStdString") else writer.GetOutputString().encode("latin-1")


PICTURE_KEY = "eyemech"


def tag_picture(path: Path, scene: str, parameters: dict, caption: str, drawn: dict | None = None) -> None:
    """Write the scene, its parameters and the caption into the PNG as a text chunk
    (``eyemech``), so that a picture in the docs can be checked against the defaults
    (:func:`picture_record`; tests/test_pictures.py); and ``drawn``, what the picture
    shows besides (:func:`render_png`'s record), when given."""
    import json

    from PIL import Image, PngImagePlugin

    record = {"scene": scene, "parameters": parameters, "caption": caption}
    if drawn is not None:
        record["drawn"] = drawn
    info = PngImagePlugin.PngInfo()
    info.add_text(PICTURE_KEY, json.dumps(record, default=str))
    with Image.open(path) as image:
        image.load()
        image.save(path, pnginfo=info)


def picture_metadata(scene: str, parameters: dict, caption: str) -> dict[str, str]:
    """The same record for matplotlib's ``savefig(..., metadata=...)``."""
    import json

    return {PICTURE_KEY: json.dumps({"scene": scene, "parameters": parameters,
                                     "caption": caption}, default=str)}


def picture_record(path: Path) -> dict | None:
    """What :func:`tag_picture` wrote into a PNG, or None."""
    import json

    from PIL import Image

    with Image.open(path) as image:
        text = image.text.get(PICTURE_KEY)
    return json.loads(text) if text else None


class PyvistaSeries:
    """Converged states as ``.vtu`` files plus a ``.pvd`` index, written by rank 0 from
    the gathered grid: what ParaView opens and notebooks read with
    ``pv.get_reader(path)`` (``reader.set_active_time_value(reader.time_values[-1])`` for
    the last state: ``pyvista.read`` gives the first)."""

    def __init__(self, out: Path | None, comm: MPI.Comm, stem: str = "state"):
        self.out, self.comm, self.stem = (Path(out) if out else None), comm, stem
        self.entries: list[tuple[float, str]] = []

    @property
    def files(self) -> list[str]:
        return [f"{self.stem}.pvd"] if self.entries else []

    def write(self, time: float, grid) -> None:
        """``grid`` from :func:`gather_grid` (None on ranks other than 0)."""
        if self.out is None or self.comm.rank != 0 or grid is None:
            return
        name = f"{self.stem}_{len(self.entries):04d}.vtu"
        from eyemech.problems.run.results import write_bytes_atomic

        write_bytes_atomic(self.out / name, vtu_bytes(grid))
        self.entries.append((time, name))
        datasets = "\n".join(f'    <DataSet timestep="{t:.9g}" part="0" file="{n}"/>'
                             for t, n in self.entries)
        index = ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
                 f'  <Collection>\n{datasets}\n  </Collection>\n</VTKFile>\n')
        from eyemech.problems.run.results import write_text_atomic

        write_text_atomic(self.out / f"{self.stem}.pvd", index)
