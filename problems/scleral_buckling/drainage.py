"""External drainage of the subretinal fluid: a term that removes the subretinal faces'
liquid pressure over the settling stage and drags the retina in pseudo-time until it rests
on the choroid (docs/scleral_buckling.md, "Subretinal drainage")."""

from __future__ import annotations

import logging
import math

import dolfinx
import dolfinx.fem
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms import follower_pressure
from eyemech.problems.run.parameters import MMHG
from eyemech.problems.scleral_buckling.body import Body
from eyemech.problems.scleral_buckling.parameters import Parameters
from eyemech.problems.solid.probes import facet_nodes
from eyemech.problems.solve.terms import Control, Term

log = logging.getLogger("eyemech")


class Drainage(Term):
    """External drainage of the subretinal fluid (``drainage = "external"``; without it the
    term adds nothing): the subretinal faces lose the liquid pressure as ``drained`` goes
    from 0 to 1, all but the choroid under the tear (the vitreous keeps wetting it through
    the hole), −∫ d w P J F⁻ᵀN·v dA; and a pseudo-time drag on the retina's subretinal face
    towards the last solved state, ∫ η (u − u_last)·v dA, with which the retina's snap onto
    the choroid is followed solve by solve (:meth:`settle`)."""

    def __init__(self, body: Body, params: Parameters, iop: float):
        self.body, self.params, self.iop = body, params, iop
        self.active = params.drainage != "none"
        mesh = body.mesh
        self.drained = dolfinx.fem.Constant(mesh, 0.0)      # subretinal pressure removed
        self.retina_drag = dolfinx.fem.Constant(mesh, 0.0)  # η
        self.drag_reference = dolfinx.fem.Function(body.u.function_space, name="u_drag_reference")
        self.retina_face_dofs = np.zeros(0, dtype=np.int32)
        if "retina_detached" in body.eye.names:
            blocks = facet_nodes(body.u.function_space, body.eye.facets("retina_detached"))
            self.retina_face_dofs = (3 * blocks[:, None] + np.arange(3)).ravel()
        self.solver = None

    def residual(self, tests):
        if not self.active:
            return None
        body, v = self.body, tests[0]
        eye = body.eye
        subretinal = body.ds(tuple(eye.tag(name) for name in ("retina_detached", "choroid_detached")))
        pressure = follower_pressure(-self.drained * self._dried() * body.P, body.u, v, subretinal)
        drag = self.retina_drag * ufl.inner(body.u - self.drag_reference, v) \
            * body.ds(eye.tag("retina_detached"))
        return pressure + drag

    def _dried(self) -> dolfinx.fem.Function:
        """1 on the cells whose subretinal face drainage dries, 0 on the choroid's cells
        under the tear's hole. Under the hole: the cell's midpoint within ``tear_radius``
        (arc on the sclera's radius) of the tear's centre, as the mesh removes the
        retina's cells."""
        mesh, geo = self.body.mesh, self.body.geometry
        weight = dolfinx.fem.Function(dolfinx.fem.functionspace(mesh, ("DG", 0)), name="dried")
        weight.x.array[:] = 1.0
        if geo.tear_radius > 0:
            cells = np.arange(len(weight.x.array), dtype=np.int32)
            mid = dolfinx.mesh.compute_midpoints(mesh, mesh.topology.dim, cells)
            unit = mid / np.linalg.norm(mid, axis=1, keepdims=True)
            centre = np.array([0.0, math.sin(math.radians(geo.tear_angle)),
                               math.cos(math.radians(geo.tear_angle))])
            arc = geo.sclera_radius * np.arccos(np.clip(unit @ centre, -1.0, 1.0))
            weight.x.array[arc < geo.tear_radius] = 0.0
        return weight

    def drag_coefficient(self) -> float:
        """η (MPa/mm) such that the full IOP moves a free retina by ``drainage_drag_step``
        per solve: a 0.5 mm blister snaps onto the choroid in about ten solves instead of
        in one Newton step that load control cannot take (a shallow dome pressed on its
        convex side; docs/scleral_buckling.md, Subretinal drainage)."""
        return self.iop / self.params.drainage_drag_step

    def install(self, solver) -> None:
        self.solver = solver

    def prepare(self) -> None:
        self.retina_drag.value = self.drag_coefficient() if self.drained.value > 0 else 0.0

    def converged(self) -> None:
        self.drag_reference.x.array[:] = self.body.u.x.array  # the drag pulls towards this state

    def controls(self) -> dict[str, Control]:
        return {"drained": Control(lambda: float(self.drained.value),
                                   lambda value: setattr(self.drained, "value", value))}

    def settle(self, tolerance: float = 1e-4, max_solves: int = 80) -> dict:
        """Pseudo-time solves at full drainage, each dragged towards the last, until the
        largest nodal move is below ``tolerance`` (mm); a failed solve is restored and
        retried with the drag doubled (a shorter pseudo-time step), an easy one (≤ 4
        iterations) halves it (down to base/1024). Then the drag is switched off and the
        eye solved once more, so that the state reported is an equilibrium of the
        undragged residual; if that last solve fails, the dragged state is kept and
        ``retina_drag_free`` says so. Its report."""
        solver, u, comm = self.solver, self.body.u, self.body.comm
        base = self.drag_coefficient()
        solves, move, retina_move, eta = 0, math.inf, math.inf, base
        while solves < max_solves and move > tolerance and eta <= 1024 * base:
            self.drag_reference.x.array[:] = u.x.array
            self.retina_drag.value = eta
            state = solver.save_state()
            converged, iterations = solver.solve()
            solves += 1
            if not converged:
                log.info("retina settling solve %d: η = %.3g MPa/mm failed (%s)", solves, eta,
                         solver.reason())
                solver.restore_state(state)
                eta *= 2.0
                continue
            if iterations <= 4:  # a longer pseudo-time step: the tail of the settling
                eta = max(base / 1024, 0.5 * eta)
            change = u.x.array - self.drag_reference.x.array
            move = comm.allreduce(float(np.abs(change).max()), op=MPI.MAX)
            retina_move = comm.allreduce(float(np.abs(change[self.retina_face_dofs]).max(initial=0.0)),
                                         op=MPI.MAX)
            log.info("retina settling solve %d: η = %.3g MPa/mm, %d iterations, move %.3g mm "
                     "(retina's subretinal face %.3g mm)", solves, eta, iterations, move,
                     retina_move)
        self.drag_reference.x.array[:] = u.x.array
        state = solver.save_state()
        self.retina_drag.value = 0.0
        free, _ = solver.solve()
        log.info("retina settling: drag-free solve %s (%s)", "converged" if free else "failed",
                 solver.reason())
        if not free:
            solver.restore_state(state)
            self.retina_drag.value = eta
        # the drag's traction left in a kept dragged state: η times the retina face's last
        # move (a component's largest; the drag acts on that face only)
        traction = 0.0 if free else eta * retina_move
        return {"retina_settling_solves": solves + 1, "retina_settling_last_move_mm": move,
                "retina_settling_last_retina_move_mm": retina_move,
                "retina_drag_free": bool(free),
                "retina_drag_traction_max_mmHg": traction / MMHG}

    def register(self, checkpoints) -> None:
        checkpoints.function("u_drag_reference", self.drag_reference)
        checkpoints.constant("drained", self.drained)
        checkpoints.constant("retina_drag", self.retina_drag)

    def measure(self) -> dict:
        return {"subretinal_drained": float(self.drained.value)}
