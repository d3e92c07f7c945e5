"""The registry entry a scene module exposes as ``SCENE``."""

from __future__ import annotations

import dataclasses
from typing import Callable, Literal

from eyemech.problems.run.parameters import SceneParameters


@dataclasses.dataclass(frozen=True)
class Scene:
    name: str
    kind: Literal["scene", "benchmark"]
    parameters: type[SceneParameters]
    run: Callable
    summary: str
    # the lines a user reads first after a run: what it found, in the terms of the scene's
    # users (the quantities of its results.json in, lines out); None: the table alone
    headline: Callable[[dict], list[str]] | None = None
