"""Shared pieces of studies: a stamp naming machine, versions and date on every chart."""

from __future__ import annotations

import datetime
import platform

from eyemech.problems.results import versions


def stamp() -> str:
    """One line for a chart footer and a CSV comment: what measured this, where, when."""
    v = versions()
    return (f"{datetime.date.today().isoformat()} · {platform.node()} ({platform.machine()}, "
            f"{__import__('os').cpu_count()} cpus) · eyemech {v.get('eyemech', '?')} · "
            f"DOLFINx {v.get('dolfinx', '?')} · PETSc {v.get('petsc', '?')}")


def save_chart(fig, path, *, dpi: int = 110, rect=(0, 0.03, 1, 1)) -> None:
    """Stamp the chart (machine, versions, date), lay it out, save it, free it."""
    import matplotlib.pyplot as plt

    fig.text(0.01, 0.01, stamp(), fontsize=7, color="grey")
    fig.tight_layout(rect=rect)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
