r"""Does the optic flip? Haptic stiffness and lens–lens friction against the way the lens
lands in the capsule (issue 8, "Done when" 3).

Every case is a whole ``iol-injection`` on the coarse lens (``resolution=coarse``, 250
triangles) from one folded state (``iol-fold`` with the default lens, run once and reused:
the fold is the same for every case, so only the deployment differs). Varied:

- the haptics' thickness h_h (bending stiffness ∝ h_h³): 0.09, 0.13 (seed 000), 0.18 mm;
- the Coulomb coefficient μ of lens–lens contact: 0, 0.2 (default), 0.5.

``--quick`` does not answer the question (a whole coarse injection is ≈ 8 min here): it
checks the pipeline on two short deformation-only runs (``contact=false``: no injector, no
capsule, no self-contact) of the coarse lens released from an isometric roll of radius 2 mm,
thin vs thick haptics, and says so on the chart.

Recorded per case: ``optic_flipped`` (the optic's mean normal points down, z < 0, at the
end), the normal's z component, ``final_decentration_mm``, whether the optic unrolled,
the run's steps, Newton iterations per step, cuts and wall time. A case whose Newton
gives up is recorded as failed, with the time it reached — not dropped.
"""

from __future__ import annotations

import time
from pathlib import Path

from mpi4py import MPI

from eyemech.problems import iol_fold, iol_injection
from eyemech.problems.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, save_chart, write_csv

CASES = [{"haptic_thickness": h, "friction": 0.2} for h in (0.09, 0.13, 0.18)] + \
        [{"haptic_thickness": 0.13, "friction": mu} for mu in (0.0, 0.5)]
QUICK_CASES = [{"haptic_thickness": 0.09, "friction": 0.2}, {"haptic_thickness": 0.18, "friction": 0.2}]
QUICK_SETTINGS = {"contact": False, "settle_time": 0.0, "plunger_speed": 50.0}


def rolled_state(out: Path, comm) -> Path:
    """The quick variant's start: the flat coarse lens rolled isometrically about the
    injector axis to radius 2 mm (haptics included: 6.5 mm of arc < 2π · 2 mm, no overlap)."""
    from eyemech.problems.iol import LensShell, rolled, save_state

    path = out / "iol_flip_rolled_coarse.npz"
    params = iol_injection.Parameters(resolution="coarse")
    shell = LensShell(params, comm)
    X = shell.node_coordinates()
    shell.u.x.array[:] = (rolled(X, 0.5) - X).ravel()
    save_state(path, shell, comm)
    return path


def folded_state(out: Path, comm) -> Path:
    """The coarse lens folded once (reused when ``out`` already holds it)."""
    path = out / "iol_flip_folded_coarse.npz"
    if not path.is_file():
        work = out / "iol_flip_fold"
        iol_fold.run(iol_fold.Parameters(resolution="coarse"), comm=comm, out=work, options=QUIET)
        (work / "folded_state.npz").replace(path)
    return path


def run_case(case: dict, folded: Path, comm, settings: dict | None = None) -> dict:
    params = iol_injection.Parameters(resolution="coarse", folded_state=str(folded), **case, **(settings or {}))
    row = dict(case)
    start = time.perf_counter()
    try:
        q = iol_injection.run(params, comm=comm, options=QUIET).quantities
    except SolveFailure as err:
        row.update(finished=False, reached_time_s=err.last_converged,
                   wall_seconds=time.perf_counter() - start)
        return row
    row.update(finished=True, optic_flipped=q["optic_flipped"], optic_normal_z=q["optic_normal_z"],
               optic_unrolled=q["optic_unrolled"], final_decentration_mm=q["final_decentration_mm"],
               min_self_distance_mm=q["min_self_distance_mm"], max_penetration_mm=q["max_penetration_mm"],
               steps=q["steps"], newton_iterations_per_step=q["newton_iterations_per_step"],
               step_cuts=q["step_cuts"], wall_seconds=time.perf_counter() - start)
    return row


def run(out: Path, quick: bool = False, comm=MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if quick:
        start = rolled_state(out, comm)
        rows = [run_case(case, start, comm, QUICK_SETTINGS) for case in QUICK_CASES]
        note = ("QUICK (pipeline check, not the flip question): contact=false, lens released from a "
                "2 mm roll, no injector/capsule/self-contact")
    else:
        folded = folded_state(out, comm)
        rows = [run_case(case, folded, comm) for case in CASES]
        note = "iol-injection, resolution=coarse, one folded state; optic_flipped: mean optic normal z < 0"
    csv = write_csv(out / "iol_flip.csv", rows, note)
    return [csv, chart(rows, out / "iol_flip.png", note if quick else "")]


def chart(rows: list[dict], path: Path, note: str = "") -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for row in rows:
        label = f"h = {row['haptic_thickness']} mm, μ = {row['friction']}"
        if not row.get("finished"):
            ax.scatter(row["haptic_thickness"], row["friction"], marker="x", color="grey", s=80)
            ax.annotate(f"failed at t = {row.get('reached_time_s', float('nan')):.3g} s",
                        (row["haptic_thickness"], row["friction"]), textcoords="offset points", xytext=(6, 6),
                        fontsize=8)
            continue
        flipped = row["optic_flipped"]
        ax.scatter(row["haptic_thickness"], row["friction"], s=120, marker="v" if flipped else "^",
                   color="tab:red" if flipped else "tab:green", label=label)
        ax.annotate(f"n_z = {row['optic_normal_z']:.2f}, dec. {row['final_decentration_mm']:.2f} mm",
                    (row["haptic_thickness"], row["friction"]), textcoords="offset points", xytext=(6, 6),
                    fontsize=8)
    ax.set_xlabel("haptic thickness (mm)")
    ax.set_ylabel("lens–lens friction μ")
    ax.set_title("optic after deployment: ▲ right side up, ▼ flipped (coarse lens)"
                 + (f"\n{note}" if note else ""), fontsize=9 if note else 11)
    ax.margins(0.25)
    save_chart(fig, path)
    return path


STUDY = Study(name="iol-flip", summary="whether the optic lands flipped, against haptic thickness and "
                                       "lens–lens friction (whole coarse injections)", run=run)
