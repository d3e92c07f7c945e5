"""The eye's own terms: its tissues, the liquid in its cavity, the lens' zonules and the
retina's contact with the choroid (the buckle's terms are :mod:`.buckle_terms`' and
:mod:`.suture_terms`'). Each is a
:class:`~eyemech.problems.solve.terms.Term`: its residual, what it adds node by node,
its checkpoint state, its measurements, its controls."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import dolfinx
import dolfinx.fem
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms import (
    NeoHooke,
    Yeoh,
    axis_volumes,
    cauchy_stress,
    deformation_gradient,
    enclosed_volume,
    follower_pressure,
    von_mises,
)
from eyemech.forms.cavity import held_liquid
from eyemech.forms.contact import default_penalty
from eyemech.forms.hyperelastic import TangentialFibres, meridian_and_latitude
from eyemech.meshes.eye import zonule_pairs
from eyemech.problems.contact.node_to_surface import NodeToSurfaceContact
from eyemech.problems.run.parameters import MMHG
from eyemech.problems.scleral_buckling.body import Body, cell_field
from eyemech.problems.scleral_buckling.parameters import Parameters
from eyemech.problems.scleral_buckling.venting import venting_route
from eyemech.problems.solid.cavity import VentedCavity, check_closed
from eyemech.problems.solid.mean_dilatation import MeanDilatation
from eyemech.problems.solid.probes import CellField, NodeProbe, facet_nodes
from eyemech.problems.solid.residual import solid_residual
from eyemech.problems.solid.zonules import ZonuleBars
from eyemech.problems.solve.scalars import assemble_scalar
from eyemech.problems.solve.terms import Control, Term

# the retina's contact partners preallocated: the master triangles within half an element
# beyond the nearest one (docs/scleral_buckling.md, "The contact pattern, preallocated")
RETINA_PATTERN_REACH = 0.5


class Tissues(Term):
    """The incompressible tissues: neo-Hooke, W = c (Ī1 − 3), with c per tissue (paper
    Table 1) in a cellwise field, or (``material = "calibrated"``) Yeoh with the stiffening
    c20 (Ī1 − 3)² in the sclera and the cornea, or (``material = "fibres"``) tension-only
    fibres c4 max(Ī4 − 1, 0)⁴ along their meridians and circles of latitude;
    incompressible by a pressure multiplier
    (Q1P0 or Q2P1), Q1P0's DG0 pressure mixed or condensed cell by cell, p̄ = κ (J̄ − 1)
    with κ a fixed multiple of each tissue's shear modulus (``condensed_bulk_ratio``)."""

    def __init__(self, body: Body, params: Parameters):
        self.body, self.params = body, params
        self.stiffness = cell_field(body, "c", params.stiffness())
        # every coefficient a cellwise field: new values compile nothing
        if params.material == "fibres":
            self.law = TangentialFibres(self.stiffness, cell_field(body, "c4", params.fibre_stiffness()),
                                        meridian_and_latitude(ufl.SpatialCoordinate(body.mesh)))
        elif params.material == "calibrated":
            self.law = Yeoh(self.stiffness, cell_field(body, "c20", params.stiffening()))
        else:
            self.law = NeoHooke(self.stiffness)
        self.mean_dilatation: MeanDilatation | None = None
        self.pressure = None if params.dg0_pressure == "condensed" else body.fields[1]
        # von Mises of the isochoric law: the deviator of σ is that of the isochoric part
        # (neo-Hooke: (2c/J) dev(b̄)); the pressure multiplier drops out
        self.von_mises = CellField(von_mises(cauchy_stress(self.law, deformation_gradient(body.u))),
                                   body.mesh, "von_mises")

    def law_of(self, tissue: str):
        """One tissue's law, its coefficients as numbers."""
        c = self.params.stiffness()[tissue]
        if self.params.material == "fibres" and tissue in self.params.fibre_stiffness():
            return dataclasses.replace(self.law, c10=c, c4=self.params.fibre_stiffness()[tissue])
        stiffening = self.params.stiffening() if self.params.material == "calibrated" else {}
        return Yeoh(c, stiffening[tissue]) if tissue in stiffening else NeoHooke(c)

    @property
    def shear_modulus(self):
        """μ per cell at small strain (the law's), the iterative solver's pressure-mass
        weight and the scale of the condensed pressure's bulk modulus."""
        return self.law.shear_modulus

    def youngs_modulus(self, tissue: str) -> float:
        """One tissue's small-strain Young's modulus (the law's, incompressible): the
        contacts' penalties are scaled from it."""
        return self.law_of(tissue).youngs_modulus

    def residual(self, tests):
        body = self.body
        if self.pressure is None:
            self.mean_dilatation = MeanDilatation(
                body.u, self.params.condensed_bulk_ratio * self.shear_modulus, body.dx, body.bcs,
                block_spaces=body.block_spaces)
            self.pressure = self.mean_dilatation.pressure
        condensed = getattr(self.mean_dilatation, "pressure", None)
        return solid_residual(self._laws_by_cells(), body.family, body.fields, tests, body.dx,
                              condensed_pressure=condensed, modes=body.modes)

    def _laws_by_cells(self):
        """The law over the whole mesh, or ``{cell tags: law}``: the stiffening law (Yeoh's
        c20, the fibres' c4) over the coats that have it, neo-Hooke over the other tissues.
        Both are the same energy where the stiffening modulus is 0; integrated apart, the
        other tissues' cells (half of the eye's) skip the stiffening term's tangent, which
        doubles the cost of a Jacobian cell by cell (docs/scleral_buckling.md, "Where the
        time goes"). The incompatible modes take one law for the mesh."""
        body, params = self.body, self.params
        coats = {"fibres": params.fibre_stiffness(), "calibrated": params.stiffening()}.get(params.material)
        if coats is None or body.modes is not None:
            return self.law
        tissues = body.eye.cell_regions()
        stiffened = tuple(body.eye.tag(name) for name in tissues if coats.get(name, 0.0) != 0.0)
        plain = tuple(body.eye.tag(name) for name in tissues if coats.get(name, 0.0) == 0.0)
        return {tags: law for tags, law in ((stiffened, self.law), (plain, NeoHooke(self.stiffness)))
                if tags}

    def install(self, solver) -> None:
        if self.mean_dilatation is not None:
            solver.state_hooks.append(self.mean_dilatation.update)
            solver.jacobian_hooks.append(self.mean_dilatation.jacobian_hook)

    def register(self, checkpoints) -> None:
        checkpoints.function("u", self.body.u)
        checkpoints.function("p", self.pressure)

    def measure(self) -> dict:
        return {"von_mises_max_MPa": self.von_mises.update()}


class CavityLiquid(Term):
    """The vitreous: its pressure P (a Real unknown) pushes on the deformed cavity wall,
    ∫ P J F⁻ᵀN·v dA, and P's row is either pinned to a target (closed off: the IOP ramp,
    the pressure's return after surgery) or the liquid law P = P_ini − K (V − V_l)/V_ini
    with V_ini, P_ini the state where the liquid was closed (seed 002, eq. 5) and V_l the
    liquid held (V_ini less what was vented), vented at ``iop_limit_mmHg`` with
    ``venting``: P = min(P_lim, the law's) (:class:`~eyemech.problems.solid.cavity.VentedCavity`):

        c · R_vented + (1 − c) · R_pin,   c = ``coupled`` ∈ {0, 1}."""

    def __init__(self, body: Body, params: Parameters):
        self.body = body
        mesh = body.mesh
        self.iop = params.iop_mmHg * MMHG
        self.pressure_target = dolfinx.fem.Constant(mesh, 0.0)
        self.acute_pressure = dolfinx.fem.Constant(mesh, self.iop)  # when the liquid is released
        self.initial_volume = dolfinx.fem.Constant(mesh, 1.0)
        self.initial_pressure = dolfinx.fem.Constant(mesh, self.iop)
        self.initial_volume.value = check_closed(body.u, body.wall, "cavity wall of the eye")
        area = assemble_scalar(dolfinx.fem.Constant(mesh, 1.0) * body.wall, body.comm)
        # Constants: the area follows the mesh, and either as a literal compiles the residual anew
        self.wall_area = dolfinx.fem.Constant(mesh, area)
        self.bulk_modulus = dolfinx.fem.Constant(mesh, params.bulk_modulus)
        self.volume_form = dolfinx.fem.form(enclosed_volume(body.u, body.wall))
        # the wall's volume by another field of divergence one (x_z e_z, not x/3): the
        # volume balance reads the wall's displacement through a formula P's row does not use
        self.wall_volume_form = dolfinx.fem.form(axis_volumes(body.u, body.wall)[2])
        self.vent = VentedCavity(body.u, body.wall, self.initial_volume, self.initial_pressure,
                                 self.bulk_modulus, params.iop_limit_mmHg * MMHG if params.venting
                                 else 0.0)
        self.coupled = self.vent.held  # 1 while the liquid law acts
        self.subretinal = self._subretinal_volume_form()
        self.subretinal_fluid = 0.0  # whole eye, µL, in the eye before surgery
        self.closed = False  # the liquid was closed (the operation began)
        # the pigment epithelium's pump (subretinal_pump_mmHg): its full deficit, switched on
        # once the liquid is released and the break is sealed (``break_sealed``, given by the
        # model: the retina contact's verdict), the target pressure it started at and the
        # pressure drop from there it is ramped over (the rest of P's return)
        self.pump = None
        self.break_sealed: Callable[[], bool] | None = None
        self.pump_waiting = False  # released, the break not yet sealed
        if (params.subretinal_pump_mmHg > 0 and self.subretinal is not None and params.settle
                and params.retina_contact):
            self.pump = dolfinx.fem.Constant(mesh, 0.0)
            self.pump_full = params.subretinal_pump_mmHg * MMHG
            self.pump_start = dolfinx.fem.Constant(mesh, self.iop)
            self.pump_span = dolfinx.fem.Constant(mesh, 1.0)

    def _subretinal_volume_form(self):
        """The subretinal space's volume, by the field x_x e_x over the faces on either
        side of it: open to the vitreous through the tear's hole, whose normal (radial, in
        the symmetry plane x = 0 at its centre) is nearly normal to e_x, so the hole adds
        almost nothing (on the coarse and default eyes x_x e_x and x_z e_z agree to 0.2 µL
        of 45-51; x/3, through which the hole's flux is ⅓ R times its area, gives 20 µL
        more). None without a detachment."""
        eye = self.body.eye
        if "retina_detached" not in eye.names:
            return None
        return dolfinx.fem.form(axis_volumes(self.body.u, self._subretinal_faces())[0])

    def residual(self, tests):
        body, v, qP = self.body, tests[0], tests[-2]
        liquid = self.vent.residual(body.P, qP, self.wall_area)
        pinned = self.initial_volume / self.bulk_modulus * (body.P - self.pressure_target) \
            / self.wall_area * qP * body.wall
        form = (follower_pressure(body.P, body.u, v, body.wall)
                + self.coupled * liquid + (1 - self.coupled) * pinned)
        if self.pump is not None:
            form += follower_pressure(-self.pump_deficit(), body.u, v, self._subretinal_faces())
        return form

    def _subretinal_faces(self) -> ufl.Measure:
        """The faces on either side of the subretinal space (the detached retina's outer
        face, the choroid's inner face)."""
        eye = self.body.eye
        return self.body.ds(tuple(eye.tag(name) for name in ("retina_detached", "choroid_detached")))

    def pump_deficit(self, value=lambda constant: constant):
        """How far the subretinal fluid's pressure lies below P: 0 until the liquid is
        released and the break sealed, then ramped with the rest of P's return, from 0 at
        the target pressure where the pump started (the acute pressure, for a break sealed
        after suturing) to ``subretinal_pump_mmHg`` at the IOP before surgery. It pulls the
        detached retina onto the choroid and the choroid towards it. A UFL expression of the
        Constants, or with ``value=float`` its number now."""
        return value(self.pump) * (value(self.pump_start) - value(self.pressure_target)) \
            / value(self.pump_span)

    def _start_the_pump_if_sealed(self, start: float) -> None:
        """Once the liquid is released: the pump starts at the target pressure ``start``
        (MPa) if the break is sealed (collective). Through an open break the vitreous fills the
        subretinal space as fast as the pigment epithelium empties it, so no deficit builds
        up; once sealed, the retina stays on (the pump keeps it there). A break that seals
        only as P reaches the IOP before surgery leaves no pressure drop to ramp over: the
        pump then stays off."""
        if self.pump is None or not self.pump_waiting or self.break_sealed is None:
            return
        if start - self.iop > 1e-9 * self.iop and self.break_sealed():
            self.pump_waiting = False
            self.pump_start.value, self.pump_span.value = start, start - self.iop
            self.pump.value = self.pump_full

    def install(self, solver) -> None:
        if self.vent.enabled:  # the branch chosen before every assembly, undone with a failed solve
            solver.state_hooks.append(lambda: self.vent.choose_branch(self.pressure()))
            solver.memory_hooks.append((self.vent.memory, self.vent.restore_memory))

    def volume(self) -> float:
        """The cavity's volume (half eye)."""
        return assemble_scalar(self.volume_form, self.body.comm)

    def pressure(self) -> float:
        return self.body.real_value(self.body.P)

    def close(self) -> None:
        """The liquid law from here: V_ini and P_ini of the current state, all of it held."""
        self.initial_volume.value = self.volume()
        self.initial_pressure.value = self.pressure()
        self.vent.hold(float(self.initial_volume.value))
        self.closed = True
        if self.subretinal is not None:
            self.subretinal_fluid = 2.0 * assemble_scalar(self.subretinal, self.body.comm)

    def release(self) -> None:
        """P pinned again, its target ramped from here (``acute_pressure``, the current
        P): the liquid's volume is free."""
        self.acute_pressure.value = self.pressure()
        self.vent.release()
        if self.pump is not None:
            self.pump_waiting = True
            self._start_the_pump_if_sealed(float(self.acute_pressure.value))

    def released(self) -> bool:
        """Step 4: the liquid was closed for the operation and is free again, P driven back."""
        return self.closed and float(self.coupled.value) == 0.0

    def started_pump_at(self) -> float:
        """The IOP (mmHg) at which the pump started; nan while it waits or is off."""
        if self.pump is None or float(self.pump.value) == 0.0:
            return math.nan
        return float(self.pump_start.value) / MMHG

    def converged(self) -> None:
        """A converged load step's vented liquid is kept: it does not come back. A pump
        waiting for the break starts here if the step sealed it."""
        self.vent.accept(self.pressure())
        self._start_the_pump_if_sealed(float(self.pressure_target.value))

    def _start_at_target(self) -> None:
        """P starts a load step at its pinned target, as a prescribed travel does. Newton's
        full first step is the same as from the last P (P's pinned row is linear in P),
        but the start's residual is then the pressure change's load on the wall, not P's
        row alone, so backtracking on ‖F‖ accepts that step instead of creeping at its
        0.1 floor (docs/scleral_buckling.md, The settling step). A P already at its target
        (a converged or restored state: relative difference below 1e-6) is left bitwise
        as it is, so a resumed run repeats the uninterrupted one."""
        target = float(self.pressure_target.value)
        if abs(self.pressure() - target) > 1e-6 * abs(target):
            self.body.P.x.array[:] = target
            self.body.P.x.scatter_forward()

    def controls(self) -> dict[str, Control]:
        return {"pressure_target": Control.of(self.pressure_target, self._start_at_target),
                "acute_pressure": Control.of(self.acute_pressure)}

    def register(self, checkpoints) -> None:
        checkpoints.function("P", self.body.P)
        for name in ("pressure_target", "coupled", "initial_volume", "initial_pressure",
                     "acute_pressure"):
            checkpoints.constant(name, getattr(self, name))
        for name in ("liquid_volume", "venting"):
            checkpoints.constant(f"vent_{name}", getattr(self.vent, name))
        if self.pump is not None:
            for name in ("pump", "pump_start", "pump_span"):
                checkpoints.constant(name, getattr(self, name))
        checkpoints.value("liquid_closed",
                          lambda: [self.closed, self.subretinal_fluid, self.pump_waiting],
                          self._restore_closed)

    def _restore_closed(self, saved) -> None:
        self.closed, self.subretinal_fluid = bool(saved[0]), float(saved[1])
        self.pump_waiting = bool(saved[2]) if len(saved) > 2 else False

    def measure(self) -> dict:
        """IOP and volume; from the liquid's closing on (the eye before surgery) the
        venting's account, whole eye in µL: ``vented_volume_uL`` (left since then, as
        :meth:`converged` will keep it), the wall's inward displacement (the cavity's
        volume lost since then, by the x_z e_z field) and the liquid's compression
        V_ini (P − P_ini)/K while the liquid is held: vented + compression = inward."""
        pressure, volume = self.pressure(), self.volume()
        out = {"iop_mmHg": pressure / MMHG, "cavity_volume_mm3": 2.0 * volume}
        if self.pump is not None:
            out["subretinal_pump_deficit_mmHg"] = self.pump_deficit(lambda c: float(c.value)) / MMHG
            out["subretinal_pump_from_iop_mmHg"] = self.started_pump_at()
        if not self.closed:
            return out
        initial_volume = float(self.initial_volume.value)
        vented = 2.0 * (initial_volume - self._liquid_left(pressure, volume))
        out |= {"vented_volume_uL": vented, "vent_open": bool(float(self.vent.venting.value)),
                "venting_route": venting_route(vented, self.subretinal_fluid),
                "subretinal_fluid_uL": self.subretinal_fluid}
        if float(self.coupled.value) == 1.0:
            wall = assemble_scalar(self.wall_volume_form, self.body.comm)
            out |= {"wall_inward_volume_uL": 2.0 * (initial_volume - wall),
                    "liquid_compression_uL": 2.0 * initial_volume
                    * (pressure - float(self.initial_pressure.value))
                    / float(self.bulk_modulus.value)}
        return out

    def _liquid_left(self, pressure: float, volume: float) -> float:
        """The liquid held now (half eye, its volume at P_ini): a venting state's is what
        :meth:`VentedCavity.accept` will keep (less liquid only: vented liquid does not
        come back)."""
        held = float(self.vent.liquid_volume.value)
        if float(self.coupled.value) == 1.0 and float(self.vent.venting.value) == 1.0:
            return min(held, held_liquid(volume, pressure, float(self.initial_volume.value),
                                         float(self.initial_pressure.value),
                                         float(self.bulk_modulus.value)))
        return held


class OpticNerveSpring(Term):
    """The optic nerve's cut end held by a spring, k ∫ u·v dA over it (k per area, MPa/mm),
    instead of clamped: the orbit's soft hold on the globe. With the symmetry plane it
    removes the rigid motions (translations along y and z, the rotation about x) without
    holding the posterior pole, so the posterior segment may lengthen behind the band: the
    band rides on the globe, not on the world (docs/scleral_buckling.md, "A living eye's
    wall"). The stiffness is a Constant: new values compile nothing."""

    def __init__(self, body: Body, stiffness: float):
        self.body = body
        V, geometry = body.u.function_space, body.geometry
        self.stiffness = dolfinx.fem.Constant(body.mesh, stiffness)
        self.end = body.ds(body.eye.tag("optic_nerve_end"))
        # the spring's force on the eye along y and z (x cancels with the mirrored half)
        self.force_forms = [dolfinx.fem.form(self.stiffness * body.u[i] * self.end) for i in (1, 2)]
        inner = facet_nodes(V, body.eye.facets("retina_inner"))
        self.pole = NodeProbe(V, np.array([[0.0, 0.0, -geometry.sclera_radius]]), inner)

    def residual(self, tests):
        return self.stiffness * ufl.inner(self.body.u, tests[0]) * self.end

    def measure(self) -> dict:
        """The spring's force on the whole eye (N) and the retina's posterior pole's axial
        displacement from the unloaded mesh (mm; negative: backwards)."""
        force = [2.0 * assemble_scalar(form, self.body.comm) for form in self.force_forms]
        pole = self.pole.positions(self.body.u)[0][2] - self.pole.nodes[0][2]
        return {"optic_nerve_end_force_N": float(np.hypot(*force)),
                "posterior_pole_axial_displacement_mm": float(pole)}


class Zonules(Term):
    """The lens hangs on the zonules: linear-elastic bars (E = ``zonule_modulus``,
    cross-section ``zonule_area``) from its equatorial belt to the ciliary body's inner
    surface, added node by node (:class:`~eyemech.problems.solid.zonules.ZonuleBars`;
    why bars: see that module)."""

    def __init__(self, body: Body, params: Parameters):
        with body.timings("mesh"):
            pairs = zonule_pairs(body.geometry)
        self.bars = ZonuleBars(body.u, pairs, params.zonule_modulus, params.zonule_area, body.bcs,
                               block_spaces=body.block_spaces)

    def install(self, solver) -> None:
        solver.residual_hooks.append(self.bars.residual_hook)
        solver.jacobian_hooks.append(self.bars.jacobian_hook)
        self.bars.allow_new_nonzeros(solver.problem.A)

    def pattern_entries(self) -> int:
        """The bars' couplings in the Jacobian's pattern beyond the finite elements'."""
        return self.bars.coupling_entries()

    def measure(self) -> dict:
        return self.bars.summary()


class RetinaContact(Term):
    """The detached retina on the choroid: penalty node to surface (or segment to
    segment), slave = the retina's outer face, master = the choroid's inner face (its
    quadrilaterals split into triangles), α = ``retina_penalty_factor`` · E_retina / h
    (its penetration under a contact pressure p is p/α = (p/E_retina) h / factor),
    searched at every Newton iteration and added node by node to the blocked Jacobian.
    With the augmented Lagrangian a multiplier per retina node. ``gaps``: the tear's rim,
    for the rim's measurements; ``retina_modulus``: E_retina; ``settling``: whether step 4
    is under way, the only step where ``retina_step_depth`` acts: it is for the flap the
    pump pulls on, and in steps 2-3 a shortened update sent a radial tire's suturing to a
    stall (1.6e-2 N, flat)."""

    def __init__(self, body: Body, params: Parameters, gaps, retina_modulus: float,
                 settling: Callable[[], bool]):
        self.body, self.params, self.gaps = body, params, gaps
        self.settling = settling
        self.augmented = params.contact_method == "augmented-lagrangian"
        alpha = default_penalty(retina_modulus, body.element_size, params.retina_penalty_factor)
        if self.augmented:
            alpha *= params.augmented_penalty_scale
        # deeper than the choroid is thick, a pair is on the wrong side (not contact)
        self.contact = NodeToSurfaceContact(
            body.u, body.eye, "retina_detached", "choroid_detached", alpha, body.bcs,
            search_depth=body.geometry.choroid_thickness, smoothing=params.contact_smoothing,
            timings=body.timings, block_spaces=body.block_spaces, method=params.retina_contact_method,
            pattern_reach=RETINA_PATTERN_REACH * body.element_size)
        # segments are measured between flat facets of two curved surfaces that meet at the
        # rim: up to a chord's sagitta h²/8R apart where the surfaces touch
        sagitta = body.element_size ** 2 / (8 * body.geometry.sclera_radius)
        self.contact.refuse_initial_penetration(
            "detachment_height",
            tolerance=sagitta if params.retina_contact_method == "segment-to-segment" else 0.0)

    def install(self, solver) -> None:
        contact = self.contact
        solver.residual_hooks.append(contact.residual_hook)
        solver.jacobian_hooks.append(contact.jacobian_hook)
        # a retina node carried through the choroid (beyond its thickness it is unpaired and
        # feels no contact) is a spurious equilibrium: the load step is cut. Converged states
        # only: refusing predicted starts too made a band alone with 4 mm bites crawl
        # (hundreds of settling steps of 4e-4, 13-18 Newton iterations each)
        solver.converged_depth_hooks.append(contact.depth_through)
        if self.params.restore_contact_memory:
            solver.memory_hooks.append((contact.memory, contact.restore_memory))
        if self.params.retina_contact_prediction:
            contact.predict_active_set(solver, below=self.params.flat_residual_limit)
        if self.params.retina_step_depth > 0:
            contact.limit_step_depth(solver, self.params.retina_step_depth, self.settling)
        contact.allow_new_nonzeros(solver.problem.A)
        solver.pattern_hooks.append(contact.grow_pattern)
        if self.augmented:  # the multipliers go back with a cut step
            solver.memory_hooks.append((contact.multiplier_memory, contact.restore_multipliers))

    def multipliers(self) -> list:
        return [self.contact] if self.augmented else []

    def register(self, checkpoints) -> None:
        checkpoints.value("retina_sticky", self.contact.sticky_state,
                          self.contact.restore_sticky_state)
        if self.augmented:
            checkpoints.value("retina_multipliers", self.contact.multiplier_state,
                              self.contact.restore_multiplier_state)

    def _rim(self) -> tuple[np.ndarray, bool]:
        """The tear's rim nodes' gaps (from the last search) and the verdict: closed when
        every paired one is below ``tear_closure_tolerance``. Collective."""
        rim = self.contact.gaps_of(self.gaps.rim_nodes())
        # nan: not a contact node (shared with the choroid); inf: unpaired, carried
        # through the choroid (the depth hook cuts such a step): not closed
        ours = rim[~np.isnan(rim)]
        return rim, bool(len(ours) and np.all(ours < self.params.tear_closure_tolerance))

    def tear_sealed(self) -> bool:
        """Whether the tear is closed at the current unknowns (``tear_closed_nts``'s
        verdict; a fresh search); without a tear there is no break to seal. Collective."""
        if not len(self.gaps.rim_nodes()):
            return True
        with self.body.timings("contact_search"):
            self.contact.state = self.contact.search()
            return self._rim()[1]

    def measure(self) -> dict:
        """The penalty contact's own view (whole eye: twice the half model's area and
        force); max_penetration_mm is the deepest retina node under the choroid."""
        contact, gaps = self.contact, self.gaps
        with self.body.timings("contact_search"):
            contact.state = contact.search()
            summary = contact.summary()
            rim, closed = self._rim()
            widest = gaps.widest_rim_node(rim)
            gap_min = contact.min_gap()
            # nodes the penalty presses (g < ε: with the round-off a very soft retina can
            # rest at 0 < g < ε on a pressure ≤ αε/4 without ever crossing g = 0)
            pressed = contact.slave_gaps < max(contact.smoothing, 0.0)
            pressed_area = self.body.comm.allreduce(float(contact.slave_weights[pressed].sum()),
                                                    op=MPI.SUM)
        return {"max_penetration_mm": summary["max_penetration"],
                # the normal gap of the retina's nodes to the choroid's surface (the twin-node
                # retina_choroid_gap_* measure along the radius to the node they started above)
                "retina_choroid_gap_nts_min_mm": gap_min,
                "tear_closed_nts": closed,
                # the widest node-to-surface gap of the paired nodes on the tear's rim
                # (those tear_closed_nts looks at): closed when below the tolerance
                "tear_rim_gap_max_mm": float(rim[np.isfinite(rim)].max())
                if np.isfinite(rim).any() else float("nan"),
                # where that widest gap is: the node's polar angle from the anterior pole in
                # the reference mesh (the tear's centre at tear_angle, 88°: a smaller angle
                # is the rim's anterior edge, next to the detached flap's root)
                "tear_rim_widest_polar_deg": widest,
                "retina_contact_nodes": summary["active_nodes"],
                "retina_pressed_nodes": self.body.comm.allreduce(int(pressed.sum()), op=MPI.SUM),
                "retina_penalty_contact_area_mm2": 2.0 * pressed_area,
                "retina_contact_force_N": 2.0 * summary["contact_normal_force"]}
