"""The hexahedral cornea of meshes/cornea.py (issue 6, item 4): shape, tags, real cuts.

References: the volume of the solid of revolution (quadrature of the thickness profile,
CorneaGeometry.volume) and the spherical-cap area 2π Ra² (1 − cos θ_L); the trilinear
mesh with 24 azimuthal divisions under-fills a circle by ≈ 1 − sin(2π/24)/(2π/24) = 1.1 %,
so 2 % is the tolerance.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import ufl

from eyemech.meshes import MeshError  # imports dolfinx_solver before dolfinx
from eyemech.meshes.cornea import CorneaGeometry, cornea
from eyemech.problems.solve.scalars import assemble_scalar


def measure(tagged, name=None):
    form = 1.0 * (ufl.dx(domain=tagged.mesh) if name is None else tagged.ds()(tagged.tag(name)))
    return assemble_scalar(form, tagged.mesh.comm)


def test_thickness_profile_meets_the_radii():
    g = CorneaGeometry()
    assert g.thickness(0.0) == pytest.approx(0.52)
    assert g.thickness(g.limbus_angle) == pytest.approx(0.67)
    # posterior apical radius of the polar curve ρ = Ra − t(θ): ρ³/(ρ² + 2kρ)... = 6.5
    k, _ = g.thickness_coefficients()
    rho = g.anterior_radius - g.central_thickness
    assert rho**2 / (rho + 2 * k) == pytest.approx(6.5)


def test_intact_cornea_shape():
    g = CorneaGeometry()
    tagged = cornea(g)
    assert measure(tagged) == pytest.approx(g.volume(), rel=2e-2)
    cap = 2 * math.pi * g.anterior_radius**2 * (1 - math.cos(g.limbus_angle))
    assert measure(tagged, "anterior") == pytest.approx(cap, rel=2e-2)
    assert "incision" not in tagged.names
    x = tagged.mesh.geometry.x
    assert x[:, 2].max() == pytest.approx(0.0, abs=1e-12)  # apex at the origin


def test_quadratic_geometry_lies_on_the_shape():
    """27-node cells with their extra nodes on the shape: volume and anterior area to the
    quadrature's and the ring's interpolation error (measured 1.3e-5), not the trilinear
    1.3 % faceting. The cuts stay open: same cut area as the trilinear mesh within the
    faceting of the radial strips."""
    g = CorneaGeometry(geometry_degree=2)
    tagged = cornea(g)
    assert measure(tagged) == pytest.approx(g.volume(), rel=1e-4)
    cap = 2 * math.pi * g.anterior_radius**2 * (1 - math.cos(g.limbus_angle))
    assert measure(tagged, "anterior") == pytest.approx(cap, rel=1e-4)
    cut = cornea(CorneaGeometry(geometry_degree=2, incisions=8))
    flat = cornea(CorneaGeometry(incisions=8))
    assert measure(cut, "incision") == pytest.approx(measure(flat, "incision"), rel=1e-2)
    assert measure(cut) == pytest.approx(g.volume(), rel=1e-4)


def test_incisions_are_real_cuts():
    """8 cuts: their faces are exterior facets (both lips), with about the area of
    2 × 8 radial strips of depth 0.9 t between the optical zone and the incision end,
    and the mesh gains the duplicated nodes."""
    intact, cut = CorneaGeometry(), CorneaGeometry(incisions=8)
    a, b = cornea(intact), cornea(cut)
    Ra = cut.anterior_radius
    theta = np.linspace(math.asin(1.5 / Ra), math.asin(5.35 / Ra), 50)
    strip = np.trapezoid(0.9 * cut.thickness(theta) * (Ra - 0.45 * cut.thickness(theta)), theta)
    assert measure(b, "incision") == pytest.approx(16 * strip, rel=3e-2)
    count = lambda t: t.mesh.comm.allreduce(t.mesh.topology.index_map(0).size_local)
    assert count(b) > count(a)
    assert measure(b) == pytest.approx(measure(a), rel=1e-12)  # same cells, only split


@pytest.mark.parametrize("changes, words", [
    ({"incision_depth": 1.0}, "incision_depth"), ({"incision_depth": 0.0}, "incision_depth"),
    ({"optical_zone": 12.0}, "narrower than the cornea"), ({"optical_zone": 0.0}, "cross"),
    ({"incision_end": 1.0}, "incision_end"), ({"incisions": -1}, "incisions"),
    ({"geometry_degree": 3}, "geometry_degree"),
    ({"posterior_radius": 20.0, "limbal_thickness": 0.1}, "thickness")])
def test_bad_geometry_is_one_clear_error(changes, words):
    with pytest.raises(MeshError, match=words):
        CorneaGeometry(**changes).validate()


def test_cuts_on_neighbouring_grid_lines():
    """8 cuts on 8 azimuthal divisions: every wedge lies between two cuts and keeps the
    other line's original nodes (a regression: the last cut once took the first cut's
    copies across the wrap-around, leaving nodes unused)."""
    from eyemech.meshes.cornea import _hexahedra

    coarse = CorneaGeometry(incisions=8, azimuthal_divisions=8, mesh_size=1.5)
    points, hexes, faces = _hexahedra(coarse)
    assert len(np.unique(hexes)) == len(points)
    finer = CorneaGeometry(incisions=8, azimuthal_divisions=16, mesh_size=1.5)
    assert measure(cornea(coarse), "incision") == pytest.approx(measure(cornea(finer), "incision"),
                                                                rel=1e-9)


@pytest.mark.parametrize("degree", [1, 2])
def test_quarter_cornea_is_a_quadrant_of_the_whole(degree):
    """The quadrant x, y > 0 of the same planform: exactly a quarter of the whole mesh's
    cells, volume and wound area (8 cuts: 16 lips, 4 of them in the quadrant — both lips
    of the 45° cut, one of the cuts on each plane). Its symmetry faces are the meridional
    sections under the cuts: each the area of the whole mesh's section at azimuth 0 minus
    the cut, i.e. equal for the two planes."""
    g = CorneaGeometry(incisions=8, azimuthal_divisions=16, mesh_size=1.5, geometry_degree=degree)
    whole, quarter = cornea(g), cornea(dataclasses.replace(g, quarter=True))
    cells = lambda tagged: tagged.mesh.topology.index_map(3).size_global
    assert cells(quarter) * 4 == cells(whole)
    assert measure(quarter) == pytest.approx(measure(whole) / 4, rel=1e-12)
    assert measure(quarter, "incision") == pytest.approx(measure(whole, "incision") / 4, rel=1e-12)
    assert measure(quarter, "symmetry_x") == pytest.approx(measure(quarter, "symmetry_y"), rel=1e-12)
    assert measure(quarter, "symmetry_x") > 0


def test_a_quarter_cornea_needs_an_even_number_of_incisions():
    with pytest.raises(MeshError, match="even number of incisions"):
        CorneaGeometry(incisions=3, quarter=True).validate()
