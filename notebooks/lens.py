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
# # The intra-ocular lens: folded, pushed, unfolding
#
# Post-processing of `eyemech run iol-injection` (or `iol-fold`): the lens is a nonlinear
# Kirchhoff–Love shell (P2, optic 0.2 mm and haptics 0.13 mm thick) integrated by damped
# implicit dynamics. Every frame of the run is a `.vtu` file indexed by `injection.pvd`
# (`fold.pvd` for a fold run) with the displacement and, per cell, the thickness, the part
# (optic / haptic) and the largest surface strain; `results.json` holds the per-step records.
#
# Point `EYEMECH_RUN_DIR` at a run's output folder, e.g. of the whole operation
# (`eyemech run iol-fold --out F` then `eyemech run iol-injection --set
# folded_state=F/folded_state.npz --out I`: about 54 min here, fold 9.6 and injection 44,
# docs/iol.md). Without one, the notebook makes
# the cheapest honest lens run itself (about half a minute): **the deformation-only
# injection** — `contact=false`, so no cartridge, plunger, capsule or self-contact — starting
# from the lens rolled in closed form onto a 3 mm cylinder (the start of the `iol-speed`
# benchmark) instead of `iol-fold` (10–20 min here), on a coarser optic (1.2 mm triangles).
# What it shows is the released lens unrolling in the damping fluid, not an injection.

# %%
import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pyvista as pv

run_dir = Path(os.environ.get("EYEMECH_RUN_DIR", "results/iol-injection"))
if not (run_dir / "results.json").exists():
    from mpi4py import MPI

    from eyemech.problems import iol_injection
    from eyemech.problems.iol_speed import initial_roll
    from eyemech.problems.lens.model import LensShell, save_state

    run_dir.mkdir(parents=True, exist_ok=True)
    small = {"mesh_size": 1.2, "contact": False, "plunger_speed": 52.0, "settle_time": 0.0,
             "frames_every": 3}
    shell = LensShell(iol_injection.Parameters(**{"mesh_size": small["mesh_size"]}), MPI.COMM_SELF)
    shell.u.x.array[:] = initial_roll(shell, radius=3.0)
    save_state(run_dir / "rolled_state.npz", shell, MPI.COMM_SELF)
    eyemech = Path(sys.executable).parent / "eyemech"
    settings = [a for k, v in small.items() for a in ("--set", f"{k}={str(v).lower()}")]
    subprocess.run([str(eyemech), "run", "iol-injection", *settings,
                    "--set", f"folded_state={run_dir / 'rolled_state.npz'}",
                    "--out", str(run_dir), "--quiet"], check=True)
results = json.loads((run_dir / "results.json").read_text())
params, q, steps = results["parameters"], results["quantities"], results["steps"]
scene = results.get("scene", "iol-injection")
contact = params.get("contact", True)  # iol-fold has no switch: its chamber is always there
where = str(run_dir / "results.json")
shown = [(where, f"quantities.{k}", q[k]) for k in ("triangles", "dofs", "steps",
                                                     "steps_per_second", "haptic_max_strain")]
print(f"{scene}: {q['triangles']} triangles, {q['dofs']} dofs, {q['steps']} steps, "
      f"{sum(s['newton_iterations'] for s in steps)} Newton iterations, {q['steps_per_second']:.2f} steps/s")
# contact=false switches self-contact off too (iol_injection.inject), whatever the flag says
print(f"rigid contact {'on' if contact else 'off'}; self-contact forces: "
      f"{q['self_contact_forces'] if contact else 'off (contact=false)'}")
print(f"haptic max surface strain {100 * q['haptic_max_strain']:.1f} %, max penetration "
      f"{q['max_penetration_mm']:.2g} mm, self-intersecting: {q['self_intersecting']}, min self distance: "
      + (f"{q['min_self_distance_mm']:.3g} mm" if q["min_self_distance_mm"] is not None
         else "no pair within ipctk's 0.25 mm search radius"))
if contact:
    for key in ("lens_exited", "optic_flipped", "optic_normal_z", "final_decentration_mm"):
        if key in q:
            print(f"  {key} = {q[key]}")
else:
    print(f"optic normal z = {q.get('optic_normal_z', float('nan')):.3f} (1: unrolled flat, face up)")

# %% [markdown]
# ## Time series
# Per step: the plunger position (it only moves in an injection with contact), the kinetic
# energy (the unfolding's violence), the Newton iterations (the cost) and, per frame, the
# smallest distance between two parts of the lens' mid-surface (ipctk; with self-contact it is
# kept above zero, without it the haptics may pass through the optic).

# %%
t = np.array([s["time"] for s in steps])
fig, axes = plt.subplots(1, 4, figsize=(15, 3.4))
if "plunger" in steps[0]:
    axes[0].plot(t, [s["plunger"] for s in steps], "-", c="tab:gray")
axes[0].set(xlabel="t (s)", ylabel="plunger face x (mm)")
if "kinetic_energy" in steps[0]:
    axes[1].semilogy(t, np.maximum([s["kinetic_energy"] for s in steps], 1e-30), "-", c="tab:red")
axes[1].set(xlabel="t (s)", ylabel="kinetic energy (mJ)")
axes[2].bar(t, [s["newton_iterations"] for s in steps], width=0.8 * np.diff(t, prepend=0.0),
            color=["tab:orange" if s["cuts"] else "tab:blue" for s in steps])
axes[2].set(xlabel="t (s)", ylabel="Newton iterations (orange: after a cut)")
distance = np.array([d if d is not None else np.nan for d in q.get("self_distance_mm", [])], float)
if len(distance) == len(t) and np.isfinite(distance).any():
    finite = np.isfinite(distance)
    axes[3].semilogy(t[finite], distance[finite], "o-", ms=3)
else:
    axes[3].text(0.5, 0.5, "no two parts within\nipctk's search radius", ha="center", va="center",
                 transform=axes[3].transAxes)
axes[3].set(xlabel="t (s)", ylabel="min self distance (mm)")
for ax in axes:
    ax.grid(alpha=0.3)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## The frames
# The `.pvd` index lists the frames with their times; each `.vtu` is read as it is.

# %%
from eyemech.problems.run.output import quiet_vtk

pv.OFF_SCREEN = True
quiet_vtk()  # no X display: VTK says so before rendering off-screen
index = run_dir / ("injection.pvd" if (run_dir / "injection.pvd").exists() else "fold.pvd")
entries = [(float(d.get("timestep")), run_dir / d.get("file")) for d in ET.parse(index).iter("DataSet")]
frames = [pv.read(path) for _, path in entries]
# the state the run started from (the saved fold, or the closed-form roll) is not a frame:
# put its displacement on the first frame's points (the same P2 nodes, matched by position)
start_file = Path(params.get("folded_state") or "")
if start_file.is_file():
    from scipy.spatial import cKDTree

    saved = np.load(start_file)
    start = frames[0].copy()
    nearest = cKDTree(saved["coordinates"]).query(start.points)[1]
    start.point_data["displacement"] = saved["displacement"][nearest]
    start.cell_data["surface strain"] = np.full(start.n_cells, np.nan)  # not saved with the state
    entries.insert(0, (0.0, start_file))
    frames.insert(0, start)
print(f"{len(frames)} frames from {index.name}, t = {entries[0][0]:.3f} … {entries[-1][0]:.3f} s; "
      f"cell data {list(frames[0].cell_data)}")


def deformed(grid):
    return grid.warp_by_vector("displacement")


def proximity(grid, separation: float = 2.0) -> np.ndarray:
    """Per node, the distance to the nearest node of another part of the lens: a node that
    was at least ``separation`` away in the flat lens (``separation`` where there is none
    closer). Node to node, so an upper bound of the mid-surface distance that ipctk measures
    exactly; it shows where layers of the folded lens approach each other."""
    from scipy.spatial import cKDTree

    x = grid.points + grid.point_data["displacement"]
    pairs = cKDTree(x).query_pairs(separation, output_type="ndarray")
    apart = np.linalg.norm(grid.points[pairs[:, 0]] - grid.points[pairs[:, 1]], axis=1) >= separation
    pairs = pairs[apart]
    distance = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
    result = np.full(len(x), separation)
    np.minimum.at(result, pairs[:, 0], distance)
    np.minimum.at(result, pairs[:, 1], distance)
    return result


# one camera for every picture: the lens seen from the side of the injector axis (x),
# framing the whole run
bounds = np.array([deformed(g).bounds for g in frames])
low, high = bounds[:, 0::2].min(axis=0), bounds[:, 1::2].max(axis=0)
everything = [low[0], high[0], low[1], high[1], low[2], high[2]]


def place_camera(plotter):
    plotter.view_vector((-1.0, -1.6, 1.1), viewup=(0.0, 0.0, 1.0))
    plotter.reset_camera(bounds=everything)
    plotter.camera.zoom(1.05)


def lens_view(plotter, grid, scalars, title, **kw):
    plotter.add_mesh(deformed(grid), scalars=scalars, show_edges=True, edge_color="#333333",
                     line_width=0.3, scalar_bar_args={"title": scalars, "n_labels": 3}, **kw)
    plotter.add_text(title, font_size=9)
    place_camera(plotter)


def show(plotter, size):
    image = plotter.screenshot(return_img=True)
    plotter.close()
    plt.figure(figsize=size)
    plt.imshow(image)
    plt.axis("off")
    return image


# %% [markdown]
# ## Start, first and last frame: proximity, surface strain, thickness
# Left: the state the run started from (the saved fold, or the closed-form roll), coloured by
# how close other parts of the lens come — nodes that were ≥ 2 mm apart in the flat lens
# (2 mm: none closer; node to node, so an upper bound of ipctk's exact mid-surface
# distance). Middle and right: the first and the last frame, coloured by the largest surface
# strain |eig(E ± h/2 K)| of each cell. Below: the thickness field and the strain per part.

# %%
has_start = start_file.is_file()
start, first, last = frames[0], frames[1 if has_start else 0], frames[-1]
for grid in (start, last):
    grid.point_data["proximity (mm)"] = proximity(grid)
strain_range = (0.0, max(float(g.cell_data["surface strain"].max()) for g in (first, last)))
k_first = 1 if has_start else 0
plotter = pv.Plotter(off_screen=True, shape=(1, 3), window_size=(1500, 480))
plotter.subplot(0, 0)
lens_view(plotter, start, "proximity (mm)", "start (t = 0): other parts within", cmap="viridis",
          clim=(0.0, 2.0))
plotter.subplot(0, 1)
lens_view(plotter, first, "surface strain", f"t = {entries[k_first][0]:.3f} s", clim=strain_range,
          cmap="magma")
plotter.subplot(0, 2)
lens_view(plotter, last, "surface strain", f"t = {entries[-1][0]:.3f} s", clim=strain_range, cmap="magma")
show(plotter, (15, 4.8))
for name, grid in (("first", first), ("last", last)):
    optic = grid.cell_data["optic"] > 0.5
    h = grid.cell_data["thickness (mm)"]
    s = grid.cell_data["surface strain"]
    print(f"{name} frame: optic h = {h[optic].mean():.3f} mm, max strain {100 * s[optic].max():.1f} %; "
          f"haptics h = {h[~optic].mean():.3f} mm, max strain {100 * s[~optic].max():.1f} %")
print(f"closest approach of other parts: start {start.point_data['proximity (mm)'].min():.3f} mm, "
      f"end {last.point_data['proximity (mm)'].min():.3f} mm")

# %% [markdown]
# ## Frame strip and animation
# Six frames evenly over the run, coloured optic / haptic, and an animated GIF of all frames
# (written next to the run as `lens_frames.gif`).

# %%
picked = np.unique(np.linspace(0, len(frames) - 1, 6).round().astype(int))
images = []
for i in range(len(frames)):
    plotter = pv.Plotter(off_screen=True, window_size=(600, 360))
    plotter.add_mesh(deformed(frames[i]), scalars="optic", cmap=["#d9a441", "#5b9bd5"], show_edges=True,
                     line_width=0.3, show_scalar_bar=False)
    plotter.add_text(f"t = {entries[i][0]:.3f} s", font_size=10)
    place_camera(plotter)
    images.append(plotter.screenshot(return_img=True))
    plotter.close()
fig, axes = plt.subplots(1, len(picked), figsize=(3 * len(picked), 2.2))
for ax, i in zip(np.atleast_1d(axes), picked):
    ax.imshow(images[i])
    ax.axis("off")
fig.tight_layout()
try:
    import imageio.v2 as imageio

    imageio.mimsave(run_dir / "lens_frames.gif", images, duration=0.15, loop=0, format="GIF")
    print("animation:", run_dir / "lens_frames.gif", f"({len(images)} frames)")
except ImportError:
    print("imageio is missing (the 'iol' extra): no animation")

# %% [markdown]
# With contact (the default `iol-injection`), the same cells show the lens in the bore, the
# plunger's travel, the penetration of the rigid bodies and the self distance kept positive
# by the barrier; `docs/iol.md` has the measured runs and what is not done yet.
