"""The hyperelastic benchmarks over the range a user tries, at the resolutions around their
defaults.

- ``sphere-inflation`` (exact): the wall from thin to thick (outer/inner radius 1.1 … 2) and
  the pressure at 0.5 and 0.9 of the limit point, at 1, 2 and 3 cells across the wall: the
  error of the inner wall's displacement and the L² displacement error, and Richardson's
  estimate that ``error_estimate=true`` reports (2 cells: the coarse solve at 1).
- ``cook-membrane`` (no closed form): load × 0.5, 1 and 2 (the same as μ × 2, 1, 0.5) on
  4 … 32 elements per side, against a Richardson value of the three finest (observed
  order); the default 8 × 8 and its estimate.

The sphere's dimensionless parameters are B/A and p/c10 (a scaled sphere is the same
problem: tests/test_scaled_benchmarks.py), Cook's is F/μ.
"""

from __future__ import annotations

import time
from pathlib import Path

from mpi4py import MPI

from eyemech.problems import cook_membrane, sphere_inflation
from eyemech.problems.reference import analytic
from eyemech.problems.run.error_estimate import extrapolate
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, save_chart, write_csv

WALL_RATIOS = (1.1, 1.2, 2.0)  # outer / inner radius, inner 10 mm
LIMIT_FRACTIONS = (0.5, 0.9)  # pressure / limit-point pressure
CELLS_ACROSS = (1.0, 2.0, 3.0)
COOK_LOADS = (0.5, 1.0, 2.0)
COOK_SIDES = (4, 8, 16, 32)
QUICK_WALLS = (1.2,)
QUICK_FRACTIONS = (0.5,)
QUICK_CELLS = (1.0,)
QUICK_LOADS = (1.0,)
QUICK_SIDES = (2, 4)
MAX_CELLS = 25_000  # finer meshes of the series are left out (the thin wall at 3 cells across)


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    if comm.rank != 0:  # serial study: rank 0 does the work
        return []
    spheres = [sphere_row(ratio, fraction, cells)
               for ratio in (QUICK_WALLS if quick else WALL_RATIOS)
               for fraction in (QUICK_FRACTIONS if quick else LIMIT_FRACTIONS)
               for cells in (QUICK_CELLS if quick else CELLS_ACROSS)]
    spheres = [r for r in spheres if r is not None]
    cook = [cook_row(load, n) for load in (QUICK_LOADS if quick else COOK_LOADS)
            for n in (QUICK_SIDES if quick else COOK_SIDES)]
    add_cook_references(cook)
    files = [write_csv(out / "hyperelastic_range_sphere.csv", spheres,
                       "displacement_error: (a - A) / (a_exact - A) - 1 at the inner wall; "
                       "l2_error: relative L2 error of the displacement; estimate: Richardson "
                       "(error_estimate=true) on the inner radius, over a_exact - A"),
             write_csv(out / "hyperelastic_range_cook.csv", cook,
                       "error: tip / Richardson value of the three finest meshes - 1")]
    files.append(_chart(out / "hyperelastic_range.png", spheres, cook))
    return files


def sphere_row(ratio: float, fraction: float, cells: float) -> dict | None:
    inner, c10 = 10.0, 0.05
    outer = inner * ratio
    _, limit = analytic.sphere_limit_point(inner, outer, c10)
    params = sphere_inflation.Parameters(inner_radius=inner, outer_radius=outer, c10=c10,
                                         pressure=fraction * limit, cells_across_wall=cells,
                                         error_estimate=cells >= 2.0)
    if params.estimated_cells > MAX_CELLS:
        return None
    row = {"wall_ratio": ratio, "limit_fraction": fraction, "pressure_over_c10": params.pressure / c10,
           "cells_across_wall": cells}
    start = time.perf_counter()
    try:
        q = sphere_inflation.run(params, comm=MPI.COMM_SELF, options=QUIET).quantities
    except SolveFailure as failure:
        return row | {"status": "failed", "error": str(failure)[:200]}
    exact = q["inner_radius_exact"]
    row |= {"status": "ok", "dofs": q["dofs"], "seconds": time.perf_counter() - start,
            "displacement_error": (q["inner_radius_deformed"] - inner) / (exact - inner) - 1.0,
            "l2_error": q["displacement_error"]}
    if q.get("inner_radius_deformed_error_estimate") is not None:
        row["estimate"] = q["inner_radius_deformed_error_estimate"] / (exact - inner)
    return row


def cook_row(load: float, sides: int) -> dict:
    base = cook_membrane.Parameters()
    params = cook_membrane.Parameters(load=base.load * load, elements_per_side=sides,
                                      error_estimate=sides == base.elements_per_side)
    row = {"load_factor": load, "elements_per_side": sides}
    start = time.perf_counter()
    try:
        q = cook_membrane.run(params, comm=MPI.COMM_SELF, options=QUIET).quantities
    except SolveFailure as failure:
        return row | {"status": "failed", "error": str(failure)[:200]}
    row |= {"status": "ok", "dofs": q["dofs"], "tip": q["tip_displacement"],
            "seconds": time.perf_counter() - start}
    if q.get("tip_displacement_error_estimate") is not None:
        row["estimate"] = q["tip_displacement_error_estimate"]
    return row


def add_cook_references(rows: list[dict]) -> None:
    """Per load: the tip extrapolated from the three finest meshes (:func:`extrapolate`,
    observed order in [0.3, 4]: the corners are singular), each row's error against it."""
    for load in {r["load_factor"] for r in rows}:
        mine = [r for r in rows if r["load_factor"] == load and r["status"] == "ok"]
        if len(mine) < 2:
            continue
        reference, order = extrapolate([r["tip"] for r in mine], [1.0 / r["elements_per_side"] for r in mine],
                                       order=1.0, bounds=(0.3, 4.0))
        for row in mine:
            row |= {"reference": reference, "observed_order": order, "error": row["tip"] / reference - 1.0}
            if "estimate" in row:
                row["estimate_relative"] = row["estimate"] / abs(reference)


def _chart(path: Path, spheres: list[dict], cook: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.4))
    for cells, marker in zip(sorted({r["cells_across_wall"] for r in spheres}), "osd"):
        mine = [r for r in spheres if r["cells_across_wall"] == cells and r["status"] == "ok"]
        for fraction, style in zip(sorted({r["limit_fraction"] for r in mine}), ("-", "--", ":")):
            same = [r for r in mine if r["limit_fraction"] == fraction]
            left.semilogy([r["wall_ratio"] for r in same], [max(abs(r["displacement_error"]), 1e-9)
                                                             for r in same],
                          marker=marker, ls=style, label=f"{cells:g} across, p = {fraction:g} p_limit")
    left.axhline(5e-3, color="grey", ls=":", label="0.5 %")
    left.set(xlabel="outer / inner radius", ylabel="|inner-wall displacement error|",
             title="sphere-inflation, P2P1")
    left.legend(fontsize=6)
    for load in sorted({r["load_factor"] for r in cook}):
        mine = [r for r in cook if r["load_factor"] == load and "error" in r]
        right.loglog([r["elements_per_side"] for r in mine], [max(abs(r["error"]), 1e-7) for r in mine],
                     marker="o", label=f"load × {load:g}")
    right.axhline(1e-2, color="grey", ls=":", label="1 %")
    right.set(xlabel="elements per side", ylabel="|tip / extrapolated − 1|", title="cook-membrane, Q2P1")
    right.legend(fontsize=7)
    save_chart(fig, path, dpi=110)
    return path


STUDY = Study(name="hyperelastic-range",
              summary="sphere-inflation over wall thickness and pressure, Cook's membrane over load: "
                      "error at and around the default resolution, with the error estimate", run=run)
