"""Studies: accuracy against cost, and where methods fail.

Each module here exposes ``STUDY`` (a :class:`Study`); ``eyemech study NAME`` runs
it and writes CSV and PNG files (with the machine, versions and date) into
``docs/studies/`` or ``--out``. ``quick=True`` runs coarse settings for the tests.
"""

from __future__ import annotations

import dataclasses
import importlib
import pkgutil
from pathlib import Path
from typing import Callable


@dataclasses.dataclass(frozen=True)
class Study:
    name: str
    summary: str
    run: Callable[..., list[Path]]  # run(out: Path, quick: bool, comm) -> files written


def studies() -> dict[str, Study]:
    found = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        study = getattr(module, "STUDY", None)
        if study is not None:
            found[study.name] = study
    return found
