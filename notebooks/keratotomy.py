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
# # Radial keratotomy: refractive change over hours
#
# Post-processing of `eyemech run keratotomy`: the corneal power of the intact and the
# incised cornea over the creep period, the power change (negative = flattening, the
# surgery's aim), the gape of the cuts, and the deformed incised cornea in pyvista.
# Point `EYEMECH_RUN_DIR` at a run's output folder; without it the notebook runs a coarse
# case itself (2 mm planform elements, 8 incisions, 1 h of creep: about 20 s here).
# `shown` collects the numbers displayed with where they are in `results.json`
# (tests/test_notebooks.py checks them).

# %%
import json
import os
import subprocess
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pyvista as pv

run_dir = Path(os.environ.get("EYEMECH_RUN_DIR", "results/keratotomy"))
if not (run_dir / "results.json").exists():
    eyemech = Path(sys.executable).parent / "eyemech"
    subprocess.run([str(eyemech), "run", "keratotomy", "--set", "mesh_size=2.0",
                    "--set", "t_end=3600", "--set", "first_dt=900", "--set", "dt_growth=1.5",
                    "--set", "time_stepping=fixed",
                    "--out", str(run_dir), "--quiet"], check=True)
results = json.loads((run_dir / "results.json").read_text())
params, q = results["parameters"], results["quantities"]
where = str(run_dir / "results.json")
shown = [(where, "quantities.power_change_initial_D", q["power_change_initial_D"]),
         (where, "quantities.power_change_final_D", q["power_change_final_D"]),
         (where, "quantities.creep_power_change_D", q["creep_power_change_D"])]
print(f"{params['incisions']} incisions, {params['incision_depth']:.0%} deep, optical zone "
      f"{params['optical_zone']} mm, IOP {params['iop_mmHg']} mmHg, τ = {params['tau'] / 3600:g} h")
print(f"power change at t = 0: {q['power_change_initial_D']:+.2f} D, after "
      f"{q['times'][-1] / 3600:g} h: {q['power_change_final_D']:+.2f} D "
      f"(creep adds {q['creep_power_change_D']:+.2f} D)")

# %% [markdown]
# ## Power and gape over time
# The keratometric power is 337.5 / R, R from a sphere fitted through the central anterior
# nodes. Both corneas creep; the difference is what the incisions do.

# %%
hours = np.array(q["times"]) / 3600.0
fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
axes[0].plot(hours, q["intact_power_D"], "o-", label="intact")
axes[0].plot(hours, q["power_D"], "s-", label="incised")
axes[0].axhline(q["unloaded_power_D"], ls=":", c="grey", label="unloaded")
axes[0].set(xlabel="time (h)", ylabel="power (D)")
axes[0].legend()
axes[1].plot(hours, q["power_change_D"], "o-", c="tab:red")
axes[1].set(xlabel="time (h)", ylabel="power change, incised − intact (D)")
axes[2].plot(hours, 1000 * np.array(q["wound_gape_mm"]), "o-", c="tab:purple")
axes[2].set(xlabel="time (h)", ylabel="mean gape of the cuts (µm)")
for ax in axes:
    ax.grid(alpha=0.3)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## The incised cornea, deformed
# The scene writes no field files yet, so this cell rebuilds the incised cornea of the run
# (same parameters) and solves its instantaneous response to the IOP — the glassy state at
# t = 0 of the run — then shows it in pyvista, coloured by the displacement. The cuts open
# where the colour jumps.

# %%
import dataclasses

try:  # the PyPI DOLFINx wheel: MPI ordered before the bindings
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass
import dolfinx
from mpi4py import MPI

from eyemech.problems import keratotomy as kt
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.output import gather_grid
from eyemech.problems.run.parameters import build
from eyemech.problems.solve.driver import Stepping, follow_path

known = {f.name for f in dataclasses.fields(kt.Parameters)}
scene_params = build(kt.Parameters, {k: v for k, v in params.items() if k in known})
with RunContext("keratotomy", scene_params, MPI.COMM_WORLD, None, RunOptions()) as ctx:
    body = kt.Cornea(scene_params, scene_params.incisions, ctx.comm,
                     scene_params.geometry(scene_params.incisions).azimuths)
    body.history.dt.value = 0.0
    follow_path(body.solver(ctx),
                lambda f, _i: setattr(body.pressure, "value", f * scene_params.iop_mmHg * kt.MMHG),
                Stepping(initial_step=1.0), quiet=True)
print(f"glassy power {body.power_D():.4f} D (run: {q['power_D'][0]:.4f} D at t = 0)")
shown.append((where, "quantities.power_D.0", body.power_D()))

nodal = dolfinx.fem.functionspace(body.tagged.mesh, ("Lagrange", 1, (3,)))
u1 = dolfinx.fem.Function(nodal, name="displacement")
u1.interpolate(body.u)
grid = gather_grid(u1)
grid.point_data["displacement (mm)"] = np.linalg.norm(grid.point_data["displacement"], axis=1)
pv.OFF_SCREEN = True
plotter = pv.Plotter(off_screen=True, window_size=(700, 550))
plotter.add_mesh(grid.warp_by_vector("displacement", factor=5.0), scalars="displacement (mm)",
                 cmap="viridis", show_edges=True, clim=(0.0, float(grid["displacement (mm)"].max())),
                 scalar_bar_args={"title": "displacement (mm)", "fmt": "%.3g"})
plotter.add_text("the incised cornea at t = 0, displacement × 5", font_size=10)
plotter.view_vector((0.3, -1.0, 1.4))
plotter.show(jupyter_backend="static")
print("max displacement", float(grid["displacement (mm)"].max()), "mm")
