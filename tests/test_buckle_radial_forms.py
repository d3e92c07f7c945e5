"""The radial tire's obstacle, footprint and slip directions (forms/buckle.py): a ring
about the x axis through the eye's centre cut by a wedge along the tear's meridian,
its sizes and centre angle as Constants. Signed distances checked against the
geometry by hand at chosen points; no solve (≈ 2 s)."""

from __future__ import annotations

import math

import dolfinx
import dolfinx.fem
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from eyemech.forms.buckle import Buckle, BuckleShape, BuckleSizes, forward_slip, slip

SHAPE = BuckleShape(kind="segmental", orientation="radial", tire_width=7.0, tire_height=1.0,
                    corner_radius=0.3, tire_length=12.0, sclera_radius=11.5)
BASE, TRAVEL, POLAR = 11.55, 0.8, math.radians(93.0)
HALF = 6.0 / 11.5   # half the tire's length over the sclera's radius (rad)
FACE = BASE - TRAVEL  # the tire's inner face, from the x axis


def _at(x_across: float, r: float, beta: float) -> tuple[float, float, float]:
    """The point x_across from the symmetry plane, r from the x axis, at polar angle β."""
    return (x_across, r * math.sin(beta), r * math.cos(beta))


# (point, signed distance by hand): the inner face under the centre, near the wedge's
# edge, beyond the wedge's edge (the wedge's distance r sin(overshoot)), inside, and
# beside the tire's side face (across the meridian, on its straight part)
CASES = [
    (_at(0.0, FACE - 0.7, POLAR), 0.7),
    (_at(0.0, FACE - 0.5, POLAR + HALF - 0.01), 0.5),
    (_at(0.0, FACE + 0.5, POLAR + HALF + 0.05), (FACE + 0.5) * math.sin(0.05)),
    (_at(0.0, FACE + 0.5, POLAR - HALF - 0.05), (FACE + 0.5) * math.sin(0.05)),
    (_at(1.0, FACE + 0.5, POLAR), -0.5),
    (_at(3.5 + 0.3, FACE + 0.5, POLAR), 0.3),
]


def _evaluate(expression, points: np.ndarray):
    """``expression(x, buckle)`` at ``points`` (the first rows of a P1 mesh's vertices
    moved there; the other vertices at random around the tire)."""
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 3, 3, 3)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    X = V.tabulate_dof_coordinates()
    rng = np.random.default_rng(7)
    r, beta = rng.uniform(9.5, 13.5, len(X)), POLAR + rng.uniform(-0.8, 0.8, len(X))
    cloud = np.column_stack([rng.uniform(0.0, 5.0, len(X)), r * np.sin(beta), r * np.cos(beta)])
    cloud[:len(points)] = points
    u = dolfinx.fem.Function(V)
    u.x.array[:] = (cloud - X).ravel()

    def constant(value: float) -> dolfinx.fem.Constant:
        return dolfinx.fem.Constant(mesh, value)

    buckle = Buckle(SHAPE, constant(0.0), constant(BASE), constant(TRAVEL),
                    sizes=BuckleSizes.of(SHAPE, constant), polar_angle=constant(POLAR))
    Q = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    values = dolfinx.fem.Function(Q)
    x = ufl.SpatialCoordinate(mesh) + u
    values.interpolate(dolfinx.fem.Expression(expression(x, buckle), Q.element.interpolation_points))
    return cloud, values.x.array, buckle


def test_radial_tire_gap_by_hand():
    points = np.array([p for p, _ in CASES])
    _, gaps, _ = _evaluate(lambda x, buckle: buckle.gap(x), points)
    # exact geometry away from corners: round-off and, inside the profile, the soft
    # norm's √1e-24 (measured 3.2e-15 outside, 1.0e-12 inside)
    assert np.abs(gaps[:len(CASES)] - [g for _, g in CASES]).max() < 1e-11


def test_radial_footprint_mask_is_the_footprint_weight():
    cloud, weights, buckle = _evaluate(lambda x, buckle: buckle.footprint_weight(x), np.zeros((0, 3)))
    mask = buckle.footprint_mask(cloud)
    assert 0 < mask.sum() < len(mask)
    assert np.array_equal(mask, weights > 0.5)


def test_radial_slip_is_tangential_to_the_meridian_ring():
    # on a radial tire (about x) a motion towards the x axis is no slip, one across
    # the meridian (e_x) or along it (e_β) is; forward = towards the cornea (−e_β)
    beta = np.array([POLAR, POLAR + 0.3])
    x0 = np.column_stack([[0.5, 1.0], 11.5 * np.sin(beta), 11.5 * np.cos(beta)])
    inward = -0.7 * np.column_stack([np.zeros(2), np.sin(beta), np.cos(beta)])
    e_beta = np.column_stack([np.zeros(2), np.cos(beta), -np.sin(beta)])
    assert slip(x0, inward, axis=0) == pytest.approx([0.0, 0.0], abs=1e-12)
    assert slip(x0, np.tile([0.2, 0.0, 0.0], (2, 1)), axis=0) == pytest.approx([0.2, 0.2])
    assert slip(x0, 0.3 * e_beta, axis=0) == pytest.approx([0.3, 0.3])
    assert forward_slip(x0, -0.3 * e_beta, axis=0) == pytest.approx([0.3, 0.3])
    assert forward_slip(x0, inward, axis=0) == pytest.approx([0.0, 0.0], abs=1e-12)


def test_radial_tire_with_a_band_is_refused():
    with pytest.raises(ValueError, match="segmental"):
        BuckleShape(kind="encircling+segmental", orientation="radial")
