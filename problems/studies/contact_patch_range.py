"""The contact patch test (``contact-patch``) over the meshes and loads a user tries: the
segment-to-segment method transmits a uniform pressure exactly for any pair of non-matching
meshes (its Gauss rule integrates the consistent nodal forces on both surfaces), so its
resolution rule is "any mesh": the stress spread stays at round-off for master/slave size
ratios from 1/2 to 2, P1 and P2, moduli × 10 and pressures × 0.1 … × 3, while
node-to-surface is shown on the default blocks for comparison."""

from __future__ import annotations

import time
from pathlib import Path

from mpi4py import MPI

from eyemech.problems import contact_patch
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, save_chart, with_units, write_csv

CASES = (
    ("default", {}),
    ("slave finer (0.25 / 0.125)", dict(slave_size=0.125)),
    ("slave coarser (0.17 / 0.25)", dict(master_size=0.17, slave_size=0.25)),
    ("master twice as coarse (0.5 / 0.17)", dict(master_size=0.5)),
    ("matching (0.25 / 0.25)", dict(slave_size=0.25)),
    ("P2", dict(degree=2)),
    ("modulus x 10", dict(youngs_modulus=10.0)),
    ("pressure x 0.1", dict(pressure=0.001)),
    ("pressure x 3", dict(pressure=0.03)),
    ("node-to-surface (default blocks)", dict(method="node-to-surface")),
)
QUICK_CASES = CASES[:1]
ROUND_OFF = 1e-8  # what "exact" means here: spreads of 1e-12 … 1e-9 measured


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    if comm.rank != 0:  # serial study: rank 0 does the work
        return []
    rows = [_row(label, changes) for label, changes in (QUICK_CASES if quick else CASES)]
    table = write_csv(out / "contact_patch_range.csv", with_units(rows, contact_patch.Parameters),
                      "stress spread: (max - min) / p of the cell-wise P_zz in each block")
    return [table, _chart(out / "contact_patch_range.png", rows)]


def _row(label: str, changes: dict) -> dict:
    params = contact_patch.Parameters(**changes)
    row = {"case": label, "method": params.method, "degree": params.degree,
           "master_size": params.master_size, "slave_size": params.slave_size}
    start = time.perf_counter()
    try:
        q = contact_patch.run(params, comm=MPI.COMM_SELF, options=QUIET).quantities
    except SolveFailure as failure:
        return row | {"status": "failed", "error": str(failure)[:200]}
    return row | {"status": "ok", "stress_spread_lower": q["stress_spread_lower"],
                  "stress_spread_upper": q["stress_spread_upper"],
                  "pressure_spread": q["pressure_spread"], "seconds": time.perf_counter() - start}


def _chart(path: Path, rows: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    ok = [r for r in rows if r["status"] == "ok"]
    fig, axis = plt.subplots(figsize=(8, 0.8 + 0.4 * len(ok)))
    y = np.arange(len(ok))
    for shift, block in ((-0.2, "lower"), (0.2, "upper")):
        axis.barh(y + shift, [max(r[f"stress_spread_{block}"], 1e-16) for r in ok], height=0.4,
                  label=f"{block} block")
    axis.axvline(ROUND_OFF, color="grey", ls=":", label=f"{ROUND_OFF:g}")
    axis.set_xscale("log")
    axis.set_yticks(y, [r["case"] for r in ok], fontsize=8)
    axis.invert_yaxis()
    axis.set(xlabel="stress spread (max − min) / p", title="contact patch test over meshes and loads")
    axis.legend(fontsize=7)
    save_chart(fig, path, dpi=110)
    return path


STUDY = Study(name="contact-patch-range",
              summary="contact patch test: stress spread over mesh ratios, degree, modulus, pressure",
              run=run)
