r"""Does the optic flip? Haptic stiffness and lens–lens friction against the way the lens
lands in the capsule (issue 8, "Done when" 3).

Every case is a whole ``iol-injection`` on the coarse lens (``resolution=coarse``, 250
triangles) from one folded state — the default coarse lens folded by ``iol-fold``, taken
from the fold cache of ``iol-injection`` (folded once and stored there when missing): the
fold is the same for every case, so only the deployment differs. Varied, one at a time:

- the Coulomb coefficient μ of lens–lens contact (haptic–optic adhesion): 0, 0.2, 0.5, 1,
  h_h = 0.13 mm;
- the haptics' thickness h_h (their bending stiffness ∝ h_h³; the lens has one Young's
  modulus, so thickness is the model's haptic stiffness): 0.13, 0.25, 0.35, 0.45 mm (the
  haptic's width), μ = 0.2;
- the same at a 10× thinner fluid (damping c = 2e3 /s instead of 2e4 /s) for 0.35 mm
  (0.13 mm there is the next case to add): the capsule's torque turns the optic by
  ∫T dt / (c I), so the fluid sets how much the haptics' stiffness can matter (see
  ``angular_balance``);
- friction on the walls, the external moments the frictionless model lacks: Coulomb μ = 1 of
  the lens on the capsular bag (the leading haptic may stick there while the plunger pushes
  the optic on) for thin and thick haptics, and μ = 0.3 in the cartridge (an uncoated bore
  twists the rolled lens about the injector axis) — ``capsule_friction`` /
  ``cartridge_friction`` of ``iol-injection`` (lagged smoothed Coulomb, problems/contact/rigid_wall.py);
- the surgeon's twist of the injector while pushing (``injector_twist`` 180° or 360°, in step
  with the plunger): the round bore drags the rolled lens round through its friction only, so
  it is run at μ_cartridge = 0, 0.3 and 1, and 360° at 0 and 0.3; thin against thick (0.35 mm)
  haptics at 180°, 0.3 (both with a wider friction regularisation, ``SLIP``). The plunger
  starts over 20 ms in these cases. They get their own chart, ``iol_flip_walls.png``.

What decides the side it lands on: the optic lands upside down only if it turns by more than
90° as a rigid body — about the injector axis while it is still rolled (it fits the capsule's
4.5 mm height only while rolled: flat it is 6 mm wide), since unrolling an isometric roll
keeps the normal of its middle line. So besides the flip itself (mean optic normal z < 0 at
the end) every case records the **roll angle** φ of the optic about the injector axis over
time, from the normal of the optic's middle strip (|y| < 0.6 mm in the flat lens) in the
``.vtu`` frames (every ``frames_every`` steps): max |φ| is the margin to a flip (90°).

Runs are kept in ``$EYEMECH_IOL_FLIP_RUNS`` (default ``results/iol-flip-runs``), one folder per
case; a folder whose ``results.json`` holds the same parameters is read, not rerun — a case
costs ≈ 8 min here. A case whose Newton gives up is recorded as failed, with the time it
reached — not dropped. Every row has a ``status``: ``ok`` for a finished case, ``failed``
for one whose Newton gave up, ``stopped`` for one stopped by hand for lack of time (kept,
not rerun); ``stopped`` names which (``Newton failed`` / ``by hand (time budget)``). Neither
gave the case's result, so ``eyemech study`` counts both as failed and exits 4.

``--quick`` does not answer the question: it checks the pipeline on two short
deformation-only runs (``contact=false``: no injector, no capsule, no self-contact) of the
coarse lens released from an isometric roll of radius 2 mm, thin vs thick haptics, and says
so on the chart.
"""

from __future__ import annotations

import json
import os
import re
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from eyemech.problems import iol_fold, iol_injection
from eyemech.problems.run.context import RunOptions
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import save_chart, with_units, write_csv

BASE = {"haptic_thickness": 0.13, "friction": 0.2}
FRICTIONS = (0.0, 0.2, 0.5, 1.0)
# 0.45 mm = the haptic's width: a thicker strip is no longer a plate bent through its thickness
THICKNESSES = (0.13, 0.25, 0.35, 0.45)
DEFAULT_DAMPING = 2.0e4  # 1/s: the scene's fluid (≈ 10 Pa·s over 2 mm)
THIN_FLUID = 2.0e3  # 1/s: ≈ 1 Pa·s, a thinned viscoelastic (the capsule's turning effect ∝ 1/c)
THIN_FLUID_THICKNESSES = (0.13, 0.35)  # does stiffness matter where the fluid lets the optic turn?
# external moments: friction on the capsular bag (the leading haptic may stick there while the
# plunger pushes on) and in the cartridge (an uncoated bore twists the rolled lens), thin and
# thick haptics
WALL_FRICTION_CASES = [{**BASE, "capsule_friction": 1.0},
                       {**BASE, "haptic_thickness": 0.35, "capsule_friction": 1.0},
                       {**BASE, "cartridge_friction": 0.3}]
# the surgeon's twist of the injector (turned in step with the plunger): the round bore can
# only drag the lens round by friction (μ_cartridge = 0: the twist does nothing). The plunger
# starts over 20 ms: from a jump to full speed with the bore's friction Newton gave up within
# the first 6 ms (μ_cartridge 0.3 at 360°, 1 at 180°)
TWISTED = {**BASE, "start_ramp": 0.02}
TWIST_CASES = [{**TWISTED, "cartridge_friction": mu, "injector_twist": 180.0} for mu in (0.0, 0.3, 1.0)] + \
              [{**TWISTED, "cartridge_friction": mu, "injector_twist": 360.0} for mu in (0.0, 0.3)]
# thick against thin haptics under the same twist: at 0.35 mm and the default friction_slip
# (1 µm per step) Newton cycled in the stick–slip of the bore at t = 4.8 ms (residual 1e-4 →
# 1e-2 and back, 25 iterations), so both run with 3 µm, the 0.13 mm case as the control
SLIP = 3e-3
TWIST_CASES += [{**TWISTED, "haptic_thickness": h, "cartridge_friction": 0.3, "injector_twist": 180.0,
                 "friction_slip": SLIP} for h in (0.13, 0.35)]
CASES = [{**BASE, "friction": mu} for mu in FRICTIONS] + \
        [{**BASE, "haptic_thickness": h} for h in THICKNESSES if h != BASE["haptic_thickness"]] + \
        [{**BASE, "haptic_thickness": h, "damping": THIN_FLUID} for h in THIN_FLUID_THICKNESSES] + \
        WALL_FRICTION_CASES + TWIST_CASES
QUICK_CASES = [{"haptic_thickness": 0.09, "friction": 0.2}, {"haptic_thickness": 0.18, "friction": 0.2}]
QUICK_SETTINGS = {"contact": False, "settle_time": 0.0, "plunger_speed": 50.0}
# frames as .vtu (the roll angle is read from them), no PNGs (25 s a run)
FRAMES_ONLY = RunOptions(fields=True, pictures=False)
FLIP_ANGLE = 90.0  # degrees of rigid roll beyond which the optic lands upside down
UNROLLED = 0.9  # optic flatness above which it is open (the scene's ``optic_unrolled``)


def rolled_state(out: Path, comm) -> Path:
    """The quick variant's start: the flat coarse lens rolled isometrically about the
    injector axis to radius 2 mm (haptics included: 6.5 mm of arc < 2π · 2 mm, no overlap)."""
    from eyemech.problems.lens.model import LensShell, rolled, save_state

    path = out / "iol_flip_rolled_coarse.npz"
    params = iol_injection.Parameters(resolution="coarse")
    shell = LensShell(params, comm)
    X = shell.node_coordinates()
    shell.u.x.array[:] = (rolled(X, 0.5) - X).ravel()
    save_state(path, shell, comm)
    return path


def folded_state(out: Path, comm) -> Path:
    """The default coarse lens folded: from ``iol-injection``'s fold cache, or folded once
    here and stored in that cache (or in ``out`` when the cache cannot be written)."""
    cached = iol_injection.fold_cache_path(iol_injection.Parameters(resolution="coarse"))
    if cached.is_file():
        return cached
    work = out / "iol_flip_fold"
    iol_fold.run(iol_fold.Parameters(resolution="coarse"), comm=comm, out=work,
                 options=RunOptions(fields=False, pictures=False))
    target = cached
    if comm.rank == 0:
        try:
            cached.parent.mkdir(parents=True, exist_ok=True)
            (work / "folded_state.npz").replace(cached)
        except OSError:
            target = out / "iol_flip_folded_coarse.npz"
            (work / "folded_state.npz").replace(target)
    return comm.bcast(target, root=0)


def case_name(case: dict) -> str:
    return "_".join(f"{key}{value:g}" if isinstance(value, float) else f"{key}{value}"
                    for key, value in sorted(case.items()))


def _same_run(results: Path, params: iol_injection.Parameters) -> bool:
    """A saved run of exactly these parameters (the folded state compared by file name)."""
    if not results.is_file():
        return False
    saved = json.loads(results.read_text())
    if not (saved.get("status") in ("ok", "failed") or _stopped_by_hand(saved)):
        return False
    wanted = params.as_dict()
    old = saved.get("parameters", {})
    keys = set(wanted) - {"folded_state"}
    return all(old.get(k) == wanted[k] for k in keys) and \
        Path(old.get("folded_state", "")).name == Path(wanted["folded_state"]).name


def _stopped_by_hand(saved: dict) -> bool:
    """A run stopped by hand (SIGINT / SIGTERM) for lack of time: kept as a partial case,
    not rerun. Its record says ``interrupted``; a record written before runs were stopped at
    the end of a step says ``error`` with a KeyboardInterrupt."""
    status, message = saved.get("status"), saved.get("message", "")
    return status == "interrupted" or (status == "error" and "KeyboardInterrupt" in message)


def run_case(case: dict, folded: Path, comm, runs: Path, settings: dict | None = None) -> tuple[dict, Path]:
    """The case's CSV row and its run folder (run now unless a saved run matches)."""
    params = iol_injection.Parameters(resolution="coarse", folded_state=str(folded), **case,
                                      **(settings or {}))
    folder = runs / case_name({**case, **(settings or {})})
    if not _same_run(folder / "results.json", params):
        start = time.perf_counter()
        try:
            iol_injection.run(params, comm=comm, out=folder, options=FRAMES_ONLY)
        except SolveFailure:
            pass  # results.json says failed, with the steps it converged
        print(f"iol-flip: {folder.name} ran in {time.perf_counter() - start:.0f} s", flush=True)
    return case_row(case, folder), folder


def case_row(case: dict, folder: Path) -> dict:
    """One row from a case's results.json and its frames (the parameters by their names:
    :func:`run` adds their units for the table)."""
    saved = json.loads((folder / "results.json").read_text())
    q = saved["quantities"]
    by_hand = _stopped_by_hand(saved)
    row = {**case, "damping": saved["parameters"]["damping"],
           "status": "ok" if saved["status"] == "ok" else "stopped" if by_hand else "failed"}
    roll = roll_history(folder)
    rolled = roll[:, 2] < UNROLLED
    if rolled.any():  # while rolled (≈ 2 mm across) the optic may turn freely in the capsule
        worst = int(np.argmax(np.where(rolled, np.abs(roll[:, 1]), -1.0)))
        row.update(max_roll_rolled_deg=float(abs(roll[worst, 1])), max_roll_time_s=float(roll[worst, 0]))
    if len(roll):
        row.update(max_roll_deg=float(np.max(np.abs(roll[:, 1]))))
    params = iol_injection.Parameters(**saved["parameters"])
    torque = capsule_torque(folder, params)
    if len(torque):
        row.update(max_capsule_torque_Nmm=float(np.max(np.abs(torque[:, 1]))))
        row.update(angular_balance(folder, params, torque))
    if saved["status"] != "ok":
        # the steps it converged (a failed run's record ends with the step that failed)
        steps = [s for s in saved.get("steps", []) if s.get("status") != "failed"]
        row.update(finished=False, stopped="by hand (time budget)" if by_hand else "Newton failed",
                   reached_time_s=steps[-1]["time"] if steps else 0.0,
                   steps=len(steps), wall_seconds=saved["timings"]["total"],
                   last_frame_optic_normal_z=last_optic_normal_z(folder))
        return row
    row.update(finished=True, optic_flipped=q["optic_flipped"], optic_normal_z=q["optic_normal_z"],
               final_roll_deg=float(roll[-1, 1]) if len(roll) else None,
               optic_unrolled=q["optic_unrolled"], final_decentration_mm=q["final_decentration_mm"],
               min_self_distance_mm=q["min_self_distance_mm"], max_penetration_mm=q["max_penetration_mm"],
               steps=q["steps"], newton_iterations_per_step=q["newton_iterations_per_step"],
               step_cuts=q["step_cuts"], wall_seconds=q["wall_seconds"])
    return row


def roll_history(folder: Path, half_width: float = 0.6) -> np.ndarray:
    """Rows (t, φ, flatness) per ``injection_*.vtu`` frame: the roll angle φ (degrees) about
    the injector axis (x) of the optic's middle strip (|y| < ``half_width`` in the flat lens),
    from the normal of its triangles — φ = 0: that strip faces +z as in the flat lens; the
    isometric roll leaves it so, a rigid turn of the lens about the axis does not — and the
    optic's flatness |∫n dA|/∫dA (as ``optic_flatness``: 0.05 folded, 1 flat)."""
    rows = []
    for t, X, x, grid in _frames(folder):
        cells = grid.cells.reshape(grid.n_cells, -1)[:, 1:4]  # the P2 triangles' vertices
        optic = cells[np.asarray(grid.cell_data["optic"]) > 0.5]
        sign = np.sign(np.cross(X[optic[:, 1]] - X[optic[:, 0]], X[optic[:, 2]] - X[optic[:, 0]])[:, 2])
        normal = np.cross(x[optic[:, 1]] - x[optic[:, 0]], x[optic[:, 2]] - x[optic[:, 0]]) * sign[:, None]
        middle = np.abs(X[optic].mean(axis=1)[:, 1]) < half_width
        n = normal[middle].sum(axis=0)
        flatness = np.linalg.norm(normal.sum(axis=0)) / np.linalg.norm(normal, axis=1).sum()
        rows.append((t, float(np.degrees(np.arctan2(n[1], n[2]))), float(flatness)))
    return np.array(rows).reshape(-1, 3)


def last_optic_normal_z(folder: Path) -> float | None:
    """z of the mean optic normal (as ``optic_normal``) in the last saved frame: where a run
    that stopped early had got to."""
    last = None
    for last in _frames(folder):
        pass
    if last is None:
        return None
    _t, X, x, grid = last
    cells = grid.cells.reshape(grid.n_cells, -1)[:, 1:4]
    optic = cells[np.asarray(grid.cell_data["optic"]) > 0.5]
    reference = np.cross(X[optic[:, 1]] - X[optic[:, 0]], X[optic[:, 2]] - X[optic[:, 0]])
    normal = np.cross(x[optic[:, 1]] - x[optic[:, 0]], x[optic[:, 2]] - x[optic[:, 0]])
    n = (normal * np.sign(reference[:, 2])[:, None]).sum(axis=0)
    return float(n[2] / np.linalg.norm(n))


def _frames(folder: Path):
    """(t, reference points, deformed points, grid) of every ``injection_*.vtu`` frame."""
    import pyvista

    pvd = folder / "injection.pvd"
    if not pvd.is_file():
        return
    for t, name in sorted(re.findall(r'timestep="([^"]+)"[^>]*file="([^"]+)"', pvd.read_text()),
                          key=lambda e: float(e[0])):
        if (folder / name).is_file():
            grid = pyvista.read(folder / name)
            X = np.asarray(grid.points)
            yield float(t), X, X + np.asarray(grid.point_data["displacement"]), grid


def capsule_torque(folder: Path, params: iol_injection.Parameters, smoothing: float = 2e-3) -> np.ndarray:
    """Rows (t, T_x): the moment (N mm) about the injector axis of the rigid capsule's nodal
    penalty forces on the lens in each frame — with frictionless walls the one external torque
    about that axis (the bore, lip and taper are surfaces of revolution about it, the plunger
    face and the fluid push along it). Same force law as ``NodalContact``. The friction of the
    capsule or the cartridge (``capsule_friction``, ``cartridge_friction``) is not in it: it is
    lagged per step, from the previous step's positions and normal forces, which the frames
    (every few steps) do not hold."""
    if not params.contact:
        return np.zeros((0, 2))
    from eyemech.problems.lens.model import InjectorLayout

    capsule = InjectorLayout().capsule(params)
    axis = params.axis_point()
    rows = []
    for t, _X, x, _grid in _frames(folder):
        gap, normal, acts = capsule.gap_normal(x)
        depth = -gap
        push = np.where(depth > smoothing, depth, np.where(depth > -smoothing,
                                                           (depth + smoothing) ** 2 / (4 * smoothing), 0.0))
        force = (params.contact_stiffness * np.where(acts, push, 0.0))[:, None] * normal
        r = x - axis
        rows.append((t, float(np.sum(r[:, 1] * force[:, 2] - r[:, 2] * force[:, 1]))))
    return np.array(rows).reshape(-1, 2)


def angular_balance(folder: Path, params: iol_injection.Parameters, torque: np.ndarray) -> dict:
    """Where the optic's roll can come from, as degrees of roll of the rolled optic.

    The lens is overdamped (c = ``damping``): c M (v − v_f) balances the forces, the fluid
    moves along the axis, and the only external moment about the axis is the capsule's T_x,
    so Σ m_i (r_i × Δx_i)_x over the lens = ∫ T_x dt / c (lumped masses, r from the axis).
    Split into the optic's part (its roll, × its moment of inertia I_o) and the haptics' part
    (the reaction: haptics unwinding one way turn the optic the other), each is divided by
    I_o of the folded optic, over the frames where the optic is still rolled (flatness <
    ``UNROLLED``): ``haptic_swirl_deg`` (largest |haptic part| / I_o) is the roll the haptics
    can give the optic by unwinding, ``capsule_roll_deg`` (largest |∫T dt| / c I_o) the roll
    the capsule's torque can; a flip needs 90°. With wall friction the balance is incomplete:
    the friction moments of the capsule and the cartridge (a twisted injector's drive) are
    the remainder (see ``capsule_torque``)."""
    frames = list(_frames(folder))
    if len(frames) < 2 or len(torque) != len(frames):
        return {}
    rolled = roll_history(folder)[:, 2] < UNROLLED
    # while rolled only: once open, the 6 mm optic is held by the 4.5 mm high capsule
    frames = [f for f, keep in zip(frames, rolled) if keep]
    torque = torque[rolled]
    if len(frames) < 2:
        return {}
    _t, X, x, grid = frames[0]
    cells = grid.cells.reshape(grid.n_cells, -1)[:, 1:]
    area = 0.5 * np.linalg.norm(np.cross(X[cells[:, 1]] - X[cells[:, 0]], X[cells[:, 2]] - X[cells[:, 0]]),
                                axis=1)
    mass = np.zeros(len(X))
    # P2 row-sum lumping: the vertices get 0, each mid-edge node a third of the cell
    thickness = np.asarray(grid.cell_data["thickness (mm)"])
    np.add.at(mass, cells[:, 3:].ravel(), np.repeat(params.density * thickness * area / 3.0, 3))
    optic = np.zeros(len(X), bool)
    optic[cells[np.asarray(grid.cell_data["optic"]) > 0.5].ravel()] = True
    axis = params.axis_point()
    inertia = float(np.sum(mass[optic] * np.sum((x[optic] - axis)[:, 1:] ** 2, axis=1)))
    haptic_part, impulse, worst_haptic, worst_impulse = 0.0, 0.0, 0.0, 0.0
    previous, t_previous = x, _t
    for (t, _X, x, _g), (_tt, T) in zip(frames[1:], torque[1:]):
        r = 0.5 * (x + previous) - axis
        step = x - previous
        haptic_part += float(np.sum((mass * (r[:, 1] * step[:, 2] - r[:, 2] * step[:, 1]))[~optic]))
        impulse += T * (t - t_previous)
        worst_haptic, worst_impulse = max(worst_haptic, abs(haptic_part)), max(worst_impulse, abs(impulse))
        previous, t_previous = x, t
    return {"haptic_swirl_deg": float(np.degrees(worst_haptic / inertia)),
            "capsule_roll_deg": float(np.degrees(worst_impulse / (params.damping * inertia)))}


def run(out: Path, quick: bool = False, comm=MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if quick:
        start = rolled_state(out, comm)
        runs = out / "iol_flip_quick_runs"
        done = [run_case(case, start, comm, runs, QUICK_SETTINGS) for case in QUICK_CASES]
        note = ("QUICK (pipeline check, not the flip question): contact=false, lens released from a "
                "2 mm roll, no injector/capsule/self-contact")
    else:
        folded = folded_state(out, comm)
        # the runs' frames (≈ 2 MB a case) stay out of docs/studies: results/ is not committed
        runs = Path(os.environ.get("EYEMECH_IOL_FLIP_RUNS", "results/iol-flip-runs"))
        done = [run_case(case, folded, comm, runs) for case in CASES]
        note = (f"iol-injection, resolution=coarse, from {folded.name}; flipped: mean optic normal z < 0; "
                f"roll φ: optic middle strip about the injector axis (flip needs > {FLIP_ANGLE:g}°)")
    # the parameters' columns with their units (haptic_thickness_mm, damping_1/s, ...), in
    # the table and for the charts alike: walls_chart also redraws from the table read back
    rows = with_units([row for row, _folder in done], iol_injection.Parameters)
    csv = write_csv(out / "iol_flip.csv", rows, note)
    histories = [roll_history(folder) for _row, folder in done]
    inside = [not _on_the_walls(row) for row in rows]
    charts = [chart([r for r, keep in zip(rows, inside) if keep],
                    [h for h, keep in zip(histories, inside) if keep], out / "iol_flip.png",
                    note if quick else "")]
    if not quick:
        charts.append(walls_chart(rows, histories, out / "iol_flip_walls.png"))
    return [csv, *charts]


def _on_the_walls(row: dict) -> bool:
    """A case with friction on the capsule or the cartridge, or a twisted injector."""
    return any(float(row.get(key) or 0.0)
               for key in ("capsule_friction", "cartridge_friction", "injector_twist_deg"))


def _wall_label(row: dict) -> str:
    twisted = bool(float(row.get("injector_twist_deg") or 0.0))
    parts = [f"h_h = {float(row['haptic_thickness_mm']):g}"]
    parts += [f"{name} = {float(row.get(key) or 0.0):g}{unit}" for name, key, unit in
              (("μ_capsule", "capsule_friction", ""), ("μ_cartridge", "cartridge_friction", ""),
               ("twist", "injector_twist_deg", "°"))
              if float(row.get(key) or 0.0) or (twisted and key == "cartridge_friction")]
    if row.get("friction_slip_mm") not in (None, ""):
        parts.append(f"slip {1e3 * float(row['friction_slip_mm']):g} µm")
    return ", ".join(parts)


def _final_normal_z(row: dict) -> float:
    """The optic normal z at the end, or in the last frame of a run that stopped."""
    if row.get("optic_normal_z") not in (None, ""):
        return float(row["optic_normal_z"])
    return float(row.get("last_frame_optic_normal_z") or "nan")


def walls_chart(rows: list[dict], histories: list[np.ndarray], path: Path) -> Path:
    """The external moments: friction on the capsule and the cartridge, and the injector
    turned while pushing. Left: the roll φ over time of those cases; right: the final optic
    normal z against μ_cartridge for each twist (h_h = 0.13 mm)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    walls = [(r, h) for r, h in zip(rows, histories) if _on_the_walls(r)]
    fig, (ax, outcome) = plt.subplots(1, 2, figsize=(13, 6.6), gridspec_kw={"width_ratios": [1.6, 1]})
    for row, h in walls:
        if len(h):
            twisted = float(row.get("injector_twist_deg") or 0.0)
            ax.plot(h[:, 0], h[:, 1], lw=1.4 if twisted else 1.0, ls="-" if twisted else "--",
                    label=_wall_label(row))
    for sign in (1, -1):
        ax.axhline(sign * FLIP_ANGLE, color="tab:red", ls=":", lw=1)
    ax.annotate("beyond ±90° while rolled: lands upside down", xy=(0.01, -FLIP_ANGLE),
                xycoords=("axes fraction", "data"), fontsize=7, color="tab:red", va="bottom")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("roll φ of the optic about the injector axis (°)")
    ax.set_title("roll over time (μ = 0.2 lens–lens; coarse lens)", fontsize=10)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2)
    for twist, marker in ((180.0, "o"), (360.0, "s")):
        group = [r for r, _h in walls if float(r.get("injector_twist_deg") or 0.0) == twist
                 and float(r["haptic_thickness_mm"]) == BASE["haptic_thickness"]
                 and float(r.get("start_ramp_s") or 0.0) == TWISTED["start_ramp"]
                 and r.get("friction_slip_mm") in (None, "")]
        group = sorted(group, key=lambda r: float(r.get("cartridge_friction") or 0.0))
        if not group:
            continue
        mu = [float(r.get("cartridge_friction") or 0.0) for r in group]
        z = [_final_normal_z(r) for r in group]
        # dotted: nothing was run between the points
        line, = outcome.plot(mu, z, marker + ":", label=f"injector turned {twist:g}° while pushing")
        stopped = [(m, v) for m, v, r in zip(mu, z, group) if str(r.get("finished")) != "True"]
        if stopped:  # a run that did not reach the end: its last frame, hollow
            outcome.plot(*zip(*stopped), marker, ms=11, mfc="white", color=line.get_color(),
                         label=f"{twist:g}°: run stopped before the end (last frame)")
    for row, _h in walls:  # the haptic-thickness pair (another friction_slip): points of their own
        if row.get("friction_slip_mm") not in (None, "") and float(row.get("injector_twist_deg") or 0.0):
            outcome.plot([float(row.get("cartridge_friction") or 0.0)], [_final_normal_z(row)],
                         "^" if float(row["haptic_thickness_mm"]) > BASE["haptic_thickness"] else "v",
                         label=_wall_label(row))
    outcome.axhline(0.0, color="tab:red", ls=":", lw=1)
    outcome.set_ylim(-1.1, 1.1)
    outcome.set_xlabel("cartridge friction μ_cartridge (μ = 0: the twist does nothing)")
    outcome.set_ylabel("final optic normal z (< 0: upside down)")
    outcome.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13))  # off the points
    fig.suptitle("External moments about the injector axis: wall friction and a twisted injector",
                 fontsize=11)
    save_chart(fig, path)
    return path


def chart(rows: list[dict], histories: list[np.ndarray], path: Path, note: str = "") -> Path:
    """Left two columns: the final optic normal z (top) and the roll during the injection
    (bottom) against μ and against h_h; right: the roll over time, every case."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(14, 6.6))
    grid = fig.add_gridspec(2, 3)
    h0, mu0 = BASE["haptic_thickness"], BASE["friction"]
    panels = (("friction", f"lens–lens friction μ (h_h = {h0:g} mm)", {"haptic_thickness_mm": h0}),
              ("haptic_thickness_mm", f"haptic thickness h_h, mm (μ = {mu0:g}; bending stiffness ∝ h_h³)",
               {"friction": mu0}))
    for column, (key, label, fixed) in enumerate(panels):
        top = fig.add_subplot(grid[0, column])
        bottom = fig.add_subplot(grid[1, column], sharex=top)
        chosen = [r for r in rows if all(r[k] == v for k, v in fixed.items())
                  and not (r.get("capsule_friction") or r.get("cartridge_friction"))]
        for damping in sorted({r["damping_1/s"] for r in chosen}, reverse=True):
            group = [r for r in chosen if r["damping_1/s"] == damping]
            if key == "friction" and damping != DEFAULT_DAMPING or len(group) < 1:
                continue
            _outcome_panel(top, bottom, group, key, damping)
        top.axhline(0.0, color="tab:red", ls=":", lw=1)
        top.set_ylim(-1.1, 1.1)
        top.set_ylabel("final optic normal z\n(▲ up, ▼ flipped)")
        top.tick_params(labelbottom=False)
        top.margins(x=0.25)
        bottom.axhline(FLIP_ANGLE, color="tab:red", ls=":", lw=1)
        bottom.annotate("roll needed to land upside down", xy=(0.01, FLIP_ANGLE),
                        xycoords=("axes fraction", "data"), fontsize=7, color="tab:red", va="top")
        bottom.set_ylim(0.0, 100.0)
        bottom.set_ylabel("roll during injection (°)")
        bottom.set_xlabel(label)
        if bottom.get_legend_handles_labels()[0]:
            bottom.legend(fontsize=6, loc="center", bbox_to_anchor=(0.5, 0.62))
    ax = fig.add_subplot(grid[:, 2])
    for row, h in zip(rows, histories):
        if len(h):
            fluid = "" if row["damping_1/s"] == DEFAULT_DAMPING else f", c = {row['damping_1/s']:g}/s"
            walls = "".join(f", μ_{name} = {row[key]:g}" for name, key in (("capsule", "capsule_friction"),
                                                                          ("cartridge", "cartridge_friction"))
                            if row.get(key))
            ax.plot(h[:, 0], h[:, 1], lw=1.2, ls="-" if not (fluid or walls) else ("--" if fluid else "-."),
                    label=f"μ = {row['friction']:g}, h_h = {row['haptic_thickness_mm']:g}{fluid}{walls}")
    for sign in (1, -1):
        ax.axhline(sign * FLIP_ANGLE, color="tab:red", ls=":", lw=1)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("roll φ of the optic about the injector axis (°)")
    ax.set_title("roll φ over time (beyond ±90°: upside down)", fontsize=10)
    ax.legend(fontsize=7)
    fig.suptitle("Does the optic flip? coarse lens, whole injections" + (f"\n{note}" if note else ""),
                 fontsize=10 if note else 12)
    save_chart(fig, path)
    return path


def _outcome_panel(top, bottom, rows: list[dict], key: str, damping: float) -> None:
    """One fluid's cases: ``top`` final mean optic normal z (▲ right side up, ▼ flipped,
    × Newton stopped: its last frame) against ``key``; ``bottom`` the largest roll while
    rolled and over the run, and what the haptics and the capsule account for. A red band
    between neighbours whose outcome differs, or a note that none does."""
    rows = sorted(rows, key=lambda r: r[key])
    thin = damping != DEFAULT_DAMPING
    fluid = f"c = {damping:g}/s" + (" (thinner fluid)" if thin else "")
    for index, row in enumerate(rows):
        if not row.get("finished"):
            z = row.get("last_frame_optic_normal_z")
            last = "no frame" if z is None else f"last frame n_z {z:.3f}"
            z = 0.0 if z is None else z
            top.scatter(row[key], z, marker="x", color="grey", s=80, zorder=3)
            reached = row.get("reached_time_s", float("nan"))
            top.annotate(f"{row.get('stopped', 'stopped')} at\nt = {reached:.3g} s;\n{last}",
                         (row[key], z), textcoords="offset points", xytext=(-30, -36), fontsize=7)
            continue
        flipped = row["optic_flipped"]
        top.scatter(row[key], row["optic_normal_z"], s=110, marker="v" if flipped else "^",
                    facecolors="none" if thin else ("tab:red" if flipped else "tab:green"),
                    edgecolors="tab:red" if flipped else "tab:green", zorder=3)
        top.annotate(f"n_z {row['optic_normal_z']:.3f}" + (f" (c = {damping:g}/s)" if thin else
                                                           f"\ndec. {row['final_decentration_mm']:.2f} mm"),
                     (row[key], row["optic_normal_z"]), textcoords="offset points",
                     # on the friction axis neighbours' labels alternate in height: 0.2
                     # apart they would overprint each other
                     xytext=(6, -48) if thin else (4, -26 - 24 * (index % 2 if key == "friction" else 0)),
                     fontsize=7)
    style = "--" if thin else "-"
    rolled = [r for r in rows if "max_roll_rolled_deg" in r]
    bottom.plot([r[key] for r in rolled], [r["max_roll_rolled_deg"] for r in rolled], "D" + style,
                color="tab:blue", ms=5, label=f"largest |φ| while rolled, {fluid}")
    for r in rolled:
        text = f"{r['max_roll_rolled_deg']:.1f}°"
        if thin and "haptic_swirl_deg" in r:
            text += (f" (c = {damping:g}/s; haptics {r['haptic_swirl_deg']:.0f}°,\n"
                     f"capsule {r['capsule_roll_deg']:.0f}°: they cancel)")
        bottom.annotate(text, (r[key], r["max_roll_rolled_deg"]), textcoords="offset points",
                        xytext=(4, 4), fontsize=7)
    landed = [r for r in rows if "max_roll_deg" in r]
    bottom.plot([r[key] for r in landed], [r["max_roll_deg"] for r in landed], "v" + style,
                color="tab:purple", ms=5, lw=1,
                label=f"largest |φ| over the run (open: ≤ 43° fits the capsule), {fluid}")
    if not thin:
        for name, marker, text in (("haptic_swirl_deg", "s:", "from the haptics' unwinding, while rolled"),
                                   ("capsule_roll_deg", "o:", "from the capsule's torque, while rolled")):
            have = [r for r in rolled if name in r]
            bottom.plot([r[key] for r in have], [r[name] for r in have], marker, ms=4, lw=1, label=text)
    outcomes = [(r[key], r.get("optic_flipped") if r.get("finished") else None) for r in rows]
    changed = False
    for (a, fa), (b, fb) in zip(outcomes, outcomes[1:]):
        if fa is not None and fb is not None and fa != fb:
            for ax in (top, bottom):
                ax.axvspan(a, b, color="tab:red", alpha=0.12)
            top.text(0.5 * (a + b), -0.5, f"outcome\nchanges\n({fluid})", ha="center", fontsize=8,
                     color="tab:red")
            changed = True
    if not changed and len(outcomes) > 1:
        top.text(0.02, 0.05 + (0.1 if thin else 0.0), f"no change of outcome over this range, {fluid}",
                 transform=top.transAxes, fontsize=7)


STUDY = Study(name="iol-flip", summary="whether the optic lands flipped, against lens–lens friction and "
                                       "haptic thickness, with the optic's roll about the injector axis "
                                       "(whole coarse injections)", run=run)
