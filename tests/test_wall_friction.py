"""Wall friction of the lens' node-to-rigid-wall contact (problems/contact/rigid_wall.py): the
lagged smoothed Coulomb law of IPC on the nodes of a small vector P1 field.

References: Coulomb's law itself — a node that slides more than ε per step is held back by
exactly μλ (λ the lagged normal force), opposite its slip; one that slides less is held
back by less (the regularised stick). The tangent is checked against central finite
differences of the residual hook (step 1e-7 mm, error O(h²) ≈ 1e-12 relative to the
blocks, so 1e-6 is safe)."""

from __future__ import annotations

import dataclasses

import dolfinx
import dolfinx.fem
import dolfinx.mesh
import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from eyemech.problems.contact.rigid_wall import NodalContact
from eyemech.problems.lens.injector import turn_about_x

STIFFNESS, MU, SLIP = 50.0, 0.4, 1e-3


@dataclasses.dataclass
class Floor:
    """The rigid plane z = level, the body above it."""

    level: float

    def gap_normal(self, x):
        normal = np.zeros_like(x)
        normal[:, 2] = 1.0
        return x[:, 2] - self.level, normal, np.ones(len(x), bool)


@pytest.fixture
def pressed():
    """A unit cube's 8 nodes; the floor 0.01 mm above its bottom face, so the 4 bottom
    nodes are pressed 0.01 mm deep (λ = k · 0.01 each)."""
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    u = dolfinx.fem.Function(V)
    contact = NodalContact(u, {"floor": Floor(0.01)}, STIFFNESS, friction=MU, slip=SLIP)
    contact.begin_step()
    return u, contact


def residual(contact, values):
    x_vec = PETSc.Vec().createWithArray(values.copy())
    F = PETSc.Vec().createWithArray(np.zeros_like(values))
    contact.residual_hook(x_vec, F)
    return F.array.copy()


def test_sliding_node_is_held_back_by_mu_times_its_normal_force(pressed):
    u, contact = pressed
    bottom = np.flatnonzero(contact.X[:, 2] < 1e-12)
    normal_force = STIFFNESS * 0.01  # the smoothing (2 µm) is below the 10 µm depth
    for slip, expected in ((5 * SLIP, MU * normal_force), (0.5 * SLIP, 0.75 * MU * normal_force)):
        values = np.zeros(u.x.array.size)
        values.reshape(-1, 3)[:, 0] = slip  # every node slides along +x
        tangential = residual(contact, values).reshape(-1, 3)[bottom, 0]
        # f₁(r) = 1 beyond ε; 2r/ε − r²/ε² = 0.75 at r = ε/2
        assert tangential == pytest.approx(np.full(4, expected), rel=1e-12)


def test_friction_does_not_act_on_free_nodes_or_push_normally(pressed):
    u, contact = pressed
    values = np.zeros(u.x.array.size)
    values.reshape(-1, 3)[:, :2] = [3 * SLIP, -2 * SLIP]
    no_friction = NodalContact(u, contact.obstacles, STIFFNESS)
    difference = (residual(contact, values) - residual(no_friction, values)).reshape(-1, 3)
    top = contact.X[:, 2] > 0.5
    assert np.all(difference[top] == 0.0)
    assert np.all(difference[:, 2] == 0.0)  # tangential only
    direction = difference[~top, :2] / np.linalg.norm(difference[~top, :2], axis=1)[:, None]
    assert direction == pytest.approx(np.tile([3, -2] / np.hypot(3, 2), (4, 1)), rel=1e-12)


@pytest.mark.parametrize("slip", [0.3 * SLIP, 2.5 * SLIP])
def test_tangent_is_the_derivative_of_the_residual(pressed, slip):
    u, contact = pressed
    rng = np.random.default_rng(1)
    values = rng.uniform(-slip, slip, u.x.array.size)
    values.reshape(-1, 3)[:, 2] *= 1e-3  # stay pressed
    x = contact.X + values.reshape(-1, 3)
    nodes, blocks = contact.friction_hessians(x)
    h = 1e-7
    for node, block in zip(nodes, blocks):
        for j in range(3):
            plus, minus = values.copy(), values.copy()
            plus[3 * node + j] += h
            minus[3 * node + j] -= h
            column = (contact.friction_forces(contact.X + plus.reshape(-1, 3))[1]
                      - contact.friction_forces(contact.X + minus.reshape(-1, 3))[1]) / (2 * h)
            row = list(nodes).index(node)
            assert column[row] == pytest.approx(block[:, j], abs=1e-6 * np.abs(blocks).max())
    eigenvalues = np.linalg.eigvalsh(blocks)
    assert eigenvalues.min() > -1e-9 * eigenvalues.max()  # a potential's convex tangent


def test_only_the_frictional_obstacles_hold_back(pressed):
    """Friction per obstacle (the injection's capsule and cartridge have their own μ): an
    obstacle without one pushes normally and nothing else."""
    u, contact = pressed
    frictionless = NodalContact(u, contact.obstacles, STIFFNESS, friction={"wall": MU}, slip=SLIP)
    frictionless.begin_step()
    values = np.zeros(u.x.array.size)
    values.reshape(-1, 3)[:, 0] = 5 * SLIP
    assert np.all(residual(frictionless, values).reshape(-1, 3)[:, 0] == 0.0)
    assert np.any(residual(contact, values).reshape(-1, 3)[:, 0] != 0.0)


def test_a_moving_wall_drags_the_nodes_pressed_on_it(pressed):
    """The anchor moves with the wall (a twisted injector): a pressed node at rest on a wall
    that slides by more than ε is pulled along the wall's motion with μλ; one that moves
    with the wall feels no friction."""
    u, contact = pressed
    shift = np.array([4 * SLIP, 0.0, 0.0])
    contact.begin_step({"floor": lambda x: x + shift})
    bottom = np.flatnonzero(contact.X[:, 2] < 1e-12)
    at_rest = np.zeros(u.x.array.size)
    tangential = -residual(contact, at_rest).reshape(-1, 3)[bottom, :2]  # z: the normal push
    assert tangential == pytest.approx(np.tile([MU * STIFFNESS * 0.01, 0.0], (4, 1)), rel=1e-12)
    along = np.tile(shift, len(contact.X)).ravel()
    assert np.abs(residual(contact, along).reshape(-1, 3)[:, :2]).max() == 0.0


def test_turn_about_x_is_the_right_handed_rigid_turn_about_the_injector_axis():
    axis_point = np.array([0.0, 0.5, 1.0])
    points = axis_point + np.array([[2.0, 1.0, 0.0], [-1.0, 0.0, 0.3]])
    turned = turn_about_x(axis_point, np.pi / 2)(points)
    assert turned == pytest.approx(axis_point + np.array([[2.0, 0.0, 1.0], [-1.0, -0.3, 0.0]]), abs=1e-15)
