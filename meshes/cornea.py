"""A hexahedral cornea with its limbus and optional radial keratotomy incisions as real cuts.

Geometry (all lengths in mm, every value a parameter of :class:`CorneaGeometry`):
the anterior surface is a sphere of radius ``anterior_radius`` with its apex at the origin
and its centre Ca = (0, 0, −Ra); the limbus is where the anterior surface reaches the
planform radius ``diameter/2``. The cornea is swept along the anterior normals (the rays
from Ca): at polar angle θ (from the optical axis, about Ca) it is

    t(θ) = t_c + k θ² + m θ⁴    thick,

k fixed by the posterior apical radius (a polar curve ρ = Ra − t(θ) has apical radius
ρ²/(ρ + 2k) at θ = 0) and m by the limbal thickness t(θ_L) — so the posterior surface has
``posterior_radius`` at its apex and flattens towards the limbus, as real corneas do.
The limbus edge (the rays at θ_L) is the support surface.

Mesh: a structured planform — an O-grid square core, then rings of radius levels that
include the optical-zone edge and the incision end exactly — mapped onto the anterior
surface and extruded along the normals in layers that include the incision depth. Radial
incisions at equally spaced azimuths (grid lines, the first at azimuth 0) run from the
optical-zone edge ``optical_zone/2`` to ``incision_end`` (planform radii), from the anterior
surface down to ``incision_depth`` × local thickness. They are real cuts: the nodes strictly
inside each cut face are duplicated, and the cells on the counter-clockwise side of the cut
take the copies, so the wound can gape; the crack front (the ends and the bottom of the cut)
stays connected.

Tags: cell ``cornea``; facets ``anterior``, ``posterior``, ``limbus`` and, with incisions,
``incision`` (both faces of every cut). With ``quarter`` only the quadrant x > 0, y > 0 is
meshed, its faces on the planes x = 0 and y = 0 tagged ``symmetry_x`` and ``symmetry_y``: valid
for an even number of incisions (the first at azimuth 0), whose pattern is mirror symmetric
about both planes. Trilinear (faceted) cells, or with ``geometry_degree`` = 2
27-node cells whose extra nodes lie on the curved shape.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from mpi4py import MPI

from eyemech.meshes.tagged import MeshError, TaggedMesh, from_gmsh

HEX8, QUAD4, HEX27, QUAD9 = 5, 3, 12, 10  # gmsh element types
# gmsh's hexahedron-27 / quadrangle-9 numbering: the vertices of every mid-edge and
# mid-face node, then the centre
HEX27_EDGES = ((0, 1), (0, 3), (0, 4), (1, 2), (1, 5), (2, 3), (2, 6), (3, 7), (4, 5), (4, 7),
               (5, 6), (6, 7))
HEX27_FACES = ((0, 1, 2, 3), (0, 1, 5, 4), (0, 3, 7, 4), (1, 2, 6, 5), (2, 3, 7, 6), (4, 5, 6, 7))
QUAD9_EDGES = ((0, 1), (1, 2), (2, 3), (3, 0))
FACET_NAMES = ("anterior", "posterior", "limbus", "incision", "symmetry_x", "symmetry_y")


def _bad(key: str, message: str) -> MeshError:
    error = MeshError(message)
    error.key = key
    return error


@dataclasses.dataclass(frozen=True)
class CorneaGeometry:
    anterior_radius: float = 7.8
    posterior_radius: float = 6.5
    central_thickness: float = 0.52
    limbal_thickness: float = 0.67
    diameter: float = 11.7          # planform diameter of the anterior limbus
    incisions: int = 0
    incision_depth: float = 0.9     # fraction of the local thickness
    optical_zone: float = 3.0       # clear central diameter
    incision_end: float = 5.35      # planform radius where the incisions stop (≤ diameter/2)
    mesh_size: float = 0.5          # radial element size in the planform
    azimuthal_divisions: int = 24   # at least; rounded up to a multiple of lcm(8, incisions)
    layers: int = 2                 # element layers through the thickness (at least)
    geometry_degree: int = 1        # 1: trilinear (faceted) cells; 2: 27-node cells on the shape
    quarter: bool = False           # only the cells in x > 0, y > 0, with symmetry planes

    def validate(self) -> None:
        """MeshError naming the offending value (its ``key`` attribute is the field name);
        nothing is built before this passes."""
        positive = ("anterior_radius", "posterior_radius", "central_thickness", "limbal_thickness",
                    "diameter", "mesh_size", "azimuthal_divisions", "layers")
        for key in positive:
            if not getattr(self, key) > 0:
                raise _bad(key, f"cornea {key} must be > 0, got {getattr(self, key)!r}")
        if not self.diameter < 2 * self.anterior_radius:
            raise _bad("diameter", f"cornea diameter {self.diameter} must be smaller than the "
                       f"anterior sphere's ({2 * self.anterior_radius})")
        if self.geometry_degree not in (1, 2):
            raise _bad("geometry_degree", f"geometry_degree must be 1 or 2, got {self.geometry_degree!r}")
        if self.incisions < 0:
            raise _bad("incisions", f"incisions must be >= 0, got {self.incisions}")
        if self.quarter and self.incisions % 2:
            raise _bad("incisions", f"a quarter cornea needs an even number of incisions (mirror "
                       f"symmetric about the planes x = 0 and y = 0), got {self.incisions}")
        if not 0 < self.incision_depth < 1:
            raise _bad("incision_depth", f"incision_depth must lie in (0, 1) (a fraction of the "
                       f"local thickness), got {self.incision_depth}")
        if not 0 < self.optical_zone < self.diameter:
            raise _bad("optical_zone", f"optical_zone {self.optical_zone} mm must be > 0 and "
                       f"narrower than the cornea ({self.diameter} mm); at 0 the incisions would "
                       "cross at the apex")
        if self.optical_zone < 1.0:
            raise _bad("optical_zone", f"optical_zone {self.optical_zone} mm is below 1 mm: the "
                       "incisions would nearly cross at the apex (and the O-grid core needs room)")
        if not self.optical_zone / 2 < self.incision_end <= self.diameter / 2:
            raise _bad("incision_end", f"incision_end {self.incision_end} mm must lie in "
                       f"(optical_zone/2, diameter/2] = ({self.optical_zone / 2}, {self.diameter / 2}]")
        theta = np.linspace(0, self.limbus_angle, 200)
        if not np.all(self.thickness(theta) > 0.05 * self.central_thickness):
            raise _bad("posterior_radius", "the thickness profile from these radii and thicknesses "
                       "is not positive over the cornea (posterior surface crosses the anterior)")

    # -- the shape --------------------------------------------------------------------
    @property
    def limbus_angle(self) -> float:
        return math.asin(self.diameter / 2 / self.anterior_radius)

    def thickness_coefficients(self) -> tuple[float, float]:
        rho = self.anterior_radius - self.central_thickness
        k = 0.5 * (rho**2 / self.posterior_radius - rho)
        theta = self.limbus_angle
        m = (self.limbal_thickness - self.central_thickness - k * theta**2) / theta**4
        return k, m

    def thickness(self, theta):
        k, m = self.thickness_coefficients()
        return self.central_thickness + k * np.asarray(theta) ** 2 + m * np.asarray(theta) ** 4

    def volume(self) -> float:
        """Exact volume of the solid of revolution, 2π/3 ∫ (Ra³ − (Ra − t)³) sin θ dθ."""
        from scipy.integrate import quad

        Ra = self.anterior_radius
        value, _ = quad(lambda th: (Ra**3 - (Ra - self.thickness(th)) ** 3) * math.sin(th), 0,
                        self.limbus_angle, epsabs=1e-13)
        return 2 * math.pi / 3 * value

    def map_to_cornea(self, planform: np.ndarray, depth: float) -> np.ndarray:
        """Planform points (x, y) on the anterior sphere's projection → 3D points at
        ``depth`` (fraction of the local thickness) below the anterior surface."""
        Ra = self.anterior_radius
        r = np.hypot(planform[:, 0], planform[:, 1])
        theta = np.arcsin(np.clip(r / Ra, 0, 1))
        phi = np.arctan2(planform[:, 1], planform[:, 0])
        normal = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], 1)
        rho = Ra - depth * self.thickness(theta)
        return np.array([0.0, 0.0, -Ra]) + rho[:, None] * normal

    def shape_coordinates(self, points: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`map_to_cornea` for points on the shape: (x, y, depth)."""
        Ra = self.anterior_radius
        v = points - np.array([0.0, 0.0, -Ra])
        rho = np.linalg.norm(v, axis=1)
        theta = np.arccos(np.clip(v[:, 2] / rho, -1, 1))
        phi = np.arctan2(v[:, 1], v[:, 0])
        r = Ra * np.sin(theta)
        return np.column_stack([r * np.cos(phi), r * np.sin(phi), (Ra - rho) / self.thickness(theta)])

    @property
    def azimuths(self) -> int:
        step = math.lcm(8, max(self.incisions, 1))
        return step * math.ceil(self.azimuthal_divisions / step)


def _levels(start: float, end: float, size: float) -> np.ndarray:
    count = max(1, math.ceil((end - start) / size - 1e-9))
    return np.linspace(start, end, count + 1)


def _radius_levels(g: CorneaGeometry) -> np.ndarray:
    """Planform radii of the polar rings: from the O-grid core's circle 0.6 × optical_zone/2
    through the optical-zone edge and the incision end to the limbus, ``mesh_size`` apart."""
    r_polar = 0.6 * g.optical_zone / 2
    return np.unique(np.concatenate([
        _levels(r_polar, g.optical_zone / 2, g.mesh_size),
        _levels(g.optical_zone / 2, g.incision_end, g.mesh_size),
        _levels(g.incision_end, g.diameter / 2, g.mesh_size) if g.incision_end < g.diameter / 2
        else [g.incision_end]]))


def cell_count(g: CorneaGeometry) -> int:
    """The number of hexahedra :func:`cornea` builds for ``g``, from the level counts alone
    (nothing is meshed): the O-grid core's (azimuths/4)² quads, one ring of quads per radius
    level, times the layers through the thickness; a quarter cornea holds a quarter of them
    (its azimuths are a multiple of 8, so no cell straddles a symmetry plane)."""
    n_theta = g.azimuths
    quads = (n_theta // 4) ** 2 + n_theta * len(_radius_levels(g))
    cells = quads * (len(_depth_levels(g)) - 1)
    return cells // 4 if g.quarter else cells


def bending_length(anterior_radius: float, central_thickness: float) -> float:
    """√(R t): the length over which a thin spherical shell's bending disturbances (the
    clamped or sprung limbus, the free edges of a cut) decay into its membrane state
    (Timoshenko & Woinowsky-Krieger, *Theory of Plates and Shells*, 1959, §§ 130–131:
    the decay length is √(R t)/[3(1 − ν²)]^¼). The planform element size of the cornea
    scenes is this length over their ``resolution``."""
    return math.sqrt(anterior_radius * central_thickness)


def _planform(g: CorneaGeometry):
    """2D nodes, quads (CCW), the polar grid index of each polar node, radius levels."""
    n_theta = g.azimuths
    n_core = n_theta // 4
    r_polar = 0.6 * g.optical_zone / 2
    a = r_polar / (math.sqrt(2) * 1.5)  # core half side: corners at 0.67 r_polar
    # O-grid core
    s = np.linspace(-a, a, n_core + 1)
    core = np.array([[x, y] for y in s for x in s])
    core_id = lambda i, m: m * (n_core + 1) + i
    quads = [[core_id(i, m), core_id(i + 1, m), core_id(i + 1, m + 1), core_id(i, m + 1)]
             for m in range(n_core) for i in range(n_core)]
    # its perimeter, counter-clockwise from the middle of the right side (azimuth 0)
    h = n_core // 2
    perimeter = ([core_id(n_core, m) for m in range(h, n_core)]
                 + [core_id(i, n_core) for i in range(n_core, 0, -1)]
                 + [core_id(0, m) for m in range(n_core, 0, -1)]
                 + [core_id(i, 0) for i in range(0, n_core)]
                 + [core_id(n_core, m) for m in range(0, h)])
    assert len(perimeter) == n_theta
    radii = _radius_levels(g)
    phi = 2 * math.pi * np.arange(n_theta) / n_theta
    polar = np.array([[r * math.cos(p), r * math.sin(p)] for r in radii for p in phi])
    nodes = np.vstack([core, polar])
    polar_id = lambda j, k: len(core) + j * n_theta + (k % n_theta)
    for k in range(n_theta):  # the ring from the square to the first circle
        quads.append([perimeter[k], polar_id(0, k), polar_id(0, k + 1), perimeter[(k + 1) % n_theta]])
    for j in range(len(radii) - 1):
        for k in range(n_theta):
            quads.append([polar_id(j, k), polar_id(j + 1, k), polar_id(j + 1, k + 1), polar_id(j, k + 1)])
    return nodes, np.array(quads), radii, polar_id, n_theta


def _depth_levels(g: CorneaGeometry) -> np.ndarray:
    upper = max(1, round(g.layers * g.incision_depth))
    lower = max(1, g.layers - upper)
    return np.unique(np.concatenate([np.linspace(0, g.incision_depth, upper + 1),
                                     np.linspace(g.incision_depth, 1, lower + 1)]))


def _hexahedra(g: CorneaGeometry):
    """3D nodes, hexahedra (gmsh order) and tagged quads, with the cuts made."""
    nodes2d, quads, radii, polar_id, n_theta = _planform(g)
    depths = _depth_levels(g)
    n2d, n_layers = len(nodes2d), len(depths) - 1
    points = np.vstack([g.map_to_cornea(nodes2d, d) for d in depths])
    node3d = lambda node, level: level * n2d + node
    # deeper level first: (v1 − v0) × (v3 − v0) then points towards the anterior side
    hexes = np.array([[node3d(q, l + 1) for q in quad] + [node3d(q, l) for q in quad]
                      for l in range(n_layers) for quad in quads])
    cell_layer = np.repeat(np.arange(n_layers), len(quads))
    cell_quad = np.tile(np.arange(len(quads)), n_layers)
    n_core_quads = len(quads) - n_theta * len(radii)  # core + square-to-circle ring
    polar_cell = lambda j, k, l: l * len(quads) + n_core_quads + n_theta + j * n_theta + k % n_theta

    j_a = int(np.argmin(abs(radii - g.optical_zone / 2)))
    j_b = int(np.argmin(abs(radii - g.incision_end)))
    l_d = int(np.argmin(abs(depths - g.incision_depth)))
    opens_at_limbus = j_b == len(radii) - 1
    incision_faces = []
    copies: dict[int, int] = {}
    for i in range(g.incisions):
        k = i * n_theta // g.incisions
        inner = range(j_a + 1, j_b + 1 if opens_at_limbus else j_b)
        mine = {}  # only this cut's nodes: with cuts on neighbouring grid lines a cell
        # lies between two cuts and must keep the other line's original nodes
        for level in range(l_d):  # the bottom level of the cut stays connected
            for j in inner:
                mine[node3d(polar_id(j, k), level)] = len(points) + len(copies) + len(mine)
        copies.update(mine)
        for level in range(l_d):
            for j in range(j_a, j_b):
                ccw, cw = polar_cell(j, k, level), polar_cell(j, k - 1, level)
                hexes[ccw] = [mine.get(v, v) for v in hexes[ccw]]
                b, t = hexes[ccw][:4], hexes[ccw][4:]
                incision_faces.append([b[0], b[1], t[1], t[0]])
                b, t = hexes[cw][:4], hexes[cw][4:]
                incision_faces.append([b[3], b[2], t[2], t[3]])
    originals = np.array(sorted(copies, key=copies.get), dtype=int)
    points = np.vstack([points, points[originals]]) if len(originals) else points
    top = [list(h[4:]) for h, l in zip(hexes, cell_layer) if l == 0]
    bottom = [list(h[:4]) for h, l in zip(hexes, cell_layer) if l == n_layers - 1]
    outer = [[h[1], h[2], h[6], h[5]] for h, q in zip(hexes, cell_quad)
             if q >= len(quads) - n_theta]
    faces = {"anterior": top, "posterior": bottom, "limbus": outer, "incision": incision_faces}
    if g.quarter:
        return _quarter(g, points, hexes, faces)
    return points, hexes, faces


def _quarter(g: CorneaGeometry, points: np.ndarray, hexes: np.ndarray, faces: dict):
    """The cells in x > 0, y > 0 of the whole cornea, renumbered, with the faces on the
    planes x = 0 and y = 0 tagged ``symmetry_x`` / ``symmetry_y``. The planform has grid
    lines at azimuths 0 and 90° (its azimuths are a multiple of 8 and the O-grid core has
    an even side), so no cell straddles a plane. A cut on a plane keeps the lip of the
    kept side: the wound face is free, the tissue under it is on the symmetry plane."""
    centroids = points[hexes].mean(axis=1)
    hexes = hexes[(centroids[:, 0] > 0) & (centroids[:, 1] > 0)]
    used = np.unique(hexes)
    new_id = np.full(len(points), -1, dtype=int)
    new_id[used] = np.arange(len(used))
    kept = {name: [list(new_id[q]) for q in quads if np.all(new_id[q] >= 0)]
            for name, quads in faces.items()}
    points, hexes = points[used], new_id[hexes]
    tolerance = 1e-9 * g.diameter
    wound = {tuple(sorted(q)) for q in kept["incision"]}
    for name, axis in (("symmetry_x", 0), ("symmetry_y", 1)):
        kept[name] = [list(h[list(f)]) for h in hexes for f in HEX27_FACES
                      if np.all(abs(points[h[list(f)], axis]) < tolerance)
                      and tuple(sorted(h[list(f)])) not in wound]
    return points, hexes, kept


def _mean_shape_point(rows: np.ndarray, polar_from: float) -> np.ndarray:
    """Mean of (x, y, depth) rows; in the polar part of the planform the mean of the
    radius and the azimuth, so that nodes between two rays stay on their ring."""
    mean = rows.mean(axis=0)
    r = np.hypot(rows[:, 0], rows[:, 1])
    if np.all(r >= polar_from):
        direction = (rows[:, :2] / r[:, None]).mean(axis=0)
        mean[:2] = r.mean() * direction / np.linalg.norm(direction)
    return mean


def _quadratic(g: CorneaGeometry, points: np.ndarray, hexes: np.ndarray, faces: dict):
    """Hexahedra-27 and quadrangles-9 whose extra nodes lie on the shape: each mid-edge,
    mid-face and centre node is the mean of its vertices' (planform x, y, depth)
    coordinates mapped by :meth:`CorneaGeometry.map_to_cornea`, so the anterior and
    posterior faces lie on their curved surfaces instead of being flat facets. Extra
    nodes are keyed by their vertex set, so a cut (duplicated vertices) stays open and
    neighbouring cells share them otherwise."""
    shape = g.shape_coordinates(points)
    polar_from = 0.6 * g.optical_zone / 2 * (1 - 1e-9)  # _planform's r_polar
    keys: dict[tuple, int] = {}
    extra: list[np.ndarray] = []

    def node(vertices) -> int:
        key = tuple(sorted(int(v) for v in vertices))
        if key not in keys:
            keys[key] = len(points) + len(extra)
            extra.append(_mean_shape_point(shape[list(key)], polar_from))
        return keys[key]

    hex27 = np.array([list(h) + [node(h[list(e)]) for e in HEX27_EDGES]
                      + [node(h[list(f)]) for f in HEX27_FACES] + [node(h)] for h in hexes])
    quad9 = {name: [list(q) + [node(np.array(q)[list(e)]) for e in QUAD9_EDGES] + [node(q)]
                    for q in quads] for name, quads in faces.items()}
    new = g.map_to_cornea(np.array(extra)[:, :2], 0.0) if extra else np.zeros((0, 3))
    if extra:  # map_to_cornea takes one depth; apply each node's own along its normal
        depth = np.array(extra)[:, 2]
        centre = np.array([0.0, 0.0, -g.anterior_radius])
        normal = (new - centre) / g.anterior_radius
        r = np.hypot(np.array(extra)[:, 0], np.array(extra)[:, 1])
        theta = np.arcsin(np.clip(r / g.anterior_radius, 0, 1))
        new = centre + (g.anterior_radius - depth * g.thickness(theta))[:, None] * normal
    return np.vstack([points, new]), hex27, quad9


def cornea(geometry: CorneaGeometry, comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    """The cornea of ``geometry`` as a distributed DOLFINx mesh with named tags."""
    geometry.validate()
    points, hexes, faces = _hexahedra(geometry) if comm.rank == 0 else (None, None, None)
    cell_type, facet_type, facet_nodes = HEX8, QUAD4, 4
    if geometry.geometry_degree == 2:
        cell_type, facet_type, facet_nodes = HEX27, QUAD9, 9
        if comm.rank == 0:
            points, hexes, faces = _quadratic(geometry, points, hexes, faces)

    def build(model):
        model.addDiscreteEntity(3, 1)
        model.mesh.addNodes(3, 1, np.arange(1, len(points) + 1), points.ravel())
        model.mesh.addElementsByType(1, cell_type, np.arange(1, len(hexes) + 1), (hexes + 1).ravel())
        model.addPhysicalGroup(3, [1], tag=1, name="cornea")
        next_element = len(hexes) + 1
        for tag, name in enumerate(FACET_NAMES, start=1):
            quads = np.array(faces.get(name, []), dtype=int).reshape(-1, facet_nodes)
            if len(quads) == 0:
                continue
            model.addDiscreteEntity(2, tag)
            model.mesh.addElementsByType(tag, facet_type, np.arange(next_element, next_element + len(quads)),
                                         (quads + 1).ravel())
            next_element += len(quads)
            model.addPhysicalGroup(2, [tag], tag=tag, name=name)

    return from_gmsh(build, comm)
