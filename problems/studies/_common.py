"""Shared pieces of studies: a stamp naming machine, versions and date on every chart,
the CSV writer, and the quiet run options every study uses."""

from __future__ import annotations

import csv
import datetime
import os
import platform
from pathlib import Path

from eyemech.problems.context import RunOptions
from eyemech.problems.results import versions

# studies measure quantities, not pictures: no fields, no PNGs from the scenes
QUIET = RunOptions(fields=False, pictures=False)


def stamp() -> str:
    """One line for a chart footer and a CSV comment: what measured this, where, when."""
    v = versions()
    return (f"{datetime.date.today().isoformat()} · {platform.node()} ({platform.machine()}, "
            f"{os.cpu_count()} cpus) · eyemech {v.get('eyemech', '?')} · "
            f"DOLFINx {v.get('dolfinx', '?')} · PETSc {v.get('petsc', '?')}")


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
