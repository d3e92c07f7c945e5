r"""Why the lens is integrated implicitly: the largest stable Δt, explicit against implicit,
and what happens when the contact penalty or the step is pushed (issue 8 §5).

- **Explicit estimate.** Central differences with a lumped mass are stable for
  Δt ≤ 2/ω_max (undamped; mass-proportional damping c changes it by the factor
  √(1+ξ²) − ξ, ξ = c/(2ω_max), < 1 % here). ω_max² is the largest eigenvalue of
  M_L^{-½} K M_L^{-½} with K the shell's tangent stiffness (at the flat and at the rolled
  state) and M_L the HRZ-lumped mass (diagonal of the consistent mass scaled to keep the
  total: P2 row sums are zero at the vertices). A nodal contact penalty k adds at most k to
  a node's diagonal: ω_max² ≤ λ_max(M_L^{-½}(K + k I)M_L^{-½}) (every node in contact, an
  upper bound; computed, not assumed).
- **Explicit, measured.** Central differences from the rolled state for ``explicit_steps``
  steps at Δt = f · 2/ω_max: stable if the displacement stays within 1 mm of the start
  (the physical motion in that time is microns); past the limit round-off in the highest
  mode grows by |λ| > 1 per step and the run blows up.
- **Implicit.** Backward Euler, Newton (fresh Jacobian) and the linearised one-iteration
  step, at Δt from 0.01 to 1 s: linear stability is unconditional; what limits the step is
  whether Newton converges (≤ 25 iterations) and, for the linearised step, whether the
  result stays bounded.
- **Contact penalty pushed.** The lens in the rigid capsule with k = 1…1000 N/mm:
  Newton iterations per step and penetration; the explicit bound for the same k.
"""

from __future__ import annotations

import os
from pathlib import Path

import dolfinx.fem
import dolfinx.fem.petsc
import numpy as np
import scipy.sparse
import scipy.sparse.linalg
import ufl
from mpi4py import MPI

from eyemech.problems import iol_speed
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import QUIET, save_chart, with_units, write_csv


def _csr(A) -> scipy.sparse.csr_matrix:
    indptr, indices, values = A.getValuesCSR()
    return scipy.sparse.csr_matrix((values, indices, indptr), shape=A.getSize())


def lumped_mass(shell) -> np.ndarray:
    """HRZ lumping: the consistent mass' diagonal scaled so each direction keeps the total."""
    M = _csr(_assembled(shell.mass()))
    diagonal = M.diagonal()
    total = M.sum()  # the three directions together: 3 × the lens mass
    return diagonal * (total / diagonal.sum())


def _assembled(form):
    A = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(form))
    A.assemble()
    return A


def highest_frequency(shell, u: np.ndarray, mass: np.ndarray, penalty: float = 0.0) -> float:
    """ω_max (rad/s) of the tangent stiffness at displacement u with the lumped mass;
    ``penalty`` N/mm added to every diagonal entry (all nodes in contact: an upper bound)."""
    shell.u.x.array[:] = u
    shell.u.x.scatter_forward()
    K = _csr(_assembled(ufl.derivative(shell.residual(), shell.u)))
    K = 0.5 * (K + K.T) + penalty * scipy.sparse.identity(K.shape[0])
    scale = scipy.sparse.diags(1.0 / np.sqrt(mass))
    top = scipy.sparse.linalg.eigsh(scale @ K @ scale, k=1, which="LA", return_eigenvectors=False,
                                    tol=1e-6)[0]
    return float(np.sqrt(top))


def central_difference(shell, u0: np.ndarray, mass: np.ndarray, dt: float, steps: int,
                       damping: float) -> tuple[bool, float]:
    """Explicit central differences from rest at u0; (stable, max |u − u0|) after ``steps``."""
    F = dolfinx.fem.form(shell.residual())
    b = dolfinx.fem.petsc.create_vector(shell.V)
    shell.u.x.array[:] = u0
    v = np.zeros_like(u0)
    drift = 0.0
    for _ in range(steps):
        with b.localForm() as local:
            local.set(0.0)
        dolfinx.fem.petsc.assemble_vector(b, F)
        acceleration = -b.array / mass
        v = ((1.0 - 0.5 * damping * dt) * v + dt * acceleration) / (1.0 + 0.5 * damping * dt)
        shell.u.x.array[:] += dt * v
        drift = float(np.max(np.abs(shell.u.x.array - u0)))
        if not np.isfinite(drift) or drift > 1.0:
            return False, drift
    return True, drift


def _implicit(common: dict, overrides: dict, steps: int) -> dict:
    params = iol_speed.Parameters(**{**common, **overrides, "steps": steps})
    try:
        q = iol_speed.run(params, comm=MPI.COMM_SELF, options=QUIET).quantities
    except RuntimeError as err:
        return {"stable": False, "status": str(err)[:100]}
    tip = np.asarray(q["tip_history"])
    finite = bool(np.all(np.isfinite(tip)))
    bounded = finite and float(np.max(np.abs(tip))) < 10.0
    return {"stable": bounded, "status": "ok" if bounded else "unbounded",
            "newton_per_step": q["iterations"] / steps, "max_penetration_mm": q["max_penetration_mm"],
            "tip_end_mm": tip[-1].tolist() if finite else None}


def run(out: Path, quick: bool = False, comm=MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    common = {"mesh_scale": 3.0} if quick else {}
    params = iol_speed.Parameters(**common)
    shell = iol_speed._lens(params)
    u0 = iol_speed.initial_roll(shell, params.roll_radius)
    mass = lumped_mass(shell)
    rows = []
    omega = {}
    for state, u in (("flat", np.zeros_like(u0)), ("rolled", u0)):
        omega[state] = highest_frequency(shell, u, mass)
        rows.append({"kind": "explicit estimate", "state": state, "omega_max": omega[state],
                     "time_step": 2.0 / omega[state], "stable": True})
    critical = 2.0 / omega["rolled"]
    factors = (0.9, 1.1) if quick else (0.5, 0.9, 0.98, 1.02, 1.1, 1.5)
    steps = 60 if quick else 300
    for f in factors:
        stable, drift = central_difference(shell, u0, mass, f * critical, steps, params.damping)
        rows.append({"kind": "explicit central difference", "state": "rolled", "factor": f,
                     "time_step": f * critical, "stable": stable, "max_drift_mm": drift, "steps": steps})
    dts = (0.01,) if quick else (0.01, 0.1, 1.0)
    implicit_steps = 2 if quick else 3
    for method in ("newton", "linearised"):
        for damping in ((params.damping,) if quick else (params.damping, 0.0)):
            for dt in dts:
                r = _implicit(common, {"method": method, "time_step": dt, "damping": damping}, implicit_steps)
                rows.append({"kind": f"implicit backward Euler, {method}", "state": "rolled",
                             "damping": damping, "time_step": dt, "steps": implicit_steps, **r})
    for k in ((1.0,) if quick else (1.0, 10.0, 100.0, 1000.0)):
        w = highest_frequency(shell, u0, mass, penalty=k)
        rows.append({"kind": "explicit estimate with contact", "state": "rolled", "penalty": k,
                     "omega_max": w, "time_step": 2.0 / w, "stable": True})
        for method in ("newton", "linearised"):
            r = _implicit(common, {"method": method, "contact": True, "contact_stiffness": k}, implicit_steps)
            rows.append({"kind": f"implicit with contact, {method}", "state": "rolled", "penalty": k,
                         "time_step": 0.01, "steps": implicit_steps, **r})
    notes = ("largest stable step: explicit central difference (HRZ-lumped mass) vs implicit backward Euler;"
             " lens of iol-speed released from the roll", f"load average {os.getloadavg()[0]:.2f}")
    files = [write_csv(out / "iol_stability.csv", with_units(rows, iol_speed.Parameters), *notes)]
    files.append(_chart(rows, out / "iol_stability.png"))
    return files


def _chart(rows: list[dict], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 5.5), gridspec_kw={"width_ratios": [1.4, 1]})
    labels: list[str] = []
    for row in rows:
        if row["kind"].startswith(("explicit estimate with", "implicit with")):
            continue
        label = row["kind"]
        if "damping" in row:
            label += f", c = {row['damping']:g}/s"
        if row["kind"] == "explicit estimate":
            label += f" ({row['state']})"
        if label not in labels:
            labels.append(label)
        y = labels.index(label)
        colour = "tab:green" if row["stable"] else "tab:red"
        marker = "|" if row["kind"] == "explicit estimate" else ("o" if row["stable"] else "x")
        left.scatter(row["time_step"], y, color=colour, marker=marker, s=120 if marker == "|" else 40)
    left.axvline(0.01, color="grey", ls=":", lw=0.8)
    left.text(0.01, len(labels) - 0.5, " paper Δt = 0.01 s", fontsize=8, color="grey")
    left.set_yticks(range(len(labels)), labels, fontsize=8)
    left.set_xscale("log")
    left.set_xlabel("time step Δt (s)")
    left.set_title("stable (green o) / unstable or not converged (red x); | = 2/ω_max")
    contact = [r for r in rows if r["kind"] == "explicit estimate with contact"]
    k = [r["penalty"] for r in contact]
    right.plot(k, [r["time_step"] for r in contact], "k.-", label="explicit limit 2/ω_max (upper-bound ω)")
    right.set_xscale("log")
    right.set_yscale("log")
    right.set_xlabel("contact penalty k (N/mm)")
    right.set_ylabel("explicit critical Δt (s)")
    twin = right.twinx()
    for method, marker in (("newton", "o"), ("linearised", "s")):
        pts = [r for r in rows if r["kind"] == f"implicit with contact, {method}"]
        twin.plot([r["penalty"] for r in pts], [r.get("newton_per_step", np.nan) if r["stable"] else np.nan
                                                  for r in pts], marker=marker, ls="--",
                  label=f"implicit Δt = 0.01 s, {method}: iterations/step")
        for r in pts:
            if not r["stable"]:
                twin.scatter(r["penalty"], 1.0, color="tab:red", marker="x")
            else:
                twin.annotate(f"pen. {1e3 * r['max_penetration_mm']:.0f} µm",
                              (r["penalty"], r["newton_per_step"]),
                              fontsize=7, xytext=(3, 4), textcoords="offset points")
    twin.set_ylabel("Newton iterations per step (implicit)")
    lines = right.get_legend_handles_labels()[0] + twin.get_legend_handles_labels()[0]
    names = right.get_legend_handles_labels()[1] + twin.get_legend_handles_labels()[1]
    right.legend(lines, names, fontsize=7, loc="upper right")
    right.set_title("pushing the contact penalty")
    save_chart(fig, path)
    return path


STUDY = Study(name="iol-stability", summary="largest stable time step of the lens, explicit central "
              "differences (eigenvalue estimate and measured) vs implicit backward Euler, and the contact "
              "penalty pushed", run=run)
