"""``retina-reattachment``: a detached retina pushed back onto the choroid — the
deformable-on-deformable contact precursor of the scleral-buckling scene.

Two concentric spherical caps about the z axis (one quarter, symmetry planes
x = 0 and y = 0): a thin soft layer (the retina, r ∈ [R, R + t_s]) lies ``gap``
inside a stiffer layer (choroid and sclera, outer face fixed). The soft layer is
held at its rim (where it is still attached) and a pressure on its inner face
(the vitreous or a gas tamponade) pushes it outwards until it lies on the stiff
layer. Contact: slave = the soft layer's outer face (nodes), master = the stiff
layer's inner face (triangles), penalty node to surface
(:mod:`eyemech.problems.contact.node_to_surface`), searched at every Newton iteration.

Both layers are compressible neo-Hookean (E, ν). Quantities: ``min_gap`` (the
smallest slave gap, negative = penetration), ``max_penetration``, the expected
penalty penetration p/α, ``contact_area`` (of the quarter model),
``contact_normal_force`` and the Newton residual histories (steps).
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
from eyemech.meshes.contact_bodies import layered_caps
from eyemech.problems.contact.node_to_surface import NodeToSurfaceContact
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.output import gather_grid, render_png
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, SOLVER, ParameterError, SceneParameters, field
from eyemech.problems.run.scene import Scene
from eyemech.problems.solid.spaces import global_dofs
from eyemech.problems.solve.driver import NonlinearSolver, Stepping, follow_path

QUADRATURE = {"quadrature_degree": 4}
# the caps' facet regions (meshes/contact_bodies.py::layered_caps) and the body each bounds;
# the contact pairs the two faces that face each other across the gap
FACETS = {"slave": "soft", "pressure": "soft", "soft_rim": "soft", "master": "stiff",
          "fixed": "stiff", "stiff_rim": "stiff", "symmetry_x": "both", "symmetry_y": "both"}
FACING = ("slave", "master")  # the soft layer's outer face, the stiff layer's inner face


@dataclasses.dataclass(frozen=True)
class Parameters(SceneParameters):
    inner_radius: float = field(10.0, "inner radius of the soft layer", "mm", group=GEOMETRY)
    soft_thickness: float = field(0.2, "thickness of the soft layer (retina)", "mm", group=GEOMETRY)
    gap: float = field(0.1, "initial gap between the layers", "mm", group=GEOMETRY)
    stiff_thickness: float = field(0.3, "thickness of the stiff layer (choroid, sclera)", "mm",
                                   group=GEOMETRY)
    half_angle: float = field(12.0, "polar half-angle of the caps", "deg", group=GEOMETRY)
    soft_modulus: float = field(0.005, "Young's modulus of the soft layer", "MPa", group=PHYSICS)
    stiff_modulus: float = field(0.05, "Young's modulus of the stiff layer", "MPa", group=PHYSICS)
    poisson_ratio: float = field(0.3, "Poisson's ratio of both layers", "", group=PHYSICS)
    pressure: float = field(2e-5, "pressure on the soft layer's inner face", "MPa", group=PHYSICS)
    penalty: float = field(30.0, "penalty factor: α = penalty · soft_modulus / mesh_size", "", group=SOLVER)
    smoothing: float = field(0.5, "penalty round-off width ε as a fraction of p/α (0 = plain kink)", "",
                             group=SOLVER)
    mesh_size: float = field(0.3, "element size", "mm", group=GEOMETRY)
    degree: int = field(2, "displacement degree (1 or 2)", group=GEOMETRY)
    load_steps: int = field(8, "initial number of load steps (cut and grown as needed)", group=SOLVER)
    # the caps' two contact faces (meshes/contact_bodies.py::layered_caps); another facet
    # region (the clamped "fixed" face) is no contact surface
    slave: Literal["slave", "master"] = field("slave", "facet region of the slave surface",
                                              group=GEOMETRY)
    master: Literal["slave", "master"] = field("master", "facet region of the master surface",
                                               group=GEOMETRY)

    def domain_volume(self) -> float:
        """The two quarter caps' volume (meshes/contact_bodies.py::layered_caps): gmsh's
        meshes have 0.7–1.4 of the estimate from it (tests/test_mesh_resolution.py)."""
        cap = math.pi / 6.0 * (1.0 - math.cos(math.radians(self.half_angle)))
        soft_out = self.inner_radius + self.soft_thickness
        stiff_in = soft_out + self.gap
        return cap * (soft_out ** 3 - self.inner_radius ** 3
                      + (stiff_in + self.stiff_thickness) ** 3 - stiff_in ** 3)

    def validate(self) -> None:
        self.require_nonnegative("smoothing")
        self.require_positive("inner_radius", "soft_thickness", "gap", "stiff_thickness",
                              "half_angle", "soft_modulus", "stiff_modulus", "pressure", "penalty",
                              "mesh_size", "load_steps")
        if not -1.0 < self.poisson_ratio < 0.5:
            raise ParameterError("poisson_ratio", f"must lie in (-1, 0.5), got {self.poisson_ratio}")
        if self.half_angle >= 80:
            raise ParameterError("half_angle", "must be below 80 degrees")
        if self.degree not in (1, 2):
            raise ParameterError("degree", f"must be 1 or 2, got {self.degree}")
        self._validate_contact_pair()

    def _validate_contact_pair(self) -> None:
        """Slave and master: two facet regions of the caps, of different bodies, facing
        each other across the gap (the soft layer's outer face and the stiff layer's inner
        one, in either role). The key named is the one set off its default."""
        defaults = {"slave": FACING[0], "master": FACING[1]}
        changed = [k for k in ("slave", "master") if getattr(self, k) != defaults[k]] \
            or ["slave"]
        for key in ("slave", "master"):
            if getattr(self, key) not in FACETS:
                raise ParameterError(key, f"'{getattr(self, key)}' is not a facet region of the "
                                     f"caps; they are {', '.join(FACETS)}")
        key = changed[0]
        if self.slave == self.master:
            raise ParameterError(key, f"slave and master are both '{self.slave}': a surface "
                                 "cannot be in contact with itself")
        bodies = {FACETS[self.slave], FACETS[self.master]}
        if "both" in bodies or len(bodies) == 1:
            raise ParameterError(key, f"slave '{self.slave}' and master '{self.master}' do not "
                                 "bound the two different layers (soft: slave, pressure, "
                                 "soft_rim; stiff: master, fixed, stiff_rim)")
        if {self.slave, self.master} != set(FACING):
            raise ParameterError(key, f"slave '{self.slave}' and master '{self.master}' do not "
                                 "face each other across the gap: the contact is between "
                                 "the soft layer's outer face 'slave' and the stiff layer's "
                                 "inner face 'master' (either may be the slave)")

    @property
    def penalty_stiffness(self) -> float:
        return default_penalty(self.soft_modulus, self.mesh_size, self.penalty)


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        with ctx.timings("mesh"):
            caps = layered_caps(params.inner_radius, params.soft_thickness, params.gap,
                                params.stiff_thickness, params.half_angle, params.mesh_size,
                                order=params.degree, comm=ctx.comm)
            caps.require_nonempty(params.slave, params.master)
        mesh = caps.mesh
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", params.degree, (3,)))
        u, v = dolfinx.fem.Function(V, name="displacement"), ufl.TestFunction(V)
        dx = caps.dx(QUADRATURE)

        def energy_density(youngs_modulus: float):
            return compressible_neo_hooke(deformation_gradient(u), youngs_modulus, params.poisson_ratio)

        energy = (energy_density(params.soft_modulus) * dx(caps.tag("soft"))
                  + energy_density(params.stiff_modulus) * dx(caps.tag("stiff")))
        pressure = dolfinx.fem.Constant(mesh, 0.0)
        residual = ufl.derivative(energy, u, v) + follower_pressure(
            pressure, u, v, caps.ds(QUADRATURE)(caps.tag("pressure")))
        bcs = _boundary_conditions(V, caps)
        alpha = params.penalty_stiffness
        contact = NodeToSurfaceContact(u, caps, params.slave, params.master, alpha, bcs,
                                       search_depth=params.gap + params.soft_thickness,
                                       smoothing=params.smoothing * params.pressure / alpha,
                                       timings=ctx.timings)
        contact.refuse_initial_penetration("gap")
        solver = NonlinearSolver(residual, u, bcs, options=ctx.options.newton, timings=ctx.timings,
                                 residual_hooks=[contact.residual_hook],
                                 jacobian_hooks=[contact.jacobian_hook])
        contact.allow_new_nonzeros(solver.problem.A)
        nonzeros_before = solver.jacobian_nonzeros()

        writer = ctx.field_writer([u])
        writer.write(0.0)

        def apply(load: float, _increment: float) -> None:
            pressure.value = load * params.pressure

        def converged(record) -> None:
            contact.search()
            ctx.record_step(step=record.step, load_factor=record.load, newton_iterations=record.iterations,
                            cuts=record.cuts, **record.counts(), residuals=record.residuals,
                            min_gap=contact.min_gap(), **contact.summary())
            with ctx.timings("output"):
                writer.write(record.load)

        try:
            records = follow_path(solver, apply, Stepping(initial_step=1.0 / params.load_steps),
                                  on_converged=converged, label=SCENE.name, quiet=ctx.options.quiet)
        finally:
            writer.close()
            ctx.result.fields = writer.files
        contact.state = contact.search()
        q = ctx.result.quantities
        q.update(contact.summary())
        q["min_gap"] = contact.min_gap()
        q["penalty_stiffness"] = alpha
        q["expected_penetration"] = params.pressure / alpha
        q["newton_iterations"] = sum(r.iterations for r in records)
        q["load_steps"] = len(records)
        q["dofs"] = global_dofs(u)
        q["slave_nodes"] = ctx.comm.allreduce(len(contact.slave_blocks))
        q["master_triangles"] = len(contact.triangles)
        q["contact_pairs_across_ranks"] = contact.pairs_across_ranks()
        q["jacobian_nonzeros_fe"] = nonzeros_before
        q["jacobian_nonzeros_with_contact"] = solver.jacobian_nonzeros()
        if ctx.pictures:
            with ctx.timings("output"):
                _picture(u, ctx, params)
    return ctx.result


def _boundary_conditions(V, caps):
    fdim = caps.mesh.topology.dim - 1
    bcs = []
    for name in ("fixed", "soft_rim"):
        dofs = dolfinx.fem.locate_dofs_topological(V, fdim, caps.facets(name))
        bcs.append(dolfinx.fem.dirichletbc(np.zeros(3), dofs, V))
    for name, component in (("symmetry_x", 0), ("symmetry_y", 1)):
        dofs = dolfinx.fem.locate_dofs_topological(V.sub(component), fdim, caps.facets(name))
        bcs.append(dolfinx.fem.dirichletbc(0.0, dofs, V.sub(component)))
    return bcs


def _picture(u, ctx: RunContext, params: Parameters) -> None:
    grid = gather_grid(u)
    if grid is None:
        return
    grid.point_data["displacement (mm)"] = np.linalg.norm(grid.point_data["displacement"], axis=1)
    path = ctx.out / "retina-reattachment.png"
    # seen across the symmetry plane y = 0: the section shows the closed gap
    render_png(grid, path, scalars="displacement (mm)", warp="displacement", camera=(0.0, -1.0, 0.0),
               show_undeformed=False,
               title=f"retina-reattachment: gap {params.gap:g} mm closed by p = {params.pressure:g} MPa",
               scene=ctx.result.scene, parameters=ctx.result.parameters)
    ctx.result.pictures.append(path.name)


SCENE = Scene(name="retina-reattachment", kind="scene", parameters=Parameters, run=run,
              summary="soft curved layer pushed across a gap onto a stiffer one (node-to-surface contact)")
