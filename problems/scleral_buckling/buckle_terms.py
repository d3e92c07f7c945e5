"""The buckle's terms: the rigid buckle itself (placed, moved in, never crossed), its
contact with the sclera and the tie that holds the sclera under it (the sutures and the
tire's row are :mod:`.suture_terms`'). The buckle's geometry (band, arc tire, radial tire)
is :mod:`eyemech.forms.buckle`'s; these terms ask it, never its kind."""

from __future__ import annotations

import dataclasses
import functools
import math

import dolfinx
import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms.buckle import (
    Buckle,
    BuckleSizes,
    forward_slip,
    slip,
    tangential_tie_energy,
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
from eyemech.problems.scleral_buckling.body import Body
from eyemech.problems.scleral_buckling.parameters import Parameters
from eyemech.problems.solid.probes import NodeProbe
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
    δ_tire); an elastic band (``buckle_control = shortening``) and the tire under it both
    travel by that unknown (:class:`.suture_terms.BandRow` its row). Node-wise it refuses
    a load step that carries the sclera through it (``Stepping.depth_limit``)."""

    def __init__(self, body: Body, params: Parameters):
        self.body, self.params = body, params
        mesh, geo = body.mesh, body.geometry
        self.angle = geo.limbus_angle + math.degrees(params.buckle_position / geo.sclera_radius)
        self.axial_position = geo.sclera_radius * math.cos(math.radians(self.angle))
        self.base_radius = dolfinx.fem.Constant(mesh, 2 * geo.sclera_radius)
        # the band's travel: prescribed (buckle_control = travel), or the value of the Real
        # unknown of an elastic band (shortening), which then carries the tire with it
        self.indentation = dolfinx.fem.Constant(mesh, 0.0)
        self.elastic_band = params.elastic_band()
        shape = params.buckle_shape()
        # which elements there are and whether the tire is arc-limited change the forms'
        # structure; their sizes are numbers in them (docs/atlas/peer-comparison.md)
        self.buckle = Buckle(shape, dolfinx.fem.Constant(mesh, self.axial_position), self.base_radius,
                             body.tire_travel if self.elastic_band else self.indentation,
                             tire_indentation=None if self.elastic_band else body.tire_travel,
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
        """The Real unknown's value: the tire's travel, or the elastic band's (which carries
        the tire). Collective."""
        return self.body.real_value(self.body.tire_travel)

    def band_travel(self) -> float:
        """The band's radial travel (collective with an elastic band)."""
        return self.tire_travel() if self.elastic_band else float(self.indentation.value)

    def numbers(self, travel: float | None = None) -> Buckle:
        """The buckle with its band's travel a number, for the questions asked of it on
        points (depth, outline, suture anchors): an elastic band's travel is a Real
        unknown in the forms (``travel``: its value, read when None). Collective."""
        if not self.elastic_band:
            return self.buckle
        travel = self.tire_travel() if travel is None else travel
        return dataclasses.replace(self.buckle, indentation=travel)

    def depth_through(self) -> float:
        """Largest depth of the sclera's outer nodes beyond the buckle's contact face, as a
        fraction of the element's thickness (forms/buckle.py, Buckle.depth_through)."""
        travel = self.tire_travel()
        depth = self.numbers(travel).depth_through(self.body.sclera_outer_positions(), travel)
        return self.body.comm.allreduce(float(depth.max()) if len(depth) else -np.inf, op=MPI.MAX)

    def outline(self) -> np.ndarray | None:
        """The buckle's cross-section in the symmetry plane at its travels, as line
        segments; None before it is placed. Collective (the tire's travel is a
        distributed unknown): every rank must call it."""
        placed = self.at_travel()
        return None if placed is None else placed[0].outline(placed[1])

    def at_travel(self) -> tuple[Buckle, float] | None:
        """The buckle with its travels as numbers and the tire's travel, what its pictures
        draw (:meth:`~eyemech.forms.buckle.Buckle.outline`, ``.parts``' sections); None
        before it is placed. Collective, as :meth:`outline`."""
        travel = self.tire_travel()
        return (self.numbers(travel), travel) if self.placed else None

    def install(self, solver) -> None:
        solver.depth_hooks.append(self.depth_through)

    def controls(self) -> dict[str, Control]:
        return {"band_travel": Control.of(self.indentation)}

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
                "buckle_travel_mm": self.band_travel()}


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
