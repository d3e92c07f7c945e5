"""Large deflection of the clamped square plate (``plate-clamped`` with
``kinematics=nonlinear``, P2 crossed): centre deflection / thickness against the load
parameter Q = q L⁴/(E h⁴), against Levy's von Kármán solution.

- Levy's plate: S. Levy, "Square plate with clamped edges under normal pressure
  producing large deflections", NACA TN 847 (1942) = NACA Report 740, Table 5:
  edges clamped against rotation and against in-plane displacement normal to the
  edge, free to slide along it; ν = 0.316. We run the same conditions
  (``in_plane=sliding``, ``poisson_ratio=0.316``) to Levy's last load Q = 402.
- Immovable edges (u = 0, ν = 0.3), the shell paper's load range q = 0…5 (Q ≤ 458):
  stiffer than Levy (the edges cannot draw in), no published table compared.
"""

from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from eyemech.problems import plate_clamped
from eyemech.problems.shell.model import (
    LEVY_CENTER_DEFLECTION,
    LEVY_LOAD_PARAMETER,
    LEVY_POISSON_RATIO,
)
from eyemech.problems.solve.driver import SolveFailure
from eyemech.problems.studies import Study
from eyemech.problems.studies._common import (
    QUIET,
    failed_row,
    save_chart,
    with_units,
    write_csv,
)


def _curve(case: str, **overrides) -> list[dict]:
    """The load steps of one case (a row each, status ok), or one row with status failed
    when its path did not reach the last load."""
    params = plate_clamped.Parameters(kinematics="nonlinear", **overrides)
    try:
        result = plate_clamped.run(params, comm=MPI.COMM_SELF, options=QUIET)
    except SolveFailure as failure:
        return [failed_row(dict(case=case, divisions=params.divisions), failure)]
    h = params.thickness
    linear_slope = 0.00126532 * params.length ** 4 * 12 * (1 - params.poisson_ratio ** 2) / (
        params.youngs_modulus * params.thickness ** 3)
    return [dict(case=case, divisions=params.divisions, load_parameter=s["load_parameter"], q=s["q"],
                 status="ok", dofs=result.quantities["dofs"], w_over_h=s["center_deflection"] / h,
                 w_over_h_levy=s.get("center_deflection_levy", float("nan")) / h,
                 w_over_h_linear=linear_slope * s["q"] / h, newton_iterations=s["newton_iterations"])
            for s in result.steps]


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    if comm.rank != 0:  # serial study: rank 0 does the work
        return []
    base = plate_clamped.Parameters()
    load_scale = base.youngs_modulus * base.thickness ** 4 / base.length ** 4  # q per unit Q
    divisions = 4 if quick else 16
    levy_top = LEVY_LOAD_PARAMETER[1 if quick else -1]
    rows = _curve("sliding, nu 0.316 (Levy)", divisions=divisions, in_plane="sliding",
                  poisson_ratio=LEVY_POISSON_RATIO, q=levy_top * load_scale, load_steps=2)
    rows += _curve("immovable, nu 0.3", divisions=divisions, q=1.0 if quick else 5.0,
                   load_steps=2 if quick else 10)
    csv_path = write_csv(out / "shell_plate_nonlinear.csv", with_units(rows, plate_clamped.Parameters),
                         "clamped square plate L 10, h 0.1, E 1.092e6, P2 crossed, uniform dead load",
                         "reference: Levy, NACA TN 847 (1942) Table 5, sliding edges, nu 0.316")
    return [csv_path, _chart(out, rows)]


def _chart(out: Path, rows: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axis = plt.subplots(figsize=(6.2, 4.5))
    ok = [r for r in rows if r["status"] == "ok"]
    if ok:
        top = max(r["load_parameter"] for r in ok)
        axis.plot([0, top], [0, ok[0]["w_over_h_linear"] / ok[0]["load_parameter"] * top], "k:",
                  label="linear plate (Timoshenko 0.00126 qL⁴/D)")
    axis.plot([0, *LEVY_LOAD_PARAMETER], [0, *LEVY_CENTER_DEFLECTION], "ks", mfc="none",
              label="Levy 1942, sliding edges, ν = 0.316")
    for case, style in (("sliding, nu 0.316 (Levy)", "o-"), ("immovable, nu 0.3", "^-")):
        mine = [r for r in rows if r["case"] == case]
        name = f"shell, {case.replace('nu', 'ν')}, {mine[0]['divisions']}² crossed P2"
        if mine[0]["status"] != "ok":  # its path did not reach the last load: a cross at the origin
            axis.plot([0], [0], "x", color="tab:red", ms=10, mew=2, clip_on=False,
                      label=f"{name}: solve failed")
            continue
        axis.plot([0] + [r["load_parameter"] for r in mine], [0] + [r["w_over_h"] for r in mine], style,
                  ms=4, label=name)
    axis.set(xlabel="Q = q L⁴ / (E h⁴)", ylabel="centre deflection / thickness",
             title="clamped square plate, large deflection", ylim=(0, 2.6))
    axis.legend(fontsize=7, loc="upper left")
    path = out / "shell_plate_nonlinear.png"
    save_chart(fig, path, dpi=110)
    return path


STUDY = Study(name="shell-plate-nonlinear", summary="clamped plate at large deflection against Levy "
                                                    "(1942), sliding and immovable edges", run=run)
