"""Files that ``--petsc`` options write stay in the run's folder (docs/cli.md).

PETSc's viewer options (``snes_view``, ``ksp_view_mat``, ``snes_monitor``,
``log_view``, ...) take a value ``[type][:file][:format][:mode]``: ``ascii:out.txt``,
``binary:A.bin``, ``hdf5:x.h5``, ``vtk:u.vts``. A run may write such a file only inside
its own output folder: the file name is a name without a folder part and is placed in
the folder itself (each sweep case's own); an absolute path, one that leaves the folder or
names a sub-folder, one of eyemech's own files, a name the file system cannot take, and
viewers that open windows or network connections are refused (exit 2) before anything is
built. ``ascii`` without a file (or ``stdout``/``stderr``) prints, as before.
"""

from __future__ import annotations

from pathlib import Path, PurePosixPath

from eyemech.problems.run.parameters import ParameterError

FILE_VIEWERS = ("ascii", "binary", "hdf5", "vtk", "matlab", "exodusii", "cgns", "adios",
                "adios2")
REFUSED_VIEWERS = ("draw", "socket", "saws", "glvis", "mathematica", "pythonviewer")
PRINTED = ("", "stdout", "stderr")
OWN_FILES = ("results.json", "run.json", ".eyemech.lock", "checkpoints")


def _viewer(value: str) -> tuple[str, str, list[str]] | None:
    """(type, file, the rest) of a viewer value; None when ``value`` is not one."""
    parts = str(value).split(":")
    kind = parts[0].strip().lower()
    if kind in FILE_VIEWERS or kind in REFUSED_VIEWERS or (kind == "" and len(parts) > 1):
        return kind or "ascii", parts[1] if len(parts) > 1 else "", parts[2:]
    return None


def _refusal(key: str, value: str) -> str | None:
    viewer = _viewer(value)
    if viewer is None:
        return None
    kind, name, _ = viewer
    if kind in REFUSED_VIEWERS:
        return (f"{key}={value}: the {kind} viewer opens a window or a connection; runs write "
                "viewers to files in their folder (ascii:FILE, binary:FILE, ...)")
    if kind == "ascii" and name in PRINTED:
        return None
    if name == "":
        return f"{key}={value}: name the file ({kind}:FILE, a name inside the run's folder)"
    path = PurePosixPath(name)
    if path.is_absolute() or ".." in path.parts:
        return (f"{key}={value}: a viewer writes inside the run's folder; give a file name "
                "relative to it (no absolute path, no '..')")
    if path.parts[0] in OWN_FILES:
        return f"{key}={value}: {path.parts[0]} is eyemech's own file in the run's folder"
    if len(path.parts) > 1:
        # the run's folder has no sub-folders for it: PETSc's trial (and the run) could not
        # open the file, which PETSc reports as a value it cannot use
        return (f"{key}={value}: a viewer's file is written in the run's folder itself; give "
                "a file name without a folder")
    return None


def check_files(petsc: dict[str, str]) -> None:
    """ParameterError for the first ``--petsc`` option that would write outside the
    run's folder (or open a window or a connection)."""
    for key, value in petsc.items():
        why = _refusal(key, value)
        if why:
            raise ParameterError("--petsc", why)


def _writes(value: str) -> bool:
    """Whether a (checked) viewer value writes a file."""
    viewer = _viewer(value)
    return viewer is not None and viewer[0] not in REFUSED_VIEWERS and bool(viewer[1]) \
        and not (viewer[0] == "ascii" and viewer[1] in PRINTED)


def _rewritten(petsc: dict[str, str], folder: Path) -> dict[str, str]:
    out = dict(petsc)
    for key, value in petsc.items():
        if _writes(value):
            kind, name, rest = _viewer(value)
            out[key] = ":".join([kind, str(Path(folder) / name), *rest])
    return out


def confined(petsc: dict[str, str], folder: Path | None) -> dict[str, str]:
    """The options with their files placed in ``folder`` (checked first; no folder: a
    file viewer is refused)."""
    check_files(petsc)
    if folder is None:
        for key, value in petsc.items():
            if _writes(value):
                raise ParameterError("--petsc", f"{key}={value} writes a file, and this run "
                                     "has no output folder")
        return dict(petsc)
    return _rewritten(petsc, Path(folder).resolve())


def for_trial(petsc: dict[str, str], scratch: str | Path) -> dict[str, str]:
    """The options with their files in ``scratch`` (the option check's trial solve
    writes them there, not in the run's folder). A file that cannot be made there (a
    name longer than the file system takes) is refused here, naming the option as given:
    PETSc's trial would report it as "a value of the wrong kind", naming the scratch path."""
    check_files(petsc)
    for key, value in petsc.items():
        if _writes(value):
            name = _viewer(value)[1]
            path = Path(scratch) / name
            try:
                path.open("x").close()
                path.unlink()
            except OSError as err:
                raise ParameterError("--petsc", f"{key}={value}: cannot make this file in the "
                                     f"run's folder ({err.strerror})") from None
    return _rewritten(petsc, Path(scratch))
