"""Python callbacks handed to PETSc objects."""

from __future__ import annotations

import weakref
from typing import Callable


def petsc_callback(method: Callable) -> Callable:
    """``method`` of an object, for a PETSc object to call, holding the object weakly.

    PETSc keeps a Python callback in C, out of sight of Python's garbage collector: a
    solver whose SNES holds the solver's own bound methods is a cycle the collector
    never frees, with its meshes, their MPI communicators (MPICH has 2,048 a
    process; a long process aborts when they run out: "Too many communicators") and its
    matrices. With the object held weakly, dropping the last reference frees it, and
    petsc4py frees its PETSc objects (tests/test_solver_lifetime.py)."""
    reference = weakref.WeakMethod(method)

    def call(*args, **kwargs):
        return reference()(*args, **kwargs)

    return call
