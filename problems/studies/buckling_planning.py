"""A planning map for scleral buckling on the living eye: the surgeon's factors swept one
at a time from the scene's defaults on the coarse eye, each case's tear verdict after
suturing and settled (closed / open / uncertain, the last where the margin to the closure
tolerance lies within the discretisation's error band), and what each setting costs: the
axial length and refraction changes from the eye before surgery, the peak IOP and the
liquid vented.

Factors (each case changes one from ``scleral_buckling.Parameters()``): the buckle kind
(band + tire, the band alone, the tire alone moving in by ``indentation``), the band's
shortening and width, the tire's width and arc, the buckle's position against the tear,
the sutures' width and force, the venting limit (Gardner et al. 1993: 48-110 mmHg) and the
detachment's height (1.0 mm: bullous). A tire wider than the default sutures' bites keeps
the default bites' overhang (the scene refuses bites narrower than the tire). Every case
runs with ``error_estimate=true``: the operation is solved again on the default mesh and
each stage reports ``tear_verdict`` and the bands (docs/scleral_buckling.md,
"Discretisation error"). ``quick``: the defaults and the tire alone.

Writes ``buckling_planning.csv``, the chart ``buckling_planning.png`` and the atlas page's
table ``buckling_planning_table.md`` (:func:`markdown_table`: one row per case, made from
the rows so that the page needs no hand edit; tests/test_buckling_planning_table.py holds
the page to the committed CSV).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from mpi4py import MPI

from eyemech.problems import scleral_buckling
from eyemech.problems.run.parameters import build
from eyemech.problems.run.sweep import run_sweep
from eyemech.problems.studies import FAILED, Study
from eyemech.problems.studies._common import QUIET, save_chart, write_csv

BASE = {"resolution": "coarse", "error_estimate": "true"}
DEFAULTS_FACTOR = "defaults"
# (parameter, values other than the scene's default): one case per value
FACTORS = (("buckle", ("encircling", "segmental")),
           ("band_shortening_percent", ("10", "15", "20", "30")),
           ("band_width", ("1.0", "2.0")),
           ("tire_width", ("5.0", "9.0")),
           ("tire_arc_deg", ("60", "180")),
           ("buckle_position", ("12.0", "12.5", "13.5")),
           ("suture_width", ("8.0", "10.0")),
           ("suture_force", ("0.1", "0.5")),
           ("iop_limit_mmHg", ("48", "110")),
           ("detachment_height", ("0.25", "1.0")))
QUICK_FACTORS = (("buckle", ("segmental",)),)
BUCKLE_KINDS = {"encircling+segmental": "band + tire", "encircling": "band alone",
                "segmental": "tire alone"}
# (CSV prefix, the scene's stage): acute after suturing, settled after the IOP returned
STAGES = (("acute", "after_suturing"), ("settled", "after_settling"))
# (CSV column, the scene's quantity) per stage
STAGE_COLUMNS = (("tear_rim_gap_max_mm", "tear_rim_gap_max_mm"),
                 ("tear_rim_gap_band_mm", "tear_rim_gap_max_mm_error_estimate"),
                 ("tear_rim_margin_mm", "tear_rim_margin_mm"),
                 ("tear_verdict", "tear_verdict"),
                 ("axial_length_change_mm", "axial_length_change_mm"),
                 ("axial_length_change_band_mm", "axial_length_change_mm_error_estimate"),
                 ("refraction_change_D", "refraction_change_D"),
                 ("refraction_change_band_D", "refraction_change_D_error_estimate"),
                 ("peak_iop_mmHg", "peak_iop_mmHg"),
                 ("vented_volume_uL", "vented_volume_uL"),
                 ("venting_route", "venting_route"),
                 ("band_tension_N", "band_tension_N"),
                 ("buckle_indentation_mm", "buckle_indentation_mm"))
# the parameters a row names, with their units in the column's name
NAMED = (("buckle", "buckle"), ("band_shortening_percent", "band_shortening_percent"),
         ("band_width", "band_width_mm"), ("tire_width", "tire_width_mm"),
         ("tire_arc_deg", "tire_arc_deg"), ("buckle_position", "buckle_position_mm"),
         ("suture_width", "suture_width_mm"), ("suture_force", "suture_force_N"),
         ("iop_limit_mmHg", "iop_limit_mmHg"), ("detachment_height", "detachment_height_mm"))
VERDICT_STYLE = {"closed": "full", "open": "none", "uncertain": "left"}


def cases(quick: bool = False) -> list[tuple[str, dict[str, str]]]:
    """(factor, the scene's overrides) of every case, the defaults first; each built (so
    validated) here, before anything runs: a refused value stops the study, exit 2."""
    defaults = scleral_buckling.Parameters()
    out = [(DEFAULTS_FACTOR, dict(BASE))]
    for factor, values in QUICK_FACTORS if quick else FACTORS:
        for value in values:
            overrides = BASE | {factor: value}
            if factor == "tire_width":  # the bites keep the default's overhang of the tire
                overrides["suture_width"] = f"{float(value) + defaults.suture_width - defaults.tire_width:g}"
            out.append((factor, overrides))
    for _, overrides in out:
        build(scleral_buckling.Parameters, overrides)
    return out


def run(out: Path, quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD) -> list[Path]:
    out = Path(out)
    rows = []
    for factor, overrides in cases(quick):
        varied = {k: v for k, v in overrides.items() if k not in BASE}
        setting = ", ".join(f"{k}={v}" for k, v in varied.items()) or DEFAULTS_FACTOR
        folder = out / "buckling_planning_cases" / setting.replace(", ", "_")
        key = next(iter(varied), "buckle")
        grid = {key: [overrides.get(key, getattr(scleral_buckling.Parameters(), key))]}
        base = {k: v for k, v in overrides.items() if k != key}
        swept = run_sweep(scleral_buckling.SCENE, base, grid, folder, options=QUIET, comm=comm)
        rows += [_row(factor, setting, overrides, case) for case in swept]
    if comm.rank != 0:
        return []
    table = write_csv(out / "buckling_planning.csv", rows,
                      "acute: after suturing; settled: after the IOP has returned; *_band_*: "
                      "the scene's error_estimate (GCI, the coarse eye against the default mesh)")
    chart = out / "buckling_planning.png"
    _chart(rows, chart)
    markdown = out / "buckling_planning_table.md"
    markdown.write_text(markdown_table(rows) + "\n")
    return [table, chart, markdown]


def markdown_table(rows: list[dict]) -> str:
    """The atlas page's table: per case (the CSV's rows, as written or read back) the rim
    after suturing and settled with its band and verdict (closed in bold), ΔAL and ΔSE
    sutured / settled, the operation's peak IOP, the liquid vented and how, and the band's
    tension; a failed case says so and why."""
    header = ("| setting | rim after suturing (mm) | rim settled (mm) | ΔAL sutured / settled (mm) "
              "| ΔSE sutured / settled (D) | peak IOP (mmHg) | vented (µL), route "
              "| band tension sutured / settled (N) |")
    lines = [header, "|---|---|---|---|---|---|---|---|"]
    for row in rows:
        label = _case_label(row)
        if row["status"] in FAILED:
            lines.append(f"| {label} | {row['status']}: {row.get('error', '')} |" + " |" * 6)
            continue
        pair = (lambda key, fmt: " / ".join(_signed(row.get(f"{stage}_{key}"), fmt)
                                            for stage in ("acute", "settled")))
        vented = _number(row.get("acute_vented_volume_uL"))
        tension = pair("band_tension_N", ".2f") if row.get("acute_band_tension_N") not in (None, "") \
            else "—"
        cells = [label, _rim_cell(row, "acute"), _rim_cell(row, "settled"),
                 pair("axial_length_change_mm", "+.2f"), pair("refraction_change_D", "+.2f"),
                 f"{_number(row.get('operation_peak_iop_mmHg')):.0f}",
                 f"{vented:.0f}, {_route_words(row.get('acute_venting_route', ''))}", tension]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _case_label(row: dict) -> str:
    """A case in words, as the atlas page names it."""
    factor = row["factor"]
    if factor == DEFAULTS_FACTOR:
        return "**defaults**"
    if factor == "buckle":
        if row["buckle"] == "segmental":
            travel = scleral_buckling.Parameters().indentation
            return f"tire alone ({travel:.1f} mm of travel)"
        return BUCKLE_KINDS[row["buckle"]]
    value = _number(row[dict(NAMED)[factor]])
    words = {"band_shortening_percent": "band shortened {:g} %", "band_width": "band {:g} mm wide",
             "tire_arc_deg": "tire over {:g}°", "buckle_position": "buckle at {:g} mm",
             "suture_width": "bites {:g} mm wide", "suture_force": "sutures {:g} N",
             "iop_limit_mmHg": "vented at {:g} mmHg", "detachment_height": "detachment {:g} mm high"}
    if factor == "tire_width":
        return f"tire {value:g} mm (bites {_number(row['suture_width_mm']):g} mm)"
    return words[factor].format(value)


def _rim_cell(row: dict, stage: str) -> str:
    """``gap ± band verdict`` (closed in bold; no band without the estimate)."""
    gap, band = row.get(f"{stage}_tear_rim_gap_max_mm"), row.get(f"{stage}_tear_rim_gap_band_mm")
    verdict = row.get(f"{stage}_tear_verdict") or ""
    verdict = f"**{verdict}**" if verdict == "closed" else verdict
    spread = f" ± {_number(band):.3f}" if band not in (None, "") else ""
    return f"{_signed(gap, '.3f')}{spread} {verdict}".strip()


def _signed(value, fmt: str) -> str:
    """A number as the docs print it (the minus sign −); a dash for none."""
    if value in (None, ""):
        return "—"
    return format(_number(value), fmt).replace("-", "−")


def _route_words(route: str) -> str:
    """``venting_route`` (scleral_buckling/venting.py) in the table's words."""
    return {"paracentesis and subretinal drainage": "+ subretinal drainage",
            "exceeds paracentesis and subretinal drainage": "**exceeds both**"}.get(route, route)


def _row(factor: str, setting: str, overrides: dict[str, str], case: dict[str, Any]) -> dict[str, Any]:
    """One CSV row: the case's factor, what it changed and its parameters, its status, and
    per stage the tear's verdict and the costs."""
    params = build(scleral_buckling.Parameters, overrides)
    row: dict[str, Any] = {"factor": factor, "setting": setting}
    row |= {column: getattr(params, name) for name, column in NAMED}
    row["status"] = case["status"]
    if case["status"] in FAILED:
        return row | {"error": case.get("error", "")}
    for prefix, stage in STAGES:
        row |= {f"{prefix}_{column}": case.get(f"{stage}.{quantity}")
                for column, quantity in STAGE_COLUMNS}
        row[f"{prefix}_tear_rim_gap_meshes_apart_mm"] = _meshes_apart(
            row[f"{prefix}_tear_rim_gap_band_mm"], case)
    peaks = [case.get(f"{stage}.peak_iop_mmHg") for stage in ("after_buckling", "after_suturing")]
    row["operation_peak_iop_mmHg"] = max((p for p in peaks if p is not None), default=None)
    row["error_estimate_mesh"] = case.get("error_estimate_mesh")
    row["error_estimate_note"] = case.get("error_estimate_note", "")
    row["wall_time_s"] = case.get("wall_time_s")
    return row


def _meshes_apart(band: float | None, case: dict[str, Any]) -> float | None:
    """|q_default − q_coarse|: the two meshes' difference behind a band about the coarse
    eye's value, GCI = Fs |Δ| r^p / (r^p − 1) (error_estimate.py), read back."""
    if band is None:
        return None
    grow = case["error_estimate_ratio"] ** case["error_estimate_order"]
    return band * (grow - 1.0) / (case["error_estimate_safety_factor"] * grow)


def tear_centre_mm() -> float:
    """The tear's centre behind the limbus along the sclera, as ``buckle_position`` is
    measured (the eye's geometry: the tear at polar angle ``tear_angle``)."""
    eye = scleral_buckling.Parameters().geometry()
    return eye.sclera_radius * math.radians(eye.tear_angle - eye.limbus_angle)


def _value(row: dict, factor: str) -> float:
    """The row's position on its factor's axis (the buckle kind by its place)."""
    if factor == "buckle":
        return float(list(BUCKLE_KINDS).index(row["buckle"]))
    return float(row[dict(NAMED)[factor]])


def _number(value) -> float:
    return float(value) if value not in (None, "") else math.nan


# chart rows: (label, [(column, its band's column or None)]), the acute stage first
RIM = "tear's rim gap (mm)\n± band (clipped)"
PANELS = ((RIM, [("acute_tear_rim_gap_max_mm", "acute_tear_rim_gap_band_mm"),
                 ("settled_tear_rim_gap_max_mm", "settled_tear_rim_gap_band_mm")]),
          ("ΔAL (mm)\n± band", [("acute_axial_length_change_mm", "acute_axial_length_change_band_mm"),
                                ("settled_axial_length_change_mm", "settled_axial_length_change_band_mm")]),
          ("ΔSE (D)", [("acute_refraction_change_D", None), ("settled_refraction_change_D", None)]),
          ("peak IOP (mmHg)", [("operation_peak_iop_mmHg", None)]),
          ("vented (µL)", [("acute_vented_volume_uL", None)]))
STAGE_COLOURS = ("tab:blue", "tab:orange")


def _chart(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    factors = list(dict.fromkeys(r["factor"] for r in rows if r["factor"] != DEFAULTS_FACTOR))
    defaults = [r for r in rows if r["factor"] == DEFAULTS_FACTOR]
    fig, axes = plt.subplots(len(PANELS), max(len(factors), 1), squeeze=False, sharey="row",
                             figsize=(2.3 * max(len(factors), 2) + 1, 2.0 * len(PANELS) + 0.8))
    tolerance = scleral_buckling.Parameters().tear_closure_tolerance
    for column, factor in enumerate(factors):
        cases = sorted([r for r in rows if r["factor"] == factor] + defaults,
                       key=lambda r: _value(r, factor))
        xs = [_value(r, factor) for r in cases]
        for ax, (label, lines) in zip(axes[:, column], PANELS):
            for (key, band), colour in zip(lines, STAGE_COLOURS):
                _plot(ax, xs, cases, key, band, colour, connect=factor != "buckle")
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
        axes[0, column].axhline(tolerance, color="k", ls="--", lw=0.8)
        bottom = axes[-1, column]
        if factor == "buckle":
            for ax in axes[:, column]:
                ax.set_xticks(range(len(BUCKLE_KINDS)), list(BUCKLE_KINDS.values()))
                ax.set_xlim(-0.4, len(BUCKLE_KINDS) - 0.6)
        elif defaults:
            for ax in axes[:, column]:
                ax.axvline(_value(defaults[0], factor), color="0.6", ls=":", lw=1)
        bottom.set_xlabel(_axis_label(factor), fontsize=8)
    for ax, (label, _) in zip(axes[:, 0], PANELS):
        ax.set_ylabel(label, fontsize=8)
    _clip_rim_row(axes[0, 0], rows, tolerance)
    _legend(fig, tolerance)
    fig.suptitle("scleral-buckling planning map, living eye (coarse, Q1P0): one factor at a time "
                 "from the defaults (dotted)\nblue after suturing, orange settled; marker: the "
                 "tear's verdict; bars: the error estimate against the default mesh", fontsize=9,
                 x=0.02, ha="left")
    save_chart(fig, path, dpi=90, rect=(0, 0.03, 1, 0.97))


def _plot(ax, xs: list[float], cases: list[dict], key: str, band: str | None, colour: str,
          connect: bool = True) -> None:
    """``key`` against ``xs`` with its band as error bars; the marker's fill is the stage's
    tear verdict (full closed, hollow open, half uncertain); a red cross where a case failed.
    ``connect``: a line through the points (not between categories)."""
    stage = key.split("_", 1)[0] if key.split("_", 1)[0] in ("acute", "settled") else "acute"
    done = [(x, r) for x, r in zip(xs, cases) if r["status"] not in FAILED and r.get(key) is not None]
    ys = [_number(r[key]) for _, r in done]
    if connect:
        ax.plot([x for x, _ in done], ys, "-", color=colour, lw=1)
    for (x, r), y in zip(done, ys):
        if band is not None and r.get(band) not in (None, ""):
            ax.errorbar(x, y, yerr=_number(r[band]), color=colour, lw=0.8, capsize=2)
        verdict = r.get(f"{stage}_tear_verdict") or "open"
        ax.plot(x, y, "o", color=colour, fillstyle=VERDICT_STYLE.get(verdict, "none"),
                markerfacecoloralt="white", mfc=colour if verdict != "open" else "white", ms=6)
    for x, r in zip(xs, cases):
        if r["status"] in FAILED:
            ax.plot(x, 0.0, "rx", ms=9, mew=2)


def _clip_rim_row(ax, rows: list[dict], tolerance: float) -> None:
    """The rim gaps' row scaled to the gaps, not to their bands (up to 4 mm where the
    meshes disagree by 0.4 mm): a bar leaving the panel is clipped at its edge."""
    gaps = [_number(r.get(f"{stage}_tear_rim_gap_max_mm")) for r in rows for stage in ("acute", "settled")
            if r["status"] not in FAILED]
    top = max([g for g in gaps if math.isfinite(g)] + [tolerance])
    ax.set_ylim(-0.25 * top, 1.25 * top)


def _axis_label(factor: str) -> str:
    if factor == "buckle_position":
        return f"buckle position (mm behind limbus;\ntear centre {tear_centre_mm():.1f})"
    if factor == "tire_width":
        return "tire width (mm; bites\nkeep their overhang)"
    column = dict(NAMED)[factor]
    return column.replace("_", " ").replace(" mmHg", " (mmHg)").replace(" mm", " (mm)") \
        .replace(" deg", " (°)").replace(" N", " (N)").replace(" percent", " (%)")


def _legend(fig, tolerance: float) -> None:
    """The verdicts' markers and the closure tolerance, above the panels on the right."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color="k", marker="o", ls="", label="closed"),
               Line2D([], [], color="k", marker="o", ls="", mfc="white", label="open"),
               Line2D([], [], color="k", marker="o", ls="", fillstyle="left",
                      markerfacecoloralt="white", label="uncertain (|margin| ≤ band)"),
               Line2D([], [], color="r", marker="x", ls="", label="failed"),
               Line2D([], [], color="k", ls="--", lw=0.8, label=f"tolerance {tolerance:g} mm")]
    fig.legend(handles=handles, loc="upper right", ncol=3, fontsize=7, frameon=False)


STUDY = Study("buckling-planning", "which buckles close the tear on the living eye (closed / "
              "open / within the discretisation's error), and their cost in ΔAL, ΔSE, peak IOP "
              "and vented volume", run)
