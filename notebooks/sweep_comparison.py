# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Comparing the cases of a sweep
#
# Post-processing of `eyemech sweep`: `sweep.csv` has one row per case (the grid values,
# the scalar quantities, status, wall time); each `case_NNNN/` holds that case's
# `results.json` (with the per-step records) and fields. Point `EYEMECH_SWEEP_DIR` at a
# sweep's folder; without it the notebook runs a small one itself: `sphere-inflation`
# with two element families at three pressures (h = 2 mm, under a minute).

# %%
import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pyvista as pv

sweep_dir = Path(os.environ.get("EYEMECH_SWEEP_DIR",
                                Path(os.environ.get("EYEMECH_RUN_DIR", "results")) / "sweep"))
if not (sweep_dir / "sweep.csv").exists():
    eyemech = Path(sys.executable).parent / "eyemech"
    subprocess.run([str(eyemech), "sweep", "sphere-inflation", "--set", "mesh_size=2",
                    "--grid", "element=P2P1,Q1P0", "--grid", "pressure=0.005,0.01,0.02",
                    "--out", str(sweep_dir), "--quiet", "--no-pictures"], check=True)
with open(sweep_dir / "sweep.csv", newline="") as handle:
    rows = list(csv.DictReader(handle))
grid_keys = [k for k in rows[0] if k not in ("case", "status")][:2]
print(f"{len(rows)} cases, {sum(r['status'] != 'ok' for r in rows)} failed; grid: {grid_keys}")
for r in rows:
    print(r["case"], {k: r[k] for k in grid_keys}, r["status"], f"{float(r['wall_time_s']):.1f} s")

# %% [markdown]
# ## One quantity across the grid
# Each line holds the first grid key fixed and runs along the second.

# %%
series_key, x_key = grid_keys
quantity = "inner_radius_error" if "inner_radius_error" in rows[0] else \
    next(k for k in rows[0] if k not in grid_keys and k not in ("case", "status", "wall_time_s"))
fig, (ax, ax_cost) = plt.subplots(1, 2, figsize=(11, 3.8))
for value in dict.fromkeys(r[series_key] for r in rows):
    mine = [r for r in rows if r[series_key] == value and r["status"] == "ok"]
    x = [float(r[x_key]) for r in mine]
    ax.semilogy(x, [abs(float(r[quantity])) for r in mine], "o-", label=f"{series_key} = {value}")
    ax_cost.plot(x, [float(r["wall_time_s"]) for r in mine], "o-", label=f"{series_key} = {value}")
ax.set(xlabel=x_key, ylabel=f"|{quantity}|")
ax_cost.set(xlabel=x_key, ylabel="wall time (s)")
for a in (ax, ax_cost):
    a.legend()
    a.grid(alpha=0.3)
fig.tight_layout()

# %% [markdown]
# ## Inside each case: the load path from its results.json

# %%
fig, ax = plt.subplots(figsize=(6, 4))
for r in rows:
    case = json.loads((sweep_dir / f"case_{int(r['case']):04d}" / "results.json").read_text())
    steps = case["steps"]
    if not steps or "inner_radius_deformed" not in steps[0]:
        continue
    A = case["parameters"]["inner_radius"]
    ax.plot([0] + [s["pressure"] for s in steps],
            [1.0] + [s["inner_radius_deformed"] / A for s in steps], "o-", ms=3,
            label=f"case {r['case']}: " + ", ".join(f"{k}={r[k]}" for k in grid_keys))
ax.set(xlabel="pressure (MPa)", ylabel="inner stretch a / A")
ax.legend(fontsize=7)
fig.tight_layout()

# %% [markdown]
# ## Two cases side by side in pyvista
# The final states of the first and the last case, from their `state.pvd` series.

# %%
pv.OFF_SCREEN = True
shown = [rows[0], rows[-1]]
plotter = pv.Plotter(off_screen=True, shape=(1, 2), window_size=(1000, 450))
for column, r in enumerate(shown):
    series = pv.read(sweep_dir / f"case_{int(r['case']):04d}" / "state.pvd")
    final = series[len(series) - 1]
    final.point_data["|u| (mm)"] = np.linalg.norm(final.point_data["displacement"], axis=1)
    plotter.subplot(0, column)
    plotter.add_mesh(final.warp_by_vector("displacement"), scalars="|u| (mm)", show_edges=True)
    plotter.add_text(", ".join(f"{k}={r[k]}" for k in grid_keys), font_size=9)
    plotter.view_vector((-1.0, -1.3, 0.8))
image = plotter.screenshot(return_img=True)
plotter.close()
plt.figure(figsize=(10, 4.5))
plt.imshow(image)
plt.axis("off")
print("rendered", image.shape)
