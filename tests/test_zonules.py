"""The zonules' bars (problems/solid/zonules.py): forces and tangent of a two-node truss with
a linear material and exact kinematics, against the closed form and finite differences."""

from __future__ import annotations

import numpy as np
import pytest

try:
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass
import dolfinx
from mpi4py import MPI
from petsc4py import PETSc

from eyemech.meshes import MeshError
from eyemech.problems.solid.zonules import ZonuleBars

E, AREA = 100.0, 0.008


@pytest.fixture(scope="module")
def space():
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 2, 2, 2, dolfinx.mesh.CellType.hexahedron)
    return dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))


def _bars(space, pairs):
    u = dolfinx.fem.Function(space)
    return u, ZonuleBars(u, np.array(pairs, float), E, AREA)


def _residual(bars, n) -> np.ndarray:
    vec = PETSc.Vec().createSeq(n)
    bars.residual_hook(None, vec)
    return vec.array.copy()


def test_stretched_bar_pulls_its_ends_together(space):
    # a bar from (0.5, 0.5, 0.5) to (1, 0.5, 0.5) (length L = 0.5, off the plane x = 0),
    # its far end moved by (0.01, 0.02, 0): N = E A (l − L)/L along the deformed bar
    u, bars = _bars(space, [[[0.5, 0.5, 0.5], [1.0, 0.5, 0.5]]])
    coords = space.tabulate_dof_coordinates()
    far = int(np.flatnonzero(np.linalg.norm(coords - [1.0, 0.5, 0.5], axis=1) < 1e-12)[0])
    near = int(np.flatnonzero(np.linalg.norm(coords - [0.5, 0.5, 0.5], axis=1) < 1e-12)[0])
    u.x.array.reshape(-1, 3)[far] = [0.01, 0.02, 0.0]
    d = np.array([0.51, 0.02, 0.0])
    force = E * AREA * (np.linalg.norm(d) - 0.5) / 0.5
    r = _residual(bars, u.x.array.size).reshape(-1, 3)
    assert r[far] == pytest.approx(force * d / np.linalg.norm(d), rel=1e-12)
    assert r[near] == pytest.approx(-force * d / np.linalg.norm(d), rel=1e-12)
    assert bars.summary()["zonule_force_total_N"] == pytest.approx(2 * force, rel=1e-12)


def test_bar_in_the_symmetry_plane_gets_half_its_area(space):
    u, bars = _bars(space, [[[0.0, 0.0, 0.0], [0.0, 0.5, 0.5]]])
    assert bars.axial_stiffness[0] == pytest.approx(0.5 * E * AREA)


def test_tangent_is_the_derivative_of_the_residual(space):
    # two bars sharing a node, a generic displacement: the hook's Jacobian equals
    # central differences of its residual (step 1e-6: truncation ~ h² K'' ≪ 1e-6 K)
    u, bars = _bars(space, [[[0.5, 0.5, 0.5], [1.0, 0.5, 0.5]],
                            [[0.5, 0.5, 0.5], [0.5, 1.0, 1.0]]])
    rng = np.random.default_rng(1)
    u.x.array[:] = 0.05 * rng.standard_normal(u.x.array.size)
    n = u.x.array.size
    A = PETSc.Mat().createDense((n, n))
    A.setUp()
    bars.jacobian_hook(None, A)
    K = A.getDenseArray().copy()
    dofs = np.unique(bars._dofs())
    h = 1e-6
    for dof in dofs:
        u.x.array[dof] += h
        plus = _residual(bars, n)
        u.x.array[dof] -= 2 * h
        minus = _residual(bars, n)
        u.x.array[dof] += h
        assert K[:, dof] == pytest.approx((plus - minus) / (2 * h), abs=1e-6 * np.abs(K).max())


def test_end_points_off_the_mesh_are_refused(space):
    with pytest.raises(MeshError, match="not mesh nodes"):
        _bars(space, [[[0.5, 0.5, 0.5], [0.3, 0.5, 0.5]]])
