"""Shared pieces of studies: a stamp naming machine, versions and date on every chart,
the CSV writer with its sidecar of settings, and the quiet run options every study uses."""

from __future__ import annotations

import ast
import csv
import dataclasses
import hashlib
import importlib
import json
import sys
from pathlib import Path
from typing import Any

from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.results import stamp

# studies measure quantities, not pictures: no fields, no PNGs from the scenes
QUIET = RunOptions(fields=False, pictures=False)


def sidecar(path: Path) -> Path:
    """Where a study CSV's metadata go: ``<stem>.meta.json`` beside it."""
    return Path(path).with_name(Path(path).stem + ".meta.json")


def write_csv(path: Path, rows: list[dict], *notes: str, partial: bool = False) -> Path:
    """``rows`` as a plain CSV (a header line, then the rows; columns are the union of the
    rows' keys in first-seen order: a failed case may lack some), and its sidecar
    (:func:`settings`, the notes, the stamp). Within ``eyemech study`` each row with a
    ``status`` is a case: one line per case on stderr, failed ones counted; not in a
    ``partial`` table, which the study writes again, whole, later (so that its cases are
    counted once)."""
    from eyemech.problems.studies import running

    keys: list[str] = []
    for row in rows:
        keys += [k for k in row if k not in keys]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)
    study = running()
    meta = {"study": study.name if study else None, "quick": study.quick if study else None,
            "made": stamp(), "notes": list(notes)}
    if study is not None:
        meta.update(settings(study.module))
        if not partial:
            _count_cases(study, path, rows)
    sidecar(path).write_text(json.dumps(meta, indent=1, default=str) + "\n")
    return path


def with_units(rows: list[dict], parameters: type) -> list[dict]:
    """The rows with each column that is a parameter of ``parameters`` (a scene's dataclass)
    named with its unit: ``indentation`` -> ``indentation_mm``."""
    units = {f.name: f.metadata.get("unit", "") for f in dataclasses.fields(parameters)}
    named = {k: f"{k}_{units[k]}" for k in units if units[k] and units[k] not in ("deg",)
             and not k.endswith(f"_{units[k]}")}
    named.update({k: f"{k}_deg" for k in units if units[k] == "deg" and not k.endswith("_deg")})
    return [{named.get(k, k): v for k, v in row.items()} for row in rows]


def case_label(row: dict) -> str:
    """A case named by its inputs: a row's columns before ``status`` (a study writes
    ``{**case, "status": ...}``), those set, so that cases differing in a late input (a
    wall's friction, an injector's twist) read apart; the first three columns when
    ``status`` comes first."""
    keys = list(row)
    inputs = keys[:keys.index("status")] if "status" in keys[1:] else \
        [k for k in keys if k not in ("status", "error")][:3]
    return ", ".join(f"{k}={row[k]}" for k in inputs if row[k] not in (None, ""))


def _count_cases(study, path: Path, rows: list[dict]) -> None:
    from eyemech.problems.studies import FAILED

    cases = [r for r in rows if "status" in r]
    study.cases += len(cases)
    for number, row in enumerate(cases, start=1):
        label = case_label(row)
        if row["status"] in FAILED:
            study.failed.append(f"{path.stem} {label}")
        why = f" ({str(row['error'])[:160]})" if row.get("error") else ""
        print(f"{study.name}: {path.name} case {number}/{len(cases)} ({label}): {row['status']}{why}",
              file=sys.stderr, flush=True)


def failed_row(case: dict, failure: BaseException) -> dict:
    """The row of a case that did not run: its inputs (``case``), status ``failed`` (what a
    sweep records for a :class:`SolveFailure`) and the message as ``error``. The row is
    kept, not dropped: ``eyemech study`` names it and exits 4, :func:`mark_failed` marks it."""
    return {**case, "status": "failed", "error": str(failure)[:300]}


def mark_failed(ax, xs, label: str = "case failed") -> None:
    """A red ✗ at the foot of ``ax`` at each ``x`` (data) of a failed case, on any y scale
    (a log axis has no 0), with one legend entry."""
    for k, x in enumerate(xs):
        ax.plot([x], [0.0], "x", color="tab:red", ms=10, mew=2, clip_on=False,
                transform=ax.get_xaxis_transform(), label=label if k == 0 else None)


def settings(module_name: str) -> dict[str, Any]:
    """What a study's numbers depend on besides the code: the defaults of every scene its
    module imports, and the module's own constants (upper-case names bound to literals:
    its grids, base settings), with their hash. A committed table whose sidecar holds
    another hash was made with other settings than the code's."""
    module = importlib.import_module(module_name)
    tree = ast.parse(Path(module.__file__).read_text())
    from eyemech.problems import scenes

    by_module = {scene.run.__module__: name for name, scene in scenes().items()}
    used = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            names = [f"{node.module}.{a.name}" for a in node.names] + [node.module]
            used.update(by_module[n] for n in names if n in by_module)
    defaults = {name: dataclasses.asdict(scenes()[name].parameters()) for name in sorted(used)}
    constants = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 \
                and isinstance(node.targets[0], ast.Name) and node.targets[0].id.isupper():
            try:
                constants[node.targets[0].id] = ast.literal_eval(node.value)
            except ValueError:
                continue
    content = {"scene_defaults": defaults, "study_constants": constants}
    digest = hashlib.sha256(json.dumps(content, sort_keys=True, default=repr).encode()).hexdigest()
    return {"settings_hash": digest[:16], **content}


def read_csv(path: Path) -> list[dict]:
    """A study CSV back (comment lines, which older tables had, skipped), values as strings."""
    with open(path, newline="") as handle:
        return list(csv.DictReader(line for line in handle if not line.startswith("#")))


def save_chart(fig, path, *, dpi: int = 110, rect=(0, 0.03, 1, 1)) -> None:
    """Stamp the chart (machine, versions, date; within ``eyemech study`` the failed cases
    in red, on a line of their own above the stamp so that neither overprints the other on
    a narrow chart), lay it out, save it, free it."""
    import matplotlib.pyplot as plt
    from matplotlib.transforms import offset_copy

    from eyemech.problems.studies import running

    line = stamp()
    fig.text(0.01, 0.01, line, fontsize=7, color="grey")
    study = running()
    if study is not None and study.failed:
        above_stamp = offset_copy(fig.transFigure, fig=fig, y=10, units="points")
        fig.text(0.01, 0.01, f"✗ {len(study.failed)} of {study.cases} cases failed: "
                 + "; ".join(study.failed)[:160], fontsize=7, color="tab:red",
                 transform=above_stamp)
        footer = 22 / (72 * fig.get_figheight())  # two 7-point lines, in figure fractions
        rect = (rect[0], max(rect[1], footer), rect[2], rect[3])
    fig.tight_layout(rect=rect)
    # the stamp also as PNG text, so that tests (and readers) can check it without OCR
    fig.savefig(path, dpi=dpi, metadata={"Comment": line})
    plt.close(fig)


def relative_deviations(rows: list[dict], quantities, reference: str) -> None:
    """Add ``deviation_KEY`` = case / reference − 1 to every row (NaN where the case or the
    reference failed, or the reference value is 0)."""
    import math

    by = {r["case"]: r for r in rows if r["status"] == "ok"}
    base = by.get(reference)
    for row in rows:
        row["reference"] = base["case"] if base else ""
        for key in quantities:
            ok = base is not None and row["status"] == "ok" and base[key] != 0
            row[f"deviation_{key}"] = row[key] / base[key] - 1.0 if ok else math.nan


def reduction_chart(path: Path, rows: list[dict], quantities: dict[str, str], *, xlabel: str,
                    title: str) -> Path:
    """Left: each case's deviation (%) of every quantity from the reference; right: its
    cost (wall time, with unknowns and Newton iterations); failed cases named in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    ok = [r for r in rows if r["status"] == "ok"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 1.6 + 0.5 * max(len(ok), 6)),
                                      gridspec_kw={"width_ratios": [2.2, 1]})
    width = 0.8 / len(quantities)
    y = np.arange(len(ok))
    for k, (key, label) in enumerate(quantities.items()):
        values = [100 * r[f"deviation_{key}"] for r in ok]
        left.barh(y + (k - len(quantities) / 2 + 0.5) * width, values, height=width, label=label)
    left.axvline(0, color="k", lw=0.8)
    left.set_yticks(y, [r["case"] for r in ok], fontsize=8)
    left.invert_yaxis()
    left.set(xlabel=xlabel, title="quantities of interest vs the reference case")
    left.legend(fontsize=7, loc="best")
    left.grid(alpha=0.3, axis="x")
    right.barh(y, [r["wall_time_s"] for r in ok], color="tab:grey")
    for yi, r in zip(y, ok):
        right.annotate(f"{r['dofs']} dofs, {r['newton_iterations']} its", (r["wall_time_s"], yi),
                       textcoords="offset points", xytext=(3, -3), fontsize=7)
    right.set_yticks(y, ["" for _ in ok])
    right.invert_yaxis()
    right.set(xlabel="wall time (s)", title="cost")
    right.set_xlim(0, 1.6 * max([r["wall_time_s"] for r in ok] or [1.0]))
    failed = [r for r in rows if r["status"] != "ok"]
    if failed:
        right.text(0.02, 0.02, "failed: " + "; ".join(f"{r['case']} ({r['status']})" for r in failed),
                   transform=right.transAxes, fontsize=7, color="tab:red")
    for ax in (left, right):
        ax.title.set_fontsize(9)
    fig.suptitle(title, fontsize=10)
    save_chart(fig, path, dpi=100, rect=(0, 0.03, 1, 1))
    return path
