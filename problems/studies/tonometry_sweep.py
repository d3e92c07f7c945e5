"""Goldmann applanation in the ``tonometry`` scene: mesh convergence of
the reading, and the reading against central corneal thickness and corneal modulus.

Published trend: readings rise with thickness and stiffness. Ehlers, Bramsen & Sperling
(1975, manometry in 29 cannulated eyes) found Goldmann true at 520 µm and a thickness error
of ≈ 0.7 mmHg per 10 µm (the correction table of Whitacre & Stein 1993 is of the same
kind); Doughty & Zaman (2000, meta-analysis, normal eyes) found a smaller slope, ≈ 1.1 mmHg
per 10 % of thickness (≈ 0.2 mmHg per 10 µm). Both lines are drawn through the true IOP at
520 µm.

Steps (full): (1) the nominal case on refining meshes (radial size, azimuthal divisions,
layers, geometry degree, penalty); (2) the reading against the modulus at 520 µm, and the
modulus ``E_cal`` at which the model reads the true IOP there (Goldmann's calibration
condition, found by linear interpolation); (3) the reading against the central thickness
at ``E_cal`` and at the scene's default modulus. Sweeps use ``SWEEP_MESH`` (its offset from
the finest mesh is in the convergence table; slopes are what is compared). Quick: two
coarse runs (nominal, thicker), no convergence, no calibration.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from eyemech.problems import tonometry
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, save_chart, write_csv

EHLERS_SLOPE = 0.071         # mmHg per µm (Ehlers et al. 1975: 0.7 mmHg per 10 µm)
DOUGHTY_ZAMAN_SLOPE = 0.021  # mmHg per µm (1.1 mmHg per 10 % of 520 µm)
NOMINAL_CCT = 0.52           # mm: Goldmann's calibration thickness (Ehlers et al. 1975)
SWEEP_MESH = dict(mesh_size=1.5, azimuthal_divisions=8)
QUICK_MESH = dict(mesh_size=1.5, azimuthal_divisions=8)
# (label, changes from the scene's defaults) — finest last
CONVERGENCE = [
    ("1.5 mm, 8 around", dict(mesh_size=1.5, azimuthal_divisions=8)),
    ("1.0 mm, 16 around", dict(mesh_size=1.0, azimuthal_divisions=16)),
    ("1.0 mm, 16 around, trilinear", dict(mesh_size=1.0, azimuthal_divisions=16, geometry_degree=1)),
    ("0.5 mm, 16 around", dict(mesh_size=0.5, azimuthal_divisions=16)),
    ("0.5 mm, 16 around, penalty 100", dict(mesh_size=0.5, azimuthal_divisions=16, penalty=100.0)),
    ("0.5 mm, 16 around, 3 layers", dict(mesh_size=0.5, azimuthal_divisions=16, layers=3)),
]
MODULI = [0.07, 0.105, 0.14, 0.21, 0.28]
THICKNESSES = [0.45, 0.52, 0.60]


def _reading(comm, **changes) -> dict:
    params = tonometry.Parameters(**changes)
    try:
        result = tonometry.run(params, comm=comm, options=QUIET)
    except SolveFailure as failure:  # a failed case: a row that says so, counted by `eyemech study`
        return {"status": "failed", "central_thickness_um": 1000 * params.central_thickness,
                "youngs_modulus_MPa": params.youngs_modulus, "iop_mmHg": params.iop_mmHg,
                "iop_reading_mmHg": float("nan"), "error": str(failure)[:120]}
    q = result.quantities
    return {"status": "ok", "central_thickness_um": 1000 * params.central_thickness,
            "youngs_modulus_MPa": params.youngs_modulus,
            "mesh_size_mm": params.mesh_size, "azimuthal_divisions": params.azimuthal_divisions,
            "layers": params.layers, "geometry_degree": params.geometry_degree, "penalty": params.penalty,
            "cells": q["cells"], "dofs": q["dofs"], "iop_mmHg": params.iop_mmHg,
            "iop_reading_mmHg": q["iop_reading_mmHg"], "iop_reading_dry_mmHg": q["iop_reading_dry_mmHg"],
            "applanation_depth_mm": q["applanation_depth_mm"],
            "newton_iterations": sum(s.get("newton_iterations", 0) for s in result.steps),
            "wall_time_s": result.timings["total"]}


def _thick(cct: float, **changes) -> dict:
    """The thickness profile shifted as a whole: the limbus stays 0.15 mm thicker."""
    return dict(central_thickness=cct, limbal_thickness=cct + 0.15, **changes)


def _default_modulus() -> float:
    """The scene's default modulus: the mesh study and the first thickness series use it."""
    return tonometry.Parameters().youngs_modulus


def _default_label() -> str:
    return f"model default, E = {_default_modulus():g} MPa"


def _calibrated_modulus(rows: list[dict]) -> float | None:
    """E at which the reading equals the true IOP (linear interpolation between the
    bracketing moduli), or None if the sweep does not bracket it."""
    E = np.array([r["youngs_modulus_MPa"] for r in rows])
    error = np.array([r["iop_reading_mmHg"] - r["iop_mmHg"] for r in rows])
    order = np.argsort(E)
    E, error = E[order], error[order]
    for i in range(len(E) - 1):
        if error[i] <= 0 <= error[i + 1]:
            return float(E[i] + (E[i + 1] - E[i]) * -error[i] / (error[i + 1] - error[i]))
    return None


def _chart(path: Path, thickness: dict[str, list[dict]], moduli: list[dict], iop: float) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    ax = axes[0]
    for label, rows in thickness.items():
        ax.plot([r["central_thickness_um"] for r in rows], [r["iop_reading_mmHg"] for r in rows], "o-",
                label=label)
    cct = np.array([440.0, 620.0])
    ax.plot(cct, iop + EHLERS_SLOPE * (cct - 1000 * NOMINAL_CCT), "k--",
            label="Ehlers et al. 1975 (0.7 mmHg / 10 µm)")
    ax.plot(cct, iop + DOUGHTY_ZAMAN_SLOPE * (cct - 1000 * NOMINAL_CCT), "k:",
            label="Doughty & Zaman 2000 (≈ 0.2 mmHg / 10 µm)")
    ax.axhline(iop, color="grey", lw=0.8)
    ax.set_xlabel("central corneal thickness (µm)")
    ax.set_ylabel("Goldmann reading (mmHg)")
    ax.set_title(f"true IOP {iop:g} mmHg, with tear film", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    ax = axes[1]
    ax.plot([r["youngs_modulus_MPa"] for r in moduli], [r["iop_reading_mmHg"] for r in moduli], "o-",
            label="model, 520 µm")
    ax.axhline(iop, color="grey", lw=0.8, label="true IOP")
    ax.set_xlabel("instantaneous Young's modulus E (MPa)")
    ax.set_ylabel("Goldmann reading (mmHg)")
    ax.set_title("readings rise with stiffness (Liu & Roberts 2005)", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    save_chart(fig, path, dpi=80)
    return path


def _convergence_chart(path: Path, rows: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.8))
    for degree, marker in ((2, "o"), (1, "s")):
        sel = [r for r in rows
               if r["geometry_degree"] == degree and r["penalty"] == 30.0 and r["layers"] == 2]
        ax.plot([r["dofs"] for r in sel], [r["iop_reading_mmHg"] for r in sel], marker,
                label=f"geometry degree {degree}, 2 layers")
    other = [r for r in rows if r["penalty"] != 30.0 or r["layers"] != 2]
    for r in other:
        ax.plot(r["dofs"], r["iop_reading_mmHg"], "^", label=r["case"])
    ax.set_xscale("log")
    ax.set_xlabel("displacement + pressure dofs")
    ax.set_ylabel("reading (mmHg), true 15")
    ax.set_title(f"tonometry: mesh convergence of the reading (520 µm, E = {_default_modulus():g} MPa)",
                 fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    save_chart(fig, path, dpi=80)
    return path


def run(out: Path, quick: bool = False, comm=None) -> list[Path]:
    comm = comm or MPI.COMM_WORLD
    out = Path(out)
    files: list[Path] = []
    if quick:
        mesh = QUICK_MESH
        nominal = _reading(comm, **mesh)
        moduli = [nominal]  # (the tests cover stiffness; quick keeps 'study all' short)
        thickness = {_default_label(): [nominal, _reading(comm, **_thick(0.60, **mesh))]}
    else:
        rows = []
        for label, changes in CONVERGENCE:
            rows.append({"case": label, **_reading(comm, **changes)})
        if comm.rank == 0:
            files.append(write_csv(out / "tonometry_convergence.csv", rows,
                                   f"tonometry: reading at 520 µm, E = {_default_modulus():g} MPa "
                                   "(the scene's default), IOP 15 mmHg, by mesh"))
            files.append(_convergence_chart(out / "tonometry_convergence.png", rows))
        mesh = SWEEP_MESH
        moduli = [_reading(comm, youngs_modulus=E, **mesh)
                  for E in sorted(set(MODULI) | {_default_modulus()})]
        E_cal = _calibrated_modulus(moduli)
        default = next(r for r in moduli if r["youngs_modulus_MPa"] == _default_modulus())
        thickness = {_default_label(): [
            default if t == NOMINAL_CCT else _reading(comm, **_thick(t, **mesh)) for t in THICKNESSES]}
        if E_cal is not None:
            thickness[f"model, E = {E_cal:.3f} MPa (reads true at 520 µm)"] = [
                _reading(comm, **_thick(t, youngs_modulus=round(E_cal, 4), **mesh)) for t in THICKNESSES]
    if comm.rank != 0:
        return []
    rows = [{"sweep": "modulus", **r} for r in moduli]
    for label, series in thickness.items():
        cct = np.array([r["central_thickness_um"] for r in series])
        reading = np.array([r["iop_reading_mmHg"] for r in series])
        slope = 10 * np.polyfit(cct, reading, 1)[0]
        rows += [{"sweep": f"thickness ({label})", **r, "slope_mmHg_per_10um": slope} for r in series]
    files.append(write_csv(out / "tonometry_sweep.csv", rows,
                           "tonometry: Goldmann reading vs central thickness and modulus (IOP 15 mmHg)"))
    files.append(_chart(out / "tonometry_sweep.png", thickness, moduli, moduli[0]["iop_mmHg"]))
    return files


STUDY = Study(name="tonometry-sweep",
              summary="Goldmann reading: mesh convergence, vs central thickness and modulus "
                      "(Ehlers et al. 1975)",
              run=run)
