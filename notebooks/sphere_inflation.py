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
# coarse case itself. `shown` collects every number displayed with where it is in
# `results.json` (tests/test_notebooks.py checks them).

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
params, quantities = results["parameters"], results["quantities"]
shown: list[tuple[str, str, float]] = []
for key in ("inner_radius_deformed", "inner_radius_exact", "inner_radius_error", "cavity_volume"):
    if key in quantities:
        print(f"{key:24s} {quantities[key]:.6g}")
        shown.append((str(run_dir / "results.json"), f"quantities.{key}", quantities[key]))

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
plt.show()

# %% [markdown]
# ## The deformed wall
# `state.pvd` indexes one `.vtu` per converged step at its load factor (0: unloaded); a
# reader picks the last, the loaded sphere (`pv.read` would give the first). The mesh is
# the sphere's octant (symmetry planes); the colour is the pressure field p (MPa).

# %%
pv.OFF_SCREEN = True
reader = pv.get_reader(str(run_dir / "state.pvd"))
reader.set_active_time_value(reader.time_values[-1])
final = reader.read()[0]
points = final.points + final.point_data["displacement"]
radii = np.linalg.norm(points, axis=1)
inner = radii[np.isclose(np.linalg.norm(final.points, axis=1), A, atol=1e-6 * A)]
print(f"load factor {reader.active_time_value:g}: deformed inner radius {inner.mean():.6g} mm "
      f"(results.json {quantities['inner_radius_deformed']:.6g}), pressure field "
      f"{final['pressure'].min():.4g} … {final['pressure'].max():.4g} MPa")
# the state drawn is the one the reader holds: its load factor must be the last step's
shown.append((str(run_dir / "results.json"), "steps.-1.load_factor", reader.active_time_value))
warped = final.warp_by_vector("displacement")
plotter = pv.Plotter(off_screen=True, window_size=(700, 500))
plotter.add_mesh(warped, scalars="pressure", show_edges=True, cmap="viridis",
                 scalar_bar_args={"title": "pressure p (MPa)", "fmt": "%.3g"})
plotter.view_vector((-1.0, -1.3, 0.8))
plotter.show(jupyter_backend="static")
