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
# # Goldmann applanation tonometry: what the instrument reads
#
# Post-processing of `eyemech run tonometry`: a flat rigid prism pushed onto the pressurised
# cornea until the contact disc is 3.06 mm across. Goldmann's instrument converts the force
# into a pressure by the Imbert–Fick law, reading = F / A; the cornea's bending stiffness adds
# to F and the tear meniscus pulls the prism on. The gap between reading and true IOP is what
# a thick or stiff cornea does to the measurement.
# Point `EYEMECH_RUN_DIR` at a run's output folder; without it the notebook runs a coarse
# case itself (1 mm planform elements, 16 around: about half a minute).

# %%
import json
import os
import subprocess
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pyvista as pv

run_dir = Path(os.environ.get("EYEMECH_RUN_DIR", "results/tonometry"))
if not (run_dir / "results.json").exists():
    eyemech = Path(sys.executable).parent / "eyemech"
    subprocess.run([str(eyemech), "run", "tonometry", "--set", "mesh_size=1.0",
                    "--set", "azimuthal_divisions=16", "--out", str(run_dir), "--quiet"],
                   check=True)
results = json.loads((run_dir / "results.json").read_text())
params, q = results["parameters"], results["quantities"]
where = str(run_dir / "results.json")
shown = [(where, f"quantities.{k}", q[k]) for k in
         ("iop_mmHg", "iop_reading_mmHg", "iop_reading_dry_mmHg", "reading_error_mmHg",
          "applanation_force_g", "applanation_depth_mm")]
print(f"cornea {1000 * params['central_thickness']:.0f} µm thick, E = {params['youngs_modulus']} MPa, "
      f"{q['cells']} cells, {q['dofs']} dofs")
print(f"true IOP {q['iop_mmHg']:.1f} mmHg → reading {q['iop_reading_mmHg']:.2f} mmHg "
      f"(dry prism {q['iop_reading_dry_mmHg']:.2f}); error {q['reading_error_mmHg']:+.2f} mmHg")
print(f"applanation force {q['applanation_force_g']:.3f} g at depth {q['applanation_depth_mm']:.3f} mm")

# %% [markdown]
# ## The path to the reading
# Each converged applanation step records the prism's depth below the pressurised apex, the
# radius of the contact disc and the contact force. The reading is taken where the disc
# reaches 3.06 mm (found by regula falsi between the last two steps). The right panel shows
# what the Imbert–Fick formula would give at each disc size: the cornea's resistance to
# flattening makes it depend on the disc size, which is why Goldmann fixed 3.06 mm. (On the
# coarse default of this notebook the disc grows node ring by node ring, so the curve is
# jagged; the scene's default mesh has half this element size in the planform, 0.5 mm:
# 416 cells against 256, docs/studies/tonometry_convergence.csv.)

# %%
from eyemech.problems.run.parameters import MMHG

steps = [s for s in results["steps"] if s.get("stage") == "applanation"]
depth = np.array([s["depth_mm"] for s in steps])
radius = np.array([s["contact_radius_mm"] for s in steps])
force = np.array([s["force_N"] for s in steps])
tear = params["tear_film_mmHg"] * MMHG * np.pi * radius**2
fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
axes[0].plot(depth, 1000 * force, "o-")
axes[0].plot(q["applanation_depth_mm"], 1000 * q["contact_force_N"], "r*", ms=12, label="reading")
axes[0].set(xlabel="prism depth (mm)", ylabel="contact force (mN)")
axes[0].legend()
axes[1].plot(depth, 2 * radius, "o-")
axes[1].axhline(params["applanation_diameter"], c="r", ls=":", label="3.06 mm")
axes[1].set(xlabel="prism depth (mm)", ylabel="contact diameter (mm)")
axes[1].legend()
touching = radius > 0
imbert_fick = (force[touching] - tear[touching]) / (np.pi * radius[touching] ** 2) / MMHG
axes[2].plot(2 * radius[touching], imbert_fick, "o-", label="(F − tear) / A")
axes[2].axhline(q["iop_mmHg"], c="k", ls="--", label="true IOP")
axes[2].axvline(params["applanation_diameter"], c="r", ls=":")
axes[2].set(xlabel="contact diameter (mm)", ylabel="Imbert–Fick pressure (mmHg)")
axes[2].legend()
for ax in axes:
    ax.grid(alpha=0.3)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## The applanated cornea
# `state.pvd` holds the cornea at the reading (its time value is the applanation depth). A
# section through the apex shows the flat disc under the prism and the cornea bending round
# its edge; the colour is the displacement from the unloaded cornea.

# %%
pv.OFF_SCREEN = True
reader = pv.get_reader(str(run_dir / "state.pvd"))  # one state: the reading, at its depth
reader.set_active_time_value(reader.time_values[-1])
grid = reader.read()[0]
shown.append((where, "quantities.applanation_depth_mm", reader.active_time_value))
grid.point_data["displacement (mm)"] = np.linalg.norm(grid.point_data["displacement"], axis=1)
deformed = grid.warp_by_vector("displacement", factor=1.0)
section = deformed.slice(normal="y", origin=(0.0, 0.0, 0.0))
plotter = pv.Plotter(off_screen=True, window_size=(900, 420))
plotter.add_mesh(grid.slice(normal="y", origin=(0.0, 0.0, 0.0)), color="grey", opacity=0.35)
plotter.add_mesh(section, scalars="displacement (mm)", show_edges=True, cmap="viridis",
                 clim=(0.0, float(grid["displacement (mm)"].max())),
                 scalar_bar_args={"title": "displacement (mm)", "fmt": "%.3g"})
apex = deformed.points[:, 2].max()
# the prism's flat face (blue) and the flattened disc of the reading (red)
plotter.add_mesh(pv.Cylinder(center=(0, 0, apex + 0.25), direction=(0, 0, 1), radius=3.5,
                             height=0.5), color="lightblue", opacity=0.6)
disc = q["contact_diameter_mm"] / 2
plotter.add_mesh(pv.Line((-disc, -0.01, apex), (disc, -0.01, apex)), color="red", line_width=5)
plotter.view_xz()
plotter.camera.zoom(1.8)
plotter.show(jupyter_backend="static")

# %% [markdown]
# The grey section is the unloaded cornea: the IOP lifts the apex (by
# `apex_displacement_iop_mm`), and the prism (blue) pushes it back by the applanation depth
# until the flat disc (red) is 3.06 mm across. The reading's error comes from the bending stiffness
# of this thick shell; the `tonometry` sweeps over `central_thickness` and `youngs_modulus`
# (docs/cornea.md) show how it grows with both.
