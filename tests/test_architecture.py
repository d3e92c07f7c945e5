"""The layout of the design card (shared/design.md §2), kept by a test: which package may
import what, read from the source with ``ast`` (nothing is imported), the size of functions
and classes, and ruff's lint (line length included).

The rooms in their dependency order (``LAYERS``): a module imports only from its own
room and from the rooms of earlier layers, never from a later one, so no two rooms
import each other (no cycle) and no scene imports a study:

    forms < meshes < run < solve < solid, shell, reference < contact < lens
          < scenes < studies < scripts

- ``run``: the run contract (parameters, results, checkpoints, the Newton settings and
  failure a run reports); ``solve``: numerics that know no model (the path follower, the
  nonlinear and linear solvers, time integration), reading the run's settings;
- ``solid``, ``shell``, ``reference``: the solid's pieces, the Kirchhoff–Love shell, the
  exact solutions; ``contact`` builds on the solid's spaces; ``lens`` on contact;
- scenes: the modules and packages at the top of problems/ (and the registry in
  problems/__init__.py); studies run scenes; scripts are the command line."""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STDLIB = sys.stdlib_module_names

ROOMS = ("run", "solve", "solid", "shell", "reference", "contact", "lens", "studies")
LAYERS: tuple[tuple[str, ...], ...] = (
    ("forms",),
    ("meshes",),
    ("run",),
    ("solve",),
    ("solid", "shell", "reference"),
    ("contact",),
    ("lens",),
    ("scenes",),
    ("studies",),
    ("scripts",),
)
LAYER = {room: depth for depth, rooms in enumerate(LAYERS) for room in rooms}

# the longest function and class, in lines (docstrings and comments included)
MAX_FUNCTION_LINES = 80
MAX_CLASS_LINES = 400
# "path" (every function and class in it) or "path::Qualified.name": why it may be longer
LONG_ALLOWED = {
    "problems/solve/driver.py::NonlinearSolver": "one SNES with the state its callbacks share "
        "(the kept Jacobian and factorisation, the counters, the fallback line search)",
    "problems/contact/node_to_surface.py::NodeToSurfaceContact": "one contact pair: its search, "
        "pattern growth, hooks and checkpointed state share the slave and master arrays",
    "problems/contact/segment_to_segment.py::SegmentToSegmentContact._segment": "one vectorised "
        "pipeline (candidate pairs, clipped segments, integration points, gaps) whose arrays "
        "flow from stage to stage",
    "problems/lens/rotation_free.py::bending_element": "a numba kernel: one triangle's bending "
        "energy, gradient and Hessian in closed form; a call per piece would cost in the hot loop",
    "problems/lens/rotation_free.py::Dynamics": "the rotation-free lens' implicit step: Newton, "
        "the Jacobian pattern that grows with contact, CCD-limited updates and the energy "
        "line search share the step's state",
}


def imported_modules(path: Path) -> set[str]:
    """Absolute names of every module ``path`` imports (relative imports resolved)."""
    package = "eyemech." + ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                module = f"{base}.{node.module}" if node.module else base
            else:
                module = node.module
            names.add(module)
            # `from eyemech.problems import keratotomy` imports a module, not a name
            names.update(f"{module}.{alias.name}" for alias in node.names)
    return names


def sources(folder: str) -> list[Path]:
    return sorted((ROOT / folder).rglob("*.py"))


def room_of_module(name: str) -> str | None:
    """The room (a name of ``LAYERS``) of an eyemech module, None outside eyemech."""
    parts = name.split(".")
    if parts[0] != "eyemech" or len(parts) == 1:
        return None
    if parts[1] != "problems":
        return parts[1]
    return parts[2] if len(parts) > 2 and parts[2] in ROOMS else "scenes"


def room_of_path(path: Path) -> str:
    return room_of_module("eyemech." + ".".join(path.relative_to(ROOT).with_suffix("").parts))


def scene_modules() -> set[str]:
    """The scenes: modules and packages at the top of problems/ that define a SCENE."""
    found = set()
    candidates = [(p, p.stem) for p in (ROOT / "problems").glob("*.py")]
    candidates += [(p, p.parent.name) for p in (ROOT / "problems").glob("*/__init__.py")
                   if p.parent.name not in ROOMS]
    for path, name in candidates:
        tree = ast.parse(path.read_text())
        if any(isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "SCENE" for t in node.targets)
               for node in tree.body):
            found.add(f"eyemech.problems.{name}")
    return found


def layering_breaches(paths: list[Path]) -> list[str]:
    """Every import of a later layer, or of another room of the same layer."""
    breaches = []
    for path in paths:
        room = room_of_path(path)
        for name in sorted(imported_modules(path)):
            target = room_of_module(name)
            if target is None or target == room:
                continue
            if LAYER[target] >= LAYER[room]:
                breaches.append(f"{path.relative_to(ROOT)} ({room}) imports {name} ({target})")
    return breaches


def code_sources() -> list[Path]:
    return [p for folder in ("forms", "meshes", "problems", "scripts") for p in sources(folder)]


def test_forms_are_pure_ufl():
    allowed = {"ufl", "numpy", "basix"}
    for path in sources("forms"):
        for name in imported_modules(path):
            top = name.split(".")[0]
            if top in STDLIB or top in allowed or name.startswith("eyemech.forms"):
                continue
            # `from eyemech.forms import x` adds "eyemech.forms.x"; anything else is a breach
            pytest.fail(f"{path.relative_to(ROOT)} imports {name}: forms/ may import only ufl, numpy, basix")


def test_every_room_is_in_the_stated_order():
    """Each folder of problems/ is a room of ``LAYERS`` (a new room needs its place)."""
    folders = {p.parent.name for p in (ROOT / "problems").glob("*/__init__.py")}
    scenes = {name.rsplit(".", 1)[1] for name in scene_modules()}
    assert folders - scenes == set(ROOMS), "rooms of problems/ and LAYERS differ"
    assert sorted(LAYER) == sorted({"forms", "meshes", "scenes", "scripts", *ROOMS})


def test_rooms_import_only_earlier_layers():
    """No room imports a later one: no run ↔ solve cycle, no scene importing a study."""
    breaches = layering_breaches(code_sources())
    assert not breaches, ("imports against the order of LAYERS (tests/test_architecture.py):\n"
                          + "\n".join(breaches))


def test_no_scene_imports_another_scene():
    scenes = scene_modules()
    assert len(scenes) >= 22
    for path in (ROOT / "problems").rglob("*.py"):
        if "studies" in path.parts:  # a study runs scenes: that is its job
            continue
        parts = path.relative_to(ROOT).with_suffix("").parts
        own = "eyemech." + ".".join(parts[:2])  # the scene a module of a scene package is part of
        for name in imported_modules(path):
            scene = ".".join(name.split(".")[:3])
            if scene in scenes and scene != own:
                pytest.fail(f"{path.relative_to(ROOT)} imports the scene {scene}: move what they "
                            "share to a room")


def long_definitions(path: Path) -> list[tuple[str, int, int]]:
    """(qualified name, lines, limit) of every function and class over its limit."""
    found = []

    def visit(node, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f"{prefix}{child.name}"
                lines = child.end_lineno - child.lineno + 1
                limit = MAX_CLASS_LINES if isinstance(child, ast.ClassDef) else MAX_FUNCTION_LINES
                if lines > limit:
                    found.append((name, lines, limit))
                visit(child, name + ".")
            else:
                visit(child, prefix)

    visit(ast.parse(path.read_text(), str(path)), "")
    return found


def test_functions_and_classes_fit_their_limits():
    """Functions of at most ~80 lines, classes of at most ~400, outside ``LONG_ALLOWED``
    (whose every entry says why, and is still needed)."""
    too_long, used = [], set()
    for path in code_sources() + sources("tests") + sources("notebooks"):
        relative = path.relative_to(ROOT).as_posix()
        for name, lines, limit in long_definitions(path):
            key = next((k for k in (f"{relative}::{name}", relative) if k in LONG_ALLOWED), None)
            if key is None:
                too_long.append(f"{relative}::{name}: {lines} lines (limit {limit})")
            used.add(key)
    assert not too_long, "split these, or add them to LONG_ALLOWED with a reason:\n" + "\n".join(too_long)
    stale = set(LONG_ALLOWED) - used
    assert not stale, f"no longer too long, drop from LONG_ALLOWED: {stale}"
    assert all(len(reason) > 20 for reason in LONG_ALLOWED.values())


def test_rooms_hold_no_scene():
    """Scenes live at eyemech.problems.<scene>; the rooms hold what scenes share."""
    for room in ("run", "solve", "solid", "contact", "lens", "shell", "reference"):
        for path in (ROOT / "problems" / room).glob("*.py"):
            assert "SCENE = Scene(" not in path.read_text(), f"{path.relative_to(ROOT)} defines a scene"


def test_packages_are_installed():
    """Every folder of problems/ with an __init__.py is in pyproject's package list, so a
    wheel carries it."""
    text = (ROOT / "pyproject.toml").read_text()
    for init in (ROOT / "problems").rglob("__init__.py"):
        dotted = "eyemech." + ".".join(init.parent.relative_to(ROOT).parts)
        assert f'"{dotted}"' in text, f"{dotted} is missing from [tool.setuptools] packages"


def test_ruff():
    ruff = shutil.which("ruff") or str(Path(sys.executable).parent / "ruff")
    if not Path(ruff).exists():
        pytest.fail("ruff is not installed: it comes with the `test` extra")
    done = subprocess.run([ruff, "check", "--no-cache", "."], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-1000:]


def test_ruff_checks_the_line_length():
    """The lint that ``test_ruff`` runs includes E501 at pyproject's line length, so a long
    line fails here and not only in a reader's editor."""
    ruff = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["ruff"]
    assert ruff["line-length"] <= 120
    selected = ruff["lint"]["select"]
    assert "E501" in selected or "E" in selected or "E5" in selected, selected


# history in the docs: git log keeps it; a page states facts and points to evidence
HISTORY = re.compile(
    r"\bissues? ?#?\d+|git merge|merge main|after the merge|pre-merge|\bbranch(es)? `[\w./-]+`"
    r"|\bcommits?\b \(?[0-9a-f]{7}|\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)[0-9a-f]{7,40}\b"
    r"|\bsessions?\b|\bwas\b[^.]*\bnow\b|\bformerly\b",
    re.IGNORECASE)
# pages a helper is rewriting; the lead removes the entry when it lands
HISTORY_ALLOWED: dict[str, str] = {}


def history_lines(paths: list[Path]) -> list[str]:
    found = []
    for path in paths:
        relative = path.relative_to(ROOT).as_posix()
        if relative in HISTORY_ALLOWED:
            continue
        for number, line in enumerate(path.read_text().splitlines(), start=1):
            if HISTORY.search(line):
                found.append(f"{relative}:{number}: {line.strip()[:160]}")
    return found


def test_docs_state_facts_not_history():
    """No issue numbers, merges, branches, commit hashes, sessions or "was … now" in
    docs/ and README.md (the project's rule: docs state facts with their evidence)."""
    pages = sorted((ROOT / "docs").rglob("*.md")) + [ROOT / "README.md"]
    assert len(pages) > 20
    found = history_lines(pages)
    assert not found, "history in the docs (state the fact and its evidence):\n" + "\n".join(found)
    assert all((ROOT / page).exists() for page in HISTORY_ALLOWED), "drop a stale HISTORY_ALLOWED entry"


def test_wheel_installs_and_runs_outside_the_checkout(tmp_path):
    """A wheel built from the project carries every package: installed into a folder of
    its own, imported from another working directory, it lists the scenes and runs one."""
    python = sys.executable
    # built from a copy: setuptools writes build/ and *.egg-info/ into the tree it builds
    source = tmp_path / "source"
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(
        ".venv", ".git", "build", "*.egg-info", "results", "docs", "__pycache__", ".pytest_cache"))
    build = subprocess.run([python, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                            "-w", str(tmp_path / "dist"), str(source)], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr[-2000:]
    (wheel,) = (tmp_path / "dist").glob("eyemech-*.whl")
    target = tmp_path / "site"
    install = subprocess.run([python, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target),
                              str(wheel)], capture_output=True, text=True)
    assert install.returncode == 0, install.stderr[-2000:]
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {**__import__("os").environ, "PYTHONPATH": str(target)}
    script = ("import eyemech.problems as p, sys; print(p.__file__); "
              "from eyemech.scripts.cli import main; sys.exit(main())")
    done = subprocess.run([python, "-c", script, "run", "sphere-inflation", "--set", "mesh_size=4",
                           "--out", str(tmp_path / "out"), "--no-fields", "--no-pictures", "--json"],
                          cwd=elsewhere, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.splitlines()[0].startswith(str(target)), "imported the checkout, not the wheel"
    assert '"status": "ok"' in done.stdout.splitlines()[-1]


def test_catalogue_read_from_source_is_the_registry():
    """`eyemech list` reads names, kinds and summaries with ast (no DOLFINx import); they
    must be the registry's."""
    from eyemech.problems import scenes
    from eyemech.scripts.catalogue import scene_catalogue

    registry = sorted((s.name, s.kind, s.summary) for s in scenes().values())
    assert [(e.name, e.kind, e.summary) for e in scene_catalogue()] == registry
