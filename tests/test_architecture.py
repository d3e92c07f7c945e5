"""The layout of the design card (shared/design.md §2), kept by a test: which package may
import what, read from the source with ``ast`` (nothing is imported), and ruff's lint."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STDLIB = sys.stdlib_module_names


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


def scene_modules() -> set[str]:
    """Top-level modules of problems/ that define a SCENE, and packages whose __init__.py
    does (a scene of several modules)."""
    found = set()
    sources = [(path.stem, path) for path in (ROOT / "problems").glob("*.py")]
    sources += [(path.parent.name, path) for path in (ROOT / "problems").glob("*/__init__.py")]
    for name, path in sources:
        tree = ast.parse(path.read_text())
        if any(isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "SCENE" for t in node.targets)
               for node in tree.body):
            found.add(f"eyemech.problems.{name}")
    return found


def test_forms_are_pure_ufl():
    allowed = {"ufl", "numpy", "basix"}
    for path in sources("forms"):
        for name in imported_modules(path):
            top = name.split(".")[0]
            if top in STDLIB or top in allowed or name.startswith("eyemech.forms"):
                continue
            # `from eyemech.forms import x` adds "eyemech.forms.x"; anything else is a breach
            pytest.fail(f"{path.relative_to(ROOT)} imports {name}: forms/ may import only ufl, numpy, basix")


def test_meshes_never_import_problems_or_scripts():
    for path in sources("meshes"):
        for name in imported_modules(path):
            assert not name.startswith(("eyemech.problems", "eyemech.scripts")), \
                f"{path.relative_to(ROOT)} imports {name}"


def test_no_scene_imports_another_scene():
    scenes = scene_modules()
    assert len(scenes) >= 22
    for path in (ROOT / "problems").rglob("*.py"):
        if "studies" in path.parts:  # a study runs scenes: that is its job
            continue
        own = "eyemech." + ".".join(path.relative_to(ROOT).with_suffix("").parts)
        for name in imported_modules(path) & scenes - {own}:
            pytest.fail(f"{path.relative_to(ROOT)} imports the scene {name}: move what they share to a room")


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
