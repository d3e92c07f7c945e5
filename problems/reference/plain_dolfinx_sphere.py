"""The thick incompressible sphere inflated by an internal follower pressure, written as a
plain DOLFINx 0.11 script the way its demos teach: the peer that ``eyemech study
peer-comparison`` times ``sphere-inflation`` against.

Nothing of eyemech's solver stack is used: a mixed element (Taylor–Hood P2P1 on
tetrahedra, or Q2 with a discontinuous P1 pressure on hexahedra), the neo-Hookean energy
W = c10 (Ī1 − 3) + p (J − 1) written out, the follower pressure ∫ P J F⁻ᵀN·v dA,
``dolfinx.fem.petsc.NonlinearProblem`` with SNES Newton (basic line search), MUMPS LU and
the whole load in one step. Only the mesh is eyemech's (the same octant mesh, so that the
two runs solve the same discrete problem: matched error). Stopping test: SNES relative
residual 1e-9, absolute 1e-10, as eyemech's default.

    python -m eyemech.problems.reference.plain_dolfinx_sphere --element P2P1 --mesh-size 1

prints one JSON line: the deformed inner radius, its error against the exact solution,
Newton iterations and the seconds spent inside the script (process start-up excluded).
"""

from __future__ import annotations

import argparse
import json
import time

START = time.perf_counter()

import basix.ufl  # noqa: E402
import dolfinx  # noqa: E402
import dolfinx.fem.petsc  # noqa: E402
import numpy as np  # noqa: E402
import ufl  # noqa: E402
from mpi4py import MPI  # noqa: E402

from eyemech.meshes import spherical_shell  # noqa: E402

ELEMENTS = {  # displacement element, pressure element, hexahedra
    "P2P1": (("Lagrange", 2), ("Lagrange", 1), False),
    "Q2P1": (("Lagrange", 2), ("DPC", 1), True),
}


def solve(element: str, mesh_size: float, inner_radius: float = 10.0, outer_radius: float = 12.0,
          c10: float = 0.05, pressure: float = 0.01) -> dict:
    (u_family, u_degree), (p_family, p_degree), hexahedra = ELEMENTS[element]
    shell = spherical_shell(inner_radius, outer_radius, mesh_size, order=2, hexahedra=hexahedra,
                            comm=MPI.COMM_WORLD)
    mesh = shell.mesh
    cell = mesh.basix_cell()
    displacement = basix.ufl.element(u_family, cell, u_degree, shape=(3,))
    if p_family == "DPC":
        pressure_element = basix.ufl.element("DPC", cell, p_degree, discontinuous=True,
                                             dpc_variant=basix.DPCVariant.legendre)
    else:
        pressure_element = basix.ufl.element(p_family, cell, p_degree)
    W = dolfinx.fem.functionspace(mesh, basix.ufl.mixed_element([displacement, pressure_element]))
    w = dolfinx.fem.Function(W)
    u, p = ufl.split(w)
    v, q = ufl.TestFunctions(W)

    F = ufl.variable(ufl.Identity(3) + ufl.grad(u))
    J = ufl.det(F)
    C = F.T * F
    energy = dolfinx.fem.Constant(mesh, c10) * (J ** (-2.0 / 3.0) * ufl.tr(C) - 3) + p * (J - 1)
    P = ufl.diff(energy, F)
    metadata = {"quadrature_degree": 4}
    dx = ufl.Measure("dx", domain=mesh, metadata=metadata)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=shell.facet_tags, metadata=metadata)
    N = ufl.FacetNormal(mesh)
    load = dolfinx.fem.Constant(mesh, pressure)
    residual = (ufl.inner(P, ufl.grad(v)) * dx + q * (J - 1) * dx
                + load * ufl.dot(J * ufl.inv(F).T * N, v) * ds(shell.tag("cavity_wall")))

    fdim = mesh.topology.dim - 1
    bcs = []
    for name, axis in (("symmetry_x", 0), ("symmetry_y", 1), ("symmetry_z", 2)):
        Vi, _ = W.sub(0).sub(axis).collapse()
        dofs = dolfinx.fem.locate_dofs_topological((W.sub(0).sub(axis), Vi), fdim, shell.facets(name))
        bcs.append(dolfinx.fem.dirichletbc(dolfinx.fem.Function(Vi), dofs, W.sub(0).sub(axis)))

    options = {"snes_type": "newtonls", "snes_linesearch_type": "basic", "snes_rtol": 1e-9,
               "snes_atol": 1e-10, "snes_max_it": 25, "ksp_type": "preonly", "pc_type": "lu",
               "pc_factor_mat_solver_type": "mumps"}
    problem = dolfinx.fem.petsc.NonlinearProblem(residual, w, bcs=bcs, petsc_options=options,
                                                 petsc_options_prefix="plain_sphere_")
    problem.solve()
    snes = problem.solver
    if snes.getConvergedReason() <= 0:
        raise RuntimeError(f"SNES did not converge: reason {snes.getConvergedReason()}")

    from eyemech.problems.reference.analytic import sphere_inner_radius

    x = ufl.SpatialCoordinate(mesh) + u
    wall = ds(shell.tag("cavity_wall"))
    area = mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(1.0 * wall)), op=MPI.SUM)
    radius = mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(
        ufl.sqrt(ufl.dot(x, x)) * wall)), op=MPI.SUM) / area
    exact = sphere_inner_radius(pressure, inner_radius, outer_radius, c10)
    return {"element": element, "mesh_size": mesh_size, "unknowns": W.dofmap.index_map.size_global
            * W.dofmap.index_map_bs, "inner_radius_deformed": radius,
            "inner_radius_error": radius / exact - 1.0, "newton_iterations": snes.getIterationNumber(),
            "seconds": time.perf_counter() - START}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--element", choices=sorted(ELEMENTS), default="P2P1")
    parser.add_argument("--mesh-size", type=float, default=1.0)
    args = parser.parse_args()
    result = solve(args.element, args.mesh_size)
    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps({k: (float(v) if isinstance(v, np.floating) else v) for k, v in result.items()}))


if __name__ == "__main__":
    main()
