"""``import dolfinx`` in any Python of an environment with the PyPI DOLFINx wheel.

The wheel ``dolfinx-solver-real`` links its bindings (``dolfinx.cpp``, ``petsc4py``'s
``PETSc``) to MPICH's ``libmpi.so.12``, which the PyPI ``mpich`` wheel installs in the
environment's ``lib/``: a folder their RPATH does not name. ``mpi4py.MPI`` loads that
library from there, and ``import dolfinx_solver`` imports ``mpi4py.MPI`` first
(/work/shared/design.md §1). A bare ``import dolfinx`` in a fresh interpreter or a
Jupyter kernel fails with "libmpi.so.12: cannot open shared object file" otherwise.

eyemech installs ``eyemech-import-order.pth`` (``scripts/build_hooks.py``), which calls
:func:`install` as Python starts: a finder that waits for the first import of DOLFINx,
petsc4py or slepc4py and imports ``dolfinx_solver`` just before it. Nothing is imported
at start-up itself, so a Python that never imports DOLFINx does not load MPI. Where
``dolfinx_solver`` is not installed (a conda-forge or Docker DOLFINx), it does nothing.
``tests/test_import_order.py`` imports DOLFINx in a fresh interpreter and kernel.
"""

from __future__ import annotations

import sys

# the packages whose compiled modules need MPI loaded before them
BINDINGS = frozenset({"dolfinx", "petsc4py", "slepc4py"})


class MPIFirst:
    """A ``sys.meta_path`` finder that finds nothing: it imports ``dolfinx_solver``
    before the first of :data:`BINDINGS` is found by the finders after it, then leaves."""

    def find_spec(self, name: str, path=None, target=None):
        if name.partition(".")[0] not in BINDINGS:
            return None
        uninstall()  # once: dolfinx_solver's own imports must not come back here
        import importlib.util

        if importlib.util.find_spec("dolfinx_solver") is not None:
            import dolfinx_solver  # noqa: F401  (loads mpi4py.MPI, then the bindings resolve)
        return None


def install() -> None:
    """Put the finder first on ``sys.meta_path`` (once; not when MPI is ordered already)."""
    if "dolfinx_solver" in sys.modules or any(type(f).__name__ == "MPIFirst" for f in sys.meta_path):
        return
    sys.meta_path.insert(0, MPIFirst())


def uninstall() -> None:
    sys.meta_path[:] = [f for f in sys.meta_path if type(f).__name__ != "MPIFirst"]
