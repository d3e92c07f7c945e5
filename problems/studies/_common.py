"""Shared pieces of studies: a stamp naming machine, versions and date on every chart,
the CSV writer, and the quiet run options every study uses."""

from __future__ import annotations

import csv
from pathlib import Path

from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.results import stamp

# studies measure quantities, not pictures: no fields, no PNGs from the scenes
QUIET = RunOptions(fields=False, pictures=False)


def write_csv(path: Path, rows: list[dict], *notes: str) -> Path:
    """``rows`` as CSV under comment lines: the notes, then the stamp. Columns are the
    union of the rows' keys in first-seen order (a failed case may lack some)."""
    keys: list[str] = []
    for row in rows:
        keys += [k for k in row if k not in keys]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as handle:
        for note in (*notes, stamp()):
            handle.write(f"# {note}\n")
        writer = csv.DictWriter(handle, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)
    return path


def read_csv(path: Path) -> list[dict]:
    """A study CSV back (comment lines skipped), values as strings."""
    with open(path, newline="") as handle:
        return list(csv.DictReader(line for line in handle if not line.startswith("#")))


def save_chart(fig, path, *, dpi: int = 110, rect=(0, 0.03, 1, 1)) -> None:
    """Stamp the chart (machine, versions, date), lay it out, save it, free it."""
    import matplotlib.pyplot as plt

    line = stamp()
    fig.text(0.01, 0.01, line, fontsize=7, color="grey")
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
