"""The layered half eye: tissues where anatomy puts them, a closed liquid cavity,
the detachment and the tear, and clear errors for unusable settings. No solves."""

from __future__ import annotations

import math

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from eyemech.meshes import MeshError
from eyemech.meshes.eye import EyeGeometry, build_grid, half_eye

GEOMETRY = EyeGeometry(cells_per_edge=8)


@pytest.fixture(scope="module")
def eye():
    return half_eye(GEOMETRY)


def _integral(tagged, integrand, measure) -> float:
    form = dolfinx.fem.form(integrand * measure)
    return tagged.mesh.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM)


def test_axial_length_is_anatomical():
    # Atchison & Smith: an emmetropic eye is about 24 mm long
    assert GEOMETRY.axial_length == pytest.approx(24.0, abs=0.5)


def test_every_tissue_and_facet_region_is_present(eye):
    for name in ("cornea", "sclera", "ciliary_body", "choroid", "retina", "optic_nerve"):
        assert eye.count(name) > 0, name
    for name in ("symmetry", "sclera_outer", "retina_inner", "retina_detached",
                 "choroid_detached", "tear_edge", "optic_nerve_end"):
        assert eye.count(name) > 0, name


def test_cavity_is_closed_and_of_eye_size(eye):
    one = dolfinx.fem.Constant(eye.mesh, 1.0)
    x = ufl.SpatialCoordinate(eye.mesh)
    n = ufl.FacetNormal(eye.mesh)
    wall = eye.ds()(eye.tag("cavity_wall"))
    volume = _integral(eye, -ufl.dot(x, n) / 3 * one, wall)
    # with a closed wall (plus the symmetry plane x = 0) any divergence-1 field gives the
    # same volume: compare x·n/3 with y n_y and z n_z
    for k in (1, 2):
        assert _integral(eye, -x[k] * n[k] * one, wall) == pytest.approx(volume, rel=1e-10)
    # a sphere of radius ≈ 10.5 mm (sclera 11.5 minus the wall) holds ≈ 4.8 ml; the
    # vitreous + aqueous of an adult eye is 4–5.5 ml: the half model holds half of it
    assert 2.0e3 < volume < 2.75e3


def test_detached_retina_is_lifted_by_the_gap(eye):
    # the subretinal faces: the retina face lies inward of its choroid counterpart
    x = ufl.SpatialCoordinate(eye.mesh)
    radius = ufl.sqrt(ufl.dot(x, x))
    ds = eye.ds()
    retina = _integral(eye, radius, ds(eye.tag("retina_detached")))
    retina_area = _integral(eye, 1.0 + 0 * radius, ds(eye.tag("retina_detached")))
    choroid = _integral(eye, radius, ds(eye.tag("choroid_detached")))
    choroid_area = _integral(eye, 1.0 + 0 * radius, ds(eye.tag("choroid_detached")))
    mean_gap = choroid / choroid_area - retina / retina_area
    assert 0.1 < mean_gap < GEOMETRY.detachment_height


def test_tear_is_a_hole_on_the_symmetry_plane():
    grid = build_grid(GEOMETRY)
    tear = grid.faces["tear_edge"]
    centre = grid.points[tear].reshape(-1, 3).mean(axis=0)
    assert abs(math.degrees(math.atan2(centre[1], centre[2])) - GEOMETRY.tear_angle) < 8
    assert centre[0] < GEOMETRY.tear_radius


def test_hexahedra_are_valid():
    grid = build_grid(EyeGeometry(cells_per_edge=12))
    p = grid.points[grid.hexes]
    # Jacobian at every corner of every hexahedron must be positive
    corners = [(0, 1, 3, 4), (1, 2, 0, 5), (2, 3, 1, 6), (3, 0, 2, 7),
               (4, 7, 5, 0), (5, 4, 6, 1), (6, 5, 7, 2), (7, 6, 4, 3)]
    for c, a, b, d in corners:
        det = np.einsum("ij,ij->i", np.cross(p[:, a] - p[:, c], p[:, b] - p[:, c]), p[:, d] - p[:, c])
        assert det.min() > 0


@pytest.mark.parametrize("change, words", [
    (dict(cells_per_edge=4), "too coarse"),
    (dict(cells_per_edge=7), "even"),
    (dict(detachment_from=60.0), "ora serrata"),
    (dict(tear_radius=0.05), "tear"),
])
def test_unusable_settings_are_refused(change, words):
    with pytest.raises(MeshError, match=words):
        build_grid(EyeGeometry(**change))


# -- the lens and the zonules -----------------------------------------------------------
def test_lens_is_a_wetted_body_excluded_from_the_liquid(eye):
    # the lens surface is part of the cavity wall with the solid's outward normal, so the
    # enclosed volume is the liquid's: the eye without the lens minus the lens body, to
    # round-off (both surfaces closed with the symmetry plane x = 0 through the origin)
    assert eye.count("lens") > 0 and eye.count("lens_surface") > 0
    x = ufl.SpatialCoordinate(eye.mesh)
    n = ufl.FacetNormal(eye.mesh)
    one = dolfinx.fem.Constant(eye.mesh, 1.0)

    def liquid(tagged):
        return _integral(tagged, -ufl.dot(ufl.SpatialCoordinate(tagged.mesh),
                                          ufl.FacetNormal(tagged.mesh)) / 3,
                         tagged.ds()(tagged.tag("cavity_wall")))

    no_lens = half_eye(EyeGeometry(cells_per_edge=8, lens=False))
    lens_volume = _integral(eye, one, eye.dx()(eye.tag("lens")))
    assert liquid(eye) == pytest.approx(liquid(no_lens) - lens_volume, rel=1e-12)
    # the 32-hexahedron ellipsoid has bilinear faces inside the true surface: within 10 %
    # of ⅔πa²b (half ellipsoid), never above it
    a, b = GEOMETRY.lens_diameter / 2, GEOMETRY.lens_thickness / 2
    assert 0.9 * (2 / 3) * math.pi * a * a * b < lens_volume < (2 / 3) * math.pi * a * a * b
    # the lens surface is closed with the symmetry plane: x·n/3 equals y n_y, z n_z
    surface = eye.ds()(eye.tag("lens_surface"))
    volume = _integral(eye, ufl.dot(x, n) / 3 * one, surface)
    assert volume == pytest.approx(lens_volume, rel=1e-10)
    assert _integral(eye, x[2] * n[2] * one, surface) == pytest.approx(lens_volume, rel=1e-10)


def test_lens_sits_behind_the_anterior_chamber():
    grid = build_grid(GEOMETRY)
    lens = grid.points[np.unique(grid.hexes[grid.tissue == 6])]
    apex = GEOMETRY.cornea_center + GEOMETRY.cornea_radius
    # Gullstrand–Le Grand: the lens's anterior pole 3.6 mm behind the corneal apex
    assert apex - lens[:, 2].max() == pytest.approx(GEOMETRY.lens_depth, abs=1e-9)
    assert lens[:, 2].max() - lens[:, 2].min() == pytest.approx(GEOMETRY.lens_thickness, abs=1e-9)
    assert 2 * np.hypot(lens[:, 0], lens[:, 1]).max() == pytest.approx(GEOMETRY.lens_diameter,
                                                                       abs=1e-9)


def test_zonules_join_the_lens_belt_to_the_ciliary_body():
    from eyemech.meshes.eye import lens_belt, zonule_pairs

    grid = build_grid(GEOMETRY)
    pairs = zonule_pairs(GEOMETRY, grid)
    assert len(pairs) >= 40
    assert np.all(lens_belt(GEOMETRY, pairs[:, 0]))
    ciliary = pairs[:, 1]
    theta = np.degrees(np.arccos(ciliary[:, 2] / np.linalg.norm(ciliary, axis=1)))
    assert np.all((theta > GEOMETRY.limbus_angle) & (theta < GEOMETRY.ora_serrata_angle))
    length = np.linalg.norm(pairs[:, 1] - pairs[:, 0], axis=1)
    assert 1.0 < length.min() and length.max() < 4.0
    # a fan, not a plane: bars leave the lens in front of and behind its equator, so they
    # hold it along the optic axis (bars in one plane would have no axial stiffness)
    lens_z = pairs[:, 0, 2] - GEOMETRY.lens_centre
    assert lens_z.min() < -0.5 and lens_z.max() > 0.5


@pytest.mark.parametrize("change", [dict(lens_diameter=19.0), dict(lens_depth=0.3),
                                    dict(lens_cells=3)])
def test_unusable_lens_is_refused(change):
    with pytest.raises(MeshError, match="lens"):
        build_grid(EyeGeometry(**change))
