"""Node-to-surface contact on hexahedra and in blocked systems (the eye's [u, p, P]).

Two hexahedral blocks with non-matching grids: the lower one's top face is the master
(its quadrilaterals split into triangles, seed 002 §2.3.1), the upper one's bottom face
the slave. Checks: exact penetration of a prescribed rigid motion (the master is flat,
so the triangle split is exact), and a solve in which a decoupled extra block [u, p]
must give the u-only solution to round-off — the blocked row mapping of the hooks
(``block_spaces``) is right or the two differ. Run as a script (``python test_eye_contact.py``) it prints the
solve's numbers as JSON for the two-rank comparison.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
import ufl
from mpi4py import MPI

try:
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass
import basix.ufl
import dolfinx
import dolfinx.fem
import dolfinx.mesh

from eyemech.forms import compressible_neo_hooke, deformation_gradient
from eyemech.meshes.tagged import TaggedMesh
from eyemech.problems.contact.node_to_surface import NodeToSurfaceContact
from eyemech.problems.solve.driver import NewtonOptions, NonlinearSolver

GAP = 0.1
NAMES = {"lower": (3, 1), "upper": (3, 2), "master": (2, 1), "slave": (2, 2), "bottom": (2, 3),
         "top": (2, 4)}


def _block(n: int, z0: float, z1: float, offset: int) -> tuple[np.ndarray, np.ndarray]:
    """Points and hexahedra (basix vertex order: x fastest, then y, then z) of the
    unit square × [z0, z1] with n × n × 1 cells."""
    t = np.linspace(0.0, 1.0, n + 1)
    x, y, z = np.meshgrid(t, t, [z0, z1], indexing="ij")
    points = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    index = np.arange(len(points)).reshape(n + 1, n + 1, 2)
    cells = [[index[i + a, j + b, c] for c in (0, 1) for b in (0, 1) for a in (0, 1)]
             for i in range(n) for j in range(n)]
    return points, np.asarray(cells) + offset


def two_blocks(lower: int = 2, upper: int = 3, comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    """Lower block z ∈ [0, 1] (lower × lower cells), upper z ∈ [1 + GAP, 1.5 + GAP]."""
    if comm.rank == 0:
        p0, c0 = _block(lower, 0.0, 1.0, 0)
        p1, c1 = _block(upper, 1.0 + GAP, 1.5 + GAP, len(p0))
        points, cells = np.vstack([p0, p1]), np.vstack([c0, c1]).astype(np.int64)
    else:
        points, cells = np.zeros((0, 3)), np.zeros((0, 8), dtype=np.int64)
    element = basix.ufl.element("Lagrange", "hexahedron", 1, shape=(3,))
    mesh = dolfinx.mesh.create_mesh(comm, cells, element, points)
    mesh.topology.create_connectivity(2, 3)
    mesh.topology.create_connectivity(3, 3)
    boundary = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    midpoints = dolfinx.mesh.compute_midpoints(mesh, 2, boundary)
    levels = {1: 1.0, 2: 1.0 + GAP, 3: 0.0, 4: 1.5 + GAP}
    facets, values = [], []
    for value, z in levels.items():
        hit = boundary[np.isclose(midpoints[:, 2], z)]
        facets.append(hit)
        values.append(np.full(len(hit), value, dtype=np.int32))
    facets, values = np.concatenate(facets), np.concatenate(values)
    order = np.argsort(facets)
    facet_tags = dolfinx.mesh.meshtags(mesh, 2, facets[order], values[order])
    cells = np.arange(mesh.topology.index_map(3).size_local + mesh.topology.index_map(3).num_ghosts,
                      dtype=np.int32)
    upper_cell = dolfinx.mesh.compute_midpoints(mesh, 3, cells)[:, 2] > 1.0
    cell_tags = dolfinx.mesh.meshtags(mesh, 3, cells, np.where(upper_cell, 2, 1).astype(np.int32))
    return TaggedMesh(mesh, cell_tags, facet_tags, dict(NAMES))


@pytest.mark.parametrize("degree, triangles_per_face", [(1, 2), (2, 8)])
def test_hexahedral_master_penetration_is_exact(degree, triangles_per_face):
    """A rigid motion of the upper block by −(GAP + δ − s x) along z puts every slave
    node δ − s x below the flat master: max penetration δ (at x = 0), every node in
    contact, the contact area the slave face's area (1)."""
    blocks = two_blocks()
    V = dolfinx.fem.functionspace(blocks.mesh, ("Lagrange", degree, (3,)))
    u = dolfinx.fem.Function(V)
    delta, slope = 0.02, 0.01
    upper = dolfinx.fem.locate_dofs_topological(V, 3, blocks.cells("upper"))
    X = V.tabulate_dof_coordinates()[upper]
    u.x.array.reshape(-1, 3)[upper, 2] = -(GAP + delta) + slope * X[:, 0]
    contact = NodeToSurfaceContact(u, blocks, "slave", "master", 1.0, search_depth=0.5)
    assert len(contact.triangles) == triangles_per_face * 2 * 2
    summary = contact.summary()
    assert summary["max_penetration"] == pytest.approx(delta, rel=1e-10)
    assert summary["contact_area"] == pytest.approx(1.0, rel=1e-10)
    nodes = (3 * degree + 1) ** 2
    assert summary["active_nodes"] == nodes
    # the pressure α (δ − s x) integrated with the lumped weights: exact for a linear field
    assert summary["contact_normal_force"] == pytest.approx(delta - slope * 0.5, rel=1e-10)


def pressed_blocks(comm: MPI.Comm = MPI.COMM_WORLD):
    """(blocks, u, energy, bcs, push) of the two blocks (:func:`two_blocks`): P1
    displacement ``u``, compressible neo-Hooke energy (μ = 1, ν = 0.3), the bottom held
    and the top moved by the Constant ``push``."""
    blocks = two_blocks(comm=comm)
    mesh = blocks.mesh
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    u = dolfinx.fem.Function(V)
    dx = ufl.dx(domain=mesh, metadata={"quadrature_degree": 2})
    energy = compressible_neo_hooke(deformation_gradient(u), 1.0, 0.3) * dx
    bottom = dolfinx.fem.locate_dofs_topological(V, 2, blocks.facets("bottom"))
    top = dolfinx.fem.locate_dofs_topological(V, 2, blocks.facets("top"))
    push = dolfinx.fem.Constant(mesh, np.zeros(3))
    bcs = [dolfinx.fem.dirichletbc(np.zeros(3), bottom, V), dolfinx.fem.dirichletbc(push, top, V)]
    return blocks, u, energy, bcs, push


def squeeze(blocked: bool, comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    """The upper block pressed 0.05 into the lower one (bottom held, top moved down),
    compressible neo-Hooke, penalty contact; ``blocked`` adds a decoupled DG0 block p
    (p = 0) so u is the first block of a blocked "mpi" system."""
    blocks, u, energy, bcs, push = pressed_blocks(comm)
    mesh, V = blocks.mesh, u.function_space
    dx = ufl.dx(domain=mesh, metadata={"quadrature_degree": 2})
    if blocked:
        Q = dolfinx.fem.functionspace(mesh, ("DG", 0))
        p = dolfinx.fem.Function(Q)
        v, q = ufl.TestFunctions(ufl.MixedFunctionSpace(V, Q))
        residual = ufl.derivative(energy, u, v) + p * q * dx
        residual, unknowns = list(ufl.extract_blocks(residual)), [u, p]
        spaces = [V, Q]
    else:
        residual, unknowns = ufl.derivative(energy, u, ufl.TestFunction(V)), u
        spaces = None
    contact = NodeToSurfaceContact(u, blocks, "slave", "master", 100.0, bcs, search_depth=0.5,
                                   block_spaces=spaces)
    solver = NonlinearSolver(residual, unknowns, bcs, options=NewtonOptions(rtol=1e-11, atol=1e-12),
                             residual_hooks=[contact.residual_hook],
                             jacobian_hooks=[contact.jacobian_hook])
    contact.allow_new_nonzeros(solver.problem.A)
    nonzeros = solver.jacobian_nonzeros()
    iterations = []
    for z in (-0.5 * GAP, -(GAP + 0.05)):
        push.value = np.array([0.0, 0.0, z])
        converged, its = solver.solve()
        assert converged, solver.residual_history
        iterations.append(its)
    contact.state = contact.search()
    out = contact.summary()
    owned = V.dofmap.index_map.size_local * 3
    out["u_norm"] = float(np.sqrt(comm.allreduce(float(np.sum(u.x.array[:owned] ** 2)))))
    out["iterations"] = iterations
    out["residuals"] = solver.residual_history
    out["nonzeros_fe"], out["nonzeros_contact"] = nonzeros, solver.jacobian_nonzeros()
    return out


@pytest.fixture(scope="module")
def squeezed():
    return squeeze(False), squeeze(True)


def test_blocked_system_gives_the_single_block_solution(squeezed):
    single, blocked = squeezed
    assert single["active_nodes"] == 16 and blocked["active_nodes"] == 16
    for key in ("max_penetration", "contact_area", "contact_normal_force", "u_norm"):
        assert blocked[key] == pytest.approx(single[key], rel=1e-9), key
    assert blocked["iterations"] == single["iterations"]
    # the couplings were added to the matrix (the FE pattern has none between the blocks)
    assert blocked["nonzeros_contact"] > blocked["nonzeros_fe"]


def test_blocked_contact_newton_converges_fast(squeezed):
    _, blocked = squeezed
    # the frozen-normal Jacobian omits the α g ∂n/∂u terms: with α = 100 E/mm and
    # g ≈ 5e-4 mm on this tilt-free but non-matching pair Newton ends at a linear
    # rate of ≈ 0.2 per iteration (measured: 13 iterations from 0.4 to 1e-12)
    r = blocked["residuals"]
    assert len(r) <= 15, r
    assert r[-1] < 1e-10 * r[0]


@pytest.mark.mpi
def test_blocked_contact_two_ranks(squeezed):
    import subprocess
    from pathlib import Path

    mpiexec = Path(sys.executable).parent / "mpiexec"
    proc = subprocess.run([str(mpiexec), "-n", "2", sys.executable, __file__], capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    parallel = json.loads(proc.stdout.strip().splitlines()[-1])
    single, _ = squeezed
    for key in ("max_penetration", "contact_area", "contact_normal_force", "u_norm"):
        assert parallel[key] == pytest.approx(single[key], rel=1e-8), key
    assert parallel["active_nodes"] == single["active_nodes"]


if __name__ == "__main__":
    result = squeeze(True)
    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps({k: v for k, v in result.items() if k != "residuals"}))
