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
# # Inflating a thick incompressible sphere
#
# Post-processing of `eyemech run sphere-inflation`: the pressure–radius path of the
# run against the exact solution, and the deformed wall coloured by the pressure field.
# Point `EYEMECH_RUN_DIR` at a run's output folder; without it the notebook runs a
# coarse case itself.

# %%
import json
import os
import subprocess
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pyvista as pv

from eyemech.problems.reference import analytic

run_dir = Path(os.environ.get("EYEMECH_RUN_DIR", "results/sphere-inflation"))
if not (run_dir / "results.json").exists():
    eyemech = Path(sys.executable).parent / "eyemech"
    subprocess.run([str(eyemech), "run", "sphere-inflation", "--set", "mesh_size=2",
                    "--out", str(run_dir), "--quiet"], check=True)
results = json.loads((run_dir / "results.json").read_text())
params = results["parameters"]
print({k: round(v, 6) if isinstance(v, float) else v for k, v in results["quantities"].items()})

# %% [markdown]
# ## The load path against the exact solution
# Each converged load step is a point; the line is the exact pressure–radius relation
# p(a) = ∫ 2μ/r (λ² − λ⁻⁴) dr, which has a maximum (the limit point) beyond which
# no inflated equilibrium exists.

# %%
A, B, c10 = params["inner_radius"], params["outer_radius"], params["c10"]
a_limit, p_limit = analytic.sphere_limit_point(A, B, c10)
radii = np.linspace(A, 1.6 * A, 80)
exact = [analytic.sphere_pressure(a, A, B, c10) for a in radii]
steps = results["steps"]
fig, ax = plt.subplots(figsize=(6, 4))
ax.plot(radii / A, exact, label="exact")
ax.plot([s["inner_radius_deformed"] / A for s in steps], [s["pressure"] for s in steps], "o",
        label=f"eyemech ({params['element']}, h = {params['mesh_size']} mm)")
ax.axhline(p_limit, ls=":", c="grey", label="limit point")
ax.set_xlabel("inner stretch a / A")
ax.set_ylabel("pressure (MPa)")
ax.legend()
fig.tight_layout()

# %% [markdown]
# ## The deformed wall
# `state.pvd` indexes one `.vtu` per converged step; the last is the final state.

# %%
pv.OFF_SCREEN = True
series = pv.read(run_dir / "state.pvd")
final = series[len(series) - 1]
warped = final.warp_by_vector("displacement")
plotter = pv.Plotter(off_screen=True, window_size=(700, 500))
plotter.add_mesh(warped, scalars="pressure", show_edges=True)
plotter.view_vector((-1.0, -1.3, 0.8))
image = plotter.screenshot(return_img=True)
plotter.close()
print("rendered", image.shape, "pressure range", final["pressure"].min(), final["pressure"].max())
