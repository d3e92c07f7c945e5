"""The buckle's obstacle and footprint (forms/buckle.py) with its sizes, position and
tire arc as Constants, as the eye builds them so that a sweep over them compiles nothing
new (tests/test_compile_once.py): the same signed distance as the union of float
profiles whose corner radius is capped in Python, and the numpy footprint mask the same
as the UFL footprint weight at the same points. Random points around the buckle; no
solve (≈ 2 s)."""

from __future__ import annotations

import math

import dolfinx
import dolfinx.fem
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from eyemech.forms.buckle import Buckle, BuckleShape, BuckleSizes
from eyemech.forms.contact import Ring, RoundedRectangle

# the band's corner radius above half its thickness (0.3 mm): the cap is active there
SHAPE = dict(band_width=2.5, band_thickness=0.6, tire_width=7.0, tire_height=1.0,
             corner_radius=0.45)
AXIAL, BASE, BAND_TRAVEL, TIRE_TRAVEL = -3.1, 12.05, 0.7, 0.9


def _on_points(expression, seed: int):
    """(points, values): ``expression(x, mesh)`` interpolated at the vertices of a P1 mesh
    moved onto random points around the buckle (ρ 9.5–13.5 mm, z within 6 mm of it, any
    azimuth)."""
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 3, 3, 3)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    X = V.tabulate_dof_coordinates()
    rng = np.random.default_rng(seed)
    rho, phi = rng.uniform(9.5, 13.5, len(X)), rng.uniform(-math.pi, math.pi, len(X))
    points = np.column_stack([rho * np.sin(phi), rho * np.cos(phi),
                              AXIAL + rng.uniform(-6.0, 6.0, len(X))])
    u = dolfinx.fem.Function(V)
    u.x.array[:] = (points - X).ravel()
    Q = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    values = dolfinx.fem.Function(Q)
    x = ufl.SpatialCoordinate(mesh) + u
    values.interpolate(dolfinx.fem.Expression(expression(x, mesh), Q.element.interpolation_points))
    return points, values.x.array


def _buckle_of_constants(shape: BuckleShape, mesh) -> Buckle:
    def constant(value: float) -> dolfinx.fem.Constant:
        return dolfinx.fem.Constant(mesh, value)

    return Buckle(shape, constant(AXIAL), constant(BASE), constant(BAND_TRAVEL),
                  tire_indentation=constant(TIRE_TRAVEL), sizes=BuckleSizes.of(shape, constant))


def _float_gap(shape: BuckleShape, x):
    """The union of band and (arc-limited) tire from float profiles, the corner radius
    capped with Python's min: the buckle as it was built with literals."""
    h = shape.tire_height
    tire = Ring(indentation=TIRE_TRAVEL, profile=RoundedRectangle(
        center=(BASE + 0.5 * h, AXIAL), width=h, height=shape.tire_width,
        corner_radius=min(shape.corner_radius, 0.5 * h, 0.5 * shape.tire_width)))
    band = Ring(indentation=BAND_TRAVEL, profile=RoundedRectangle(
        center=(BASE + 0.5 * shape.band_thickness, AXIAL), width=shape.band_thickness,
        height=shape.band_width, corner_radius=min(shape.corner_radius, 0.5 * shape.band_thickness)))
    gaps = []
    if shape.has_tire:
        g = tire.gap(x)
        if shape.tire_arc_deg < 360.0:
            half = math.radians(0.5 * shape.tire_arc_deg)
            rho = ufl.sqrt(x[0] ** 2 + x[1] ** 2 + 1e-24)
            azimuth = ufl.atan2(ufl.sqrt(x[0] ** 2 + 1e-24), x[1])
            over = ufl.min_value(ufl.max_value(azimuth - half, -0.5 * math.pi), 0.5 * math.pi)
            g = ufl.max_value(g, rho * ufl.sin(over))
        gaps.append(g)
    if shape.has_band:
        gaps.append(band.gap(x))
    return gaps[0] if len(gaps) == 1 else ufl.min_value(*gaps)


KINDS = [("encircling+segmental", 90.0), ("encircling+segmental", 360.0), ("segmental", 60.0),
         ("encircling", 360.0)]


@pytest.mark.parametrize("kind, arc", KINDS, ids=[f"{k}-{a:g}" for k, a in KINDS])
def test_buckle_of_constants_has_the_float_buckles_gap(kind, arc):
    shape = BuckleShape(kind=kind, tire_arc_deg=arc, **SHAPE)
    _, of_constants = _on_points(lambda x, mesh: _buckle_of_constants(shape, mesh).gap(x), seed=3)
    _, of_floats = _on_points(lambda x, mesh: _float_gap(shape, x), seed=3)
    # the same operations on the same doubles: equal to round-off (measured 0 to 2.0e-15; an uncapped band
    # corner radius differs by 0.06)
    assert np.allclose(of_constants, of_floats, rtol=0.0, atol=1e-12)
    assert (of_constants < 0).any() and (of_constants > 0).any()  # points inside and out


@pytest.mark.parametrize("kind, arc", KINDS, ids=[f"{k}-{a:g}" for k, a in KINDS])
def test_footprint_mask_is_the_footprint_weight(kind, arc):
    shape = BuckleShape(kind=kind, tire_arc_deg=arc, **SHAPE)
    buckles = []

    def weight(x, mesh):
        buckles.append(_buckle_of_constants(shape, mesh))
        return buckles[-1].footprint_weight(x)

    points, weights = _on_points(weight, seed=5)
    mask = buckles[-1].footprint_mask(points)
    assert 0 < mask.sum() < len(mask)
    assert np.array_equal(mask, weights > 0.5)
