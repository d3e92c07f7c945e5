"""Accuracy against cost for every element family, and the cost of the two cavity
formulations.

- ``sphere-inflation`` (exact solution): relative L² displacement error and inner
  radius error against unknowns and against wall time, each family on a refinement
  sequence.
- ``cook-membrane`` (no closed form): tip displacement error against a reference
  extrapolated (Richardson) from the three finest Q2P1 meshes; the published value
  ≈ 6.9 mm is shown for comparison.
- ``liquid-sphere``: Jacobian nonzeros and seconds per Newton step, ``real`` against
  ``substituted``.
- The pressure of Q1P0 next to Q2P1 on Cook's membrane (pyvista).

Wall time = mesh + assembly + solve (form compilation excluded: it is cached by FFCx
and paid once per family, not per mesh).
"""

from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from eyemech.problems import cook_membrane, liquid_sphere, sphere_inflation
from eyemech.problems.run.context import RunOptions
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import save_chart, with_units, write_csv

FAMILIES = ("P2P1", "P2P0", "Q1P0", "Q2P1", "P1")
SPHERE_SIZES = {"P2P1": (2.0, 1.0, 0.7), "P2P0": (2.0, 1.0, 0.7), "Q1P0": (2.0, 1.0, 0.7, 0.5),
                "Q2P1": (2.0, 1.0, 0.7), "P1": (2.0, 1.0, 0.7, 0.5)}
COOK_SIDES = {"P2P1": (4, 8, 16), "P2P0": (4, 8, 16), "Q1P0": (4, 8, 16, 32),
              "Q2P1": (4, 8, 16, 32), "P1": (4, 8, 16, 32)}
CAVITY_CASES = (("P2P1", 2.0), ("P2P1", 1.5), ("P2P1", 1.0), ("Q2P1", 2.0), ("Q2P1", 1.5))
PUBLISHED_TIP = 6.9
QUIET = RunOptions(fields=False, pictures=False)


def _attempt(run, params, comm):
    """(the run's result, its failure's message): a failed Newton solve is a case that did
    not run, recorded as a row with ``status`` failed (the study then exits 4)."""
    try:
        return run(params, comm=comm, options=QUIET), ""
    except SolveFailure as failure:
        return None, str(failure)


def _failed(case: dict, why: str) -> dict:
    return {**case, "status": "failed", "error": why[:300]}


def _ok(rows: list[dict]) -> list[dict]:
    return [r for r in rows if r["status"] == "ok"]


def _wall_time(result) -> float:
    t = result.timings
    return t.get("mesh", 0.0) + t.get("assembly", 0.0) + t.get("solve", 0.0)


def sphere_rows(quick: bool, comm) -> list[dict]:
    rows = []
    for family in FAMILIES:
        for size in (SPHERE_SIZES[family][:1] if quick else SPHERE_SIZES[family]):
            result, why = _attempt(sphere_inflation.run, sphere_inflation.Parameters(
                element=family, mesh_size=size, pressure=0.02), comm)
            case = {"element": family, "mesh_size": size}
            if result is None:
                rows.append(_failed(case, why))
                continue
            q = result.quantities
            rows.append({**case, "status": "ok", "dofs": q["dofs"],
                         "displacement_error": q["displacement_error"],
                         "inner_radius_error": abs(q["inner_radius_error"]),
                         "wall_time_s": _wall_time(result)})
    return rows


def cook_rows(quick: bool, comm) -> tuple[list[dict], float]:
    rows = []
    for family in FAMILIES:
        for n in (COOK_SIDES[family][:1] if quick else COOK_SIDES[family]):
            result, why = _attempt(cook_membrane.run,
                                   cook_membrane.Parameters(element=family, elements_per_side=n), comm)
            case = {"element": family, "elements_per_side": n}
            if result is None:
                rows.append(_failed(case, why))
                continue
            rows.append({**case, "status": "ok", "dofs": result.quantities["dofs"],
                         "tip_displacement": result.quantities["tip_displacement"],
                         "wall_time_s": _wall_time(result)})
    reference = _richardson([r["tip_displacement"] for r in _ok(rows) if r["element"] == "Q2P1"])
    for row in _ok(rows):
        row["tip_error"] = abs(row["tip_displacement"] / reference - 1.0)
    return rows, reference


def _richardson(values: list[float]) -> float:
    """Limit of a sequence on meshes halved each time (three finest values); the
    published value when fewer are available."""
    if len(values) < 3:
        return PUBLISHED_TIP
    a, b, c = values[-3:]
    if (b - a) == 0 or (c - b) / (b - a) <= 0 or (c - b) / (b - a) >= 1:
        return c
    ratio = (c - b) / (b - a)
    return c + (c - b) * ratio / (1.0 - ratio)


def cavity_rows(quick: bool, comm) -> list[dict]:
    rows = []
    for family, size in (CAVITY_CASES[:1] if quick else CAVITY_CASES):
        for formulation in ("real", "substituted"):
            result, why = _attempt(liquid_sphere.run, liquid_sphere.Parameters(
                element=family, mesh_size=size, cavity_formulation=formulation), comm)
            case = {"element": family, "mesh_size": size, "formulation": formulation}
            if result is None:
                rows.append(_failed(case, why))
                continue
            q = result.quantities
            rows.append({**case, "status": "ok", "dofs": q["dofs"],
                         "jacobian_nonzeros": q["jacobian_nonzeros"],
                         "newton_iterations": q["newton_iterations"],
                         "seconds_per_newton_step": q["seconds_per_newton_step"],
                         "cavity_pressure_error": abs(q["cavity_pressure_error"])})
    return rows


def _chart(path: Path, rows: list[dict], error_key: str, title: str, ylabel: str,
           extra=None) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
    for family in FAMILIES:
        mine = [r for r in _ok(rows) if r["element"] == family and r[error_key] > 0]
        if not mine:
            continue
        for ax, x_key in zip(axes, ("dofs", "wall_time_s")):
            ax.loglog([r[x_key] for r in mine], [r[error_key] for r in mine], "o-", label=family)
    axes[0].set_xlabel("unknowns")
    axes[1].set_xlabel("wall time: mesh + assembly + solve (s)")
    for ax in axes:
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
    if extra is not None:
        extra(axes[0])
    axes[0].legend()
    fig.suptitle(title)
    save_chart(fig, path, dpi=110, rect=(0, 0.03, 1, 1))
    return path


def _slopes(ax) -> None:
    """Guide lines for error ∝ h^k = N^(-k/3)."""
    import numpy as np

    n = np.array([3e2, 3e4])
    for k, style in ((1, ":"), (2, "--"), (3, "-.")):
        ax.loglog(n, 0.3 * (n / n[0]) ** (-k / 3.0), "k" + style, lw=0.8, label=f"h^{k}")


def _cavity_chart(path: Path, rows: list[dict]) -> Path:
    """Jacobian nonzeros and seconds per Newton step, Real-space pressure against the
    substituted one, per case (the chart of cavity_formulations.csv)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.0))
    for formulation, marker in (("real", "o-"), ("substituted", "s--")):
        mine = [r for r in _ok(rows) if r["formulation"] == formulation]
        for ax, key in zip(axes, ("jacobian_nonzeros", "seconds_per_newton_step")):
            for family in dict.fromkeys(r["element"] for r in mine):
                fam = [r for r in mine if r["element"] == family]
                ax.loglog([r["dofs"] for r in fam], [r[key] for r in fam], marker,
                          label=f"{family}, {formulation}")
    axes[0].set(xlabel="unknowns", ylabel="Jacobian nonzeros")
    axes[1].set(xlabel="unknowns", ylabel="seconds per Newton step")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("liquid-sphere: one Real pressure unknown against the substituted P(u)")
    save_chart(fig, path, dpi=100, rect=(0, 0.03, 1, 1))
    return path


def pressure_pictures(out: Path, comm, n: int) -> Path | None:
    """Q1P0 next to Q2P1 on the same n×n Cook mesh: the panel, and the clamped top
    corner where the pressure gradient is steepest (Q1P0's checkerboard shows there)."""
    import shutil

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folders = {}
    for family in ("Q1P0", "Q2P1"):
        folders[family] = out / f"_cook_{family}"
        cook_membrane.run(cook_membrane.Parameters(element=family, elements_per_side=n), comm=comm,
                          out=folders[family], options=RunOptions(fields=False, pictures=True))
    if comm.rank != 0:
        return None
    fig, axes = plt.subplots(2, 2, figsize=(12, 10))
    for column, family in enumerate(("Q1P0", "Q2P1")):
        for row, name in enumerate(("pressure.png", "pressure_corner.png")):
            axes[row, column].imshow(plt.imread(folders[family] / name))
            axes[row, column].set_axis_off()
        axes[0, column].set_title(family)
    target = out / "cook_pressure_Q1P0_vs_Q2P1.png"
    save_chart(fig, target, dpi=80, rect=(0, 0, 1, 1))
    for folder in folders.values():
        shutil.rmtree(folder)
    return target


def run(out: Path, quick: bool = False, comm=None) -> list[Path]:
    comm = comm or MPI.COMM_WORLD
    out = Path(out)
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    comm.Barrier()
    sphere = sphere_rows(quick, comm)
    cook, reference = cook_rows(quick, comm)
    cavity = cavity_rows(quick, comm)
    picture = pressure_pictures(out, comm, 4 if quick else 32)
    if comm.rank != 0:
        return []
    files = [
        write_csv(out / "sphere_inflation_convergence.csv",
                  with_units(sphere, sphere_inflation.Parameters),
                   "sphere-inflation, p = 0.02 MPa: errors against the exact solution"),
        _chart(out / "sphere_inflation_convergence.png", sphere, "displacement_error",
               "sphere-inflation (exact solution): relative L² displacement error",
               "‖u − u_exact‖ / ‖u_exact‖", extra=_slopes),
        write_csv(out / "cook_membrane_convergence.csv", with_units(cook, cook_membrane.Parameters),
                   f"cook-membrane: tip error against {reference:.5f} mm (Richardson, Q2P1); "
                   f"published ≈ {PUBLISHED_TIP} mm"),
        _chart(out / "cook_membrane_convergence.png", cook, "tip_error",
               f"cook-membrane: tip displacement error (reference {reference:.4f} mm, "
               f"published ≈ {PUBLISHED_TIP})", "|u_tip / u_ref − 1|"),
        write_csv(out / "cavity_formulations.csv", with_units(cavity, liquid_sphere.Parameters),
                   "liquid-sphere: Real-space pressure against the substituted formulation"),
        _cavity_chart(out / "cavity_formulations.png", cavity),
    ]
    if picture is not None:
        files.append(picture)
    return files


STUDY = Study(name="hyperelastic-convergence",
              summary="error vs unknowns and wall time for every element family; cavity formulations",
              run=run)
