"""The buckle's terms: the rigid buckle itself (placed, moved in, never crossed), its
contact with the sclera, the tie that holds the sclera under it, the sutures, and the
row of the tire's travel. The buckle's geometry (band, arc tire, radial tire) is
:mod:`eyemech.forms.buckle`'s; these terms ask it, never its kind."""

from __future__ import annotations

import functools
import math
from typing import Callable

import dolfinx
import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms.buckle import (
    Buckle,
    BuckleSizes,
    forward_slip,
    pinned_travel_residual,
    slip,
    tangential_tie_energy,
    tire_travel_residual,
)
from eyemech.forms.contact import penetration, smoothed_penalty_energy
from eyemech.forms.kinematics import without_variables
from eyemech.problems.contact.rigid import (
    FacePoints,
    NodalPenetration,
    ObstacleMultipliers,
    QuadraturePointMultipliers,
)
from eyemech.problems.run.parameters import ParameterError
from eyemech.problems.scleral_buckling.parameters import Parameters
from eyemech.problems.scleral_buckling.terms import Body
from eyemech.problems.solid.probes import NodeProbe
from eyemech.problems.solid.sutures import SutureForces, SuturePoint
from eyemech.problems.solve.scalars import assemble_scalar
from eyemech.problems.solve.terms import Control, Term


def contact_quadrature(integration: str, family) -> dict:
    """Quadrature of the buckle's penalty integral. ``nodal``: Gauss–Lobatto of degree 1
    (the trapezoidal rule, points at the face's vertices; Q1 faces only), so the
    penalty acts on the sclera's nodes as in a node-to-rigid-surface scheme."""
    if integration == "gauss":
        return {"quadrature_degree": family.quadrature_degree}
    if family.displacement_degree != 1:
        raise ParameterError("contact_integration", "nodal contact needs a Q1 displacement")
    return {"quadrature_rule": "GLL", "quadrature_degree": 1}


class RigidBuckle(Term):
    """The rigid buckle (:class:`~eyemech.forms.buckle.Buckle`): its sizes and axial
    position as Constants (a sweep over them reuses the compiled residual), its base
    radius (far away until :meth:`place` puts it ``buckle_clearance`` outside the inflated
    sclera), the band's travel (control ``band_travel``) and the tire's (the Real unknown
    δ_tire). Node-wise it refuses a load step that carries the sclera through it
    (``Stepping.depth_limit``)."""

    def __init__(self, body: Body, params: Parameters):
        self.body, self.params = body, params
        mesh, geo = body.mesh, body.geometry
        self.angle = geo.limbus_angle + math.degrees(params.buckle_position / geo.sclera_radius)
        self.axial_position = geo.sclera_radius * math.cos(math.radians(self.angle))
        self.base_radius = dolfinx.fem.Constant(mesh, 2 * geo.sclera_radius)
        self.indentation = dolfinx.fem.Constant(mesh, 0.0)  # the band's (prescribed) travel
        shape = params.buckle_shape()
        # which elements there are and whether the tire is arc-limited change the forms'
        # structure; their sizes are numbers in them (docs/atlas/peer-comparison.md)
        self.buckle = Buckle(shape, dolfinx.fem.Constant(mesh, self.axial_position), self.base_radius,
                             self.indentation, tire_indentation=body.tire_travel,
                             sizes=BuckleSizes.of(shape, lambda value: dolfinx.fem.Constant(mesh, value)),
                             polar_angle=dolfinx.fem.Constant(mesh, math.radians(self.angle)))
        self.surface = body.eye.ds(contact_quadrature(params.contact_integration, body.family))(
            body.eye.tag("sclera_outer"))  # the sclera's outer face, as the contact integrates it
        theta = math.radians(self.angle)
        under = np.array([[0.0, geo.sclera_radius * math.sin(theta), self.axial_position]])
        self.under = NodeProbe(body.u.function_space, under, body.sclera_nodes)
        self.under_reference: np.ndarray | None = None  # where it was when the buckle was placed

    @property
    def placed(self) -> bool:
        return float(self.base_radius.value) - float(self.indentation.value) \
            <= 1.5 * self.body.geometry.sclera_radius

    def place(self) -> None:
        """``buckle_clearance`` outside the deformed sclera under it: its flat inner faces
        must clear the largest distance from its axis within its span."""
        x = self.body.sclera_outer_positions()
        near = self.buckle.span_mask(x)
        local = float(self.buckle.axis_distance(x[near]).max()) if near.any() else 0.0
        radius = self.body.comm.allreduce(local, op=MPI.MAX)
        self.base_radius.value = radius + self.params.buckle_clearance
        self.under_reference = self.under.positions(self.body.u)

    def tire_travel(self) -> float:
        return self.body.real_value(self.body.tire_travel)

    def depth_through(self) -> float:
        """Largest depth of the sclera's outer nodes beyond the buckle's contact face, as a
        fraction of the element's thickness (forms/buckle.py, Buckle.depth_through)."""
        depth = self.buckle.depth_through(self.body.sclera_outer_positions(), self.tire_travel())
        return self.body.comm.allreduce(float(depth.max()) if len(depth) else -np.inf, op=MPI.MAX)

    def outline(self) -> np.ndarray | None:
        """The buckle's cross-section in the symmetry plane at its travels, as line
        segments; None before it is placed. Collective (the tire's travel is a
        distributed unknown): every rank must call it."""
        travel = self.tire_travel()
        return self.buckle.outline(travel) if self.placed else None

    def install(self, solver) -> None:
        solver.depth_hooks.append(self.depth_through)

    def controls(self) -> dict[str, Control]:
        return {"band_travel": Control(lambda: float(self.indentation.value),
                                       lambda value: setattr(self.indentation, "value", value))}

    def register(self, checkpoints) -> None:
        checkpoints.constant("base_radius", self.base_radius)
        checkpoints.constant("indentation", self.indentation)
        checkpoints.value("under_buckle_reference", lambda: self.under_reference,
                          lambda saved: setattr(self, "under_reference",
                                                None if saved is None else np.asarray(saved)))

    def measure(self) -> dict:
        under = self.under.positions(self.body.u)[0]
        before = (self.under.nodes if self.under_reference is None else self.under_reference)[0]
        indentation = float(self.buckle.axis_distance(before) - self.buckle.axis_distance(under))
        return {"buckle_indentation_mm": indentation,
                "buckle_travel_mm": float(self.indentation.value)}


class BuckleContact(Term):
    """The sclera's outer face on the rigid buckle: smoothed penalty contact, Π_c =
    ∫ φ(g) dA (α = ``penalty_factor`` · E_sclera / h), or with the augmented Lagrangian
    p = ⟨λ − α g⟩ with multipliers λ at the contact integral's points (at the nodes with
    ``contact_integration = nodal``): Uzawa's fixed point is then its constraint, g ≥ 0
    at those points, whatever α (docs/contact.md, Augmented Lagrangian)."""

    def __init__(self, body: Body, params: Parameters, buckle: RigidBuckle, penalty: float):
        self.body, self.params, self.buckle = body, params, buckle
        mesh = body.mesh
        self.augmented = params.contact_method == "augmented-lagrangian"
        self.penalty = penalty
        # the normal contact: the penalty's α, or the augmented Lagrangian's lower one
        self.normal_penalty = penalty * (params.augmented_penalty_scale if self.augmented else 1.0)
        # a Constant, not a literal: the penalty follows the mesh size and the sclera's
        # modulus, and a literal would compile the eye's residual anew for each of them
        self.contact_penalty = dolfinx.fem.Constant(mesh, self.normal_penalty)
        # the tangential tie keeps the penalty's α (the same Constant with the penalty method)
        self.tie_penalty = dolfinx.fem.Constant(mesh, penalty) if self.augmented else self.contact_penalty
        self.nodal_penetration = NodalPenetration(buckle.buckle, body.u, body.eye, "sclera_outer")
        self._points = FacePoints(body.eye, "sclera_outer", body.family.quadrature_degree)
        self._point_penetration = dolfinx.fem.Expression(
            without_variables(penetration(buckle.buckle, body.u)), self._points.reference_points)

    @functools.cached_property
    def _multipliers(self) -> QuadraturePointMultipliers | ObstacleMultipliers | None:
        if not self.augmented:
            return None
        params, body, buckle = self.params, self.body, self.buckle.buckle
        if params.contact_integration == "gauss":
            return QuadraturePointMultipliers(buckle, body.u, body.eye, "sclera_outer",
                                              self.contact_penalty, body.family.quadrature_degree,
                                              self._smoothing, name="buckle_contact_pressure")
        return ObstacleMultipliers(buckle, body.u, body.eye, "sclera_outer", self.contact_penalty,
                                   self._smoothing, name="buckle_contact_pressure")

    @functools.cached_property
    def _smoothing(self):
        # ε = 0 and ε > 0 are two forms; ε's value is a Constant
        epsilon = self.params.contact_smoothing
        return dolfinx.fem.Constant(self.body.mesh, epsilon) if epsilon > 0 else 0.0

    @functools.cached_property
    def energy(self):
        """Π_c, the buckle's penalty energy (a function of u and of the tire's travel)."""
        smoothing, multipliers = self._smoothing, self._multipliers
        return smoothed_penalty_energy(
            self.buckle.buckle, self.body.u, self.contact_penalty, smoothing, self.buckle.surface,
            multiplier=None if multipliers is None else multipliers.function)

    def residual(self, tests):
        return ufl.derivative(self.energy, self.body.u, tests[0])

    def install(self, solver) -> None:
        if self._multipliers is not None:  # the multipliers go back with a cut step
            solver.memory_hooks.append((self._multipliers.memory, self._multipliers.restore))

    def multipliers(self) -> list:
        return [] if self._multipliers is None else [self._multipliers]

    def register(self, checkpoints) -> None:
        if self._multipliers is not None:
            checkpoints.function("buckle_contact_pressure", self._multipliers.function)

    def measure(self) -> dict:
        return {
            # the deepest sclera node inside the buckle (the penalty's penetration; → 0 with
            # the augmented Lagrangian's multipliers)
            "buckle_penetration_max_mm": self.nodal_penetration(),
            # ... at the contact integral's points, where the penalty acts (Gauss points)
            "buckle_penetration_points_max_mm": self.body.comm.allreduce(float(np.max(
                self._points.values(self._point_penetration), initial=0.0)), op=MPI.MAX)}


class BuckleTie(Term):
    """The sclera under the buckle's footprint held on it tangentially from when the
    buckle is tied (:meth:`tie`): the sutured buckle (``buckle_attachment = sutured``,
    the penalty's α), or the frictionless buckle's weak spring for its friction on the
    sclera (``frictionless_slip_stiffness``; 0: none). Its measurement: the slip along
    the buckle since then."""

    def __init__(self, body: Body, params: Parameters, buckle: RigidBuckle, tie_penalty):
        self.body, self.params, self.buckle = body, params, buckle
        self.tie_penalty = tie_penalty
        self.u_tied = dolfinx.fem.Function(body.u.function_space, name="u_tied")
        self.tied = dolfinx.fem.Constant(body.mesh, 0.0)

    def residual(self, tests):
        params = self.params
        if params.buckle_attachment == "sutured":
            stiffness = self.tie_penalty
        elif params.frictionless_slip_stiffness > 0:
            # a weak spring for the buckle's friction on the sclera: it removes the
            # frictionless slide's near-zero stiffness (docs/scleral_buckling.md, "The
            # frictionless buckle's spring")
            stiffness = dolfinx.fem.Constant(self.body.mesh, params.frictionless_slip_stiffness)
        else:
            return None
        tie = tangential_tie_energy(self.buckle.buckle, self.body.u, self.u_tied, self.tied * stiffness,
                                    self.buckle.surface)
        return ufl.derivative(tie, self.body.u, tests[0])

    def tie(self) -> None:
        """The sclera's displacement now is where it is held."""
        self.u_tied.x.array[:] = self.body.u.x.array
        self.tied.value = 1.0

    def register(self, checkpoints) -> None:
        checkpoints.function("u_tied", self.u_tied)
        checkpoints.constant("tied", self.tied)

    def measure(self) -> dict:
        """Tangential motion (axial and circumferential) of the sclera's outer nodes under
        the buckle's footprint since it was tied: the buckle moves only radially, so this
        is the slip along it. ``buckle_slip_axial_mean_mm`` > 0: the sclera moved forward
        (towards the cornea) under the buckle (along the optic axis; along the meridian
        under a radial tire). Absent before the buckle is tied."""
        if float(self.tied.value) == 0.0:
            return {}
        V = self.body.u.function_space
        nodes = self.body.sclera_nodes[self.body.sclera_nodes < V.dofmap.index_map.size_local]
        tied = self.u_tied.x.array.reshape(-1, 3)[nodes]
        x0 = V.tabulate_dof_coordinates()[nodes] + tied
        buckle = self.buckle.buckle
        under = buckle.footprint_mask(x0)
        du = self.body.u.x.array.reshape(-1, 3)[nodes][under] - tied[under]
        comm = self.body.comm
        count = comm.allreduce(int(under.sum()), op=MPI.SUM)
        return {"buckle_slip_max_mm": comm.allreduce(float(slip(x0[under], du, buckle.axis).max(initial=0.0)),
                                                     op=MPI.MAX),
                "buckle_slip_axial_mean_mm": comm.allreduce(float(forward_slip(
                    x0[under], du, buckle.axis).sum()), op=MPI.SUM) / max(count, 1),
                "buckle_footprint_nodes": count}


class Sutures(Term):
    """Suture forces at the bites (both bites of each suture, ``suture_width`` apart
    across the element its meridian crosses), spread over each bite (radius
    ``suture_bite_radius``; a point load's response does not converge under refinement),
    tangent to the buckle's outline: from the bite to where the suture leaves the buckle,
    lagged (the last converged step's; seed 002, §2.2). Control ``suture_force``: the
    pull on each suture. With the loop model the sutures' pull also pushes the tire in
    (:meth:`pull_on_tire`)."""

    def __init__(self, body: Body, params: Parameters, buckle: RigidBuckle, loop: bool):
        self.body, self.buckle, self.loop = body, buckle, loop
        geo = body.geometry
        self.bites = buckle.buckle.suture_bites(params.suture_azimuths, params.suture_width,
                                                geo.sclera_radius, math.radians(buckle.angle))
        points = [SuturePoint(azimuth, side, centre) for azimuth, side, centre in self.bites]
        self.forces = SutureForces(body.mesh, body.u.function_space, points, body.sclera_nodes,
                                   params.suture_bite_radius)
        # each bite normalised on this mesh: the half model carries exactly its share
        self.forces.normalise(body.ds(body.eye.tag("sclera_outer")), body.comm)
        self.on_tire = [buckle.buckle.part_at(b[0]).is_tire for b in self.bites]

    def residual(self, tests):
        return self.forces.residual(tests[0], self.body.ds(self.body.eye.tag("sclera_outer")))

    def anchors(self) -> np.ndarray:
        """Where each suture leaves the buckle (directions for the next step)."""
        travel = self.buckle.tire_travel() if self.loop else None
        return self.buckle.buckle.suture_anchors(self.bites, travel)

    def pull_on_tire(self) -> float:
        """The sutures' inward radial resultant on the tire (half model, N): each tire
        suture's loop turns over the tire, which takes the opposite of its bite loads,
        −F_s ∫s_s w_s dA, whose inward component is |F| ∫s_s w_s dA d_s·e_in at its
        meridian (d_s from the bite to the tire's corner: lagged, as the bite loads).
        0 unless the loop drives the tire."""
        forces, pull = self.forces, 0.0
        for bite, direction, share, on_tire in zip(self.bites, forces.directions, forces.shares,
                                                   self.on_tire):
            if on_tire:  # the loop's reaction on the tire: −F_s, along the inward direction
                pull -= forces.magnitude * share * float(direction @ self.buckle.buckle.inward(bite))
        return pull if self.loop else 0.0

    def converged(self) -> None:
        self.forces.update_directions(self.body.u, self.anchors())

    def controls(self) -> dict[str, Control]:
        return {"suture_force": Control(lambda: self.forces.magnitude, self.forces.set_magnitude)}

    def register(self, checkpoints) -> None:
        checkpoints.value("sutures", lambda: {"directions": self.forces.directions,
                                              "magnitude": self.forces.magnitude}, self._restore)

    def _restore(self, saved: dict) -> None:
        self.forces.directions = np.asarray(saved["directions"], dtype=float)
        self.forces.set_magnitude(saved["magnitude"])

    def measure(self) -> dict:
        return {"suture_force_N": float(self.forces.magnitude)}


class TireRow(Term):
    """The tire's radial travel δ (a Real unknown) and its row: pinned to the band's
    travel, k (δ − δ_band) = 0, or free (``tire_free``): the sclera's contact force on the
    tire, ∂Π_c/∂δ, balanced against the sutures' inward pull (``suture_pull``, from
    ``pull``), the instrument's hold (``tire_hold``, released over suturing) and the
    band's push on the tire it runs over (a unilateral stop). The loop model frees the
    tire: without a band when buckling ends (:meth:`free`), with one once the pull exceeds
    the contact force (:meth:`release_from_band`)."""

    def __init__(self, body: Body, buckle: RigidBuckle, contact: BuckleContact, loop: bool,
                 pull: Callable[[], float]):
        self.body, self.buckle, self.contact, self.loop, self.pull = body, buckle, contact, loop, pull
        mesh = body.mesh
        self.tire_free = dolfinx.fem.Constant(mesh, 0.0)
        self.tire_hold = dolfinx.fem.Constant(mesh, 0.0)    # the instrument's hold
        self.suture_pull = dolfinx.fem.Constant(mesh, 0.0)  # the sutures' inward resultant
        self.held_force = 0.0  # the sclera's force on the tire when it was freed
        # Constants of the row from the reference configuration, not literals (the mesh and
        # the penalty set them, and a literal would compile the residual anew for each):
        # the sclera's outer area (the row's constant terms are spread over it) and the
        # stiffness of the band's push and of the pinned row (the buckle's penalty over
        # the tire's footprint: as stiff as the sclera's contact with it)
        X = ufl.SpatialCoordinate(mesh)
        one = dolfinx.fem.Constant(mesh, 1.0)
        measure = body.ds(body.eye.tag("sclera_outer"))
        self.sclera_area = dolfinx.fem.Constant(mesh, assemble_scalar(one * measure, body.comm))
        footprint = assemble_scalar(buckle.buckle.footprint_weight(X) * measure, body.comm)
        self.tire_stiffness = dolfinx.fem.Constant(mesh, contact.penalty * max(footprint, 1.0))
        self.band_backed = buckle.buckle.backs_tire

    def residual(self, tests):
        delta, q, surface = self.body.tire_travel, tests[-1], self.buckle.surface
        band_travel = self.buckle.indentation
        inward = self.suture_pull + self.tire_hold + self.buckle.buckle.band_push(delta, self.tire_stiffness)
        free = tire_travel_residual(self.contact.energy, delta, q, inward, surface, self.sclera_area)
        pinned = pinned_travel_residual(delta, band_travel, q, self.tire_stiffness, surface,
                                        self.sclera_area)
        return self.tire_free * free + (1 - self.tire_free) * pinned

    @functools.cached_property
    def _force_form(self) -> dolfinx.fem.Form:
        direction = dolfinx.fem.Function(self.body.tire_travel.function_space)
        direction.x.array[:] = 1.0
        return dolfinx.fem.form(ufl.derivative(self.contact.energy, self.body.tire_travel, direction))

    def contact_force(self) -> float:
        """∂Π_c/∂δ: the sclera's contact force on the tire along its inward travel (half
        model, N)."""
        return assemble_scalar(self._force_form, self.body.comm)

    @property
    def free_(self) -> bool:
        return float(self.tire_free.value) == 1.0

    def free(self) -> None:
        """Buckling ends (loop, no band): the tire's travel becomes an unknown; the force
        that holds it there is measured, to be released over suturing. A tire that does
        not touch the sclera (travel within the clearance) has no contact force to balance
        its row (∂Π_c/∂δ ≡ 0 would make the Jacobian singular): it keeps its travel."""
        if not self.loop or self.band_backed:
            return  # a band holds it: see release_from_band
        force = self.contact_force()
        if force <= 0.0:
            return
        self.held_force = force
        self.tire_free.value = 1.0
        self.tire_hold.value = self.held_force

    def release_from_band(self) -> None:
        """With a band (loop): the band holds the tire at its travel while the sclera
        pushes the tire out harder than the sutures pull it in. Once the pull exceeds the
        sclera's contact force (checked after every converged step while the sutures pull,
        lagged by one step as the suture directions are), the tire's travel is free and
        the band's push becomes the unilateral stop of its row, which takes the tire back if
        the pull drops. Freed on the stop's kink with the pull winning, Newton starts on
        the side where the stop is inactive; freed with the contact winning, Newton
        stalled there on the default mesh (residual constant at 2.3e-4), and a
        frictionless 1 mm buckle stalled in the suturing stage on the coarse eye."""
        if not (self.loop and self.band_backed) or self.free_:
            return
        pull = float(self.suture_pull.value)
        if pull > 0.0 and pull > self.contact_force():
            self.tire_free.value = 1.0

    def prepare(self) -> None:
        self.suture_pull.value = self.pull()
        if not self.free_:  # prescribed: start Newton at the target
            self.body.tire_travel.x.array[:] = float(self.buckle.indentation.value)

    def converged(self) -> None:
        self.suture_pull.value = self.pull()
        self.release_from_band()

    def controls(self) -> dict[str, Control]:
        return {"tire_hold": Control(lambda: float(self.tire_hold.value),
                                     lambda value: setattr(self.tire_hold, "value", value)),
                "held_force": Control(lambda: self.held_force,
                                      lambda value: setattr(self, "held_force", value))}

    def register(self, checkpoints) -> None:
        checkpoints.function("tire_travel", self.body.tire_travel)
        for name in ("tire_free", "tire_hold", "suture_pull"):
            checkpoints.constant(name, getattr(self, name))
        checkpoints.value("held_force", lambda: self.held_force,
                          lambda saved: setattr(self, "held_force", float(saved)))

    def measure(self) -> dict:
        # the tire's radial travel (= the band's unless the sutures' loop drives it), the
        # sclera's contact force on it and the sutures' inward pull (whole eye)
        return {"tire_travel_mm": self.buckle.tire_travel(),
                "tire_contact_force_N": 2.0 * self.contact_force(),
                "tire_suture_pull_N": 2.0 * float(self.suture_pull.value),
                "tire_free": self.free_}
