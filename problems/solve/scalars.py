"""The global value of a scalar form: each rank assembles its cells, the ranks sum.

A form assembled repeatedly (a quantity read at every step, a Newton-loop measure) is
compiled once by its owner with ``dolfinx.fem.form`` and passed here compiled; a UFL
form is compiled on the spot, which suits a number computed once (an area, a volume at
set-up). Compiling at every call would redo UFL's processing and look up the JIT cache
each time (tests/test_compile_once.py counts compilations)."""

from __future__ import annotations

import dolfinx
import ufl
from mpi4py import MPI


def assemble_scalar(form: dolfinx.fem.Form | ufl.Form, comm: MPI.Comm | None = None) -> float:
    """∫ of ``form`` over the whole mesh: the sum over ``comm`` (by default the
    communicator of the form's mesh) of every rank's local assembly."""
    compiled = form if isinstance(form, dolfinx.fem.Form) else dolfinx.fem.form(form)
    comm = compiled.mesh.comm if comm is None else comm
    return comm.allreduce(dolfinx.fem.assemble_scalar(compiled), op=MPI.SUM)
