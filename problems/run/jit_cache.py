"""FFCx's lookup of a compiled form in its disk cache, by the file's name instead of a
listing of the cache folder.

FFCx 0.11 (``ffcx.codegeneration.jit.get_cached_module``) finds a cached module with a new
``importlib.machinery.FileFinder`` on the cache folder for every form, which lists the
whole folder: the cost of a cache hit grows with the number of forms ever compiled
(measured: 35 ms a form with 13,000 files in ``~/.cache/fenics``, 2 shared cores under
load; 14 lookups were 0.49 s of a 10 s sphere-inflation run). :func:`cached_module` keeps
FFCx's protocol (the C file created exclusively by the one process that compiles it, the
``.c.cached`` marker waited for by the others) and opens the extension module at its path,
trying the interpreter's extension suffixes in the order ``FileFinder`` tries them.
Installed by the run contract (``problems/run/context.py``) for FFCx 0.11 only; another
version keeps its own lookup.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import logging
import os
import time
from pathlib import Path

import ffcx
import ffcx.codegeneration.jit as jit

logger = logging.getLogger("eyemech")

SUPPORTED_FFCX = "0.11."


def _extension(cache_dir: Path, module_name: str) -> Path | None:
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = cache_dir / (module_name + suffix)
        if path.exists():
            return path
    return None


def cached_module(module_name: str, object_names: list[str], cache_dir, timeout: int):
    """(compiled objects, module) of a form compiled before, waiting up to ``timeout``
    seconds for a compilation in progress elsewhere; (None, None) when this process
    must compile it (it has created the C file). FFCx's signature and semantics."""
    cache_dir = Path(cache_dir)
    c_filename = cache_dir.joinpath(module_name).with_suffix(".c")
    ready_name = c_filename.with_suffix(".c.cached")
    cache_dir.mkdir(exist_ok=True, parents=True)
    try:
        with open(c_filename, "x"):
            pass
        return None, None
    except FileExistsError:
        pass
    for _ in range(timeout):
        if os.path.exists(ready_name):
            path = _extension(cache_dir, module_name)
            if path is None:
                raise ModuleNotFoundError(f"Unable to find JIT module {module_name} in {cache_dir}.")
            spec = importlib.util.spec_from_file_location(
                module_name, path, loader=importlib.machinery.ExtensionFileLoader(module_name, str(path)))
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            return [getattr(module.lib, name) for name in object_names], module
        logger.info("waiting for %s to appear", ready_name)
        time.sleep(1)
    raise TimeoutError(f"JIT compilation timed out, probably due to a failed previous compile: "
                       f"remove {c_filename} or raise the timeout")


def install() -> None:
    """Use :func:`cached_module` in FFCx's JIT (FFCx 0.11 only; idempotent)."""
    if ffcx.__version__.startswith(SUPPORTED_FFCX):
        jit.get_cached_module = cached_module
