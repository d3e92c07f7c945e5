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
# # Scleral buckling: what each surgical step does
#
# Post-processing of `eyemech run scleral-buckling`: the clinical quantities step by step,
# and the deformed eye from the pyvista series. Point `EYEMECH_RUN_DIR` at a run's output
# folder; without it the notebook runs the coarse eye itself (about a minute).

# %%
import json
import os
import subprocess
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pyvista as pv

run_dir = Path(os.environ.get("EYEMECH_RUN_DIR", "results"))
if not (run_dir / "results.json").exists():
    eyemech = Path(sys.executable).parent / "eyemech"
    subprocess.run([str(eyemech), "run", "scleral-buckling", "--set", "resolution=coarse",
                    "--out", str(run_dir), "--quiet", "--no-pictures"], check=True)
results = json.loads((run_dir / "results.json").read_text())
for stage in ("after_iop", "after_buckling", "after_suturing"):
    values = results["quantities"][stage]
    print(f"{stage:16s} axial {values['axial_length_change_mm']:+.3f} mm, "
          f"IOP {values['iop_mmHg']:.1f} mmHg, gap {values['retina_choroid_gap_mean_mm']:.3f} mm, "
          f"tear closed: {values['tear_closed']}")

# %% [markdown]
# ## Along the load path
# The load parameter runs 0→1 (IOP), 1→2 (buckle indentation), 2→3 (suture pull).

# %%
steps = results["steps"]
load = np.array([s["load"] for s in steps])
fig, axes = plt.subplots(1, 3, figsize=(13, 3.5))
# changes are read from the eye before surgery (the end of step 1): step 1's own points
# have none, and plot as gaps
for ax, key, label in zip(axes, ("axial_length_change_mm", "iop_mmHg", "retina_choroid_gap_mean_mm"),
                          ("axial length change from before surgery (mm)", "IOP (mmHg)",
                           "mean retina–choroid gap (mm)")):
    ax.plot(load, [s.get(key, np.nan) for s in steps], "o-")
    for boundary in (1, 2, 3):
        ax.axvline(boundary, ls=":", c="grey")
    ax.set(xlabel="load path (1: IOP, 2: buckled, 3: sutured, 4: settled)", ylabel=label)
fig.tight_layout()

# %% [markdown]
# ## The eye after suturing, coloured by von Mises stress
# `state.pvd` holds one `.vtu` per converged step with the displacement and the cellwise
# von Mises stress; the stress concentrates at the suture bites.

# %%
pv.OFF_SCREEN = True
series = pv.read(run_dir / "state.pvd")
final = series[len(series) - 1].warp_by_vector("displacement")
plotter = pv.Plotter(off_screen=True, window_size=(700, 600))
plotter.add_mesh(final, scalars="von_mises", cmap="inferno")
plotter.view_vector((0.6, 1.0, 0.35))
image = plotter.screenshot(return_img=True)
plotter.close()
print("rendered", image.shape, "max von Mises", float(final["von_mises"].max()), "MPa")
