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

**An abandoned compilation.** FFCx moves the C file aside when a compilation raises, but a
process killed while compiling (Ctrl-C, SIGTERM, SIGKILL, a job's time limit) leaves it
behind without the ``.c.cached`` marker, and every later process that needs the form waits
``timeout`` seconds and fails until someone deletes the file by hand. The process that
creates the C file therefore writes ``host pid`` beside it (``.c.owner``); a waiter that
finds that process gone from this host moves the C file aside (``.c.abandoned``, an atomic
rename, so only one waiter wins it) and compiles the form itself. A C file with no owner
record (made by plain FFCx) or an owner on another host keeps FFCx's wait and timeout.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import logging
import os
import socket
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
    if _claim(c_filename):
        return None, None
    for _ in range(timeout):
        if not os.path.exists(ready_name) and _abandoned(c_filename) and _claim(c_filename):
            logger.warning("compiling %s again: the process compiling it before ended "
                           "without finishing (moved aside as .c.abandoned)", module_name)
            return None, None
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


def _claim(c_filename: Path) -> bool:
    """Create the C file exclusively (FFCx's lock: this process compiles) and record its
    owner; False when it exists already."""
    try:
        with open(c_filename, "x"):
            pass
    except FileExistsError:
        return False
    c_filename.with_suffix(".c.owner").write_text(f"{socket.gethostname()} {os.getpid()}\n")
    return True


def _abandoned(c_filename: Path) -> bool:
    """True when the C file's owner record names a process of this host that has ended;
    the C file is then moved aside. Only one waiter does so: it first takes the record
    (an atomic rename) and checks that what it took is still the dead owner's."""
    owner = c_filename.with_suffix(".c.owner")
    if not _ended_here(owner):
        return False
    taken = owner.with_name(f"{owner.name}.{socket.gethostname()}.{os.getpid()}")
    try:
        os.rename(owner, taken)
    except FileNotFoundError:  # another waiter took it first
        return False
    if not _ended_here(taken):  # a new owner wrote its record meanwhile: give it back
        os.replace(taken, owner)
        return False
    taken.unlink()
    try:
        os.replace(c_filename, c_filename.with_suffix(".c.abandoned"))
    except FileNotFoundError:
        return False
    return True


def _ended_here(owner: Path) -> bool:
    """The owner record ``host pid`` names this host and a process that no longer runs."""
    try:
        host, pid = owner.read_text().split()
        return host == socket.gethostname() and not _alive(int(pid))
    except (OSError, ValueError):
        return False


def _alive(pid: int) -> bool:
    """Signal 0 checks that the process exists (PermissionError: another user's, alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


def install() -> None:
    """Use :func:`cached_module` in FFCx's JIT (FFCx 0.11 only; idempotent)."""
    if ffcx.__version__.startswith(SUPPORTED_FFCX):
        jit.get_cached_module = cached_module
