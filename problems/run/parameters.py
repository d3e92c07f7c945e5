"""Scene parameters: one dataclass per scene, typed overrides, clear errors.

Every scene declares its parameters as a frozen dataclass. The command line
(``--set key=value``) and TOML configs use the dataclass field names; values are
converted to the field's declared type, and each dataclass checks physics in its
``validate`` method. Every failure raises :class:`ParameterError` naming the key,
before any mesh is built or any form compiled.
"""

from __future__ import annotations

import dataclasses
import tomllib
import typing
from pathlib import Path
from typing import Any, Literal, get_args, get_origin

MMHG = 1.33322e-4  # MPa per mmHg



class ParameterError(ValueError):
    """Bad input: names the offending key and what is wrong with it."""

    def __init__(self, key: str, message: str):
        self.key = key
        super().__init__(f"parameter '{key}': {message}")


@dataclasses.dataclass(frozen=True)
class SceneParameters:
    """Base class: field metadata ``help`` and ``unit`` document each parameter. A choice
    is typed ``Literal[...]``: a value outside it is refused on construction, from the
    command line, a TOML file or Python alike."""

    def __post_init__(self) -> None:
        for key, kind in _field_types(type(self)).items():
            if get_origin(kind) is Literal and getattr(self, key) not in get_args(kind):
                raise ParameterError(key, f"must be one of {', '.join(map(str, get_args(kind)))}, "
                                          f"got {getattr(self, key)!r}")

    def validate(self) -> None:
        """Check physical sense; subclasses extend and raise ParameterError."""

    # -- helpers for subclasses -------------------------------------------------
    def require_positive(self, *keys: str) -> None:
        for key in keys:
            if not getattr(self, key) > 0:
                raise ParameterError(key, f"must be > 0, got {getattr(self, key)!r}")

    def require_nonnegative(self, *keys: str) -> None:
        for key in keys:
            if not getattr(self, key) >= 0:
                raise ParameterError(key, f"must be >= 0, got {getattr(self, key)!r}")

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def field(default: Any, help: str, unit: str = "") -> Any:
    """A dataclass field with documentation (shown by ``eyemech list -v``)."""
    return dataclasses.field(default=default, metadata={"help": help, "unit": unit})


def _field_types(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def convert(cls: type, key: str, raw: Any) -> Any:
    """Convert ``raw`` (a string from the command line, or a TOML value) to the type
    of field ``key`` of the dataclass ``cls``."""
    types = _field_types(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    if key not in names:
        raise ParameterError(key, f"unknown key; valid keys are: {', '.join(names)}")
    kind = types[key]
    try:
        return _convert_value(kind, raw)
    except (TypeError, ValueError):
        raise ParameterError(key, f"cannot read {raw!r} as {_type_name(kind)}") from None


def _type_name(kind: Any) -> str:
    if get_origin(kind) is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(kind))
    plain = {int: "an integer", float: "a number", bool: "true or false", str: "text"}
    return plain.get(kind, getattr(kind, "__name__", str(kind)))


def _convert_value(kind: Any, raw: Any) -> Any:
    origin = get_origin(kind)
    if origin is Literal:
        choices = get_args(kind)
        value = raw if not isinstance(raw, str) else raw.strip()
        for choice in choices:
            if value == choice or (isinstance(value, str) and str(choice) == value):
                return choice
        raise ValueError(f"not one of {', '.join(repr(c) for c in choices)}")
    if origin in (tuple, list):
        (item,) = get_args(kind)[:1]
        items = raw.split(",") if isinstance(raw, str) else list(raw)
        return tuple(_convert_value(item, v) for v in items if v != "")
    if kind is bool:
        if isinstance(raw, bool):
            return raw
        text = str(raw).strip().lower()
        if text in ("1", "true", "yes", "on"):
            return True
        if text in ("0", "false", "no", "off"):
            return False
        raise ValueError("expected true or false")
    if kind is int:
        if isinstance(raw, bool):
            raise ValueError("expected an integer")
        if isinstance(raw, float) and not raw.is_integer():
            raise ValueError("expected an integer")
        return int(raw)
    if kind is float:
        if isinstance(raw, bool):
            raise ValueError("expected a number")
        return float(raw)
    if kind is str:
        return str(raw)
    raise TypeError(f"unsupported parameter type {kind}")


def parse_assignments(pairs: list[str]) -> dict[str, str]:
    """``["a=1", "b=x"]`` -> ``{"a": "1", "b": "x"}``."""
    out: dict[str, str] = {}
    for pair in pairs:
        if "=" not in pair:
            raise ParameterError(pair, "expected key=value")
        key, value = pair.split("=", 1)
        out[key.strip()] = value.strip()
    return out


def load_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML config; a ``[parameters]`` table or top-level keys are accepted."""
    try:
        data = tomllib.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ParameterError("--config", f"file not found: {path}") from None
    except tomllib.TOMLDecodeError as err:
        raise ParameterError("--config", f"{path} is not valid TOML: {err}") from None
    return dict(data.get("parameters", data))


def build(cls: type[SceneParameters], overrides: dict[str, Any] | None = None) -> SceneParameters:
    """Defaults of ``cls`` updated by ``overrides`` (typed), then validated."""
    values = {key: convert(cls, key, raw) for key, raw in (overrides or {}).items()}
    params = cls(**values)
    params.validate()
    return params


def describe(cls: type[SceneParameters]) -> list[tuple[str, str, Any, str, str]]:
    """(name, type, default, unit, help) rows for documentation and ``list -v``."""
    types = _field_types(cls)
    rows = []
    for f in dataclasses.fields(cls):
        rows.append((f.name, _type_name(types[f.name]), f.default, f.metadata.get("unit", ""),
                     f.metadata.get("help", "")))
    return rows
