"""The retina contact's predicted active set (``NodeToSurfaceContact.predict_active_set``) and
its limit on a step's depth (``limit_step_depth``), on two blocks that touch (stacked_blocks:
the upper block's bottom on the lower's top, gap 0).

The upper block's top is pushed down by δ. At the start every pair is open (g = 0, no
force, no stiffness), so Newton's first direction moves the upper block down as if the lower
one were not there: its bottom goes δ through the lower block, and at the full step the
penalty's force is far above the residual. With the prediction the open pairs that step
would carry through get the penalty's stiffness and the direction is solved again: the
first step then stops the bottom at the penetration the penalty's stiffness allows. With the
depth limit the first step is shortened to stop the bottom at the limit. All
solves end in the same state (the residual is the same), the prediction's re-solves counted
(factorisations are PETSc's own log events)."""

from __future__ import annotations

import dolfinx
import dolfinx.fem
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from eyemech.forms import compressible_neo_hooke, deformation_gradient
from eyemech.meshes.contact_bodies import stacked_blocks
from eyemech.problems.contact.node_to_surface import NodeToSurfaceContact
from eyemech.problems.solid.spaces import symmetry_bcs
from eyemech.problems.solve.driver import NewtonOptions, NonlinearSolver

PUSH = 0.01  # mm, the upper block's top pushed down (blocks 1 × 1 × 0.5 mm)
E_BLOCK, ALPHA = 1.0, 100.0  # MPa, MPa/mm


SEARCH_DEPTH = 0.25  # mm: deeper, a slave node is unpaired


def _blocks(predict: bool, options: NewtonOptions, depth_limit: float = 0.0, acting=None):
    blocks = stacked_blocks(1.0, 0.5, 0.5, 0.5, 0.4, comm=MPI.COMM_SELF)
    V = dolfinx.fem.functionspace(blocks.mesh, ("Lagrange", 1, (3,)))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    energy = compressible_neo_hooke(deformation_gradient(u), E_BLOCK, 0.3) * blocks.dx()
    bcs = symmetry_bcs(V, blocks, {"symmetry_x": 0, "symmetry_y": 1, "bottom": 2})
    top = dolfinx.fem.locate_dofs_topological(V.sub(2), 2, blocks.facets("top"))
    bcs.append(dolfinx.fem.dirichletbc(-PUSH, top, V.sub(2)))
    contact = NodeToSurfaceContact(u, blocks, "slave", "master", ALPHA, bcs, search_depth=SEARCH_DEPTH)
    solver = NonlinearSolver(ufl.derivative(energy, u, v), u, bcs, options=options,
                             residual_hooks=[contact.residual_hook],
                             jacobian_hooks=[contact.jacobian_hook])
    contact.allow_new_nonzeros(solver.problem.A)
    if predict:
        contact.predict_active_set(solver, below=np.inf)
    if depth_limit > 0:
        contact.limit_step_depth(solver, depth_limit, acting)
    return solver, contact, u


def _first_step_depth(predict: bool, depth_limit: float = 0.0, acting=None) -> float:
    """The deepest slave node after one full Newton step from u = 0."""
    solver, contact, _u = _blocks(predict, NewtonOptions(line_search="basic", max_it=1),
                                  depth_limit, acting)
    solver.solve()
    depth = -contact.search().min_gap
    solver.close()  # the pre-check's reference to the contact lives in PETSc's SNES
    return depth


def test_the_first_step_stops_at_the_lower_block_with_the_prediction():
    """Without the prediction the first step carries the bottom δ through (its depth > 0.9 δ;
    measured 0.93 δ). With it the penalty (α = 100 MPa/mm) and the upper block (E/h ≈ 2
    MPa/mm) share the push as springs in series: a depth of about δ · 2/102 ≈ 0.02 δ
    (measured 0.011 δ), under a tenth of δ."""
    assert _first_step_depth(predict=False) > 0.9 * PUSH
    assert _first_step_depth(predict=True) < 0.1 * PUSH


def test_the_first_step_stops_at_the_depth_limit():
    """A limit of 1 % of the search depth (2.5 µm, a quarter of the 9.3 µm the full step
    reaches): the lower block does not move in the first step (its pairs are open), so the
    depth is linear in the step's length and the shortened step lands on the limit (measured
    1 + 9e-6 of it: the search's gap and the limit's depth are taken on nearest triangles
    chosen apart, the search's by the closest point's distance)."""
    assert _first_step_depth(False, depth_limit=0.01) == pytest.approx(0.01 * SEARCH_DEPTH,
                                                                       rel=1e-4)
    # a limit the full step stays within leaves it whole
    assert _first_step_depth(False, depth_limit=0.5) == pytest.approx(_first_step_depth(False),
                                                                      rel=1e-12)


def test_the_depth_limit_acts_only_when_told():
    """The eye's limit acts in the settling only (``acting``: the liquid released): while
    ``acting()`` is false the first step is the unlimited one, to the last bit; once true
    it stops at the limit."""
    free = _first_step_depth(False)
    assert _first_step_depth(False, depth_limit=0.01, acting=lambda: False) == free
    assert _first_step_depth(False, depth_limit=0.01, acting=lambda: True) == \
        pytest.approx(0.01 * SEARCH_DEPTH, rel=1e-4)


@pytest.mark.parametrize("line_search", ["bt", "basic"])
def test_the_solution_is_the_same_and_the_resolves_are_counted(line_search):
    options = NewtonOptions(line_search=line_search, rtol=1e-11, atol=1e-13, max_it=30)
    states = {}
    for predict, depth_limit in ((False, 0.0), (True, 0.0), (False, 0.01)):
        solver, contact, u = _blocks(predict, options, depth_limit)
        converged, _ = solver.solve()
        assert converged
        counts = solver.last_counts.as_dict()
        if predict:
            assert contact.predicted_pairs > 0
            # each re-solve a factorisation beyond the Jacobians' own
            assert counts["factorisations"] > counts["jacobians"]
        if depth_limit:
            assert contact.limited_steps >= 1
        states[predict, depth_limit] = u.x.array.copy()
        solver.close()
    for key, state in states.items():
        assert np.allclose(state, states[False, 0.0], rtol=0, atol=1e-9), key
