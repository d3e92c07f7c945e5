"""The sutures and the row of the tire's travel: a suture's loop pulls its bites towards
the buckle and, over a tire, pushes the tire in, whose travel then balances the sclera's
contact force (docs/scleral_buckling.md, "The sutures and the tire's travel"). The
buckle's geometry is :mod:`eyemech.forms.buckle`'s."""

from __future__ import annotations

import functools
import math
from typing import Callable

import dolfinx
import dolfinx.fem
import numpy as np
import ufl

from eyemech.forms.buckle import (
    band_hoop_residual,
    band_length,
    band_tension,
    pinned_travel_residual,
    tire_travel_residual,
)
from eyemech.forms.sutures import bite_weight, tied_leg_energy, tied_leg_stretch
from eyemech.problems.run.parameters import ParameterError
from eyemech.problems.scleral_buckling.body import Body
from eyemech.problems.scleral_buckling.buckle_terms import BuckleContact, RigidBuckle
from eyemech.problems.scleral_buckling.parameters import Parameters
from eyemech.problems.solid.sutures import BitesMissed, SutureForces, SuturePoint
from eyemech.problems.solve.scalars import assemble_scalar
from eyemech.problems.solve.terms import Control, Term


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
        self.bites = buckle.buckle.suture_bites(params.suture_meridians(), params.suture_width,
                                                geo.sclera_radius, math.radians(buckle.angle))
        points = [SuturePoint(azimuth, side, centre) for azimuth, side, centre in self.bites]
        self.forces = SutureForces(body.mesh, body.u.function_space, points, body.sclera_nodes,
                                   params.suture_bite_radius)
        # each bite normalised on this mesh: the half model carries exactly its share
        try:
            self.forces.normalise(body.ds(body.eye.tag("sclera_outer")), body.comm)
        except BitesMissed as missed:
            raise ParameterError("suture_bite_radius", f"{params.suture_bite_radius} mm: "
                                 f"{len(missed.centres)} bite(s) hold nothing on this mesh (no "
                                 "quadrature point of the sclera's surface within the bite, at "
                                 f"{', '.join(_point(c) for c in missed.centres)}); use a wider "
                                 "bite or a finer resolution") from None
        self.on_tire = [buckle.buckle.part_at(b[0]).is_tire for b in self.bites]

    def residual(self, tests):
        return self.forces.residual(tests[0], self.body.ds(self.body.eye.tag("sclera_outer")))

    def anchors(self) -> np.ndarray:
        """Where each suture leaves the buckle (directions for the next step)."""
        travel = self.buckle.tire_travel() if self.loop else None
        return self.buckle.numbers().suture_anchors(self.bites, travel)

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


class MattressSutures(Sutures):
    """Mattress sutures tied to a length (``suture_model = mattress``): each leg runs from
    its bite to where it leaves the buckle (the element's outer corner on its side) and is
    a stiff elastic thread (``suture_stiffness``, tension only). Over suturing the knot
    (control ``suture_tie``, 0 → 1) shortens each leg by ``suture_tie_fraction`` of the
    sclera between its bite and the element's edge, (suture_width − element width)/2: the
    surgeon draws the bites towards the element, so wider bites imbricate more sclera under
    it. The legs' energy (:func:`~eyemech.forms.sutures.tied_leg_energy`) gives both the
    bites' loads (∂/∂u) and, as the anchors ride on the buckle's travel δ, the sutures' push
    on the buckle (∂/∂δ, in the tire's or the band's row): the tension follows from the
    sclera's resistance, it is not prescribed (docs/scleral_buckling.md, Mattress sutures)."""

    def __init__(self, body: Body, params: Parameters, buckle: RigidBuckle, driven: bool):
        super().__init__(body, params, buckle, driven)
        mesh, X = body.mesh, ufl.SpatialCoordinate(body.mesh)
        self.stiffness = float(params.suture_stiffness)
        self.tie = dolfinx.fem.Constant(mesh, 0.0)
        # 0 until tying begins: the legs have no length to keep before the sutures are placed
        self.placed = dolfinx.fem.Constant(mesh, 0.0)
        # the displacement when tying began: each leg's length is measured from it
        self.u_tied = dolfinx.fem.Function(body.u.function_space, name="suture_u_tied")
        parts = [buckle.buckle.part_at(bite[0]) for bite in self.bites]
        # what each anchor travels with: the tire's (or the elastic band's) unknown, or the
        # rigid band's prescribed travel
        self.travels = [body.tire_travel if (part.is_tire or buckle.elastic_band)
                        else buckle.indentation for part in parts]
        self.parts = parts
        # the anchor a(t) = a₀ + t e of each leg (set when tying begins: the buckle is
        # placed by then), and t when tying began
        self.anchor_base = [dolfinx.fem.Constant(mesh, np.zeros(3)) for _ in self.bites]
        self.anchor_motion = [dolfinx.fem.Constant(mesh, np.zeros(3)) for _ in self.bites]
        self.travel_tied = [dolfinx.fem.Constant(mesh, 0.0) for _ in self.bites]
        # what the knot takes out of each leg at the end of tying (mm); Constants, not
        # literals, as the thread's stiffness: a sweep over suture width, knot or thread
        # would otherwise compile the eye's residual anew for each value
        self.slack = [dolfinx.fem.Constant(mesh, params.suture_tie_fraction * 0.5
                                           * (params.suture_width - part.cross_section[0]))
                      for part in parts]
        stiffness = dolfinx.fem.Constant(mesh, self.stiffness)
        x, x_tied = X + body.u, X + self.u_tied
        self.stretches, self.weights = [], []
        for k, (travel, base, motion, tied, slack) in enumerate(zip(
                self.travels, self.anchor_base, self.anchor_motion, self.travel_tied, self.slack)):
            self.weights.append(self.forces.scales[k] * bite_weight(X, self.forces.centres[k],
                                                                    self.forces.bite_radius))
            self.stretches.append(tied_leg_stretch(x, x_tied, base + travel * motion,
                                                   base + tied * motion, self.tie * slack))
        self.measure_ = body.ds(body.eye.tag("sclera_outer"))
        # a leg is taut while its tension is positive at the last converged step (lagged, as
        # the loop's directions): a suture pulls but cannot push
        self.taut = [dolfinx.fem.Constant(mesh, 1.0) for _ in self.bites]
        self.energy = self.placed * sum(
            taut * tied_leg_energy(stretch, stiffness, weight)
            for taut, stretch, weight in zip(self.taut, self.stretches, self.weights)) * self.measure_

    def residual(self, tests):
        return ufl.derivative(self.energy, self.body.u, tests[0])

    def start_tying(self) -> None:
        """Suturing begins: every leg's length is measured from the eye and the buckle as
        they are now."""
        self.u_tied.x.array[:] = self.body.u.x.array
        self.placed.value = 1.0
        base_radius = float(self.buckle.base_radius.value)
        for k, (bite, part) in enumerate(zip(self.bites, self.parts)):
            def at(t, bite=bite, part=part):
                return np.asarray(part.anchor(bite, base_radius, t, t if part.is_tire else None))
            self.anchor_base[k].value[:] = at(0.0)
            self.anchor_motion[k].value[:] = at(1.0) - at(0.0)
            travel = self.travels[k]
            self.travel_tied[k].value = self.body.real_value(travel) \
                if isinstance(travel, dolfinx.fem.Function) else float(travel.value)

    def pull_on_tire(self) -> float:
        """0: the tied legs' push on the buckle is in its row through their energy."""
        return 0.0

    @functools.cached_property
    def _tension_forms(self) -> list[dolfinx.fem.Form]:
        return [dolfinx.fem.form(self.placed * stretch * weight * self.measure_)
                for stretch, weight in zip(self.stretches, self.weights)]

    def tensions(self) -> list[float]:
        """Each leg's tension (N): k ∫ (ℓ − ℓ_tied + s) w dA over its share of the bite, 0
        for a slack leg. Collective."""
        return [max(stretch, 0.0) for stretch in self._stretch_forces()]

    def _stretch_forces(self) -> list[float]:
        return [self.stiffness * assemble_scalar(form, self.body.comm) / share
                for form, share in zip(self._tension_forms, self.forces.shares)]

    def converged(self) -> None:
        super().converged()
        for taut, force in zip(self.taut, self._stretch_forces()):
            taut.value = 1.0 if force > 0.0 else 0.0

    def controls(self) -> dict[str, Control]:
        return super().controls() | {
            "suture_tie": Control.of(self.tie)}

    def register(self, checkpoints) -> None:
        super().register(checkpoints)
        checkpoints.function("suture_u_tied", self.u_tied)
        checkpoints.constant("suture_tie", self.tie)
        checkpoints.constant("sutures_placed", self.placed)
        for k, taut in enumerate(self.taut):
            checkpoints.constant(f"suture_leg_{k}_taut", taut)
        checkpoints.value("suture_anchors", lambda: {
            "base": [c.value.copy() for c in self.anchor_base],
            "motion": [c.value.copy() for c in self.anchor_motion],
            "travel": [float(c.value) for c in self.travel_tied]}, self._restore_anchors)

    def _restore_anchors(self, saved: dict) -> None:
        for constants, key in ((self.anchor_base, "base"), (self.anchor_motion, "motion")):
            for c, value in zip(constants, saved[key]):
                c.value[:] = value
        for c, value in zip(self.travel_tied, saved["travel"]):
            c.value = value

    def measure(self) -> dict:
        # the tightest and the loosest leg (N); the knot's progress (0 → 1 over suturing)
        tensions = self.tensions()
        return {"suture_force_N": max(tensions, default=0.0),
                "suture_force_min_N": min(tensions, default=0.0),
                "suture_tie": float(self.tie.value)}


class TireRow(Term):
    """The tire's radial travel δ (a Real unknown) and its row: pinned to the band's
    travel, k (δ − δ_band) = 0, or free (``tire_free``): the sclera's contact force on the
    tire, ∂Π_c/∂δ, balanced against the sutures' inward pull (``suture_pull``, from
    ``pull``), the instrument's hold (``tire_hold``, released over suturing) and the
    band's push on the tire it runs over (a unilateral stop). The loop model frees the
    tire: without a band when buckling ends (:meth:`free`), with one once the pull exceeds
    the contact force (:meth:`release_from_band`)."""

    def __init__(self, body: Body, buckle: RigidBuckle, contact: BuckleContact, loop: bool,
                 pull: Callable[[], float], suture_energy=None):
        self.body, self.buckle, self.contact, self.loop, self.pull = body, buckle, contact, loop, pull
        # tied mattress sutures: their energy depends on the travel, and its derivative is
        # their push on the buckle (None: the pull comes from ``pull``)
        self.suture_energy = suture_energy
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

    @property
    def energy(self):
        """What the travel's row differentiates: the buckle's contact energy, and the tied
        sutures' when they ride on the buckle."""
        if self.suture_energy is None:
            return self.contact.energy
        return self.contact.energy + self.suture_energy

    def residual(self, tests):
        delta, q, surface = self.body.tire_travel, tests[-1], self.buckle.surface
        band_travel = self.buckle.indentation
        inward = self.suture_pull + self.tire_hold + self.buckle.buckle.band_push(delta, self.tire_stiffness)
        free = tire_travel_residual(self.energy, delta, q, inward, surface, self.sclera_area)
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

    @functools.cached_property
    def _suture_push_form(self) -> dolfinx.fem.Form | None:
        if self.suture_energy is None:
            return None
        direction = dolfinx.fem.Function(self.body.tire_travel.function_space)
        direction.x.array[:] = 1.0
        return dolfinx.fem.form(-ufl.derivative(self.suture_energy, self.body.tire_travel, direction))

    def suture_push(self) -> float:
        """The sutures' inward force on the buckle (half model, N): the loop's pull, or
        −∂Π_s/∂δ of tied sutures. Collective."""
        pull = float(self.suture_pull.value)
        if self._suture_push_form is not None:
            pull += assemble_scalar(self._suture_push_form, self.body.comm)
        return pull

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
        pull = self.suture_push()
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
        return {"tire_hold": Control.of(self.tire_hold),
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
                "tire_suture_pull_N": 2.0 * self.suture_push(),
                "tire_free": self.free_}


class BandRow(TireRow):
    """The elastic band's radial travel δ (``buckle_control = shortening``; the Real
    unknown of :class:`TireRow`, the tire riding under the band): its row balances the
    sclera's contact force on band and tire, ∂Π_c/∂δ, against the inward resultant of
    the band's hoop tension, ½ · 2π T (the half eye), and the sutures' pull on the tire
    (forms/buckle.py, band_hoop_residual). T = E A (L − L_set)/L_set with L the band's
    centreline length at δ over the tire (band_length) and L_set its length as laid
    less the shortening, which control ``band_tightening`` (0 → 1 over buckling) takes
    out. Free from the start: before the band touches the eye its row is the slack
    band's, T = 0 at δ = ΔL/2π."""

    def __init__(self, body: Body, buckle: RigidBuckle, contact: BuckleContact, loop: bool,
                 pull: Callable[[], float], params: Parameters, suture_energy=None):
        super().__init__(body, buckle, contact, loop, pull, suture_energy)
        mesh = body.mesh
        self.tire_free.value = 1.0
        self.tightening = dolfinx.fem.Constant(mesh, 0.0)
        self.modulus_area = dolfinx.fem.Constant(
            mesh, params.band_modulus_MPa * params.band_width * params.band_thickness)
        shape = buckle.buckle.shape
        tire = buckle.buckle.tire
        # the band runs over the tire: raised by its height over its arc
        self.tire_height = dolfinx.fem.Constant(mesh, params.tire_height if tire is not None else 0.0)
        self.tire_arc = dolfinx.fem.Constant(mesh, 2.0 * shape.half_arc if tire is not None else 0.0)
        self.band_thickness = dolfinx.fem.Constant(mesh, params.band_thickness)
        # ΔL = tightening · (mm + percent/100 · L_laid): one of the two is zero
        self.shortening_mm = dolfinx.fem.Constant(mesh, params.band_shortening_mm)
        self.shortening_fraction = dolfinx.fem.Constant(
            mesh, 0.0 if params.band_shortening_mm > 0 else params.band_shortening_percent / 100.0)

    def lengths(self, travel, value=lambda c: c):
        """(L, L_laid, L_set): the band's centreline length at the travel ``travel``, as
        laid (ρ_c, its inner face at the base radius) and after the shortening taken out so
        far; UFL, or numbers with ``value`` reading the Constants."""
        centre = value(self.buckle.base_radius) + 0.5 * value(self.band_thickness)
        height, arc = value(self.tire_height), value(self.tire_arc)
        laid = band_length(centre, 0.0, height, arc)
        taken = value(self.tightening) * (value(self.shortening_mm)
                                          + value(self.shortening_fraction) * laid)
        return band_length(centre, travel, height, arc), laid, laid - taken

    def residual(self, tests):
        delta, q = self.body.tire_travel, tests[-1]
        length, _laid, set_length = self.lengths(delta)
        tension = band_tension(length, set_length, self.modulus_area)
        return band_hoop_residual(self.energy, delta, q, tension, 0.5, self.suture_pull,
                                  self.buckle.surface, self.sclera_area)

    def free(self) -> None:
        """Free from the start (see the class)."""

    def release_from_band(self) -> None:
        """The tire rides under the band (one unknown)."""

    def prepare(self) -> None:
        self.suture_pull.value = self.pull()

    def converged(self) -> None:
        self.suture_pull.value = self.pull()

    def controls(self) -> dict[str, Control]:
        return super().controls() | {
            "band_tightening": Control.of(self.tightening)}

    def register(self, checkpoints) -> None:
        super().register(checkpoints)
        checkpoints.constant("band_tightening", self.tightening)

    def band(self) -> dict:
        """The band now: travel δ, centreline length L, the length taken out L_laid − L_set,
        tension T = E A (L − L_set)/L_set. Collective."""
        travel = self.buckle.tire_travel()
        length, laid, set_length = self.lengths(travel, lambda c: float(c.value))
        tension = band_tension(length, set_length, float(self.modulus_area.value))
        return {"band_travel_mm": travel, "band_circumference_mm": length,
                "band_laid_circumference_mm": laid, "band_shortening_mm": laid - set_length,
                "band_shortening_percent": 100.0 * (laid - set_length) / laid,
                "band_tension_N": tension,
                # the inward resultant of the tension on the whole eye, 2π T: the sclera's
                # contact force on band and tire less the sutures' pull balances it
                "band_hoop_force_N": 2.0 * math.pi * tension}

    def measure(self) -> dict:
        # the band's numbers once it is laid on the eye (its base radius is far away before)
        return super().measure() | (self.band() if self.buckle.placed else {})


def _point(centre) -> str:
    return "(" + ", ".join(f"{float(x):.2f}" for x in centre) + ") mm"
