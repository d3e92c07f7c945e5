"""Bending of a thin wall: why the eye's Q1P0 axial-length change converges slowly.

A plane-strain incompressible cantilever (length 20 mm, thickness t = 0.5 mm, the
sclera at the equator), clamped at one end, a small shear load at the other (linear
response), meshed like the eye's wall: structured hexahedra, ``layers`` through the
thickness, in-plane size h. Its tip deflection against Timoshenko beam theory,
w = F L³ / (3 E' I) + F L / (κ G A) with E' = 4μ (ν = ½, plane strain), κ = 5/6.

Q1P0 hexahedra lock in bending by parasitic shear: a Q1 element bent by a curvature κ
shears by about κ h / 2, so the wall's stiffness is overestimated by a term in (h / t)²
that more layers do not remove (more, thinner cells are slightly stiffer still). At the
eye's in-plane sizes at the equator — h / t = 4.5, 3.0, 1.4 for the coarse, default and
paper meshes — the beam is 6.0, 3.3 and 1.4 times too stiff with 2 layers. Q2P1 does not lock: within
4 % at h / t = 8 with one cell through the thickness. docs/scleral_buckling.md, "Q2P1 and
Q1P0 at equal accuracy of the axial-length change".
"""

from __future__ import annotations

# isort: off
from mpi4py import MPI  # first: it loads the libmpi DOLFINx's extension links against
# isort: on
import dolfinx
import numpy as np
import pytest
import ufl
from dolfinx.fem.petsc import LinearProblem

from eyemech.problems.solid.spaces import ELEMENTS, displacement_space, point_value, pressure_space

LENGTH, THICKNESS, SHEAR_MODULUS, LOAD = 20.0, 0.5, 1.0, 1e-4  # mm, mm, MPa, N per mm of width


def beam_theory() -> float:
    inertia = THICKNESS**3 / 12
    return (LOAD * LENGTH**3 / (3 * 4 * SHEAR_MODULUS * inertia)
            + LOAD * LENGTH / (5 / 6 * SHEAR_MODULUS * THICKNESS))


def tip_deflection(element: str, cells_along: int, layers: int) -> float:
    """Tip deflection over beam theory of the cantilever meshed with ``cells_along``
    cells along its length and ``layers`` through its thickness."""
    family = ELEMENTS[element]
    mesh = dolfinx.mesh.create_box(MPI.COMM_SELF, [[0, 0, 0], [LENGTH, 1.0, THICKNESS]],
                                   [cells_along, 1, layers], dolfinx.mesh.CellType.hexahedron)
    V, Q = displacement_space(mesh, family), pressure_space(mesh, family)
    u, p = ufl.TrialFunction(V), ufl.TrialFunction(Q)
    v, q = ufl.TestFunction(V), ufl.TestFunction(Q)
    strain = lambda w: ufl.sym(ufl.grad(w))  # noqa: E731
    a = [[2 * SHEAR_MODULUS * ufl.inner(strain(u), strain(v)) * ufl.dx, -p * ufl.div(v) * ufl.dx],
         [-q * ufl.div(u) * ufl.dx, None]]
    facets = dolfinx.mesh.locate_entities_boundary(mesh, 2, lambda x: np.isclose(x[0], LENGTH))
    tags = dolfinx.mesh.meshtags(mesh, 2, facets, np.ones(len(facets), np.int32))
    traction = ufl.as_vector((0.0, 0.0, -LOAD / THICKNESS))
    rhs = [ufl.inner(traction, v) * ufl.ds(domain=mesh, subdomain_data=tags, subdomain_id=1),
           dolfinx.fem.Constant(mesh, 0.0) * q * ufl.dx]
    clamped = dolfinx.fem.locate_dofs_geometrical(V, lambda x: np.isclose(x[0], 0.0))
    bcs = [dolfinx.fem.dirichletbc(np.zeros(3), clamped, V)]
    # plane strain: no displacement across the width, at every node
    Vy, _ = V.sub(1).collapse()
    every = dolfinx.fem.locate_dofs_geometrical((V.sub(1), Vy), lambda x: np.full(x.shape[1], True))
    bcs.append(dolfinx.fem.dirichletbc(dolfinx.fem.Function(Vy), every, V.sub(1)))
    problem = LinearProblem(a, rhs, bcs=bcs, kind="mpi", petsc_options_prefix="wall_bending_",
                            petsc_options={"ksp_type": "preonly", "pc_type": "lu",
                                           "pc_factor_mat_solver_type": "mumps"})
    uh, _ = problem.solve()
    return -point_value(uh, (LENGTH, 0.5, THICKNESS / 2))[2] / beam_theory()


@pytest.mark.parametrize("cells_along, bound", [(9, 0.19), (13, 0.33), (29, 0.76)])
def test_q1p0_locks_at_the_eyes_in_plane_sizes(cells_along, bound):
    # h / t = 4.4, 3.1, 1.4: the coarse, default and paper eye at the equator
    two = tip_deflection("Q1P0", cells_along, 2)
    four = tip_deflection("Q1P0", cells_along, 4)
    assert two < bound, two  # measured 0.168, 0.301, 0.728
    assert four < 1.01 * two, (two, four)  # measured 0.165, 0.293, 0.680


def test_q2p1_does_not_lock():
    ratio = tip_deflection("Q2P1", 5, 1)  # h / t = 8
    assert 0.95 < ratio < 1.0, ratio  # measured 0.961; 0.993 at h / t = 1.4 (29 cells)
