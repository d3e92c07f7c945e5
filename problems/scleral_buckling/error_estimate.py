"""The eye's estimate of its discretisation error (``--set error_estimate=true``).

The whole operation is solved a second time on the neighbouring mesh of the ladder
coarse (n = 8) → default (12) → n = 20 (``cells_per_bending_length=2.5``) → paper (26),
n the cells along the cubed sphere's edge: the next coarser one, or, for a run on the
coarsest, the next finer one (``error_estimate_note`` says so). For ΔAL, ΔSE and the
tear's rim gap at the end of every stage (``after_<stage>`` and the top level, the last
stage's) the band about the run's value is Roache's grid convergence index (Roache 1994,
J. Fluids Eng. 116:405; ASME V&V 20-2009 §2-4;
:func:`~eyemech.problems.run.error_estimate.grid_convergence_index`):

    GCI = Fs |q_fine − q_coarse| / (r^p − 1)          the run on the finer mesh
    GCI = Fs |q_fine − q_coarse| r^p / (r^p − 1)      the run on the coarser mesh

reported as ``<quantity>_error_estimate`` beside each quantity, in its units, with the
meshes (``error_estimate_mesh``, ``error_estimate_cells``), r, p and Fs. r is the ratio of
the two meshes' in-plane element sizes (π R / 2n): the refinement is in-plane only; the
layers through the wall (``coat_layers``) stay, and their effect on ΔAL, +0.3–0.5 % for 4
or 6 layers instead of 2, is not in the band (docs/scleral_buckling.md, "Q2P1 and Q1P0 at
equal accuracy").

Fs = 3: two grids, no observed order (Roache's value for them). p = 1, not Q1P0's formal
order 2 for displacements: the eye's Q1P0 sequence is not in its asymptotic range. Its
wall bends, and Q1P0 locks in bending by a term in (h/t)² with h/t = 4.4 / 3.1 / 1.4 on
the coarse / default / paper meshes (tests/test_wall_bending_locking.py), so ΔAL after
buckling falls 2.484, 2.330, 2.245, 2.240, 2.199 mm at n = 8, 12, 20, 26, 36 with fitted
orders from 0.6 to 5.2, and the fine end extrapolates at order 1 (docs/scleral_buckling.md,
"Q2P1 and Q1P0 at equal accuracy"). With p = 2 the default mesh's settled ΔAL band
(0.100 mm) would hold the paper mesh's value by 0.002 mm (0.407 against 0.309 mm); with
p = 1 (0.250 mm) it holds it with room (docs/scleral_buckling.md, "Discretisation error").

The rim gap is a contact quantity: a node lands on the choroid or does not, the widest
node moves between meshes, and its sequence has no order. Its band says how far the two
meshes disagree, not where the converged rim lies; the verdict (``tear_verdict``) reads
the margin against it: ``uncertain`` where |margin| <= the band
(:func:`~eyemech.problems.scleral_buckling.measures.rim_verdict`).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, NamedTuple

from eyemech.meshes.eye import RESOLUTIONS
from eyemech.problems.run.error_estimate import grid_convergence_index, is_number, solve_again
from eyemech.problems.run.parameters import ParameterError, check
from eyemech.problems.scleral_buckling.measures import rim_verdict

ORDER = 1.0   # p: the eye's Q1P0 sequence converges below its formal order (docstring)
SAFETY = 3.0  # Fs: Roache's factor for two grids
QUANTITIES = ("axial_length_change_mm", "refraction_change_D", "tear_rim_gap_max_mm")
RIM_GAP = "tear_rim_gap_max_mm"


class Mesh(NamedTuple):
    """A rung of the ladder: its name, its cube-edge count n, and the parameters that
    select it."""

    name: str
    cells_per_edge: int
    settings: dict[str, Any]


# n = 20 is the docs' cells_per_bending_length=2.5 (docs/scleral_buckling.md, Conventions)
LADDER = (Mesh("coarse", RESOLUTIONS["coarse"], {"resolution": "coarse"}),
          Mesh("default", RESOLUTIONS["default"], {"resolution": "default"}),
          Mesh("n20", 20, {"resolution": "default", "cells_per_bending_length": 2.5}),
          Mesh("paper", RESOLUTIONS["paper"], {"resolution": "paper"}))


@dataclasses.dataclass(frozen=True)
class Companion:
    """The second solve: its mesh, its parameters, and whether it is the finer."""

    mesh: Mesh
    params: Any
    finer: bool

    def ratio(self, params) -> float:
        """r: the coarser mesh's in-plane element size over the finer's."""
        run, other = params.geometry().element_size, self.params.geometry().element_size
        return run / other if self.finer else other / run


def companion(params) -> Companion:
    """The neighbouring rung of the ladder: the next coarser than the run's mesh, or the
    next finer for a run on (or below) the coarsest."""
    n = params.cells_per_edge
    coarser = [mesh for mesh in LADDER if mesh.cells_per_edge < n]
    mesh = coarser[-1] if coarser else next(mesh for mesh in LADDER if mesh.cells_per_edge > n)
    settings = {"resolution": "default", "cells_per_bending_length": 0.0, "mesh_size": 0.0}
    other = dataclasses.replace(params, **(settings | mesh.settings), error_estimate=False)
    return Companion(mesh, other, finer=not coarser)


def validate(params) -> None:
    """A second solve the scene would refuse (a mesh that cannot hold the geometry, more
    cells than ``max_cells``) is bad input of ``error_estimate``, refused before anything
    is meshed."""
    if not params.error_estimate:
        return
    other = companion(params)
    try:
        check(other.params)
    except ParameterError as err:
        raise ParameterError("error_estimate", f"the estimate's second solve, on the {other.mesh.name} "
                             f"mesh (n = {other.mesh.cells_per_edge}), would be refused: {err}") from None


def estimate(ctx, run: Callable, params) -> dict[str, Any]:
    """Solve the operation again on the companion mesh (same communicator, quietly) and
    add the bands and verdicts to ``ctx.result.quantities``; returns the top level's
    additions."""
    other = companion(params)
    ratio = other.ratio(params)
    others, note = solve_again(ctx, run, other.params)
    quantities = ctx.result.quantities
    of = "coarse" if other.finer else "fine"
    groups = [(quantities, others)] + [(value, others.get(key, {})) for key, value in quantities.items()
                                       if key.startswith("after_") and isinstance(value, dict)]
    for mine, theirs in groups:
        mine |= bands(mine, theirs, ratio, of)
    added = {"error_estimate_mesh": other.mesh.name,
             "error_estimate_cells": others.get("cells"),
             "error_estimate_ratio": ratio, "error_estimate_order": ORDER,
             "error_estimate_safety_factor": SAFETY}
    notes = [note] if note else []
    if other.finer:
        notes.append(f"the run is on the coarsest mesh of the ladder: the second solve is on the "
                     f"{other.mesh.name} mesh (n = {other.mesh.cells_per_edge}), finer, and each band "
                     "is the coarse mesh's, Fs |q_fine - q_coarse| r^p / (r^p - 1)")
    if notes:
        added["error_estimate_note"] = "; ".join(notes)
    quantities |= added
    return added


def bands(mine: dict, theirs: dict, ratio: float, of: str) -> dict[str, Any]:
    """Each quantity's band (None where either solve lacks it) and the rim's verdict."""
    out: dict[str, Any] = {}
    for name in QUANTITIES:
        if name not in mine:
            continue
        value, other = mine[name], theirs.get(name)
        out[f"{name}_error_estimate"] = grid_convergence_index(value, other, ratio, ORDER, SAFETY, of) \
            if is_number(value) and is_number(other) else None
    if "tear_rim_margin_mm" in mine:
        out["tear_verdict"] = rim_verdict(mine["tear_rim_margin_mm"], out.get(f"{RIM_GAP}_error_estimate"))
    return out
