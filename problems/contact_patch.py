"""``contact-patch``: the contact patch test (Taylor & Papadopoulos, 1991) for the
deformable-on-deformable penalty contact: segment-to-segment with mortar integration
(:mod:`eyemech.problems.contact.segment_to_segment`, ``method="segment-to-segment"``, the
default) or node to surface (:mod:`eyemech.problems.contact.node_to_surface`).

Two elastic blocks, one on the other, meshed separately with different element
sizes so the contact faces do not match. The lower block sits on a frictionless
support (u_z = 0 at its bottom); symmetry planes x = 0 and y = 0; a uniform
pressure p on the top. The exact solution is uniform: P_zz = −p in both blocks
(up to the lateral stretch of the follower load's area), so the contact pressure
must be the same everywhere. A method passes the patch test when it reproduces this
to round-off (up to the penalty's uniform penetration p/α). Segment-to-segment does
(stress spread ~1e-12 with P1, ~4e-10 with P2); node-to-surface does not (25 %
single pass, 5–7 % two pass; docs/contact.md §4).

Quantities: ``pressure_mean``, ``pressure_min``, ``pressure_max`` (MPa, over the
touching slave nodes for node-to-surface, the touching segment quadrature points for
segment-to-segment), ``pressure_spread`` = (max − min)/p, ``pressure_rms_error`` =
rms(p_i − p)/p, ``touching_fraction`` of the slave nodes (of the segments),
``stress_spread_lower``/``_upper`` = (max − min)/p of the cell-wise P_zz (the test
proper), the contact summary (``contact_active_nodes`` counts touching segments for
segment-to-segment).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Literal

import dolfinx
import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms import compressible_neo_hooke, deformation_gradient, follower_pressure
from eyemech.forms.contact import default_penalty
from eyemech.meshes.contact_bodies import stacked_blocks
from eyemech.problems.contact.node_to_surface import NodeToSurfaceContact
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, SceneParameters, field
from eyemech.problems.run.scene import Scene
from eyemech.problems.solid.spaces import global_dofs, symmetry_bcs
from eyemech.problems.solve.driver import NonlinearSolver, Stepping, follow_path

QUADRATURE = {"quadrature_degree": 2}


@dataclasses.dataclass(frozen=True)
class Parameters(SceneParameters):
    width: float = field(1.0, "width of both blocks (square)", "mm", group=GEOMETRY)
    youngs_modulus: float = field(1.0, "Young's modulus of both blocks", "MPa", group=PHYSICS)
    poisson_ratio: float = field(0.3, "Poisson's ratio", "", group=PHYSICS)
    pressure: float = field(0.01, "pressure on the top face", "MPa", group=PHYSICS)
    penalty: float = field(30.0, "penalty factor: α = penalty · E / master_size", "", group=SOLVER)
    master_size: float = field(0.25, "element size of the lower (master) block", "mm", group=GEOMETRY)
    slave_size: float = field(0.17, "element size of the upper (slave) block", "mm", group=GEOMETRY)
    degree: int = field(1, "displacement degree (1 or 2)", group=GEOMETRY)
    passes: int = field(1, "1: slave surface on master surface; 2: also the reverse (two-pass)", group=SOLVER)
    method: Literal["segment-to-segment", "node-to-surface"] = field(
        "segment-to-segment", "contact discretisation: pressure integrated over the slave "
        "surface segmented by the master triangles (mortar integration), or at the slave nodes", group=SOLVER)

    def _block_cells(self) -> dict[str, float]:
        """Tetrahedra of each w × w × w/2 block at its size (regular tetrahedra, h³/(6√2));
        gmsh's meshes have 0.64–0.76 of this (tests/test_mesh_resolution.py)."""
        volume = 0.5 * self.width ** 3
        return {key: volume / (getattr(self, key) ** 3 / (6.0 * math.sqrt(2.0)))
                for key in ("master_size", "slave_size")}

    @property
    def estimated_cells(self) -> int:
        return int(sum(self._block_cells().values()))

    def resolution_key(self) -> str:
        """The block size that contributes most of the cells."""
        cells = self._block_cells()
        return max(cells, key=cells.get)

    def validate(self) -> None:
        self.require_positive("width", "youngs_modulus", "pressure", "penalty", "master_size",
                              "slave_size")
        if not -1.0 < self.poisson_ratio < 0.5:
            from eyemech.problems.run.parameters import ParameterError

            raise ParameterError("poisson_ratio", f"must lie in (-1, 0.5), got {self.poisson_ratio}")
        if self.passes not in (1, 2):
            from eyemech.problems.run.parameters import ParameterError

            raise ParameterError("passes", f"must be 1 or 2, got {self.passes}")


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        w = params.width
        with ctx.timings("mesh"):
            blocks = stacked_blocks(w, 0.5 * w, 0.5 * w, params.master_size, params.slave_size,
                                    comm=ctx.comm)
        V = dolfinx.fem.functionspace(blocks.mesh, ("Lagrange", params.degree, (3,)))
        u, v = dolfinx.fem.Function(V, name="displacement"), ufl.TestFunction(V)
        energy = (compressible_neo_hooke(deformation_gradient(u), params.youngs_modulus, params.poisson_ratio)
                  * blocks.dx(QUADRATURE))
        load = dolfinx.fem.Constant(blocks.mesh, 0.0)
        residual = ufl.derivative(energy, u, v) + follower_pressure(
            load, u, v, blocks.ds(QUADRATURE)(blocks.tag("top")))
        bcs = symmetry_bcs(V, blocks, {"symmetry_x": 0, "symmetry_y": 1, "bottom": 2})
        alpha = default_penalty(params.youngs_modulus, params.master_size, params.penalty)
        contact = NodeToSurfaceContact(u, blocks, "slave", "master", alpha, bcs,
                                       search_depth=0.25 * w, timings=ctx.timings,
                                       method=params.method)
        contact.refuse_initial_penetration("width", tolerance=1e-9 * w)
        searches = [contact]
        if params.passes == 2:  # the reverse pass: the lower block's nodes on the upper's faces
            searches.append(NodeToSurfaceContact(u, blocks, "master", "slave", alpha, bcs,
                                                 search_depth=0.25 * w, timings=ctx.timings,
                                                 method=params.method))
        solver = NonlinearSolver(residual, u, bcs, options=ctx.options.newton, timings=ctx.timings,
                                 residual_hooks=[s.residual_hook for s in searches],
                                 jacobian_hooks=[s.jacobian_hook for s in searches])
        contact.allow_new_nonzeros(solver.problem.A)

        def apply(value: float, _increment: float) -> None:
            load.value = value * params.pressure

        def converged(record) -> None:
            ctx.record_step(step=record.step, load_factor=record.load,
                            newton_iterations=record.iterations, cuts=record.cuts,
                            **record.counts(), residuals=record.residuals)

        records = follow_path(solver, apply, Stepping(initial_step=0.5), on_converged=converged,
                              label=SCENE.name, quiet=ctx.options.quiet)
        contact.state = contact.search()
        summary = contact.summary()
        _, pressures = contact.nodal_pressures()
        everything = np.concatenate(ctx.comm.allgather(pressures))
        if params.method == "segment-to-segment":  # over the segments and their points
            touching = summary["active_nodes"] / ctx.comm.allreduce(contact.search_segments().segments)
        else:
            touching = len(everything) / ctx.comm.allreduce(len(contact.slave_blocks))
        p = params.pressure
        q = ctx.result.quantities
        q.update({"pressure_mean": float(everything.mean()), "pressure_min": float(everything.min()),
                  "pressure_max": float(everything.max()),
                  "pressure_spread": float((everything.max() - everything.min()) / p),
                  "pressure_rms_error": float(np.sqrt(np.mean((everything - p) ** 2)) / p),
                  "touching_fraction": touching,
                  "penalty_stiffness": alpha, "newton_iterations": sum(r.iterations for r in records),
                  "dofs": global_dofs(u)})
        q.update({f"contact_{k}": val for k, val in summary.items()})
        q.update(_stress_spread(u, blocks, params))
    return ctx.result


def _stress_spread(u, blocks, params: Parameters) -> dict[str, float]:
    """(max − min)/p of the cell-wise first Piola–Kirchhoff P_zz in each block: the patch
    test proper (the exact P_zz is −p everywhere)."""
    F = deformation_gradient(u)
    P = ufl.diff(compressible_neo_hooke(F, params.youngs_modulus, params.poisson_ratio), F)
    Q = dolfinx.fem.functionspace(blocks.mesh, ("DG", 0))
    stress = dolfinx.fem.Function(Q)
    stress.interpolate(dolfinx.fem.Expression(P[2, 2], Q.element.interpolation_points))
    out = {}
    comm = blocks.mesh.comm
    owned = blocks.mesh.topology.index_map(3).size_local
    for name in ("lower", "upper"):
        cells = blocks.cells(name)
        values = stress.x.array[cells[cells < owned]]
        high = comm.allreduce(float(values.max(initial=-np.inf)), op=MPI.MAX)
        low = comm.allreduce(float(values.min(initial=np.inf)), op=MPI.MIN)
        out[f"stress_spread_{name}"] = (high - low) / params.pressure
    return out


SCENE = Scene(name="contact-patch", kind="benchmark", parameters=Parameters, run=run,
              summary="patch test: two blocks with non-matching meshes under uniform pressure")
