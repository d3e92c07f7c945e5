"""Model no more than the scene needs: the keratotomy quantities of interest against
model reductions and refinements, with the cost of each (issue 9, item 1, the cornea).

The reference is the ``keratotomy`` scene at its defaults (whole cornea, 8 incisions at a
3 mm optical zone, 90 % deep, Q2P1 on trilinear hexahedra, 2 element layers above the cut
bottom, clamped limbus, Le Tallec viscoelasticity over 4 h). One change per case:

- ``quarter symmetry``: the quadrant x, y > 0 with symmetry planes — the same discrete
  problem (tests/test_keratotomy.py: equal to 1e-14), so every further case runs on the
  quarter and its cost compares with ``quarter symmetry``, not with the whole cornea;
- through the thickness: fewer (``layers=1``) or more (``layers=3``) element layers;
- ``curved cells``: 27-node cells on the curved surfaces (``geometry_degree=2``) instead of
  facets;
- ``finer planform``: half the radial element size, twice the azimuthal divisions;
- ``elastic limbus``: springs standing in for the sclera instead of a clamped limbus;
- elastic instead of viscoelastic: the long-time limit (μ = μ∞, the viscous branch
  switched off: μv = 1e-6 MPa) and the instantaneous one (μ = μ∞ + μv) in one time step —
  against the viscoelastic reference after 4 h; this is the seed's own question, how much
  of the change is a short-time viscoelastic effect.

Deviations are of the final values (t = 4 h; an elastic case has only one), relative to
the whole-cornea reference; cost = wall time, unknowns, Newton iterations (both corneas,
intact and incised). A case whose Newton solve fails is recorded, not fatal.
"""

from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from eyemech.forms import Viscoelastic
from eyemech.problems import keratotomy
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import (
    QUIET,
    reduction_chart,
    relative_deviations,
    write_csv,
)

REFERENCE = "whole cornea"
QUARTER = {"symmetry": "quarter"}
ONE_STEP = {"t_end": 300.0, "first_dt": 300.0}  # an elastic cornea has nothing to creep
OFF = 1e-6  # MPa: a viscous branch 4e4 times softer than μ∞, i.e. none
DEFAULTS = keratotomy.Parameters()
MATERIAL = Viscoelastic(DEFAULTS.mu_inf, DEFAULTS.mu_v, DEFAULTS.tau)
CASES = {
    REFERENCE: {},
    "quarter symmetry": QUARTER,
    "1 layer (2 through the cut)": QUARTER | {"layers": 1},
    "3 layers": QUARTER | {"layers": 3},
    "curved cells": QUARTER | {"geometry_degree": 2},
    "finer planform": QUARTER | {"mesh_size": 0.5, "azimuthal_divisions": 48},
    "elastic limbus": QUARTER | {"support": "elastic"},
    "elastic, long-time (μ∞)": QUARTER | ONE_STEP | {"mu_v": OFF},
    "elastic, instantaneous (μ∞+μv)": QUARTER | ONE_STEP | {"mu_inf": MATERIAL.glassy_shear_modulus,
                                                            "mu_v": OFF},
}
# quick: a coarse 1 h creep (5 s a case here), whole cornea against its quarter
QUICK_BASE = {"mesh_size": 1.5, "azimuthal_divisions": 8, "t_end": 3600.0, "first_dt": 1800.0,
              "dt_growth": 1.0}
QUICK_CASES = {REFERENCE: {}, "quarter symmetry": QUARTER}
QUANTITIES = {"power_change_final_D": "power change",
              "apex_displacement_mm": "apex displacement",
              "wound_gape_mm": "wound gape",
              "intact_power_D": "intact power"}


def one_case(label: str, overrides: dict, comm) -> dict:
    # the time grid fixed: the cases differ in space only (docs/studies/cornea_model_reduction.csv)
    params = keratotomy.Parameters(**{"time_stepping": "fixed", **overrides})
    row = {"case": label, "symmetry": params.symmetry, "layers": params.layers,
           "geometry_degree": params.geometry_degree, "support": params.support,
           "changes": " ".join(f"{k}={v}" for k, v in overrides.items()) or "defaults"}
    try:
        result = keratotomy.run(params, comm=comm, options=QUIET)
    except SolveFailure as failure:
        # a case that should have run: counted as failed by `eyemech study` (exit 4)
        return row | {"status": "failed", "error": f"no convergence at t = {failure.load:.3g} s"}
    q = result.quantities
    final = {key: q[key][-1] if isinstance(q[key], list) else q[key] for key in QUANTITIES}
    return row | {"status": "ok", **final,
                  "power_change_initial_D": q["power_change_initial_D"],
                  "cells": q["cells"], "dofs": q["dofs"],
                  "newton_iterations": sum(s.get("newton_iterations", 0) for s in result.steps),
                  "time_steps": len(result.steps), "wall_time_s": result.timings["total"]}


def run(out: Path, quick: bool = False, comm: MPI.Comm | None = None) -> list[Path]:
    comm = comm or MPI.COMM_WORLD
    out = Path(out)
    cases = {label: QUICK_BASE | o for label, o in QUICK_CASES.items()} if quick else CASES
    rows = [one_case(label, overrides, comm) for label, overrides in cases.items()]
    if comm.rank != 0:
        return []
    relative_deviations(rows, QUANTITIES, reference=REFERENCE)
    table = write_csv(out / "cornea_model_reduction.csv", rows,
                      "keratotomy (8 incisions, 3 mm zone): one change per case, final values "
                      "(t_end); deviation_* = case / whole cornea - 1; cases after the quarter "
                      "run on the quarter; newton_iterations: of the time steps (not the IOP ramp)")
    chart = reduction_chart(out / "cornea_model_reduction.png", rows, QUANTITIES,
                            xlabel="deviation of the final value (%)",
                            title="keratotomy: what each model reduction changes, and what it saves")
    return [table, chart]


STUDY = Study(name="cornea-model-reduction",
              summary="keratotomy: quantities of interest vs model reduction (symmetry, layers, "
                      "curved cells, planform, limbus, elastic vs viscoelastic) with the cost",
              run=run)
