"""Radial keratotomy (issue 6, item 5): how converged ``power_change_D`` is, which
parameters drive its magnitude against Salz et al. (1985), and what creep adds at each
optical zone.

1. Convergence: 8 incisions, 3 mm zone, 90 % depth, 15 mmHg, one 1 h creep step, on
   refining meshes (radial size, azimuthal divisions, trilinear vs 27-node cells), with
   cells, dofs and wall time (shared 2-cpu machine: noisy).
2. Magnitude: the same case on ``SWEEP_MESH`` with one parameter changed at a time —
   moduli ×½ and ×2 (μ∞ and μv together), IOP 10 and 20 mmHg, depth 70 and 80 %, the
   elastic limbus — against Salz's 9.06 D.
3. Creep by optical zone: intact and incised power at t = 0 and after 4 h for zones
   3 / 4 / 5 mm: the creep change of ``power_change_D`` is the difference of two
   steepenings (intact and incised), which is why it can vanish.

Quick: one coarse run (a glassy step and one creep step), no (2) or (3).
"""

from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from eyemech.problems import keratotomy
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, failed_row, mark_failed, save_chart, write_csv

SALZ_3MM = 9.06  # D, 8 incisions, 3 mm zone (Salz et al. 1985)
BASE = dict(incisions=8, optical_zone=3.0, incision_depth=0.9, t_end=3600.0, first_dt=3600.0)
CONVERGENCE = [
    ("2.0 mm, 16 around", dict(mesh_size=2.0, azimuthal_divisions=16)),
    ("1.0 mm, 24 around", dict(mesh_size=1.0, azimuthal_divisions=24)),
    ("0.7 mm, 32 around", dict(mesh_size=0.7, azimuthal_divisions=32)),
    ("1.0 mm, 24 around, 27-node", dict(mesh_size=1.0, azimuthal_divisions=24, geometry_degree=2)),
]
SWEEP_MESH = dict(mesh_size=1.5, azimuthal_divisions=16)
CREEP_MESH = dict(mesh_size=1.0, azimuthal_divisions=24)  # the Salz study's
MU = keratotomy.Parameters().mu_inf, keratotomy.Parameters().mu_v
MAGNITUDE = [
    ("baseline", {}),
    ("moduli × 0.5", dict(mu_inf=MU[0] / 2, mu_v=MU[1] / 2)),
    ("moduli × 2", dict(mu_inf=MU[0] * 2, mu_v=MU[1] * 2)),
    ("IOP 10 mmHg", dict(iop_mmHg=10.0)),
    ("IOP 20 mmHg", dict(iop_mmHg=20.0)),
    ("depth 70 %", dict(incision_depth=0.7, layers=3)),
    ("depth 80 %", dict(incision_depth=0.8, layers=3)),
    ("elastic limbus", dict(support="elastic")),
]


def _case(label: str, comm, **changes) -> dict:
    """The case's row: its label and mesh, then status ok and its quantities, or status
    failed (``eyemech study`` exits 4) with the solver's message."""
    # the time grid fixed: the cases differ in mesh and geometry (docs/studies/keratotomy_magnitude.csv)
    params = keratotomy.Parameters(**{**BASE, **changes, "time_stepping": "fixed"})
    row = {"case": label, "mesh_size_mm": params.mesh_size, "azimuthal_divisions": params.azimuthal_divisions,
           "geometry_degree": params.geometry_degree, "optical_zone_mm": params.optical_zone}
    try:
        result = keratotomy.run(params, comm=comm, options=QUIET)
    except SolveFailure as failure:
        return failed_row(row, failure)
    q = result.quantities
    return row | {
        "status": "ok", "cells": q["cells"], "hours": q["times"][-1] / 3600,
        "flattening_t0_D": -q["power_change_initial_D"], "flattening_end_D": -q["power_change_final_D"],
        "creep_D": -q["creep_power_change_D"],
        "intact_power_t0_D": q["intact_power_D"][0], "intact_power_end_D": q["intact_power_D"][-1],
        "incised_power_t0_D": q["power_D"][0], "incised_power_end_D": q["power_D"][-1],
        "apex_displacement_t0_mm": q["apex_displacement_mm"][0],
        "wound_gape_t0_mm": q["wound_gape_mm"][0], "wound_gape_end_mm": q["wound_gape_mm"][-1],
        "newton_iterations": sum(s.get("newton_iterations", 0) for s in result.steps),
        "wall_time_s": result.timings["total"]}


def _chart(path: Path, convergence: list[dict], magnitude: list[dict], creep: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    failed = [r["case"] for r in convergence if r["status"] != "ok"]
    convergence = [r for r in convergence if r["status"] == "ok"]
    creep_failed = [r["optical_zone_mm"] for r in creep if r["status"] != "ok"]
    creep = [r for r in creep if r["status"] == "ok"]
    panels = 3 if creep or creep_failed else 2
    fig, axes = plt.subplots(1, panels, figsize=(4.6 * panels, 4))
    ax = axes[0]
    for degree, marker in ((1, "o-"), (2, "s-")):
        rows = [r for r in convergence if r["geometry_degree"] == degree]
        if rows:
            ax.plot([r["cells"] for r in rows], [r["flattening_t0_D"] for r in rows], marker,
                    label=f"t = 0, geometry degree {degree}")
            ax.plot([r["cells"] for r in rows], [r["flattening_end_D"] for r in rows], marker, alpha=0.5,
                    label=f"t = 1 h, degree {degree}")
    ax.axhline(SALZ_3MM, color="k", ls="--", label="Salz et al. 1985")
    ax.set_xscale("log")
    ax.set_xlabel("cells")
    ax.set_ylabel("flattening (D)")
    ax.set_title("8 incisions, OZ 3 mm: mesh convergence", fontsize=9)
    if failed:  # a failed case has no cells to be placed at: named
        ax.text(0.02, 0.02, "✗ solve failed: " + "; ".join(failed), transform=ax.transAxes,
                fontsize=7, color="tab:red")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    ax = axes[1]
    labels = [r["case"] for r in magnitude]
    if magnitude:
        ax.barh(labels, [r["flattening_t0_D"] if r["status"] == "ok" else 0.0 for r in magnitude],
                color="C0", label="t = 0")
        for label, r in zip(labels, magnitude):
            if r["status"] != "ok":  # a failed case: a cross on its bar's line
                ax.plot([0.0], [label], "x", color="tab:red", ms=10, mew=2, clip_on=False)
                ax.annotate(" solve failed", (0.0, label), color="tab:red", fontsize=7, va="center")
    ax.axvline(SALZ_3MM, color="k", ls="--", label="Salz et al. 1985")
    ax.set_xlabel("flattening (D)")
    ax.set_title("what drives the magnitude (one change at a time)", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, axis="x")
    if panels == 3:
        ax = axes[2]
        zones = [r["optical_zone_mm"] for r in creep]
        ax.plot(zones, [r["intact_power_end_D"] - r["intact_power_t0_D"] for r in creep], "o-",
                label="intact: creep steepening")
        ax.plot(zones, [r["incised_power_end_D"] - r["incised_power_t0_D"] for r in creep], "s-",
                label="incised: creep steepening")
        ax.plot(zones, [-r["creep_D"] for r in creep], "k^-", label="difference = creep of power change")
        mark_failed(ax, creep_failed, "solve failed")
        ax.axhline(0, color="grey", lw=0.8)
        ax.set_xlabel("optical zone (mm)")
        ax.set_ylabel(f"power change over {creep[0]['hours']:g} h (D)" if creep else "power change (D)")
        ax.set_title("creep: two steepenings that nearly cancel", fontsize=9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    save_chart(fig, path, dpi=80)
    return path


def run(out: Path, quick: bool = False, comm=None) -> list[Path]:
    comm = comm or MPI.COMM_WORLD
    out = Path(out)
    if quick:
        coarse = dict(mesh_size=2.0, azimuthal_divisions=8, t_end=1800.0, first_dt=1800.0)
        convergence = [_case("2.0 mm, 8 around", comm, **coarse)]
        magnitude: list[dict] = []
        creep: list[dict] = []
    else:  # the CSV is rewritten after each part: a partial study keeps what it measured
        convergence = [_case(label, comm, **changes) for label, changes in CONVERGENCE]
        _write(out, comm, convergence, [], [], partial=True)
        magnitude = [_case(label, comm, **{**SWEEP_MESH, **changes}) for label, changes in MAGNITUDE]
        _write(out, comm, convergence, magnitude, [], partial=True)
        creep = [_case(f"OZ {zone:g} mm, 4 h", comm, optical_zone=zone, t_end=4 * 3600.0,
                          first_dt=1800.0, dt_growth=2.0, **CREEP_MESH)
                 for zone in (3.0, 4.0, 5.0)]
    return _write(out, comm, convergence, magnitude, creep)


def _write(out: Path, comm, convergence: list[dict], magnitude: list[dict], creep: list[dict],
           partial: bool = False) -> list[Path]:
    """The table and the chart of the parts measured so far (``partial``: the study goes on
    and writes them again; its cases are counted in the last, whole table)."""
    if comm.rank != 0:
        return []
    rows = ([{"part": "convergence", **r} for r in convergence]
            + [{"part": "magnitude", **r} for r in magnitude]
            + [{"part": "creep", **r} for r in creep])
    csv = write_csv(out / "keratotomy_magnitude.csv", rows,
                    "keratotomy: flattening (= -power_change_D) of 8 incisions, 90 % depth, 15 mmHg; "
                    "Salz et al. 1985: 9.06 D at OZ 3 mm", partial=partial)
    return [csv, _chart(out / "keratotomy_magnitude.png", convergence, magnitude, creep)]


STUDY = Study(name="keratotomy-magnitude",
              summary="keratotomy: mesh convergence of the power change, what drives its "
                      "magnitude (Salz et al. 1985), creep by optical zone",
              run=run)
