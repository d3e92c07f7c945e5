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
# Post-processing of `eyemech sweep` for any scene: `sweep.csv` has one row per case (the
# grid values, status, wall time, the scalar quantities and, for a staged scene such as
# `scleral-buckling`, one column group per stage: `after_suturing.axial_length_change_mm`);
# each `case_NNNN/` holds that case's `results.json` (with the per-step records) and, with
# `sweep --fields`, its fields. Point `EYEMECH_SWEEP_DIR` at a sweep's folder (and
# `EYEMECH_SWEEP_QUANTITY` at a column to chart); without it the notebook runs a small one
# itself: `sphere-inflation` with two element families at three pressures (h = 2 mm,
# under a minute). `shown` collects the numbers displayed with where they are.

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
                    "--out", str(sweep_dir), "--quiet", "--fields"], check=True)
with open(sweep_dir / "sweep.csv", newline="") as handle:
    rows = list(csv.DictReader(handle))


def case_results(row: dict) -> tuple[Path, dict]:
    path = sweep_dir / f"case_{int(row['case']):04d}" / "results.json"
    return path, json.loads(path.read_text())


first_path, first = case_results(rows[0])
scene = first["scene"]
columns = list(rows[0])
# sweep.csv's columns: case, the grid's keys, status, then what the case measured
grid_keys = columns[1:columns.index("status")]
ok = [r for r in rows if r["status"] == "ok"]
failed = [r for r in rows if r["status"] != "ok"]
print(f"{scene}: {len(rows)} cases over {', '.join(grid_keys)}; {len(failed)} failed")
for r in failed:
    print(f"  case {r['case']} ({', '.join(f'{k}={r[k]}' for k in grid_keys)}): {r['status']}: "
          f"{r.get('error', '')[:200]}")
if not ok:
    raise RuntimeError(f"every case of {sweep_dir} failed: nothing to compare")
shown: list[tuple[str, str, float]] = []

# %% [markdown]
# ## One quantity across the grid
# The chosen quantity (the first scalar one unless `EYEMECH_SWEEP_QUANTITY` names a
# column), one line per value of the first grid key along the second; ✗ marks a failed
# case. For a staged scene, each stage's value of it side by side.

# %%
skip = {"case", "status", "error", "wall_time_s", "form_compilation_s", *grid_keys}


def number(text: str) -> float | None:
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


numeric = [k for k in rows[0] if k not in skip and "." not in k and number(ok[0].get(k)) is not None]
quantity = os.environ.get("EYEMECH_SWEEP_QUANTITY", numeric[0] if numeric else "")
stages = [k.split(".", 1)[0] for k in rows[0] if k.endswith(f".{quantity}")]
series_key, x_key = (grid_keys[0], grid_keys[1]) if len(grid_keys) > 1 else (None, grid_keys[0])


def along_x(row: dict):
    """The case's value of the x key: a number where it is one (else a category)."""
    value = number(row[x_key])
    return row[x_key] if value is None else value


charted = [f"{stage}.{quantity}" for stage in stages] or [quantity]
fig, axes = plt.subplots(1, len(charted) + 1, figsize=(4.2 * (len(charted) + 1), 3.6),
                         squeeze=False)
for ax, column in zip(axes[0], charted):
    for value in dict.fromkeys(r[series_key] for r in rows) if series_key else [None]:
        mine = [r for r in rows if series_key is None or r[series_key] == value]
        xs = [along_x(r) for r in mine if r["status"] == "ok"]
        ys = [float(r[column]) for r in mine if r["status"] == "ok"]
        label = f"{series_key} = {value}" if series_key else None
        ax.plot(xs, ys, "o-", label=label)
        ax.plot([along_x(r) for r in mine if r["status"] != "ok"],
                [0.0] * sum(r["status"] != "ok" for r in mine), "rx", ms=9, mew=2)
    ax.set(xlabel=x_key, ylabel=column, title=column.split(".", 1)[0] if stages else "")
    if all(isinstance(along_x(r), float) for r in rows):
        ax.set_xticks(sorted({along_x(r) for r in rows}))
    ax.grid(alpha=0.3)
    if series_key:
        ax.legend(fontsize=8)
for r in ok:
    path, data = case_results(r)
    for column in charted:
        stage, _, key = column.rpartition(".")
        where = f"quantities.{stage}.{key}" if stage else f"quantities.{key}"
        shown.append((str(path), where, float(r[column])))
cost = axes[0][-1]
for r in ok:
    cost.bar(f"{r['case']}", float(r["wall_time_s"]), color="tab:grey")
cost.set(xlabel="case", ylabel="wall time (s)", title="cost")
fig.tight_layout()
plt.show()

# %% [markdown]
# ## Inside each case: the path from its results.json
# The chosen quantity along each case's load or time steps, where the steps record it.

# %%
paths = {}
for r in ok:
    steps = case_results(r)[1]["steps"]
    along = next((k for k in ("load_factor", "load", "time") if steps and k in steps[0]), None)
    if along is not None and quantity in steps[-1]:
        paths[r["case"]] = (r, along, steps)
if max((len(steps) for _, _, steps in paths.values()), default=0) > 1:
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for r, along, steps in paths.values():
        ax.plot([s[along] for s in steps], [s.get(quantity, np.nan) for s in steps], "o-", ms=3,
                label=f"case {r['case']}: " + ", ".join(f"{k}={r[k]}" for k in grid_keys))
        ax.set(xlabel=along, ylabel=quantity)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    plt.show()
else:
    print(f"every case took its load in one step: no path to draw for {quantity}")

# %% [markdown]
# ## The first and the last case side by side
# Their last converged step from their `.pvd` series (written with `sweep --fields`),
# coloured by the displacement's magnitude on one scale from zero.

# %%
pv.OFF_SCREEN = True
pair = [ok[0], ok[-1]]
series = [next(iter(sorted((sweep_dir / f"case_{int(r['case']):04d}").glob("*.pvd"))), None)
          for r in pair]
if all(series):
    grids = []
    for r, path in zip(pair, series):
        reader = pv.get_reader(str(path))
        reader.set_active_time_value(reader.time_values[-1])
        grid = reader.read()[0]
        grid.point_data["displacement (mm)"] = np.linalg.norm(grid.point_data["displacement"], axis=1)
        grids.append(grid)
        steps = case_results(r)[1]["steps"]
        along = next((k for k in ("load_factor", "load", "time") if steps and k in steps[0]), None)
        if along:
            shown.append((str(path.parent / "results.json"), f"steps.-1.{along}",
                          reader.active_time_value))  # the state drawn: the last step's
    top = max(float(g["displacement (mm)"].max()) for g in grids)
    plotter = pv.Plotter(off_screen=True, shape=(1, 2), window_size=(1000, 450))
    for column, (r, grid) in enumerate(zip(pair, grids)):
        plotter.subplot(0, column)
        plotter.add_mesh(grid.warp_by_vector("displacement"), scalars="displacement (mm)",
                         clim=(0.0, top), show_edges=True,
                         scalar_bar_args={"title": "displacement (mm)", "fmt": "%.3g"})
        plotter.add_text(f"case {r['case']}: " + ", ".join(f"{k}={r[k]}" for k in grid_keys),
                         font_size=9)
        plotter.view_isometric()
    plotter.show(jupyter_backend="static")
else:
    print("no fields in the cases (run the sweep with --fields to see them)")
