"""A layered half eye for scleral buckling: hexahedral tissue shells with a detached
retina, a causative tear and an optic-nerve stub.

Coordinates: the optic axis is z (anterior +z, posterior pole at z = −R), the model is
the half x ≥ 0 and the symmetry plane x = 0 passes through the tear at the top (+y),
as in Sun & Makinouchi (seed 002, §3.1).

Construction
- The eye wall is a structured layered shell: a half cubed sphere (equiangular
  gnomonic patches, so no degenerate cells at the poles) gives the surface grid, and
  radial levels give the layers: ``coat_layers`` for the sclera/cornea, one for the
  choroid (ciliary body anterior of the ora serrata), one for the retina. Each cell's
  tissue follows from its layer and its polar angle θ from the anterior pole.
- The outer surface is the scleral sphere (radius ``sclera_radius``) and, anterior of
  the limbus, the corneal sphere (radius ``cornea_radius``) that meets it on the limbus
  circle of diameter ``cornea_diameter``.
- In the detached zone the retina's outer nodes are duplicated and the retina is lifted
  inward by a smooth bump of height ``detachment_height``: a subretinal space that the
  liquid fills through the tear. The zone ends where the bump reaches zero, so the
  retina is attached at its rim.
- The tear removes the retina cells over a block of surface quads about its centre (on
  the symmetry plane, so the model holds half of it) whose rim nodes are moved onto the
  circle at geodesic distance ``tear_radius`` from the centre, the move spread over the
  hole and one ring of quads around it (:func:`_conform_tear`): the rim is on its circle
  on every mesh (tests/test_eye_mesh.py), not on the grid lines. ``tear_radius = 0`` and
  ``detachment_height = 0`` give an intact, attached retina: then the whole model has
  the cube's symmetries about the optic axis (mirror y → −y, swap x ↔ y).
- The optic-nerve stub is the outer-surface patch within ``optic_nerve_radius`` of the
  posterior pole extruded backwards; its end is where the eye is held.
- The lens (``lens=True``) is a separate hexahedral body inside the liquid: a half
  ellipsoid (equatorial ``lens_diameter``, axial ``lens_thickness``) meshed as a
  "cubed ball" (a structured cube grid, each point pushed radially onto the concentric
  sphere its cube shell belongs to, x ↦ x‖x‖∞/‖x‖₂, then scaled), its anterior pole
  ``lens_depth`` behind the corneal apex. It shares no node with the eye wall: it hangs
  on the zonules, which are not cells but node pairs (:func:`zonule_pairs`, bars
  between the lens's equatorial belt and the ciliary body's inner surface, added to the
  residual by :class:`eyemech.problems.solid.zonules.ZonuleBars`). Its whole surface is wetted
  (``lens_surface`` is part of ``cavity_wall``): with the solid's outward normal on every
  wetted face, V = −⅓∮ x·n da over the eye's inner wall *and* the lens surface is the
  liquid's volume, the lens's own volume excluded, exactly (both are closed, with the
  symmetry plane through the origin), and the liquid pressure acts on all sides of it.

Why not gmsh's CAD kernel: revolving a meridian profile about the optic axis gives
degenerate wedges on the axis, and O-grid blocking of eight layered tissues in OCC is
brittle. The structured grid is computed here and handed to gmsh as a discrete model,
so that it is a gmsh mesh (``.msh`` export, gmsh's viewer) distributed by DOLFINx like
every other mesh of the project.

Default dimensions (mm) and sources
- Scleral outer radius 11.5 and corneal radius 7.8 with corneal diameter 11.7 give an
  axial length ≈ 24 mm (Atchison & Smith, *Optics of the Human Eye*, 2000).
- Scleral thickness ≈ 0.8 at the limbus, 0.5 near the equator, 1.0 at the posterior pole
  (Olsen et al., Am J Ophthalmol 125:237, 1998); central corneal thickness 0.52 rising to
  0.67 at the limbus; choroid ≈ 0.25, retina ≈ 0.2 (Alamouti & Funk, Br J Ophthalmol 87, 2003).
- The ora serrata ≈ 7 mm posterior of the limbus (θ ≈ 65°); the ciliary body between.
- Optic nerve ≈ 3 mm in diameter.
- Lens: equatorial diameter 9.0 mm and central thickness 4.0 mm of the adult
  unaccommodated lens (Rosen et al., Vision Res 46:1002, 2006: 8.8–9.6 mm in vitro;
  Atchison & Smith 2000, Table 2.1: 3.6–4.0 mm); its anterior pole 3.6 mm behind the
  corneal apex (anterior chamber depth 3.1 mm + cornea 0.5 mm; Gullstrand–Le Grand eye,
  Atchison & Smith 2000). The real lens is an asymmetric biconvex body (anterior radius
  ≈ 10 mm, posterior ≈ 6 mm); an ellipsoid of the same diameter and thickness is enough
  for a body 120 times stiffer than Table 1's sclera (c 10 against 0.0833 MPa) that only
  transmits the zonules' pull.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from mpi4py import MPI

from eyemech.meshes.tagged import MeshError, TaggedMesh, from_gmsh

TISSUES = ("cornea", "sclera", "ciliary_body", "choroid", "retina", "optic_nerve", "lens")
FACETS = ("symmetry", "cornea_outer", "sclera_outer", "optic_nerve_side", "optic_nerve_end",
          "retina_inner", "retina_detached", "choroid_detached", "tear_edge", "lens_surface")
# every face the liquid wets: the vitreous side, the subretinal space, the tear's edges,
# and all of the lens (it floats in the liquid, held by the zonules)
CAVITY_WALL = ("retina_inner", "retina_detached", "choroid_detached", "tear_edge", "lens_surface")
RESOLUTIONS = {"coarse": 8, "default": 12, "paper": 26}  # cells along a cube edge
# rings of surface quads around the tear's hole over which its rim's move onto the circle
# is spread (:func:`_conform_tear`). One: the cells stay as well shaped as the grid-line
# rim's (tests/test_eye_mesh.py), and on the coarse and default meshes a second ring reaches
# the ora serrata's cells, where a moved centroid changes the tissue of a cell.
TEAR_BAND = 1


@dataclasses.dataclass(frozen=True)
class EyeGeometry:
    sclera_radius: float = 11.5
    cornea_radius: float = 7.8
    cornea_diameter: float = 11.7
    cornea_thickness_center: float = 0.52
    cornea_thickness_limbus: float = 0.67
    sclera_thickness_limbus: float = 0.8
    sclera_thickness_equator: float = 0.5
    sclera_thickness_posterior: float = 1.0
    choroid_thickness: float = 0.25
    ciliary_body_thickness: float = 0.6
    retina_thickness: float = 0.2
    ora_serrata_angle: float = 65.0        # degrees from the anterior pole
    detachment_from: float = 72.0          # polar angles bounding the detached zone (deg)
    detachment_to: float = 115.0
    detachment_half_width: float = 40.0    # azimuth half-width about the tear (deg)
    detachment_height: float = 0.5         # subretinal gap at the centre (mm)
    tear_angle: float = 88.0               # polar angle of the tear centre (deg)
    tear_radius: float = 1.6               # mm (0: no tear)
    optic_nerve_radius: float = 1.5
    optic_nerve_length: float = 3.0
    coat_layers: int = 2
    cells_per_edge: int = 12               # cubed-sphere cells along a cube edge (even)
    lens: bool = True                      # the lens body (and, in a scene, its zonules)
    lens_diameter: float = 9.0             # equatorial (mm)
    lens_thickness: float = 4.0            # axial (mm)
    lens_depth: float = 3.6                # corneal apex to the lens's anterior pole (mm)
    lens_cells: int = 4                    # cells along an edge of the lens's cube (even)

    def validate(self) -> None:
        if self.cells_per_edge % 2 or self.cells_per_edge < 4:
            raise MeshError("cells_per_edge must be an even number >= 4")
        if self.coat_layers < 1:
            raise MeshError("coat_layers must be >= 1")
        if not self.ora_serrata_angle < self.detachment_from < self.tear_angle < self.detachment_to:
            raise MeshError("need ora serrata < detachment start < tear angle < detachment end")
        if self.cornea_diameter / 2 >= self.sclera_radius or self.cornea_radius <= self.cornea_diameter / 2:
            raise MeshError("the cornea must be a cap smaller than the scleral sphere")
        element = self.element_size
        if element / self.retina_thickness > 12.0:
            raise MeshError(
                f"resolution too coarse to resolve the retina: elements of {element:.2f} mm on a "
                f"{self.retina_thickness} mm layer (aspect ratio > 12); raise cells_per_edge")
        if self.lens:
            self._validate_lens()
        zone = math.radians(self.detachment_to - self.detachment_from) * self.sclera_radius
        if zone / element < 3:
            raise MeshError(f"resolution too coarse: the detached zone spans {zone / element:.1f} "
                            "elements (need at least 3)")

    def _validate_lens(self) -> None:
        if self.lens_cells % 2 or self.lens_cells < 2:
            raise MeshError("lens_cells must be an even number >= 2")
        if not (self.lens_diameter > 0 and self.lens_thickness > 0 and self.lens_depth > 0):
            raise MeshError("lens_diameter, lens_thickness and lens_depth must be > 0")
        apex = self.cornea_center + self.cornea_radius
        inner_apex = apex - self.cornea_thickness_center
        if self.lens_depth <= self.cornea_thickness_center:
            raise MeshError(f"lens_depth {self.lens_depth} mm puts the lens inside the cornea "
                            f"(central thickness {self.cornea_thickness_center} mm)")
        # the wall's inner surface is at least this far from the origin behind the limbus
        inner = self.sclera_radius - max(self.sclera_thickness_limbus, self.sclera_thickness_posterior,
                                         self.sclera_thickness_equator) \
            - max(self.ciliary_body_thickness, self.choroid_thickness) - self.retina_thickness
        centre = self.lens_centre
        a, b = self.lens_diameter / 2, self.lens_thickness / 2
        t = np.linspace(0, math.pi, 91)
        rim = np.hypot(a * np.sin(t), centre + b * np.cos(t))
        if rim.max() >= inner or centre + b >= inner_apex:
            raise MeshError("the lens does not fit inside the eye (lens_diameter, lens_thickness "
                            "or lens_depth too large)")

    @property
    def bending_length(self) -> float:
        """√(R t) of the scleral shell at its thinnest (the equator): the length over which
        a spherical shell's bending disturbances (the buckle's indentation, the limbus, the
        optic nerve) decay into its membrane state (Timoshenko & Woinowsky-Krieger, *Theory
        of Plates and Shells*, 1959, §§ 130–131: √(R t)/[3(1 − ν²)]^¼)."""
        return math.sqrt(self.sclera_radius * self.sclera_thickness_equator)

    @property
    def element_size(self) -> float:
        """In-plane size of the wall's cells: a quarter great circle over ``cells_per_edge``."""
        return 0.5 * math.pi * self.sclera_radius / self.cells_per_edge

    def cells_per_edge_for(self, size: float) -> int:
        """The even cube-edge count (≥ 4) whose cells are at most ``size`` wide in-plane."""
        return max(4, 2 * math.ceil(0.25 * math.pi * self.sclera_radius / size - 1e-9))

    @property
    def estimated_cells(self) -> int:
        """Hexahedra before meshing: the half cubed sphere's 3 n² quads times the wall's
        layers (coat, choroid, retina), plus the lens's half cube; the optic-nerve stub
        adds and the tear removes a few cells (within 1 % at n = 8 and 12:
        tests/test_eye_mesh.py)."""
        n = self.cells_per_edge
        lens = self.lens_cells ** 3 // 2 if self.lens else 0
        return (self.coat_layers + 2) * 3 * n * n + lens

    @property
    def lens_centre(self) -> float:
        """z of the lens's centre."""
        return self.cornea_center + self.cornea_radius - self.lens_depth - self.lens_thickness / 2

    # -- derived geometry ---------------------------------------------------------
    @property
    def limbus(self) -> tuple[float, float]:
        """(ρ, z) of the limbus circle, where the corneal and scleral spheres meet."""
        rho = self.cornea_diameter / 2
        return rho, math.sqrt(self.sclera_radius**2 - rho**2)

    @property
    def cornea_center(self) -> float:
        rho, z = self.limbus
        return z - math.sqrt(self.cornea_radius**2 - rho**2)

    @property
    def limbus_angle(self) -> float:
        rho, z = self.limbus
        return math.degrees(math.atan2(rho, z))

    @property
    def axial_length(self) -> float:
        return self.cornea_center + self.cornea_radius + self.sclera_radius


def _smoothstep(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _half_cubed_sphere(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions and quads of the half sphere x ≥ 0, equiangular patches."""
    t = np.tan(np.linspace(-np.pi / 4, np.pi / 4, n + 1))
    half = t[n // 2:]
    patches = [  # (direction maker, first-parameter values)
        (lambda a, b: np.stack([np.ones_like(a), a, b], -1), t),     # +x
        (lambda a, b: np.stack([a, np.ones_like(a), b], -1), half),  # +y, x = a ≥ 0
        (lambda a, b: np.stack([a, -np.ones_like(a), b], -1), half),  # −y
        (lambda a, b: np.stack([a, b, np.ones_like(a)], -1), half),  # +z
        (lambda a, b: np.stack([a, b, -np.ones_like(a)], -1), half),  # −z
    ]
    points, quads, offset = [], [], 0
    for make, first in patches:
        a, b = np.meshgrid(first, t, indexing="ij")
        p = make(a, b)
        p /= np.linalg.norm(p, axis=-1, keepdims=True)
        na, nb = a.shape
        index = offset + np.arange(na * nb).reshape(na, nb)
        quads.append(np.stack([index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]],
                              -1).reshape(-1, 4))
        points.append(p.reshape(-1, 3))
        offset += na * nb
    points = np.vstack(points)
    quads = np.vstack(quads)
    # patches share their edges: merge coincident directions
    _, first_index, inverse = np.unique(np.round(points, 9), axis=0, return_index=True,
                                        return_inverse=True)
    return points[first_index], inverse.ravel()[quads]


def _outer_radius(geo: EyeGeometry, theta: np.ndarray) -> np.ndarray:
    """Distance from the origin to the outer surface along polar angle θ (radians)."""
    zc = geo.cornea_center
    cornea = zc * np.cos(theta) + np.sqrt(geo.cornea_radius**2 - (zc * np.sin(theta))**2)
    return np.where(theta < math.radians(geo.limbus_angle), cornea, geo.sclera_radius)


def _layer_thicknesses(geo: EyeGeometry, theta: np.ndarray) -> np.ndarray:
    """(n, 3) thicknesses of coat, choroid layer and retina layer along θ (radians).

    Anterior of the limbus the three layers are thirds of the cornea; posterior they are
    sclera, choroid (ciliary body before the ora) and retina. The tissue jumps at the
    limbus and the ora are blended over a few degrees so the cells stay regular."""
    deg = np.degrees(theta)
    limbus, ora = geo.limbus_angle, geo.ora_serrata_angle
    cornea = geo.cornea_thickness_center + (geo.cornea_thickness_limbus - geo.cornea_thickness_center) \
        * (deg / limbus) ** 2
    sclera = np.interp(deg, [limbus, 90.0, 180.0], [geo.sclera_thickness_limbus,
                                                     geo.sclera_thickness_equator,
                                                     geo.sclera_thickness_posterior])
    middle = geo.ciliary_body_thickness + (geo.choroid_thickness - geo.ciliary_body_thickness) \
        * _smoothstep((deg - ora + 3.0) / 6.0)
    posterior = np.stack([sclera, middle, np.full_like(deg, geo.retina_thickness)], -1)
    anterior = np.stack([0.5 * cornea, 0.25 * cornea, 0.25 * cornea], -1)
    blend = _smoothstep((deg - limbus + 2.0) / 4.0)[:, None]
    return (1 - blend) * anterior + blend * posterior


def _detachment(geo: EyeGeometry, directions: np.ndarray) -> np.ndarray:
    """Subretinal gap (mm) at each surface direction: a smooth bump, zero outside."""
    theta = np.degrees(np.arccos(np.clip(directions[:, 2], -1, 1)))
    azimuth = np.degrees(np.abs(np.arctan2(directions[:, 0], directions[:, 1])))  # 0 on +y
    ramp = 6.0  # degrees over which the retina rises
    bump = (_smoothstep((theta - geo.detachment_from) / ramp)
            * _smoothstep((geo.detachment_to - theta) / ramp)
            * _smoothstep((geo.detachment_half_width - azimuth) / ramp))
    return geo.detachment_height * bump


@dataclasses.dataclass
class EyeGrid:
    """The structured mesh before it becomes a gmsh model (all numpy, rank 0)."""

    points: np.ndarray            # (n, 3)
    hexes: np.ndarray             # (m, 8) gmsh ordering
    tissue: np.ndarray            # (m,) index into TISSUES
    faces: dict[str, np.ndarray]  # facet name -> (k, 4) quads


def build_grid(geo: EyeGeometry) -> EyeGrid:
    geo.validate()
    directions, quads = _half_cubed_sphere(geo.cells_per_edge)
    hole = _tear_quads(geo, directions, quads) if geo.tear_radius > 0 else np.zeros(len(quads), bool)
    if hole.any():
        directions = _conform_tear(geo, directions, quads, hole)
    n_dir = len(directions)
    theta = np.arccos(np.clip(directions[:, 2], -1, 1))
    thickness = _layer_thicknesses(geo, theta)
    gap = _detachment(geo, directions)
    detached = gap > 1e-12

    # radial levels from outside in: coat levels, choroid/retina interface, retina inner
    outer = _outer_radius(geo, theta)
    coat_levels = [outer - thickness[:, 0] * k / geo.coat_layers for k in range(geo.coat_layers + 1)]
    interface = coat_levels[-1] - thickness[:, 1]
    retina_inner = interface - thickness[:, 2] - gap
    radii = coat_levels + [interface, retina_inner]  # choroid side of the interface
    points = [directions * r[:, None] for r in radii]
    level_index = [np.arange(n_dir) + k * n_dir for k in range(len(radii))]
    # the retina side of the interface: new nodes only where the retina is lifted
    lifted = np.flatnonzero(detached)
    retina_outer_index = level_index[-2].copy()
    retina_outer_index[lifted] = len(radii) * n_dir + np.arange(len(lifted))
    points.append(directions[lifted] * (interface[lifted] - gap[lifted])[:, None])
    points = np.vstack(points)

    layers = [(level_index[k], level_index[k + 1]) for k in range(geo.coat_layers)]
    layers.append((level_index[-3], level_index[-2]))        # choroid layer
    layers.append((retina_outer_index, level_index[-1]))     # retina layer
    hexes, tissue, layer_of = [], [], []
    quad_theta = np.degrees(theta[quads].mean(axis=1))
    for number, (out_idx, in_idx) in enumerate(layers):
        hexes.append(np.hstack([in_idx[quads], out_idx[quads]]))
        layer_of.append(np.full(len(quads), number))
        tissue.append(_tissue(geo, number, quad_theta))
    hexes, tissue, layer_of = np.vstack(hexes), np.concatenate(tissue), np.concatenate(layer_of)

    keep = ~_tear_cells(geo, hole, layer_of == geo.coat_layers + 1)
    hexes, tissue = hexes[keep], tissue[keep]
    points, hexes, tissue = _add_optic_nerve(geo, points, hexes, tissue, level_index[0], quads)
    if geo.lens:
        points, hexes, tissue = _add_lens(geo, points, hexes, tissue)
    hexes = _orient(points, hexes)
    faces = _classify_faces(geo, points, hexes, tissue, level_index, retina_outer_index, lifted)
    # the tear leaves nodes no cell uses; DOLFINx expects every node to be in a cell
    used, renumber = np.unique(hexes, return_inverse=True)
    old_to_new = np.full(len(points), -1)
    old_to_new[used] = np.arange(len(used))
    return EyeGrid(points[used], renumber.reshape(hexes.shape), tissue,
                   {name: old_to_new[quads] for name, quads in faces.items()})


def _tissue(geo: EyeGeometry, layer: int, theta_deg: np.ndarray) -> np.ndarray:
    index = {name: i for i, name in enumerate(TISSUES)}
    anterior = theta_deg < geo.limbus_angle
    ciliary = theta_deg < geo.ora_serrata_angle
    if layer < geo.coat_layers:
        inner = np.full(len(theta_deg), index["sclera"])
    else:
        inner = np.full(len(theta_deg), index["choroid" if layer == geo.coat_layers else "retina"])
        inner[ciliary] = index["ciliary_body"]
    inner[anterior] = index["cornea"]
    return inner


def _tear_cells(geo: EyeGeometry, hole: np.ndarray, retina: np.ndarray) -> np.ndarray:
    """Mask of the cells the tear removes: the retina's cells over the hole's quads (the
    wall's cells are stacked layer by layer in the surface grid's quad order)."""
    tear = retina & np.tile(hole, len(retina) // len(hole))
    if geo.tear_radius > 0 and not tear.any():
        raise MeshError(f"resolution too coarse to resolve the tear (radius {geo.tear_radius} mm): "
                        "no retina cell falls inside it; raise cells_per_edge or tear_radius")
    return tear


def _tear_frame(geo: EyeGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tear's centre c on the unit sphere and the tangent basis there: e1 = +x (out of
    the symmetry plane), e2 towards larger polar angle (posterior)."""
    tau = math.radians(geo.tear_angle)
    centre = np.array([0.0, math.sin(tau), math.cos(tau)])
    return centre, np.array([1.0, 0.0, 0.0]), np.array([0.0, math.cos(tau), -math.sin(tau)])


def _to_tear_plane(geo: EyeGeometry, directions: np.ndarray) -> np.ndarray:
    """(n, 2) geodesic polar coordinates about the tear's centre on the sclera's sphere,
    as Cartesian w = R s (cos φ, sin φ) (the azimuthal equidistant map: |w| is the
    geodesic distance from the centre on the sclera's sphere)."""
    centre, e1, e2 = _tear_frame(geo)
    s = np.arccos(np.clip(directions @ centre, -1.0, 1.0))
    tangent = np.stack([directions @ e1, directions @ e2], -1)
    norm = np.linalg.norm(tangent, axis=1, keepdims=True)
    unit = np.divide(tangent, norm, out=np.zeros_like(tangent), where=norm > 0)
    return geo.sclera_radius * s[:, None] * unit


def _from_tear_plane(geo: EyeGeometry, w: np.ndarray) -> np.ndarray:
    """Unit directions of the tear-plane points ``w`` (inverse of :func:`_to_tear_plane`)."""
    centre, e1, e2 = _tear_frame(geo)
    length = np.linalg.norm(w, axis=1)
    s = length / geo.sclera_radius
    unit = np.divide(w, length[:, None], out=np.zeros_like(w), where=length[:, None] > 0)
    return (np.cos(s)[:, None] * centre
            + np.sin(s)[:, None] * (unit[:, :1] * e1 + unit[:, 1:] * e2))


def _tear_quads(geo: EyeGeometry, directions: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Mask of the surface quads that become the tear's hole: a block of quads. It starts
    from those whose mean direction lies in the half square |w₁|, |w₂| < ``tear_radius``
    about the tear's centre (tear-plane coordinates, :func:`_to_tear_plane`: the quads
    between the grid lines nearest to the circle's extremes) and takes in every quad with
    two edges on the hole (where the grid lines bend in the tear plane) until none is
    left. A block and not the quads inside the circle: a staircase hole has inner corners,
    and the outside quad at an inner corner has three rim nodes, which on the convex
    circle make its middle corner reflex (an inverted cell); a block has none."""
    w = _to_tear_plane(geo, directions)
    hole = np.all(np.abs(w[quads].mean(axis=1)) < geo.tear_radius, axis=1)
    edges = np.sort(quads[:, [[0, 1], [1, 2], [2, 3], [3, 0]]], axis=2).reshape(-1, 2)
    _, edge_id = np.unique(edges, axis=0, return_inverse=True)
    edge_id = edge_id.reshape(len(quads), 4)
    while hole.any():
        on_hole = np.zeros(edge_id.max() + 1, bool)
        on_hole[edge_id[hole]] = True
        inner_corner = ~hole & (on_hole[edge_id].sum(axis=1) >= 2)
        if not inner_corner.any():
            break
        hole |= inner_corner
    return hole


def _rim_path(quads: np.ndarray, hole: np.ndarray, on_plane: np.ndarray) -> np.ndarray:
    """The hole's rim as an ordered node path from one symmetry-plane node to the other:
    the hole's edges that no other hole quad shares, less those on the symmetry plane."""
    edges = np.sort(quads[hole][:, [[0, 1], [1, 2], [2, 3], [3, 0]]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    rim = unique[(counts == 1) & ~(on_plane[unique[:, 0]] & on_plane[unique[:, 1]])]
    neighbours: dict[int, list[int]] = {}
    for a, b in rim:
        neighbours.setdefault(int(a), []).append(int(b))
        neighbours.setdefault(int(b), []).append(int(a))
    ends = [n for n, near in neighbours.items() if len(near) == 1]
    if len(ends) != 2 or any(len(near) > 2 for near in neighbours.values()) \
            or not all(on_plane[ends]):
        raise MeshError("the tear's hole on this grid is not a single patch on the symmetry "
                        "plane; change cells_per_edge or tear_radius")
    path = [ends[0]]
    while len(path) < len(neighbours):
        step = [n for n in neighbours[path[-1]] if len(path) < 2 or n != path[-2]]
        path.append(step[0])
    if path[-1] != ends[1]:
        raise MeshError("the tear's rim on this grid is not one path; change cells_per_edge")
    return np.array(path)


def _conform_tear(geo: EyeGeometry, directions: np.ndarray, quads: np.ndarray,
                  hole: np.ndarray) -> np.ndarray:
    """Directions with the tear's rim on its circle: the rim nodes of the ``hole`` (the quads
    of :func:`_tear_quads`) moved onto the geodesic circle of radius ``tear_radius`` about the
    tear's centre, and the move spread harmonically (the graph Laplacian of the surface
    grid) over the hole's inside and ``TEAR_BAND`` rings of quads around it, falling to zero
    on the ring beyond. Without it the rim is the hole's staircase of grid lines: 1.1 mm from
    the centre in front on the 12-cell grid for a 1.6 mm tear.

    The rim nodes are spaced evenly in angle along the half circle, in their order along
    the hole's rim (the even spacing gives the best-shaped cells at the block's corners:
    tests/test_eye_mesh.py); symmetry-plane nodes slide along the plane. The move is in
    the tear's azimuthal equidistant plane, so distances from the centre are the
    geodesics the hole's quads were chosen by."""
    w = _to_tear_plane(geo, directions)
    on_plane = np.abs(directions[:, 0]) < 1e-12
    path = _rim_path(quads, hole, on_plane)
    rim_w = w[path]
    # from −90° (anterior, w₂ < 0) to +90° along the path
    angle = np.linspace(-0.5 * math.pi, 0.5 * math.pi, len(path))
    if rim_w[0, 1] > rim_w[-1, 1]:
        angle = angle[::-1]
    target = geo.tear_radius * np.stack([np.cos(angle), np.sin(angle)], -1)
    target[[0, -1], 0] = 0.0

    # the region that moves: the hole's nodes and TEAR_BAND rings of quads around them
    region = np.zeros(len(directions), bool)
    region[quads[hole]] = True
    for _ in range(TEAR_BAND):
        region[quads[region[quads].any(axis=1)]] = True
    move = np.zeros_like(w)
    move[path] = target - rim_w
    rim = np.zeros(len(directions), bool)
    rim[path] = True
    move[:, 0] = _harmonic_extension(quads, region, rim | on_plane, move[:, 0])
    move[:, 1] = _harmonic_extension(quads, region, rim, move[:, 1])
    moved = directions.copy()
    moved[region] = _from_tear_plane(geo, w[region] + move[region])
    moved[on_plane, 0] = 0.0
    return moved


def _harmonic_extension(quads: np.ndarray, region: np.ndarray, prescribed: np.ndarray,
                        value: np.ndarray) -> np.ndarray:
    """``value`` kept on the ``prescribed`` nodes and zero on the nodes next to the
    ``region`` (the ring beyond it), and in between the discrete harmonic function of the
    surface grid's edge graph (each free node the mean of its neighbours). With the rim on
    a convex circle this is Tutte's barycentric embedding inside the hole, whose faces are
    convex."""
    touching = region[quads].any(axis=1)
    nodes = np.unique(quads[touching])
    known = prescribed[nodes] | ~region[nodes]
    local = np.full(len(region), -1)
    local[nodes] = np.arange(len(nodes))
    edges = np.unique(np.sort(quads[touching][:, [[0, 1], [1, 2], [2, 3], [3, 0]]].reshape(-1, 2),
                              axis=1), axis=0)
    a, b = local[edges[:, 0]], local[edges[:, 1]]
    laplacian = np.zeros((len(nodes), len(nodes)))
    np.add.at(laplacian, (a, b), -1.0)
    np.add.at(laplacian, (b, a), -1.0)
    np.add.at(laplacian, (a, a), 1.0)
    np.add.at(laplacian, (b, b), 1.0)
    local_value = np.where(region[nodes], value[nodes], 0.0)
    free = ~known
    local_value[free] = np.linalg.solve(laplacian[np.ix_(free, free)],
                                        -laplacian[np.ix_(free, known)] @ local_value[known])
    extended = value.copy()
    extended[nodes] = local_value
    return extended


def _add_optic_nerve(geo, points, hexes, tissue, outer_level, quads):
    """Extrude the outer-surface quads near the posterior pole backwards."""
    outer_quads = outer_level[quads]
    centres = points[outer_quads].mean(axis=1)
    off_axis = np.where(centres[:, 2] < 0, np.hypot(centres[:, 0], centres[:, 1]), np.inf)
    # at coarse resolutions the nerve is at least the ring of quads around the pole
    selected = outer_quads[off_axis < max(geo.optic_nerve_radius, 1.01 * off_axis.min())]
    base = np.unique(selected)
    layers = 2
    new_points, current = [points], {int(n): int(n) for n in base}
    level_maps = [current]
    z_end = points[base, 2].min() - geo.optic_nerve_length
    count = len(points)
    for k in range(1, layers + 1):
        mapping = {}
        for n in base:
            p = points[n].copy()
            p[2] = p[2] + (z_end - p[2]) * k / layers
            mapping[int(n)] = count
            new_points.append(p[None, :])
            count += 1
        level_maps.append(mapping)
    stub = []
    for k in range(layers):
        top, bottom = level_maps[k], level_maps[k + 1]
        for quad in selected:
            stub.append([top[int(n)] for n in quad] + [bottom[int(n)] for n in quad])
    stub = np.array(stub)
    nerve = TISSUES.index("optic_nerve")
    return (np.vstack(new_points), np.vstack([hexes, stub]),
            np.concatenate([tissue, np.full(len(stub), nerve)]))


def _cubed_ball(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Points and hexes (gmsh corner order, orientation not yet fixed) of the half unit
    ball x ≥ 0: an n×n×n cube grid (x from 0), each point moved radially onto the
    sphere of radius ‖x‖∞. The map is homogeneous of degree one, so every cube shell
    becomes a sphere and the cells stay valid (worst at the cube's edges)."""
    full = np.linspace(-1.0, 1.0, n + 1)
    half = full[n // 2:]
    X, Y, Z = np.meshgrid(half, full, full, indexing="ij")
    cube = np.stack([X, Y, Z], -1).reshape(-1, 3)
    norm2 = np.linalg.norm(cube, axis=1)
    scale = np.divide(np.abs(cube).max(axis=1), norm2, out=np.zeros(len(cube)), where=norm2 > 0)
    points = cube * scale[:, None]
    index = np.arange(len(cube)).reshape(X.shape)
    bottom = [index[:-1, :-1, :-1], index[1:, :-1, :-1], index[1:, 1:, :-1], index[:-1, 1:, :-1]]
    top = [index[:-1, :-1, 1:], index[1:, :-1, 1:], index[1:, 1:, 1:], index[:-1, 1:, 1:]]
    hexes = np.stack(bottom + top, -1)
    return points, hexes.reshape(-1, 8)


def _add_lens(geo: EyeGeometry, points, hexes, tissue):
    """Append the lens body (a scaled half cubed ball, see the module docstring)."""
    unit, cells = _cubed_ball(geo.lens_cells)
    scale = np.array([geo.lens_diameter / 2, geo.lens_diameter / 2, geo.lens_thickness / 2])
    lens_points = unit * scale + np.array([0.0, 0.0, geo.lens_centre])
    lens_points[:, 0] = np.where(np.abs(lens_points[:, 0]) < 1e-12, 0.0, lens_points[:, 0])
    return (np.vstack([points, lens_points]), np.vstack([hexes, cells + len(points)]),
            np.concatenate([tissue, np.full(len(cells), TISSUES.index("lens"))]))


def lens_belt(geo: EyeGeometry, points: np.ndarray) -> np.ndarray:
    """Mask of points on the lens surface within the zonules' insertion belt: the
    equator and the capsule up to ``geo.lens_thickness/4`` in front of and behind it
    (anterior, equatorial and posterior zonular fibres; the fan keeps the lens from
    sliding or tilting along the optic axis, which bars in one plane would allow)."""
    a, b = geo.lens_diameter / 2, geo.lens_thickness / 2
    rel = points - np.array([0.0, 0.0, geo.lens_centre])
    on_surface = np.abs((rel[:, 0] / a) ** 2 + (rel[:, 1] / a) ** 2 + (rel[:, 2] / b) ** 2 - 1) < 1e-9
    return on_surface & (np.abs(rel[:, 2]) <= 0.5 * b + 1e-9)


def _orient(points, hexes):
    """Flip hexes whose (first corner) Jacobian is negative into gmsh's orientation."""
    p = points[hexes]
    det = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 3] - p[:, 0]), p[:, 4] - p[:, 0])
    flipped = hexes.copy()
    bad = det < 0
    flipped[bad] = hexes[bad][:, [0, 3, 2, 1, 4, 7, 6, 5]]
    return flipped


_HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6],
                       [3, 0, 4, 7]])


def _classify_faces(geo, points, hexes, tissue, level_index, retina_outer_index, lifted):
    """Boundary faces (faces of exactly one cell), named by where they lie."""
    faces = hexes[:, _HEX_FACES].reshape(-1, 4)
    owner = np.repeat(np.arange(len(hexes)), 6)
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    boundary = counts[inverse.ravel()] == 1
    faces, owner = faces[boundary], owner[boundary]

    level = np.full(len(points), -1)
    for k, index in enumerate(level_index):
        level[index] = k
    retina_side = np.zeros(len(points), bool)
    retina_side[retina_outer_index[lifted]] = True
    nerve = tissue[owner] == TISSUES.index("optic_nerve")
    x = points[faces]
    theta = np.degrees(np.arccos(np.clip(
        x.mean(1)[:, 2] / np.linalg.norm(x.mean(1), axis=1), -1, 1)))
    face_levels = level[faces]
    last = len(level_index) - 1
    names = np.full(len(faces), "", dtype=object)
    names[np.all(np.abs(x[:, :, 0]) < 1e-9, axis=1)] = "symmetry"
    todo = names == ""
    names[todo & (tissue[owner] == TISSUES.index("lens"))] = "lens_surface"
    todo = names == ""
    end = nerve & np.all(np.abs(x[:, :, 2] - x[:, :, 2].min()) < 1e-9, axis=1)
    names[todo & end] = "optic_nerve_end"
    names[todo & nerve & ~end] = "optic_nerve_side"
    todo = names == ""
    on_outer = np.all(face_levels == 0, axis=1)
    names[todo & on_outer & (theta < geo.limbus_angle)] = "cornea_outer"
    names[todo & on_outer & (theta >= geo.limbus_angle)] = "sclera_outer"
    todo = names == ""
    names[todo & np.all(face_levels == last, axis=1)] = "retina_inner"
    todo = names == ""
    interface = np.all((face_levels == last - 1) | retina_side[faces], axis=1)
    retina_cell = tissue[owner] == TISSUES.index("retina")
    names[todo & interface & retina_cell] = "retina_detached"
    names[todo & interface & ~retina_cell] = "choroid_detached"
    todo = names == ""
    names[todo] = "tear_edge"
    return {name: faces[names == name] for name in FACETS}


def zonule_pairs(geo: EyeGeometry, grid: EyeGrid | None = None,
                 per_node: int = 2) -> np.ndarray:
    """(n, 2, 3) reference coordinates of the zonules' bars: each node of the lens's
    insertion belt (:func:`lens_belt`) joined to its ``per_node`` nearest nodes (and
    any tied with the last) of the
    ciliary body's inner surface (the inner wall between the limbus and the ora
    serrata). Pure numpy, the same on every rank; the scene finds the nodes by their
    coordinates."""
    if not geo.lens:
        return np.zeros((0, 2, 3))
    grid = grid or build_grid(geo)
    belt = np.flatnonzero(lens_belt(geo, grid.points))
    inner = np.unique(grid.faces["retina_inner"])
    x = grid.points[inner]
    theta = np.degrees(np.arccos(np.clip(x[:, 2] / np.linalg.norm(x, axis=1), -1, 1)))
    ciliary = inner[(theta > geo.limbus_angle + 2.0) & (theta < geo.ora_serrata_angle)]
    if len(ciliary) < per_node:
        raise MeshError("no ciliary-body nodes for the zonules to attach to")
    distance = np.linalg.norm(grid.points[belt][:, None, :] - grid.points[ciliary][None], axis=2)
    # every node as near as the per_node-th nearest (ties all taken, so that the bars
    # keep the mesh's symmetries instead of depending on the node numbering)
    cutoff = np.sort(distance, axis=1)[:, per_node - 1:per_node] * (1 + 1e-9)
    lens_index, wall_index = np.nonzero(distance <= cutoff)
    return np.stack([grid.points[belt[lens_index]], grid.points[ciliary[wall_index]]], axis=1)


def to_gmsh(grid: EyeGrid, model) -> None:
    """Hand the grid to gmsh as a discrete model with physical groups."""
    node_tags = np.arange(1, len(grid.points) + 1)
    model.addDiscreteEntity(3, 1)
    model.mesh.addNodes(3, 1, node_tags, grid.points.ravel())
    next_tag = 1
    for number, name in enumerate(TISSUES, start=1):
        cells = grid.hexes[grid.tissue == number - 1]
        if len(cells) == 0:
            continue
        entity = 100 + number
        model.addDiscreteEntity(3, entity)
        tags = np.arange(next_tag, next_tag + len(cells))
        model.mesh.addElementsByType(entity, 5, tags, (cells + 1).ravel())
        next_tag += len(cells)
        model.addPhysicalGroup(3, [entity], tag=number, name=name)
    for number, name in enumerate(FACETS, start=1):
        quads = grid.faces[name]
        if len(quads) == 0:
            continue
        entity = 200 + number
        model.addDiscreteEntity(2, entity)
        tags = np.arange(next_tag, next_tag + len(quads))
        model.mesh.addElementsByType(entity, 3, tags, (quads + 1).ravel())
        next_tag += len(quads)
        model.addPhysicalGroup(2, [entity], tag=number, name=name)


def half_eye(geometry: EyeGeometry | None = None, comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    """The half eye as a DOLFINx mesh; ``cavity_wall`` is the union of the wetted faces."""
    geometry = geometry or EyeGeometry()
    geometry.validate()  # on every rank: the same clear error everywhere
    tagged = from_gmsh(lambda model: to_gmsh(build_grid(geometry), model), comm)
    tagged.unions["cavity_wall"] = tuple(n for n in CAVITY_WALL if n in tagged.names)
    return tagged
