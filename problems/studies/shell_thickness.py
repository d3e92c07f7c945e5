"""Membrane locking test: the linear pinched hemisphere (``hemisphere``, crossed
triangles) on one fixed mesh, P2 and P3, while the thickness goes from R/h = 25 to
2500 (h = 0.4 … 0.004; the benchmark is R/h = 250).

The hemisphere's pinching is bending dominated (an almost inextensional mode): the
displacement under the load behaves like c F R²/(E h³) with c tending to a constant
as h → 0. We load with F ∝ h³ (F = 2 at the benchmark's h = 0.04) and plot the scaled
displacement c = u E h³/(F R²) at the outward load point. A locking-free
discretisation gives a curve that levels off as h shrinks; a locking one gives a
scaled displacement that falls towards zero on a fixed mesh as R/h grows (the
membrane energy, ∝ h, cannot vanish on the discrete space and takes over from the
bending energy ∝ h³). The first slenderness (R/h = 25) is a thick shell where the
Kirchhoff–Love model itself is at its limit; the interesting end is the thin one.
"""

from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from eyemech.problems import hemisphere
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import (
    QUIET,
    failed_row,
    mark_failed,
    save_chart,
    with_units,
    write_csv,
)

SLENDERNESS = (25, 50, 100, 250, 500, 1000, 2500)  # R / h
# (degree, divisions): P2 and P3 on the fixed mesh of 16 divisions (80 around), and P2
# on 24 divisions, which has as many unknowns as P3 on 16 (69 840): is the drop locking
# (it recedes under refinement) and does P3 beat P2 at equal cost?
CASES = ((2, 16), (3, 16), (2, 24))
QUICK_CASES = ((2, 4), (3, 4))


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    if comm.rank != 0:  # serial study: rank 0 does the work
        return []
    base = hemisphere.Parameters()
    R, E = base.radius, base.youngs_modulus
    slenderness = (SLENDERNESS[0], SLENDERNESS[-1]) if quick else SLENDERNESS
    rows = []
    for degree, divisions in QUICK_CASES if quick else CASES:
        for ratio in slenderness:
            h = R / ratio
            force = base.force * (h / base.thickness) ** 3
            params = hemisphere.Parameters(divisions=divisions, degree=degree, thickness=h, force=force)
            case = dict(degree=degree, divisions=divisions, slenderness=ratio, thickness=h, force=force)
            try:
                result = hemisphere.run(params, comm=MPI.COMM_SELF, options=QUIET)
            except SolveFailure as failure:  # a case that did not run: a row that says so (exit 4)
                rows.append(failed_row(case, failure))
                continue
            u = result.quantities["radial_displacement_x"]
            rows.append(case | dict(status="ok", dofs=result.quantities["dofs"], radial_displacement_x=u,
                                    scaled_displacement=u * E * h ** 3 / (force * R ** 2),
                                    assembly_solve_seconds=result.timings["assembly"]
                                    + result.timings["solve"]))
    csv_path = write_csv(out / "shell_thickness.csv", with_units(rows, hemisphere.Parameters),
                         "linear pinched hemisphere R 10, 18 deg hole, E 6.825e7, nu 0.3, crossed; "
                         "F = 2 (h/0.04)^3; scaled = u E h^3 / (F R^2)",
                         "benchmark (R/h 250): u = 0.093 for F = 2, i.e. scaled 2.03")
    return [csv_path, _chart(out, rows)]


def _chart(out: Path, rows: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    base = hemisphere.Parameters()
    reference = (hemisphere.REFERENCE * base.youngs_modulus * base.thickness ** 3
                 / (base.force * base.radius ** 2))
    fig, axis = plt.subplots(figsize=(6.2, 4.4))
    ok = [r for r in rows if r["status"] == "ok"]
    for case in dict.fromkeys((r["degree"], r["divisions"]) for r in ok):
        mine = [r for r in ok if (r["degree"], r["divisions"]) == case]
        axis.semilogx([r["slenderness"] for r in mine], [r["scaled_displacement"] for r in mine],
                      "s--" if case == (2, 24) else "o-",
                      label=f"P{case[0]}, {case[1]} div. ({mine[0]['dofs']} dofs)")
    axis.set_xscale("log")
    mark_failed(axis, [r["slenderness"] for r in rows if r["status"] != "ok"], "solve failed")
    axis.plot([250], [reference], "k*", ms=10, label="reference 0.093 at R/h = 250")
    axis.set_ylim(bottom=0)
    axis.set(xlabel="R / h (fixed mesh)", ylabel="u E h³ / (F R²)  (outward load point)",
             title="pinched hemisphere, thickness sweep: membrane locking")
    axis.grid(alpha=0.3)
    axis.legend(fontsize=8)
    path = out / "shell_thickness.png"
    save_chart(fig, path, dpi=110)
    return path


STUDY = Study(name="shell-thickness", summary="pinched hemisphere on one fixed mesh, R/h = 25…2500, "
                                              "P2 and P3: membrane locking of the faceted shell", run=run)
