"""The half eye as a sum of terms, and the Newton solver over them.

The unknowns are [u, p, P, δ_tire]: the displacement, the tissues' pressure (Q1P0's
mixed DG0 unknown; condensed: none), the cavity's pressure and the tire's radial travel
(Real unknowns). The residual is the sum of the terms' residuals:

    R = R_tissues(u, p)              incompressible tissues (:class:`~.terms.Tissues`)
      + ∫ P J F⁻ᵀN·v dA + P's row    the vitreous (:class:`~.terms.CavityLiquid`)
      + δΠ_buckle                    penalty contact with the rigid buckle
      + δΠ_tie                       the sclera tied under the buckle's footprint
      + R_sutures                    suture forces at the bites (lagged directions)
      + r_δ                          the tire's travel: pinned or balanced; or the
                                     elastic band's, its hoop tension balanced
      + zonules, retina contact      node by node, after the assembly (solver hooks)

The eye's measurements beyond its terms are :mod:`.measures`'; what moves them along
the operation is :mod:`.stages`'.
"""

from __future__ import annotations

import dataclasses

import dolfinx
import numpy as np
import ufl

from eyemech.meshes.eye import half_eye
from eyemech.problems.run.context import RunContext
from eyemech.problems.run.parameters import MMHG
from eyemech.problems.scleral_buckling.body import Body, retina_modes
from eyemech.problems.scleral_buckling.buckle_terms import BuckleContact, BuckleTie, RigidBuckle
from eyemech.problems.scleral_buckling.measures import Optics, RetinaGaps
from eyemech.problems.scleral_buckling.parameters import Parameters
from eyemech.problems.scleral_buckling.suture_terms import BandRow, MattressSutures, Sutures, TireRow
from eyemech.problems.scleral_buckling.terms import (
    CavityLiquid,
    OpticNerveSpring,
    RetinaContact,
    Tissues,
    Zonules,
)
from eyemech.problems.solid.cavity import real_pressure_space
from eyemech.problems.solid.spaces import ELEMENTS, global_dofs, solid_fields, symmetry_bcs
from eyemech.problems.solve.driver import NonlinearSolver
from eyemech.problems.solve.terms import total_residual


class BucklingModel:
    """The half eye, its terms and the solver over them; its measurements.

    The terms' order is the residual's (the order of the integrals in each block's form,
    which its compiled code and so its round-off follows) and the order their hooks run
    in: the tissues' condensed pressure first; the sutures' new directions before the
    tire's row reads their pull; the zonules' node-wise residual before the retina's."""

    def __init__(self, params: Parameters, ctx: RunContext):
        self.params, self.ctx = params, ctx
        self.geometry = params.geometry()
        with ctx.timings("mesh"):
            self.eye = half_eye(self.geometry, ctx.comm)
        family = ELEMENTS[params.element]
        mesh = self.eye.mesh
        modes = retina_modes(self.eye) if params.retina_incompatible_modes else None
        fields, tests = solid_fields(mesh, family, real_pressure_space(mesh), real_pressure_space(mesh),
                                     condensed=params.dg0_pressure == "condensed", modes=modes)
        fields[-2].name, fields[-1].name = "P", "tire_travel"
        metadata = {"quadrature_degree": family.quadrature_degree}
        self.body = body = Body(self.eye, self.geometry, family, fields, self.eye.dx(metadata),
                                self.eye.ds(metadata),
                                self._boundary_conditions(fields[0], params.optic_nerve_end_spring == 0),
                                ctx.comm, ctx.timings, modes)
        self.tissues = Tissues(body, params)
        self.liquid = CavityLiquid(body, params)
        self.buckle = RigidBuckle(body, params)
        # the buckle's penalty α = factor · E_sclera / h
        penalty = params.penalty_factor * self.tissues.youngs_modulus("sclera") / body.element_size
        self.contact = BuckleContact(body, params, self.buckle, penalty)
        self.tie = BuckleTie(body, params, self.buckle, self.contact.tie_penalty)
        # the loop and the tied mattress sutures push the tire in, whose travel balances them
        loop = params.suture_model in ("loop", "mattress") and self.buckle.buckle.tire is not None
        if params.suture_model == "mattress":
            self.sutures = MattressSutures(body, params, self.buckle, loop)
            tied = self.sutures.energy
        else:
            self.sutures, tied = Sutures(body, params, self.buckle, loop), None
        if params.elastic_band():  # the elastic band's travel, the tire under it
            self.tire = BandRow(body, self.buckle, self.contact, loop, self.sutures.pull_on_tire,
                                params, tied)
        else:
            self.tire = TireRow(body, self.buckle, self.contact, loop, self.sutures.pull_on_tire,
                                tied)
        self.optics = Optics(body)
        self.gaps = RetinaGaps(body, params.tear_closure_tolerance)
        self.zonules = Zonules(body, params) if params.lens else None
        self.retina = RetinaContact(body, params, self.gaps, self.tissues.youngs_modulus("retina"),
                                    settling=self.liquid.released) \
            if params.retina_contact and self.gaps.detached else None
        if self.retina is not None:  # the pigment epithelium's pump waits for a sealed break
            self.liquid.break_sealed = self.retina.tear_sealed
        self.nerve_spring = OpticNerveSpring(body, params.optic_nerve_end_spring) \
            if params.optic_nerve_end_spring > 0 else None
        self.terms = [term for term in (self.tissues, self.liquid, self.contact,
                                        self.tie, self.sutures, self.tire, self.buckle,
                                        self.zonules, self.retina, self.nerve_spring)
                      if term is not None]
        self.solver = self._solver(total_residual(self.terms, tests))
        # the formulation's pattern (solid, liquid row and column, zonule bars), before any
        # contact pair: the retina's preallocated pairs and those added at a solve's start
        # depend on the load path (and differ in a run resumed from a checkpoint)
        # (DOLFINx's exact preallocation plus the bars' couplings, counted: PETSc's own
        # allocation grows by chunks when the bars are inserted, differently on 1 and 2 ranks)
        self.pattern_nonzeros = self.solver.jacobian_nonzeros() + (
            self.zonules.pattern_entries() if self.zonules is not None else 0)
        for term in self.terms:
            term.install(self.solver)
        self.controls = {name: control for term in self.terms
                         for name, control in term.controls().items()}

    def _boundary_conditions(self, u, clamped: bool) -> list:
        """The symmetry plane x = 0 (through the tear); the optic nerve's end held
        (``clamped``) or on a spring (:class:`~.terms.OpticNerveSpring`)."""
        V = u.function_space
        bcs = symmetry_bcs(V, self.eye, {"symmetry": 0})
        if not clamped:
            return bcs
        held = dolfinx.fem.locate_dofs_topological(V, 2, self.eye.facets("optic_nerve_end"))
        bcs.append(dolfinx.fem.dirichletbc(np.zeros(3), held, V))
        return bcs

    def _solver(self, residual) -> NonlinearSolver:
        params, ctx, body = self.params, self.ctx, self.body
        krylov = params.linear_reuse == "krylov"
        newton = dataclasses.replace(ctx.options.newton,
                                     reuse_contraction=params.krylov_jacobian_reuse if krylov
                                     else params.jacobian_reuse,
                                     linear_reuse=params.linear_reuse,
                                     krylov_max_it=params.krylov_max_it,
                                     krylov_rtol=params.krylov_rtol,
                                     krylov_ew=params.krylov_ew,
                                     krylov_refresh_above=params.krylov_refresh_above,
                                     krylov_predict_after=params.krylov_predict_after,
                                     reuse_step_relative=params.jacobian_reuse_test == "step",
                                     cut_on_nan=params.full_step_nan == "cut",
                                     increment_tolerance=params.increment_tolerance,
                                     flat_residual_limit=params.flat_residual_limit,
                                     cycle_max_period=params.cycle_max_period,
                                     reuse_creep_window=params.creep_window,
                                     fallback_line_search="bt" if {
                                         params.line_search, params.suture_line_search,
                                         params.settle_line_search} != {"bt"}
                                     else ctx.options.newton.fallback_line_search)
        bcs = body.bcs + (body.modes.bcs if body.modes is not None else [])
        return NonlinearSolver(list(ufl.extract_blocks(residual)), body.fields, bcs,
                               options=newton, timings=ctx.timings,
                               iterative=params.linear_solver(self.tissues.shear_modulus, body.dx))

    @property
    def u(self) -> dolfinx.fem.Function:
        return self.body.u

    @property
    def fields(self) -> list:
        return self.body.fields

    def multipliers(self) -> list:
        return [m for term in self.terms for m in term.multipliers()]

    def prepare(self) -> None:
        """Before each attempt, after the stage set its controls."""
        for term in self.terms:
            term.prepare()

    def converged(self) -> None:
        """After each converged step, once it is recorded."""
        for term in self.terms:
            term.converged()

    def register(self, checkpoints) -> None:
        """Everything a restart needs besides the load (docs/restart.md)."""
        for term in self.terms:
            term.register(checkpoints)
        if self.body.modes is not None:
            for f in self.body.modes.fields:
                checkpoints.function(f.name, f)
        self.optics.register(checkpoints)

    def measure(self) -> dict:
        """Every measurement now (collective), in results.json's order."""
        optics = self.optics.read()
        volume, iop = 2.0 * self.liquid.volume(), self.liquid.pressure() / MMHG
        out: dict = {}
        for part in (self.retina, self.zonules):
            if part is not None:
                out |= part.measure()
        out |= self.optics.changes(optics, volume, iop) | self.tie.measure() | self.optics.lengths(optics)
        for part in (self.buckle, self.contact, self.tire, self.liquid, self.gaps,
                     self.tissues, self.sutures, self.nerve_spring):
            if part is not None:
                out |= part.measure()
        return out | self.gaps.margin(out)

    def summary(self) -> dict:
        out = {"dofs": global_dofs(*self.fields),
               "cells": self.eye.mesh.topology.index_map(3).size_global,
               "jacobian_nonzeros": self.pattern_nonzeros,
               "contact_penalty": self.contact.normal_penalty}
        if self.retina is not None:
            out["retina_contact_penalty"] = self.retina.contact.penalty
        return out
