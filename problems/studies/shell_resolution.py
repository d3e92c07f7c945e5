"""Resolution rules of the linear shell benchmarks, from their errors over the thicknesses a
user tries.

- **plates** (``plate-clamped``, ``plate-simply-supported``): the Kirchhoff plate's
  deflection is c q L⁴/D exactly, so the error depends on the mesh alone: the
  default 32 divisions on a refinement sequence, and at thickness × 0.1 and × 5.
- **curved shells** (``hemisphere``, ``scordelis-lo``): the faceted P2 shell locks in
  membrane, and the error is a function of the elements per bending length √(R h)
  (``cells_per_bending_length``), not of the divisions: each thickness on a sequence of
  that resolution, against a reference extrapolated (Richardson, observed order) from
  the three finest; the hemisphere's displacement as c = u E h³/(F R²) (bending
  scaling), the roof's edge deflection at the same load.
"""

from __future__ import annotations

import time
from pathlib import Path

from mpi4py import MPI

from eyemech.problems import hemisphere, plate_clamped, plate_simply_supported, scordelis_lo
from eyemech.problems.run.error_estimate import extrapolate
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, save_chart, with_units, write_csv

PLATE_DIVISIONS = (8, 16, 32, 64)
PLATE_THICKNESS_FACTORS = (0.1, 5.0)
HEMISPHERE_THICKNESSES = (0.2, 0.1, 0.04, 0.02)  # R/h = 50, 100, 250, 500
ROOF_THICKNESSES = (1.0, 0.25, 0.1, 0.05)  # R/h = 25, 100, 250, 500
RESOLUTIONS = (0.8, 1.2, 1.8, 2.7)  # cells per bending length
MAX_CELLS = 40_000  # finer meshes of the series are left out (≈ 240,000 unknowns and more)
QUICK_PLATE_DIVISIONS = (8, 16)
QUICK_THICKNESSES = (0.04,)
QUICK_RESOLUTIONS = (0.4, 0.6)
TOLERANCE = 0.02  # the curved shells' stated bound (tests/test_shell.py)


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    if comm.rank != 0:  # serial study: rank 0 does the work
        return []
    plates = plate_rows(QUICK_PLATE_DIVISIONS if quick else PLATE_DIVISIONS, () if quick
                        else PLATE_THICKNESS_FACTORS)
    resolutions = QUICK_RESOLUTIONS if quick else RESOLUTIONS
    curved = (curved_rows(hemisphere, QUICK_THICKNESSES if quick else HEMISPHERE_THICKNESSES,
                          resolutions)
              + curved_rows(scordelis_lo, (0.25,) if quick else ROOF_THICKNESSES, resolutions))
    add_references(curved)
    # the columns that are parameters named with their units: both plates share one
    # Parameters, each curved row takes its scene's
    parameters = {module.SCENE.name: module.Parameters for module in (hemisphere, scordelis_lo)}
    files = [write_csv(out / "shell_resolution_plates.csv", with_units(plates, plate_clamped.Parameters),
                       "error: centre deflection / (c q L^4 / D) - 1, Timoshenko's c"),
             write_csv(out / "shell_resolution_curved.csv",
                       [with_units([row], parameters[row["scene"]])[0] for row in curved],
                       "value: hemisphere c = u E h^3 / (F R^2); roof edge deflection; "
                       "error against the Richardson value of the finest three resolutions")]
    files.append(_chart(out / "shell_resolution.png", plates, curved))
    return files


def plate_rows(divisions, thickness_factors) -> list[dict]:
    rows = []
    for module, support in ((plate_clamped, "clamped"), (plate_simply_supported, "simply-supported")):
        base = module.Parameters()
        cases = [(n, 1.0) for n in divisions] + [(base.divisions, f) for f in thickness_factors]
        for n, factor in cases:
            params = module.Parameters(divisions=n, thickness=base.thickness * factor)
            row = {"support": support, "divisions": n, "thickness": params.thickness}
            result = _solve(module, params)
            if result is not None:
                q, seconds = result
                row |= {"status": "ok", "dofs": q["dofs"], "error": q["center_deflection_error"],
                        "seconds": seconds}
            else:
                row["status"] = "failed"
            rows.append(row)
    return rows


def curved_rows(module, thicknesses, resolutions) -> list[dict]:
    rows = []
    scene = module.SCENE.name
    for thickness in thicknesses:
        for resolution in resolutions:
            base = module.Parameters()
            params = module.Parameters(thickness=thickness, cells_per_bending_length=resolution,
                                       **_load(module, base, thickness))
            if params.estimated_cells > MAX_CELLS:
                continue
            radius = params.radius
            row = {"scene": scene, "thickness": thickness, "slenderness": radius / thickness,
                   "cells_per_bending_length": resolution}
            result = _solve(module, params)
            if result is None:
                rows.append(row | {"status": "failed"})
                continue
            q, seconds = result
            rows.append(row | {"status": "ok", "divisions": q["divisions"], "dofs": q["dofs"],
                               "value": _value(module, params, q), "seconds": seconds})
    return rows


def _load(module, base, thickness: float) -> dict:
    """The hemisphere's force scaled with h³ (a bending-dominated response keeps its size)."""
    if module is hemisphere:
        return {"force": base.force * (thickness / base.thickness) ** 3}
    return {}


def _value(module, params, q) -> float:
    if module is hemisphere:
        return (q["radial_displacement_x"] * params.youngs_modulus * params.thickness ** 3
                / (params.force * params.radius ** 2))
    return q["edge_deflection"]


def _solve(module, params):
    start = time.perf_counter()
    try:
        return module.run(params, comm=MPI.COMM_SELF, options=QUIET).quantities, time.perf_counter() - start
    except SolveFailure:
        return None


def add_references(rows: list[dict]) -> None:
    """Per scene and thickness: the value extrapolated from the three finest resolutions
    (:func:`extrapolate`), and each row's error against it."""
    for key in {(r["scene"], r["thickness"]) for r in rows}:
        mine = [r for r in rows if (r["scene"], r["thickness"]) == key and r["status"] == "ok"]
        if len(mine) < 2:
            continue
        reference, order = extrapolate([r["value"] for r in mine], [1.0 / r["divisions"] for r in mine])
        for row in mine:
            row |= {"reference": reference, "observed_order": order, "error": row["value"] / reference - 1.0}


def _chart(path: Path, plates: list[dict], curved: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.6))
    for support, marker in (("clamped", "o"), ("simply-supported", "s")):
        mine = [r for r in plates if r["support"] == support and r["status"] == "ok"]
        for thickness in sorted({r["thickness"] for r in mine}):
            same = [r for r in mine if r["thickness"] == thickness]
            left.loglog([r["divisions"] for r in same], [abs(r["error"]) for r in same], marker=marker,
                        ls="-" if len(same) > 1 else "none", label=f"{support}, h = {thickness:g}")
    left.set(xlabel="divisions per side", ylabel="|w / w_Timoshenko − 1|", title="plates (P2, crossed)")
    left.axhline(3e-3, color="grey", ls=":", label="0.3 %")
    left.legend(fontsize=7)
    for scene, style in (("hemisphere", "-"), ("scordelis-lo", "--")):
        for thickness in sorted({r["thickness"] for r in curved if r["scene"] == scene}):
            same = [r for r in curved if r["scene"] == scene and r["thickness"] == thickness
                    and "error" in r]
            if same:
                right.semilogy([r["cells_per_bending_length"] for r in same],
                               [max(abs(r["error"]), 1e-6) for r in same], style, marker="o",
                               label=f"{scene}, R/h = {same[0]['slenderness']:g}")
    right.axhline(TOLERANCE, color="grey", ls=":", label="2 %")
    right.set(xlabel="cells per bending length √(R h)", ylabel="|error| against the extrapolated value",
              title="curved shells: membrane locking set by cells per √(R h)")
    right.legend(fontsize=7)
    save_chart(fig, path, dpi=110)
    return path


STUDY = Study(name="shell-resolution",
              summary="shell resolution rules: plates vs divisions and thickness; hemisphere and "
                      "Scordelis-Lo vs cells per bending length over R/h", run=run)
