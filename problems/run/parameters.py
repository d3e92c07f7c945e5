"""Scene parameters: one dataclass per scene, typed overrides, clear errors.

Every scene declares its parameters as a frozen dataclass. The command line
(``--set key=value``) and TOML configs use the dataclass field names; values are
converted to the field's declared type, and each dataclass checks physics in its
``validate`` method. Every failure raises :class:`ParameterError` naming the key,
before any mesh is built or any form compiled.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
import tomllib
import typing
from pathlib import Path
from typing import Any, ClassVar, Literal, get_args, get_origin

import msgspec

MMHG = 1.33322e-4  # MPa per mmHg

# Time-stepped scenes (a ``t_end`` with ``dt`` or ``first_dt`` and ``dt_growth``) are
# refused when their time grid has more steps than this (or than their ``max_steps``
# field, or than EYEMECH_MAX_STEPS): a typo must not run until the memory is gone.
DEFAULT_MAX_STEPS = 20_000  # as the viscoelastic bars (problems/solid/viscous_bar.py)
MAX_STEPS_ENV = "EYEMECH_MAX_STEPS"
# Meshes are refused before meshing when their estimated cell count exceeds this (or
# EYEMECH_MAX_CELLS): gmsh would otherwise mesh a typo (mesh_size=0.01) without end.
DEFAULT_MAX_CELLS = 2_000_000
MAX_CELLS_ENV = "EYEMECH_MAX_CELLS"


class ParameterError(ValueError):
    """Bad input: names the offending key and what is wrong with it."""

    def __init__(self, key: str, message: str):
        self.key = key
        super().__init__(f"parameter '{key}': {message}")


@dataclasses.dataclass(frozen=True)
class SceneParameters:
    """Base class: field metadata ``help`` and ``unit`` document each parameter. A choice
    is typed ``Literal[...]``: a value outside it is refused on construction, from the
    command line, a TOML file or Python alike; so is a float that is not finite (unless
    its field says ``finite=False``)."""

    # the parameter that sets the mesh's fineness, named by a refused cell count
    RESOLUTION_KEY: ClassVar[str] = "mesh_size"

    def __post_init__(self) -> None:
        for key, kind in _field_types(type(self)).items():
            if get_origin(kind) is Literal and getattr(self, key) not in get_args(kind):
                raise ParameterError(key, f"must be one of {', '.join(map(str, get_args(kind)))}, "
                                          f"got {getattr(self, key)!r}")
        check_finite(self)  # inf and nan are refused on construction too

    def validate(self) -> None:
        """Check physical sense; subclasses extend and raise ParameterError."""

    def resolution_key(self) -> str:
        """The parameter that sets this mesh's fineness: ``mesh_size`` when that absolute
        override is set, else ``RESOLUTION_KEY``."""
        return "mesh_size" if getattr(self, "mesh_size", 0) > 0 else type(self).RESOLUTION_KEY

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

    def domain_volume(self) -> float | None:
        """Volume (mm³) meshed with ``mesh_size``, for the cell-count estimate; None when
        unknown. Default: the full thick sphere of ``inner_radius`` and ``outer_radius``
        (an upper bound for a sector of it). Scenes may override it."""
        names = {f.name for f in dataclasses.fields(self)}
        if {"inner_radius", "outer_radius", "mesh_size"} <= names:
            return 4.0 / 3.0 * math.pi * (self.outer_radius ** 3 - self.inner_radius ** 3)
        return None

    @property
    def estimated_cells(self) -> int | None:
        """Cells of a mesh of ``domain_volume`` with tetrahedra of edge ``element_size`` (the
        size a scene derives) or ``mesh_size`` (regular tetrahedron: h³/(6√2)); None when the
        volume is unknown. Scenes with a mesh of their own (hertz) override it."""
        volume = self.domain_volume()
        size = getattr(self, "element_size", getattr(self, "mesh_size", None))
        if volume is None or not isinstance(size, (int, float)) or not size > 0:
            return None
        return int(volume / (size ** 3 / (6.0 * math.sqrt(2.0))))


# The groups a parameter is listed under (help, docs/parameters.md): what the model is,
# where it lives and how finely it is meshed, and how it is solved.
PHYSICS = "physics"
GEOMETRY = "geometry and mesh"
SOLVER = "solver and stepping"
GROUPS = (PHYSICS, GEOMETRY, SOLVER)


def field(default: Any, help: str, unit: str = "", finite: bool = True,
          group: str = PHYSICS) -> Any:
    """A dataclass field with documentation (shown by ``eyemech list -v``).

    Numbers must be finite (``inf`` and ``nan`` are refused) unless ``finite=False``.
    ``group`` is one of :data:`GROUPS`."""
    if group not in GROUPS:
        raise ValueError(f"group must be one of {GROUPS}, got {group!r}")
    return dataclasses.field(default=default, metadata={"help": help, "unit": unit,
                                                        "finite": finite, "group": group})


def check_finite(params: SceneParameters) -> None:
    """Every float (and every float of a tuple) is finite unless its field says otherwise."""
    for f in dataclasses.fields(params):
        if not f.metadata.get("finite", True):
            continue
        value = getattr(params, f.name)
        values = value if isinstance(value, (tuple, list)) else (value,)
        for item in values:
            if isinstance(item, float) and not math.isfinite(item):
                raise ParameterError(f.name, f"must be a finite number, got {item!r}")


def time_steps(params: SceneParameters) -> int | None:
    """The number of time steps of a scene with ``t_end`` and ``dt`` or ``first_dt``
    (growing by ``dt_growth``), or None for other scenes and for adaptive steps, whose
    number the solve decides (the step cap stops those at run time, with TooManySteps)."""
    if getattr(params, "time_stepping", "fixed") == "adaptive":
        return None
    t_end = getattr(params, "t_end", None)
    dt = getattr(params, "first_dt", getattr(params, "dt", None))
    if not isinstance(t_end, (int, float)) or not isinstance(dt, (int, float)):
        return None
    if not (math.isfinite(t_end) and math.isfinite(dt)) or t_end <= 0 or dt <= 0:
        return None  # the finite and positive checks name the key
    growth = getattr(params, "dt_growth", 1.0)
    if not isinstance(growth, (int, float)) or not math.isfinite(growth) or growth < 1.0:
        return None
    if growth - 1.0 < 1e-12:
        return math.ceil(t_end / dt * (1 - 1e-12))
    # dt (1 + g + ... + g^(n-1)) >= t_end
    return math.ceil(math.log1p(t_end / dt * (growth - 1.0)) / math.log(growth) * (1 - 1e-12))


def max_steps(params: SceneParameters) -> int:
    own = getattr(params, "max_steps", None)
    if isinstance(own, int) and own > 0:
        return own
    env = os.environ.get(MAX_STEPS_ENV, "").strip()
    return int(env) if env.isdigit() and int(env) > 0 else DEFAULT_MAX_STEPS


def check_step_count(params: SceneParameters) -> None:
    steps = time_steps(params)
    limit = max_steps(params)
    if steps is not None and steps > limit:
        first = "first_dt" if hasattr(params, "first_dt") else "dt"
        growth = f", dt_growth={params.dt_growth:g}" if hasattr(params, "dt_growth") else ""
        raise ParameterError("t_end", f"t_end={params.t_end:g} with {first}="
                             f"{getattr(params, first):g}{growth} takes {steps} time steps, "
                             f"more than the limit of {limit} (raise it with "
                             f"{'max_steps' if hasattr(params, 'max_steps') else MAX_STEPS_ENV})")


def max_cells(params: SceneParameters) -> tuple[int, str]:
    """The cell limit of ``params`` and how to raise it: the scene's own ``max_cells``
    field, else EYEMECH_MAX_CELLS, else DEFAULT_MAX_CELLS."""
    own = getattr(params, "max_cells", None)
    if isinstance(own, int) and own > 0:
        return own, "max_cells"
    env = os.environ.get(MAX_CELLS_ENV, "").strip()
    return (int(env) if env.isdigit() and int(env) > 0 else DEFAULT_MAX_CELLS), MAX_CELLS_ENV


def check_cell_count(params: SceneParameters) -> None:
    """Refuse, before meshing, a mesh whose estimated cell count exceeds the limit,
    naming the scene's resolution parameter (``RESOLUTION_KEY``) and the override."""
    cells = params.estimated_cells
    limit, override = max_cells(params)
    if cells is not None and cells > limit:
        key = params.resolution_key()
        size = getattr(params, "element_size", getattr(params, "mesh_size", None))
        sized = f"an element size of {size:.3g} mm" if isinstance(size, (int, float)) and size > 0 \
            else f"{key}={getattr(params, key)!r}"
        raise ParameterError(key, f"{sized} gives about {int(cells):,} cells (estimated before "
                             f"meshing), more than the limit of {limit:,}: coarsen the mesh with {key}, "
                             f"or raise the limit with {override}")


def check_types(params: SceneParameters) -> None:
    """A flag is a bool and a number is not text. The command line, TOML and ``build``
    convert their values (:func:`convert`); a Python caller's are taken as given, and a
    ``"false"`` flag would be true."""
    types = _field_types(type(params))
    for f in dataclasses.fields(params):
        kind, value = types[f.name], getattr(params, f.name)
        if kind is bool and not isinstance(value, bool):
            raise ParameterError(f.name, f"expected True or False, got {value!r}")
        if kind in (int, float) and isinstance(value, (str, bool)):
            raise ParameterError(f.name, f"expected a number, got {value!r}")


def check(params: SceneParameters) -> None:
    """The shared checks, then the scene's own ``validate``."""
    check_types(params)
    check_finite(params)
    params.validate()
    check_step_count(params)
    check_cell_count(params)


def _field_types(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def convert(cls: type, key: str, raw: Any) -> Any:
    """Convert ``raw`` (a string from the command line, or a TOML value) to the type
    of field ``key`` of the dataclass ``cls`` (:func:`coerce`)."""
    if key not in {f.name for f in dataclasses.fields(cls)}:
        raise ParameterError(key, unknown_key(cls, key))
    kind = _field_types(cls)[key]
    try:
        return coerce(kind, raw)
    except (TypeError, ValueError, msgspec.ValidationError):
        raise ParameterError(key, f"cannot read {raw!r} as {_type_name(kind)}") from None


def coerce(kind: Any, raw: Any) -> Any:
    """The one reading of a parameter value, whether it comes from ``--set`` (text) or a
    TOML file (text, numbers, booleans, arrays): a TOML value is read as its command-line
    text, so ``--set n=2.0`` and ``n = 2.0`` give the same value or the same error.
    msgspec parses the text (lax mode): an integer accepts ``3``, ``2.0`` and ``1e3`` but
    not ``0.1`` or ``1_0``; a number accepts what JSON writes (``0.5``, ``5e-1``, not
    ``.5``); a flag ``true``/``false``/``1``/``0`` in any case; a choice one of its values.
    A tuple is a comma-separated text or a TOML array."""
    if get_origin(kind) in (tuple, list):
        (item,) = get_args(kind)[:1]
        items = raw.split(",") if isinstance(raw, str) else raw if isinstance(raw, list) else [raw]
        return tuple(coerce(item, v.strip() if isinstance(v, str) else v) for v in items
                     if v != "")
    if isinstance(raw, bool):
        text = "true" if raw else "false"
    elif isinstance(raw, (str, int, float)):
        text = str(raw)
    else:
        raise TypeError(f"expected a single value, got {type(raw).__name__}")
    return text if kind is str else msgspec.convert(text, kind, strict=False)


def unknown_key(cls: type, key: str) -> str:
    """The message for an unknown key: the close ones (difflib), and the valid ones when
    they are few enough to read (else where they are listed)."""
    names = [f.name for f in dataclasses.fields(cls)]
    close = difflib.get_close_matches(key, names, n=3, cutoff=0.6)
    hint = f"did you mean {' or '.join(repr(c) for c in close)}? " if close else ""
    if len(names) <= 24:
        return f"unknown key; {hint}valid keys are: {', '.join(names)}"
    return (f"unknown key; {hint}the {len(names)} valid keys are listed by group with "
            f"'eyemech run SCENE --help' and in docs/parameters.md")


def _type_name(kind: Any) -> str:
    if get_origin(kind) is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(kind))
    if get_origin(kind) in (tuple, list):
        return "a comma-separated list of " + _type_name(get_args(kind)[0]).removeprefix("a ") + "s"
    plain = {int: "an integer", float: "a number", bool: "true or false", str: "text"}
    return plain.get(kind, getattr(kind, "__name__", str(kind)))


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
    """Read a TOML config: parameters as top-level keys or in a ``[parameters]`` table,
    not both (keys beside the table would otherwise be dropped without a word)."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
        data = tomllib.loads(text)
    except FileNotFoundError:
        raise ParameterError("--config", f"file not found: {path}") from None
    except IsADirectoryError:
        raise ParameterError("--config", f"{path} is a folder, not a TOML file") from None
    except OSError as err:
        raise ParameterError("--config", f"cannot read {path}: {err.strerror or err}") from None
    except UnicodeDecodeError as err:
        raise ParameterError("--config", f"{path} is not UTF-8 text (byte {err.start})") from None
    except tomllib.TOMLDecodeError as err:
        raise ParameterError("--config", f"{path} is not valid TOML: {err}") from None
    if "parameters" not in data:
        return dict(data)
    table = data["parameters"]
    if not isinstance(table, dict):
        raise ParameterError("parameters", f"in {path} must be a table ([parameters]), "
                             f"got {type(table).__name__}")
    others = sorted(k for k in data if k != "parameters")
    if others:
        raise ParameterError(others[0], f"in {path} is a top-level key beside the "
                             f"[parameters] table: put every parameter in the table "
                             f"(top-level keys: {', '.join(others)})")
    return dict(table)


def build(cls: type[SceneParameters], overrides: dict[str, Any] | None = None) -> SceneParameters:
    """Defaults of ``cls`` updated by ``overrides`` (typed), then validated."""
    values = {key: convert(cls, key, raw) for key, raw in (overrides or {}).items()}
    params = cls(**values)
    check(params)
    return params


def describe(cls: type[SceneParameters]) -> list[tuple[str, str, Any, str, str]]:
    """(name, type, default, unit, help) rows for documentation and ``list -v``."""
    types = _field_types(cls)
    rows = []
    for f in dataclasses.fields(cls):
        rows.append((f.name, _type_name(types[f.name]), f.default, f.metadata.get("unit", ""),
                     f.metadata.get("help", "")))
    return rows


def groups(cls: type[SceneParameters]) -> dict[str, list[tuple[str, str, Any, str, str]]]:
    """:func:`describe`'s rows by group (:data:`GROUPS` order; empty groups left out)."""
    group_of = {f.name: f.metadata.get("group", PHYSICS) for f in dataclasses.fields(cls)}
    out: dict[str, list] = {group: [] for group in GROUPS}
    for row in describe(cls):
        out[group_of[row[0]]].append(row)
    return {group: rows for group, rows in out.items() if rows}


# --petsc names under these prefixes configure parts of a solver that exist only on the
# scene's real system (fieldsplit blocks, multigrid levels, block-Jacobi blocks): the
# one-unknown trial solve below cannot read them, so their names are not checked there.
PETSC_UNCHECKED_PREFIXES = ("fieldsplit_", "pc_fieldsplit_", "mg_", "pc_mg_", "pc_gamg_",
                            "pc_hypre_", "sub_", "pc_bjacobi_", "pc_asm_", "mat_superlu_dist_")
# preconditioners the trial solve sets up (others need the real operator's structure)
_PETSC_TRIAL_PCS = ("lu", "cholesky", "ilu", "icc", "jacobi", "none", "sor", "bjacobi")


def check_petsc_options(petsc: dict[str, str]) -> None:
    """Refuse ``--petsc`` options that PETSc would not use or cannot read, before anything
    is built: the Newton solver's options (:class:`NewtonOptions`, ``petsc`` on top) are
    given to a SNES on one unknown (x - 1 = 0, MUMPS LU by default) that sets itself up
    and solves, with its output hidden; then PETSc's options database tells which of the
    given names were never read (a typo such as ``snes_linesearch_typ``), and a value
    PETSc cannot read (``snes_linesearch_type=bogus``, ``snes_rtol=abc``) is an error of
    that trial. Both are a ParameterError for ``--petsc``."""
    if not petsc:
        return
    from mpi4py import MPI  # noqa: F401  (loads the MPI library petsc4py links to)
    from petsc4py import PETSc

    from eyemech.problems.run.newton import NewtonOptions

    prefix = "eyemechcheck_"
    values = NewtonOptions(petsc=dict(petsc)).as_petsc()
    if "ksp_type" not in petsc:
        # a Krylov KSP reads the Krylov options (ksp_rtol, ksp_monitor, ...) that a
        # scene's iterative linear solver (``solver=iterative``) uses; preonly would not
        values["ksp_type"] = "gmres"
    opts = PETSc.Options()
    for key, value in values.items():
        opts[prefix + key] = value
    pc_type = values.get("pc_type", "lu")
    snes = PETSc.SNES().create(PETSc.COMM_SELF)
    A = PETSc.Mat().createAIJ([1, 1], nnz=1, comm=PETSc.COMM_SELF)
    A.setValue(0, 0, 1.0)
    A.assemble()
    x, f = A.createVecs()
    refused = None
    try:
        snes.setOptionsPrefix(prefix)
        snes.setFunction(lambda _s, u, r: (u.copy(r), r.shift(-1.0)), f)
        snes.setJacobian(lambda *_: None, A, A)
        try:
            with _quiet_stdout():
                snes.setFromOptions()
                snes.getKSP().setFromOptions()
        except PETSc.Error as err:
            refused = err
        if refused is None:
            try:
                with _quiet_stdout():
                    x.set(0.0)
                    snes.solve(None, x)
            except PETSc.Error as err:
                if pc_type in _PETSC_TRIAL_PCS:
                    refused = err
        unused = sorted(key for key in petsc
                        if not opts.used(prefix + key)
                        and not key.startswith(PETSC_UNCHECKED_PREFIXES))
    finally:
        for key in values:
            if opts.hasName(prefix + key):
                opts.delValue(prefix + key)
        for obj in (snes, A, x, f):
            obj.destroy()
    if refused is not None:
        given = " ".join(f"{k}={v}" for k, v in petsc.items())
        raise ParameterError("--petsc", f"PETSc cannot use {given} (PETSc error "
                             f"{getattr(refused, 'ierr', refused)}: a value of the wrong kind "
                             "or an unknown type name)")
    if unused:
        raise ParameterError("--petsc", f"PETSc does not use {', '.join(unused)}: not an "
                             "option of the Newton solver, its line search, KSP or PC "
                             "(a typo?)")


class _quiet_stdout:
    """Hide what PETSc prints to the C stdout (monitors, views) during the trial."""

    def __enter__(self):
        import sys

        sys.stdout.flush()
        self.saved = os.dup(1)
        self.null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(self.null, 1)

    def __exit__(self, *exc):
        os.dup2(self.saved, 1)
        os.close(self.saved)
        os.close(self.null)
