"""Scenes and benchmarks. Each scene module (or package, for a scene of several modules)
exposes ``SCENE`` (name, parameter dataclass, ``run``); :func:`scenes` finds them all, so
adding a scene is adding a module.

    from eyemech.problems import sphere_inflation
    result = sphere_inflation.run(sphere_inflation.Parameters(pressure=0.02))
"""

from __future__ import annotations

# The PyPI DOLFINx wheel must import dolfinx_solver (it orders MPI ahead of the compiled
# bindings) before dolfinx or petsc4py; a conda-forge or Docker DOLFINx has no such module.
# Every module of this package is imported after this file, so none repeats it.
try:
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass


import importlib
import pkgutil


def scenes() -> dict:
    """Name -> Scene for every scene (module or package) in this package."""
    found = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        scene = getattr(module, "SCENE", None)
        if scene is not None:  # a package without one is a room (what scenes share)
            found[scene.name] = scene
    return found


def get(name: str):
    """The scene called ``name`` (KeyError listing the known names otherwise)."""
    # by convention scene "a-b" lives in module a_b: import just that one (fast start-up)
    try:
        module = importlib.import_module(f"{__name__}.{name.replace('-', '_')}")
        scene = getattr(module, "SCENE", None)
        if scene is not None and scene.name == name:
            return scene
    except ModuleNotFoundError:
        pass
    known = scenes()
    if name not in known:
        raise KeyError(f"unknown scene '{name}'; known: {', '.join(sorted(known))}")
    return known[name]
