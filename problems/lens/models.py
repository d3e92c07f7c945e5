"""The lens models the lens scenes run on (``model`` of ``iol-speed``, ``iol-fold``,
``iol-injection``)."""

from __future__ import annotations

from typing import Literal, get_args

Model = Literal["p2-c0ip", "p1-rotation-free"]
MODELS = get_args(Model)
