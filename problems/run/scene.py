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
