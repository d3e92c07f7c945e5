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
# Post-processing of `eyemech run scleral-buckling`: the clinical quantities after each
# stage of the operation (IOP, buckling, suturing, settling), along the load path, and the
# deformed eye of each stage from the run's `state.pvd`. Point `EYEMECH_RUN_DIR` at a
# run's output folder; without it the notebook runs the coarse eye itself (about a minute).
# `shown` collects every number this notebook displays with where it is in `results.json`
# (tests/test_notebooks.py checks them against the files).

# %%
import json
import os
import subprocess
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pyvista as pv

run_dir = Path(os.environ.get("EYEMECH_RUN_DIR", "results/scleral-buckling"))
if not (run_dir / "results.json").exists():
    eyemech = Path(sys.executable).parent / "eyemech"
    subprocess.run([str(eyemech), "run", "scleral-buckling", "--set", "resolution=coarse",
                    "--out", str(run_dir), "--quiet", "--no-pictures"], check=True)
results = json.loads((run_dir / "results.json").read_text())
quantities = results["quantities"]
# one group of quantities per stage, in the order of the operation
stages = {k: v for k, v in quantities.items() if k.startswith("after_") and isinstance(v, dict)}
shown: list[tuple[str, str, float]] = []  # (file, key path, value displayed)

# %% [markdown]
# ## After each stage
# Changes are measured from the eye before surgery (the end of step 1, IOP 15 mmHg);
# "settling" returns the IOP to its pre-operative value and releases the liquid volume.

# %%
rows = [("axial length change (mm)", "axial_length_change_mm"),
        ("refraction change (D)", "refraction_change_D"),
        ("IOP (mmHg)", "iop_mmHg"),
        ("volume change (mm³)", "volume_change_mm3"),
        ("tear's rim gap, widest (mm)", "tear_rim_gap_max_mm"),
        ("mean retina–choroid gap (mm)", "retina_choroid_gap_mean_mm"),
        ("tear closed (rim gap < tolerance)", "tear_closed_nts"),
        ("largest von Mises stress (MPa)", "von_mises_max_MPa")]
print(f"{'':32s}" + "".join(f"{name.removeprefix('after_'):>12s}" for name in stages))
for label, key in rows:
    cells = []
    for name, values in stages.items():
        value = values.get(key)
        cells.append(f"{value!s:>12s}" if isinstance(value, bool) or value is None
                     else f"{value:12.4g}")
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            shown.append((str(run_dir / "results.json"), f"quantities.{name}.{key}", value))
    print(f"{label:32s}" + "".join(cells))

# %% [markdown]
# ## Along the load path
# The load parameter runs 0→1 (IOP), 1→2 (the band shortened, the IOP vented at its
# limit), 2→3 (suture pull), 3→4 (settling). Step 1's points carry no change (the
# reference is its end).

# %%
steps = results["steps"]
load = np.array([s["load"] for s in steps])
fig, axes = plt.subplots(1, 3, figsize=(13, 3.5))
for ax, key, label in zip(axes, ("axial_length_change_mm", "iop_mmHg", "tear_rim_gap_max_mm"),
                          ("axial length change (mm)", "IOP (mmHg)", "tear's rim gap (mm)")):
    ax.plot(load, [s.get(key, np.nan) for s in steps], "o-", ms=3)
    for boundary, name in zip(range(1, len(stages) + 1), stages):
        ax.axvline(boundary, ls=":", c="grey")
        ax.text(boundary - 0.5, 1.0, name.removeprefix("after_"), ha="center", va="bottom",
                transform=ax.get_xaxis_transform(), fontsize=8)
    ax.set(xlabel="load path", ylabel=label)
    ax.grid(alpha=0.3)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## The eye at the end of each stage, coloured by von Mises stress
# `state.pvd` holds one `.vtu` per converged step, at its load value; a reader picks a
# step by its value (`pv.read` would give the first, the unloaded eye). The stress
# concentrates under the buckle and at the suture bites. One colour scale for all four.

# %%
pv.OFF_SCREEN = True
reader = pv.get_reader(str(run_dir / "state.pvd"))
ends = {name: float(number) for number, name in enumerate(stages, start=1)}
grids = {}
for name, value in ends.items():
    reader.set_active_time_value(value)
    grids[name] = reader.read()[0]
    shown.append((str(run_dir / "results.json"), f"quantities.{name}.von_mises_max_MPa",
                  float(grids[name].cell_data["von_mises"].max())))
top = max(float(g.cell_data["von_mises"].max()) for g in grids.values())
plotter = pv.Plotter(off_screen=True, shape=(1, len(grids)), window_size=(340 * len(grids), 380))
for column, (name, grid) in enumerate(grids.items()):
    plotter.subplot(0, column)
    plotter.add_mesh(grid.warp_by_vector("displacement"), scalars="von_mises", cmap="inferno",
                     clim=(0.0, top), scalar_bar_args={"title": "von Mises (MPa)", "n_labels": 3,
                                                       "fmt": "%.2f"})
    plotter.add_text(f"after {name.removeprefix('after_')}", font_size=9)
    plotter.view_vector((0.6, 1.0, 0.35))
plotter.show(jupyter_backend="static")

# %% [markdown]
# ## The tissues, on the symmetry plane through the tear
# Each cell carries its tissue as the cell array `tissue`, named by the legend in the
# field data (`tissue_names`, `tissue_tags`). The section is the settled eye.

# %%
final = grids[list(grids)[-1]]
names = dict(zip(final.field_data["tissue_tags"], final.field_data["tissue_names"]))
section = final.slice(normal=(1.0, 0.0, 0.0), origin=(0.02, 0.0, 0.0)).warp_by_vector("displacement")
plotter = pv.Plotter(off_screen=True, window_size=(760, 650))
colours = plt.get_cmap("tab10").colors
for colour, (tag, name) in zip(colours, names.items()):
    cells = np.flatnonzero(section.cell_data["tissue"] == tag)
    if cells.size:
        plotter.add_mesh(section.extract_cells(cells), color=colour, show_edges=True,
                         label=str(name).replace("_", " "))
plotter.add_legend(bcolor="white", face="rectangle", size=(0.22, 0.3), loc="lower left")
plotter.view_yz(negative=True)
plotter.add_text("settled eye, section x = 0 (cornea up)", font_size=9)
plotter.show(jupyter_backend="static")
print("tissues:", ", ".join(f"{tag} {name}" for tag, name in names.items()))
