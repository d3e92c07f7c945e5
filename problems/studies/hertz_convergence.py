"""Hertz's contact (``hertz``) over the range a user tries: how far the default resolution
is from the model's mesh-converged force, and how far that model is from Hertz's law.

The scene is self-similar: a ball of radius R pressed to d/R into a body of modulus E is
the unit ball pressed to d/R with every length × R and every stress × E (the mesh sizes
and the body are multiples of the contact radius a = √(Rd), the penalty α = factor · E / h),
so its errors depend on d/R (and ν = 0.3) alone. Three parts:

- **converged**: for each d/R, the augmented-Lagrangian solve (no penalty penetration)
  on a family of meshes refined uniformly by 1.5 (``resolution`` and ``far_resolution``
  together), and Richardson's extrapolation from the last three (observed order, clipped to
  [1, 4]; the finest level only at the d/R of ``FINEST_AT``, elsewhere two levels and
  order 2); the converged force against Hertz's 4/3 E* R^½ d^{3/2} is the model's
  deviation from Hertz's half-space (the clamp at ``extent`` · a, finite strain, the
  sphere against Hertz's paraboloid), fitted as c₀ + c₁ (a/R): c₀ the clamp (≈ 1.2/extent,
  the same at every d/R), c₁ what grows with the strain a/R.
- **levels**: the default penalty method on the same meshes: its error against the
  converged force is the discretisation error (the penalty's penetration, ∝ h, lowers
  the force; the mesh, ∝ h², stiffens it).
- **range**: the default parameters at the corners and the middle of radius 2–10 mm,
  modulus 0.5–5 MPa, d/R 0.002–0.02, with ``error_estimate=true``: force against
  Hertz's law, against the converged force, and Richardson's estimate.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from eyemech.problems import hertz
from eyemech.problems.run.error_estimate import extrapolate
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, save_chart, with_units, write_csv

INDENTATIONS = (0.001, 0.002, 0.005, 0.01, 0.02)  # d/R
LEVELS = (1.0, 1.5, 2.25)  # resolution and far_resolution × these
# the finest level (≈ 17,000 cells, 5–10 min each here) only where asked: two levels with
# order 2 elsewhere
FINEST_AT = (0.01,)
RANGE = tuple((radius, modulus, ratio) for ratio in (0.002, 0.02) for radius in (2.0, 10.0)
              for modulus in (0.5, 5.0)) + ((4.0, 1.0, 0.005), (6.0, 2.0, 0.01), (3.0, 0.8, 0.015))
QUICK_INDENTATIONS = (0.01,)
QUICK_LEVELS = (0.5, 0.75)
QUICK_RANGE = ((2.0, 0.5, 0.01),)
METHODS = ("augmented-lagrangian", "penalty")


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    if comm.rank != 0:  # serial study: rank 0 does the work
        return []
    indentations = QUICK_INDENTATIONS if quick else INDENTATIONS
    levels = QUICK_LEVELS if quick else LEVELS
    level_rows = [_level_row(ratio, level, method) for ratio in indentations for level in levels
                  for method in METHODS if level < levels[-1] or ratio in FINEST_AT or quick]
    converged = converged_rows(level_rows, indentations)
    fit = fit_deviation(converged)
    reference = {r["d_over_R"]: r["converged_force_error"] for r in converged}
    for row in level_rows:
        row["error_vs_converged"] = _relative(row.get("force_error"), reference.get(row["d_over_R"]))
    range_rows = [_range_row(*case, fit) for case in (QUICK_RANGE if quick else RANGE)]
    stem = "hertz_convergence"
    note = "force_error: F / F_Hertz - 1; error_vs_converged: F / F_converged - 1 (same d/R)"
    files = [write_csv(out / f"{stem}.csv", with_units(level_rows, hertz.Parameters), note,
                       "meshes: resolution = 2.6 level, far_resolution = 3 level"),
             write_csv(out / f"{stem}_converged.csv", with_units(converged + [fit], hertz.Parameters),
                       "Richardson from the augmented-Lagrangian solves of the last three levels; "
                       "the last row: converged_force_error = c0 + c1 (a/R) fitted"),
             write_csv(out / f"{stem}_range.csv", with_units(range_rows, hertz.Parameters), note,
                       "converged: the fit of hertz_convergence_converged.csv at the case's d/R")]
    files.append(_chart(out / f"{stem}.png", level_rows, converged, fit, range_rows))
    return files


def _level_row(ratio: float, level: float, method: str) -> dict:
    base = hertz.Parameters()
    params = dataclasses.replace(base, indentation=ratio * base.radius, contact_method=method,
                                 resolution=base.resolution * level,
                                 far_resolution=base.far_resolution * level, max_cells=10**6)
    row = {"d_over_R": ratio, "level": level, "method": method, "resolution": params.resolution,
           "far_resolution": params.far_resolution}
    return row | _solve(params)


def _solve(params) -> dict:
    start = time.perf_counter()
    try:
        q = hertz.run(params, comm=MPI.COMM_SELF, options=QUIET).quantities
    except SolveFailure as failure:
        return {"status": "failed", "error": str(failure)[:200]}
    out = {"status": "ok", "cells": q["cells"], "dofs": q["dofs"], "force_error": q["force_error"],
           "radius_error": q["radius_error"],
           "penetration_over_indentation": q["max_penetration"] / params.indentation,
           "newton_iterations": q["newton_iterations"], "seconds": time.perf_counter() - start}
    if "contact_force_error_estimate" in q:
        out["force_error_estimate"] = q["contact_force_error_estimate"] / q["hertz_force"]
        out["seconds_with_estimate"] = out.pop("seconds")
    return out


def converged_rows(level_rows: list[dict], indentations) -> list[dict]:
    """Per d/R: Richardson from the augmented-Lagrangian forces of the finest three levels
    (two: order 2; :func:`extrapolate`)."""
    rows = []
    for ratio in indentations:
        ok = [r for r in level_rows if r["d_over_R"] == ratio and r["status"] == "ok"
              and r["method"] == "augmented-lagrangian"]
        if len(ok) < 2:
            rows.append({"d_over_R": ratio, "status": "failed", "error": "fewer than two levels"})
            continue
        forces = [1.0 + r["force_error"] for r in ok]
        converged, order = extrapolate(forces, [1.0 / r["level"] for r in ok])
        finest = max(ok, key=lambda r: r["level"])
        rows.append({"d_over_R": ratio, "status": "ok", "a_over_R": math.sqrt(ratio),
                     "observed_order": order, "finest_force_error": finest["force_error"],
                     "converged_force_error": converged - 1.0})
    return rows


def fit_deviation(converged: list[dict]) -> dict:
    """c₀, c₁ of F_converged / F_Hertz − 1 = c₀ + c₁ x, x = a/R (least squares)."""
    ok = [r for r in converged if r["status"] == "ok"]
    x = np.array([r["a_over_R"] for r in ok])
    y = np.array([r["converged_force_error"] for r in ok])
    basis = np.column_stack([np.ones_like(x), x])
    if len(ok) >= 2:
        (c0, c1), *_ = np.linalg.lstsq(basis, y, rcond=None)
    else:  # one d/R (quick): the constant alone
        c0, c1 = y[0], 0.0
    return {"d_over_R": "fit", "status": "ok", "c0": float(c0), "c1": float(c1),
            "max_fit_residual": float(np.abs(basis @ [c0, c1] - y).max())}


def fitted_deviation(fit: dict, ratio: float) -> float:
    return fit["c0"] + fit["c1"] * math.sqrt(ratio)


def _range_row(radius: float, modulus: float, ratio: float, fit: dict) -> dict:
    params = hertz.Parameters(radius=radius, youngs_modulus=modulus, indentation=ratio * radius,
                              error_estimate=True)
    row = {"radius": radius, "youngs_modulus": modulus, "d_over_R": ratio} | _solve(params)
    if row["status"] == "ok":
        converged = fitted_deviation(fit, ratio)
        row["converged_force_error"] = converged
        row["error_vs_converged"] = _relative(row["force_error"], converged)
    return row


def _relative(force_error, converged_error) -> float:
    """F / F_converged − 1 from both errors against Hertz's law."""
    if force_error is None or converged_error is None:
        return math.nan
    return (1.0 + force_error) / (1.0 + converged_error) - 1.0


def _chart(path: Path, level_rows, converged, fit, range_rows) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.6))
    ratios = np.geomspace(1e-3, 2e-2, 60)
    left.plot(ratios, [100 * fitted_deviation(fit, r) for r in ratios], "k-",
              label=f"converged: {100 * fit['c0']:.2f} + {100 * fit['c1']:.1f} (a/R) %")
    ok = [r for r in converged if r["status"] == "ok"]
    left.plot([r["d_over_R"] for r in ok], [100 * r["converged_force_error"] for r in ok], "ko",
              label=f"Richardson (augmented Lagrangian, {len({r['level'] for r in level_rows})} meshes)")
    default = [r for r in range_rows if r["status"] == "ok"]
    left.plot([r["d_over_R"] for r in default], [100 * r["force_error"] for r in default], "x",
              color="tab:red", label="default resolution, R 2–10 mm, E 0.5–5 MPa")
    left.axhline(3.0, color="grey", ls=":", label="3 %")
    left.set(xscale="log", xlabel="d / R", ylabel="F / F_Hertz − 1 (%)",
             title="the model against Hertz's law (clamp at 200 a, finite strain)")
    left.legend(fontsize=7)
    for method, marker in zip(METHODS, ("o", "s")):
        for level in sorted({r["level"] for r in level_rows}):
            mine = [r for r in level_rows if r["method"] == method and r["level"] == level
                    and r["status"] == "ok"]
            right.plot([r["d_over_R"] for r in mine], [100 * r["error_vs_converged"] for r in mine],
                       marker=marker, ls="-" if method == "penalty" else "--",
                       label=f"{method}, {2.6 * level:.3g} per a, {3 * level:.3g} per ρ")
    right.plot([r["d_over_R"] for r in default], [100 * r["error_vs_converged"] for r in default], "x",
               color="tab:red", label="default, range cases")
    for bound in (1.0, -1.0):
        right.axhline(bound, color="grey", ls=":")
    right.set(xscale="log", xlabel="d / R", ylabel="F / F_converged − 1 (%)",
              title="discretisation error against the converged force")
    right.legend(fontsize=6)
    save_chart(fig, path, dpi=110)
    return path


STUDY = Study(name="hertz-convergence",
              summary="hertz: force vs the mesh-converged model and Hertz's law, d/R 0.001-0.02, "
                      "radius 2-10 mm, modulus 0.5-5 MPa", run=run)
