"""Two ways incompressible elements fail, on ``cook-membrane`` (issue 9, stability map).

- **Volumetric locking** (``P1``, displacement only, bulk energy K/4 (J² − 1 − 2 ln J)):
  tip displacement against K/μ on refined meshes, next to the converged incompressible
  value (Q2P1, Richardson-extrapolated in docs/studies/cook_membrane_convergence.csv).
  A locking element gets stiffer as K/μ grows and refinement cures it only slowly; the
  chart marks where the error passes 10 %.
- **Pressure checkerboard** (``Q1P0``): the cell pressures of the exactly incompressible
  panel. Each cell's pressure minus the mean of its in-plane neighbours (a discrete
  high-pass) is zero for a smooth field and ±2·amplitude for a checkerboard; its RMS over
  the RMS pressure is charted against mesh size for Q1P0 and Q2P1 (Q2P1's pressure taken
  at the cell centres), with the "alternation": minus the correlation of that high-pass
  between neighbouring cells (1 for a perfect checkerboard, ≤ 0 for smooth fields); and
  the pressures of the cells along the clamped edge, where the gradient is steepest.

Every case is a row with a ``status``. P1's cases that stop converging at large K/μ are the
locking finding: their status names it ("Newton failed (load factor … reached)"), not a
lost case. A checkerboard case (Q1P0, Q2P1) whose solve fails is a lost case: a row with
status failed and the message as ``error``, crossed on the chart, and ``eyemech study``
exits 4.
"""

from __future__ import annotations

from pathlib import Path

import dolfinx
import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms import NeoHooke
from eyemech.meshes.cook import cook_membrane as cook_mesh
from eyemech.problems import cook_membrane
from eyemech.problems.solid.residual import solid_residual
from eyemech.problems.solid.spaces import ELEMENTS, solid_fields
from eyemech.problems.solve.driver import (
    NonlinearSolver,
    SolveFailure,
    Stepping,
    follow_path,
)
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, failed_row, mark_failed, save_chart, write_csv

COOK_REFERENCE_TIP = 6.93287  # mm, Q2P1 Richardson limit (docs/studies/cook_membrane_convergence.csv)
BULK_RATIOS = (1.0, 10.0, 100.0, 1e3, 1e4, 1e5)
LOCKING_SIDES = (8, 16, 32)
CHECKER_SIDES = (4, 8, 16, 32)
QUICK = dict(ratios=(1.0, 100.0, 1e4), locking_sides=(4,), checker_sides=(4, 8))


def locking_rows(ratios, sides, comm) -> list[dict]:
    mu = cook_membrane.Parameters().shear_modulus
    rows = []
    for n in sides:
        for ratio in ratios:
            params = cook_membrane.Parameters(element="P1", elements_per_side=n,
                                              bulk_modulus=ratio * mu)
            try:
                result = cook_membrane.run(params, comm=comm, options=QUIET)
            except SolveFailure as failure:  # where P1 stops converging: a finding, not a lost case
                rows.append({"elements_per_side": n, "bulk_over_shear": ratio,
                             "status": f"Newton failed (load factor {failure.last_converged:.3g} reached)"})
                continue
            tip = result.quantities["tip_displacement"]
            rows.append({"elements_per_side": n, "bulk_over_shear": ratio, "status": "ok",
                         "dofs": result.quantities["dofs"], "tip_displacement": tip,
                         "tip_over_incompressible": tip / COOK_REFERENCE_TIP,
                         "wall_time_s": result.timings["assembly"] + result.timings["solve"]})
    return rows


def cook_pressures(element: str, n: int, comm) -> tuple[np.ndarray, np.ndarray, list]:
    """Solve Cook's membrane (as the scene does) and return, per cell, the pressure at
    the cell centre, the centre's reference (x, y), and the in-plane neighbour cells."""
    params = cook_membrane.Parameters(element=element, elements_per_side=n)
    family = ELEMENTS[element]
    panel = cook_mesh(n, family.hexahedral, family.geometry_order, comm=comm)
    fields, tests = solid_fields(panel.mesh, family)
    metadata = {"quadrature_degree": family.quadrature_degree}
    traction = dolfinx.fem.Constant(panel.mesh, np.zeros(3))
    residual = (solid_residual(NeoHooke(0.5 * params.shear_modulus), family, fields, tests,
                               panel.dx(metadata))
                - ufl.dot(traction, tests[0]) * panel.ds(metadata)(panel.tag("loaded")))
    solver = NonlinearSolver(list(ufl.extract_blocks(residual)), fields,
                             cook_membrane._boundary_conditions(fields[0].function_space, panel))
    follow_path(solver, lambda load, _: setattr(traction, "value",
                                                np.array([0.0, load * params.load / 16.0, 0.0])),
                Stepping(initial_step=1.0 / params.load_steps), quiet=True)
    mesh = panel.mesh
    DG0 = dolfinx.fem.functionspace(mesh, ("DG", 0))
    centre = dolfinx.fem.Function(DG0)
    centre.interpolate(dolfinx.fem.Expression(fields[1], DG0.element.interpolation_points))
    tdim = mesh.topology.dim
    cells = mesh.topology.index_map(tdim).size_local
    pressure = centre.x.array[:cells]
    midpoints = dolfinx.mesh.compute_midpoints(mesh, tdim, np.arange(cells, dtype=np.int32))[:, :2]
    mesh.topology.create_connectivity(tdim, tdim - 1)
    mesh.topology.create_connectivity(tdim - 1, tdim)
    to_facets, to_cells = mesh.topology.connectivity(tdim, tdim - 1), \
        mesh.topology.connectivity(tdim - 1, tdim)
    neighbours = [[c for f in to_facets.links(cell) for c in to_cells.links(f) if c != cell]
                  for cell in range(cells)]
    return pressure, midpoints, neighbours


def checker_rows(sides, comm) -> tuple[list[dict], dict]:
    rows, edge_profiles = [], {}
    for element in ("Q1P0", "Q2P1"):
        for n in sides:
            case = {"element": element, "elements_per_side": n}
            try:
                pressure, midpoints, neighbours = cook_pressures(element, n, comm)
            except SolveFailure as failure:  # a case that did not run: a row that says so (exit 4)
                rows.append(failed_row(case, failure))
                continue
            high_pass = pressure - np.array([pressure[nb].mean() for nb in neighbours])
            # a checkerboard's high-pass flips sign from each cell to its neighbours
            pairs = sum(float(high_pass[c] * high_pass[nb].sum()) for c, nb in enumerate(neighbours))
            degree = sum(len(nb) * high_pass[c] ** 2 for c, nb in enumerate(neighbours))
            rows.append({**case, "status": "ok",
                         "checkerboard_index": float(np.sqrt(np.mean(high_pass**2))
                                                     / np.sqrt(np.mean(pressure**2))),
                         "alternation": -pairs / degree,
                         "pressure_min_MPa": float(pressure.min()),
                         "pressure_max_MPa": float(pressure.max())})
            if n == sides[-1]:
                column = midpoints[:, 0] < 48.0 / n  # the cells touching the clamped edge
                order = np.argsort(midpoints[column, 1])
                edge_profiles[element] = (midpoints[column, 1][order], pressure[column][order])
    return rows, edge_profiles


def run(out: Path, quick: bool = False, comm: MPI.Comm | None = None) -> list[Path]:
    comm = comm or MPI.COMM_WORLD
    out = Path(out)
    if comm.rank != 0:  # serial study: rank 0 does the work (cell neighbours need the whole mesh)
        return []
    self_comm = MPI.COMM_SELF
    ratios = QUICK["ratios"] if quick else BULK_RATIOS
    locking = locking_rows(ratios, QUICK["locking_sides"] if quick else LOCKING_SIDES, self_comm)
    sides = QUICK["checker_sides"] if quick else CHECKER_SIDES
    checker, profiles = checker_rows(sides, self_comm)
    files = [write_csv(out / "volumetric_locking.csv", locking,
                       f"cook-membrane P1 (bulk energy K/4 (J^2-1-2 ln J)), tip vs K/mu; "
                       f"incompressible reference {COOK_REFERENCE_TIP} mm (Q2P1, Richardson)"),
             write_csv(out / "pressure_checkerboard.csv", checker,
                       "cook-membrane, exactly incompressible: RMS(p - mean of in-plane "
                       "neighbours) / RMS(p), cell-centre pressures")]
    files.append(_chart(out / "locking_checkerboard.png", locking, checker, profiles, sides[-1]))
    return files


def _chart(path: Path, locking, checker, profiles, n_profile: int) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.3))
    ax = axes[0]
    for n in dict.fromkeys(r["elements_per_side"] for r in locking):
        ok = [r for r in locking if r["elements_per_side"] == n and r["status"] == "ok"]
        ax.semilogx([r["bulk_over_shear"] for r in ok], [r["tip_over_incompressible"] for r in ok],
                    "o-", label=f"P1, {n}×{n}")
        failed = [r for r in locking if r["elements_per_side"] == n and r["status"] != "ok"]
        ax.semilogx([r["bulk_over_shear"] for r in failed], [0.04] * len(failed), "rv", ms=9)
        locked = [r for r in ok if r["tip_over_incompressible"] < 0.9]
        if locked:
            first = locked[0]
            ax.plot(first["bulk_over_shear"], first["tip_over_incompressible"], "kx", ms=11, mew=2)
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="incompressible, converged")
    ax.axhline(0.9, color="grey", lw=0.8, ls=":", label="−10 % (×: first locked case)")
    ax.plot([], [], "rv", label="Newton failed (cut-back exhausted)")
    ax.axvline(5000, color="tab:red", lw=0.8, ls=":")
    ax.text(5000, 0.05, " K/μ of the references", fontsize=7, color="tab:red", rotation=90)
    ax.set(xlabel="K / μ", ylabel="tip displacement / incompressible limit", ylim=(0, 1.3),
           title="volumetric locking of P1")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    ax = axes[1]
    for k, element in enumerate(("Q1P0", "Q2P1")):
        mine = [r for r in checker if r["element"] == element and r["status"] == "ok"]
        n = [r["elements_per_side"] for r in mine]
        ax.semilogx(n, [r["checkerboard_index"] for r in mine], "o-", color=f"C{k}",
                    label=f"{element}: RMS(p − neighbour mean) / RMS(p)")
        ax.semilogx(n, [r["alternation"] for r in mine], "s--", color=f"C{k}",
                    label=f"{element}: sign alternation of that high-pass")
    ax.set_xscale("log")
    mark_failed(ax, [r["elements_per_side"] for r in checker if r["status"] != "ok"],
                "checkerboard case failed (solve)")
    ax.axhline(0, color="k", lw=0.6)
    ax.set(xlabel="elements per side", ylabel="index (0 = smooth, alternation 1 = checkerboard)",
           title="pressure checkerboard")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    ax = axes[2]
    for element, style in (("Q1P0", "s-"), ("Q2P1", "o-")):
        if element in profiles:
            y, p = profiles[element]
            ax.plot(y, p, style, ms=3, label=element)
    ax.set(xlabel="y along the clamped edge (mm)", ylabel="cell-centre pressure (MPa)",
           title=f"pressures of the cells on the clamped edge, {n_profile}×{n_profile}")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    for ax in axes:
        ax.title.set_fontsize(9)
    fig.suptitle("cook-membrane: where incompressible elements fail", fontsize=10)
    save_chart(fig, path, dpi=100, rect=(0, 0.03, 1, 1))
    return path


STUDY = Study(name="locking-checkerboard",
              summary="cook-membrane: P1 volumetric locking vs K/μ and the Q1P0 pressure "
                      "checkerboard vs Q2P1",
              run=run)
