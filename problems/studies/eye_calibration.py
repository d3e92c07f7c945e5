"""The eye's pressure–volume curve against the living human eye's, and the fit of the
calibrated coats (``scleral-buckling``, ``material = "calibrated"``).

Data: Pallikaris et al., "Ocular rigidity in living human eyes", IOVS 46:409 (2005).
Volume injected into the eyes of 79 patients before cataract surgery, pressure measured
in the anterior chamber; they fitted Friedenwald's relation in natural logarithms,
ln(P₂/P₁) = K ΔV, with mean K = 0.0126 µL⁻¹ (range 0.0065–0.0220). The reference curve is
therefore ΔV(P) = ln(P / 10 mmHg) / K, the volume added to the whole eye from 10 mmHg.

Model: the scene's healthy eye (no tear, retina attached, lens and zonules), step 1 only:
the follower pressure ramped from 0 to 40 mmHg with P pinned, stopping on every pressure
of the comparison; V is the whole eye's liquid volume (twice the half model's).

Fit (:func:`fit_c20`): c20 of the sclera (the cornea's in Table 1's ratio) minimises the
root mean square of ΔV_model / ΔV_data − 1 over 15, 20, …, 40 mmHg (golden-section search
on log c20). The fitted value is ``scleral_buckling.CALIBRATED_C20_SCLERA``.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from mpi4py import MPI

from eyemech.problems import scleral_buckling
from eyemech.problems.run.context import RunContext
from eyemech.problems.solve.driver import SolveFailure, Stepping, follow_path
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, failed_row, save_chart, write_csv

# Pallikaris et al. 2005 (IOVS 46:409): mean in vivo ocular rigidity, natural logarithm
PALLIKARIS_K = 0.0126  # µL⁻¹
REFERENCE_PRESSURE = 10.0  # mmHg: ΔV is counted from here
PRESSURES = (10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0)  # mmHg


def pallikaris_volume_change(pressure_mmHg: float, k: float = PALLIKARIS_K) -> float:
    """Volume (µL = mm³) added to the whole eye from 10 mmHg to ``pressure_mmHg``."""
    return math.log(pressure_mmHg / REFERENCE_PRESSURE) / k


def healthy_eye(**overrides) -> scleral_buckling.Parameters:
    """The scene's eye without a tear or detachment (the eyes of the rigidity studies)."""
    base = dict(detachment_height=0.0, tear_radius=0.0, suture_force=0.0, settle=False)
    return scleral_buckling.Parameters(**(base | overrides))


def inflation_curve(params: scleral_buckling.Parameters, pressures=PRESSURES,
                    comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    """Whole-eye liquid volume (mm³) at each pressure (mmHg) of step 1, from 0 to the
    largest; with the Newton iterations and load steps it took."""
    top = max(pressures)
    params = dataclasses.replace(params, iop_mmHg=top)
    volumes: dict[float, float] = {}
    with RunContext(scleral_buckling.SCENE.name, params, comm, None, QUIET) as ctx:
        model = scleral_buckling.BucklingModel(params, ctx)
        volumes[0.0] = 2.0 * model.liquid.volume()

        def record(step) -> None:
            volumes[round(step.load * top, 9)] = 2.0 * model.liquid.volume()

        # the first stage's controls (the IOP's ramp) along a path of its own
        records = follow_path(model.solver, scleral_buckling.Operation(model, ctx).apply,
                              Stepping(0.0, 1.0, initial_step=0.125, max_step=0.125,
                                       stops=tuple(p / top for p in pressures)),
                              on_converged=record, label="inflation", quiet=True)
    return {"volumes": {p: volumes[round(p, 9)] for p in (0.0, *pressures)},
            "newton_iterations": sum(r.iterations for r in records),
            "load_steps": len(records)}


def deviations(volumes: dict[float, float], k: float = PALLIKARIS_K) -> dict[float, float]:
    """ΔV_model / ΔV_data − 1 at each pressure above 10 mmHg."""
    base = volumes[REFERENCE_PRESSURE]
    return {p: (v - base) / pallikaris_volume_change(p, k) - 1.0
            for p, v in volumes.items() if p > REFERENCE_PRESSURE}


def fit_c20(resolution: str = "default", bracket=(2.0, 200.0), tolerance: float = 0.02,
            comm: MPI.Comm = MPI.COMM_WORLD) -> tuple[float, float, list[dict]]:
    """Golden-section search of log c20_sclera for the least RMS relative deviation from
    Pallikaris' curve; returns (c20, RMS, the evaluated cases). ``tolerance``: the final
    bracket's relative width."""
    cases: list[dict] = []

    def rms(log_c20: float) -> float:
        c20 = math.exp(log_c20)
        curve = inflation_curve(_calibrated(resolution, c20), comm=comm)
        dev = np.array(list(deviations(curve["volumes"]).values()))
        value = float(np.sqrt(np.mean(dev**2)))
        cases.append({"c20_sclera": c20, "rms": value, "max": float(np.abs(dev).max())})
        return value

    golden = (math.sqrt(5) - 1) / 2
    a, b = math.log(bracket[0]), math.log(bracket[1])
    c, d = b - golden * (b - a), a + golden * (b - a)
    fc, fd = rms(c), rms(d)
    while b - a > tolerance:
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - golden * (b - a)
            fc = rms(c)
        else:
            a, c, fc = c, d, fd
            d = a + golden * (b - a)
            fd = rms(d)
    best = min(cases, key=lambda case: case["rms"])
    return best["c20_sclera"], best["rms"], cases


def _calibrated(resolution: str, c20: float) -> scleral_buckling.Parameters:
    return healthy_eye(resolution=resolution, material="calibrated", c20_sclera=c20,
                       c20_cornea=scleral_buckling.CORNEA_TO_SCLERA * c20)


def equibiaxial_tangent_modulus(c10: float, c20: float, stress: float) -> tuple[float, float]:
    """(stretch, tangent modulus dσ/dε) of an incompressible Yeoh membrane under the
    equibiaxial Cauchy stress ``stress`` (MPa): σ = 2 (λ² − λ⁻⁴) W'(Ī1), Ī1 = 2λ² + λ⁻⁴,
    ε = λ − 1. The sclera's physiological stress is Laplace's P R / (2 t)."""
    def sigma(lam: float) -> float:
        x = 2 * lam**2 + lam**-4 - 3
        return 2 * (lam**2 - lam**-4) * (c10 + 2 * c20 * x)

    low, high = 1.0, 1.5
    for _ in range(100):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if sigma(mid) < stress else (low, mid)
    lam, h = 0.5 * (low + high), 1e-7
    return lam, (sigma(lam + h) - sigma(lam - h)) / (2 * h)


def run(out: Path, quick: bool, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    """P–V curves of the coarse (quick) or default eye, table-1 and calibrated, against
    Pallikaris' mean and range of K: a row per pressure (status ok), or one row with status
    failed for a material whose inflation did not reach 40 mmHg (``eyemech study`` exits 4).
    NaN where a column is not defined: Pallikaris' ΔV at 0 mmHg, the deviation up to 10 mmHg."""
    resolution = "coarse" if quick else "default"
    rows = []
    for material in ("table-1", "calibrated"):
        try:
            curve = inflation_curve(healthy_eye(resolution=resolution, material=material), comm=comm)
        except SolveFailure as failure:
            rows.append(failed_row({"material": material, "resolution": resolution}, failure))
            continue
        dev = deviations(curve["volumes"])
        base = curve["volumes"][REFERENCE_PRESSURE]
        for p, v in curve["volumes"].items():
            rows.append({"material": material, "resolution": resolution, "pressure_mmHg": p,
                         "status": "ok", "volume_mm3": v, "volume_change_from_10_mmHg": v - base,
                         "pallikaris_volume_change": pallikaris_volume_change(p) if p > 0 else math.nan,
                         "deviation": dev.get(p, math.nan),
                         "newton_iterations": curve["newton_iterations"]})
    if comm.rank != 0:
        return []
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    stem = "eye_calibration" + ("_quick" if quick else "")
    table = write_csv(out / f"{stem}.csv", rows,
                      f"whole-eye liquid volume under IOP, {resolution} eye; reference: "
                      f"Pallikaris et al. 2005, ln(P/10) = K dV, K = {PALLIKARIS_K} /uL")
    chart = out / f"{stem}.png"
    _chart(rows, chart)
    return [table, chart]


def _chart(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.2))
    pressures = np.linspace(REFERENCE_PRESSURE, 40.0, 61)
    for k, style in ((PALLIKARIS_K, "k-"), (0.0065, "k:"), (0.0220, "k:")):
        ax.plot([math.log(p / REFERENCE_PRESSURE) / k for p in pressures], pressures, style,
                label=f"Pallikaris 2005, K = {k} µL⁻¹" + (" (mean)" if k == PALLIKARIS_K else ""))
    for material, marker in (("table-1", "s"), ("calibrated", "o")):
        if any(r["material"] == material and r["status"] != "ok" for r in rows):
            # its inflation failed: a cross where its curve would start
            ax.plot([0.0], [REFERENCE_PRESSURE], "x", color="tab:red", ms=10, mew=2, clip_on=False,
                    label=f"model, {material}: solve failed")
            continue
        mine = [r for r in rows if r["material"] == material and r["pressure_mmHg"] >= REFERENCE_PRESSURE]
        ax.plot([r["volume_change_from_10_mmHg"] for r in mine], [r["pressure_mmHg"] for r in mine],
                marker + "-", label=f"model, {material}")
    ax.set_xlabel("volume added from 10 mmHg, whole eye (µL)")
    ax.set_ylabel("IOP (mmHg)")
    ax.set_xlim(0, 250)
    ax.legend(fontsize=8)
    ax.set_title(f"eye pressure–volume curve ({rows[0]['resolution']} eye)")
    save_chart(fig, path)


STUDY = Study(name="eye-calibration",
              summary="scleral-buckling eye: pressure–volume curve vs Pallikaris 2005 (table-1, calibrated)",
              run=run)
