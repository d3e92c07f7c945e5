"""The scenes' names, kinds and one-line summaries, read from the source of
``eyemech.problems`` with ``ast`` instead of importing it.

Why: importing a scene imports DOLFINx, PETSc and the scene's dependencies (≈ 1–2 s);
``eyemech list`` only prints what each module's ``SCENE = Scene(name=..., kind=...,
summary=...)`` states as literals. The registry (:func:`eyemech.problems.scenes`) stays
the authority: ``tests/test_cli.py`` checks that both agree.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib.util
from pathlib import Path


@dataclasses.dataclass(frozen=True)
class SceneEntry:
    name: str
    kind: str
    summary: str


def problems_folder() -> Path:
    """Where ``eyemech.problems`` lives, found without executing its ``__init__``."""
    spec = importlib.util.find_spec("eyemech.problems")
    if spec is None or not spec.submodule_search_locations:
        raise ModuleNotFoundError("eyemech.problems is not installed")
    return Path(next(iter(spec.submodule_search_locations)))


def _scene_literal(path: Path) -> SceneEntry | None:
    """The ``SCENE = Scene(...)`` of a module, when its name, kind and summary are literals."""
    for node in ast.parse(path.read_text(encoding="utf-8"), str(path)).body:
        if not (isinstance(node, ast.Assign) and isinstance(node.value, ast.Call)
                and any(getattr(target, "id", None) == "SCENE" for target in node.targets)):
            continue
        keywords = {k.arg: k.value for k in node.value.keywords}
        try:
            return SceneEntry(*(ast.literal_eval(keywords[key]) for key in ("name", "kind", "summary")))
        except (KeyError, ValueError):
            return None
    return None


def scene_sources(folder: Path) -> list[tuple[str, Path]]:
    """(module name, source) of every top-level module and package of ``folder``: a
    package's source is its ``__init__.py``."""
    found = [(path.stem, path) for path in folder.glob("*.py")]
    found += [(path.parent.name, path) for path in folder.glob("*/__init__.py")]
    return sorted((name, path) for name, path in found if not name.startswith("_"))


def scene_catalogue() -> list[SceneEntry]:
    """Every scene of the top level of ``eyemech.problems`` (a module, or a package whose
    ``__init__.py`` defines SCENE), sorted by name. A module whose SCENE is not written
    with literals is imported to read it."""
    entries = []
    for name, path in scene_sources(problems_folder()):
        entry = _scene_literal(path)
        if entry is None and "SCENE = " in path.read_text(encoding="utf-8"):
            import importlib

            scene = getattr(importlib.import_module(f"eyemech.problems.{name}"), "SCENE", None)
            entry = SceneEntry(scene.name, scene.kind, scene.summary) if scene is not None else None
        if entry is not None:
            entries.append(entry)
    return sorted(entries, key=lambda e: e.name)
