"""The end of a run destroys the parallel PETSc objects the run made.

When Python frees a petsc4py object on more than one rank, petsc4py does not destroy it:
destroying can be collective (a MUMPS factorisation ends on every rank together) and
Python's cycle collector frees at a different moment on each rank, so the object is parked
in PETSc's garbage on its communicator until a collective ``PetscGarbageCleanup`` of that
communicator. Nothing calls it there, and once the mesh whose communicator PETSc
duplicated is gone nothing can: each parked object keeps PETSc's inner communicator (and
a MUMPS factorisation its own four) for the rest of the process. MPICH has 2,048
communicators a process; a long process that runs out aborts or crashes where the next
``MPI_Comm_dup`` fails (docs/parallel.md, "Long processes").

:func:`destroy_run_objects` runs at the end of every run (the run contract,
``RunContext.__exit__``), on every rank at the same point: the objects a scene still holds
there (a time integrator's mass matrix, a contact term's vectors) are destroyed in the
order they were made, the same order on every rank. The solvers are closed just before
(``driver.close_solvers``), and a run keeps every parallel solver it made until then
(``driver.hold_solvers``), so that no MUMPS factorisation is parked before the end.
"""

from __future__ import annotations

import gc
import logging
from typing import Callable

from mpi4py import MPI
from petsc4py import PETSc

log = logging.getLogger("eyemech")


def next_object_id() -> int:
    """The id PETSc gives the next object it makes (ids grow by one per object and
    process, so the objects made after this call have ids >= it)."""
    probe = PETSc.IS().createGeneral([], comm=PETSc.COMM_SELF)
    try:
        return probe.getId() + 1
    finally:
        probe.destroy()


def _parallel_objects(first_id: int) -> list[PETSc.Object]:
    """The petsc4py objects Python still holds whose PETSc object was made at or after
    ``first_id`` on more than one rank, in the order PETSc made them."""
    found = []
    for obj in gc.get_objects():
        if not isinstance(obj, PETSc.Object) or not obj.handle:
            continue
        if obj.getId() >= first_id and obj.getComm().getSize() > 1:
            found.append(obj)
    found.sort(key=lambda obj: obj.getId())
    return found


def release_run_objects(comm: MPI.Comm, first_id: int, close_solvers: Callable[[], None]) -> int:
    """Free the PETSc objects of a run that made its objects from ``first_id`` on:
    ``close_solvers()`` closes its solvers; on more than one rank, the objects parked in
    PETSc's garbage of the communicators the run's objects live on are destroyed first,
    and the objects Python still holds after the solvers are closed last. Returns how
    many objects Python still held.

    Collective: every rank of ``comm`` (the run's communicator) calls it at the same point
    of the run. The parallel objects are destroyed only if every rank holds the same
    number of them: a rank that holds others made them on its own, and destroying a
    different set on each rank could hang in MUMPS's collective end (they are then left to
    petsc4py's garbage, and a warning says so)."""
    if comm.size == 1:  # petsc4py destroys a serial object as soon as Python frees it
        close_solvers()
        return 0
    gc.collect()
    objects = _parallel_objects(first_id)
    counts = comm.allgather(len(objects))
    if min(counts) != max(counts):
        close_solvers()
        log.warning("the ranks hold %s PETSc objects of this run: left to petsc4py's garbage "
                    "(they keep their communicators)", counts)
        return 0
    # each inner communicator once, in the order of its first object (alike on every rank),
    # while the objects on it keep it alive
    inner = {}
    for obj in objects:
        communicator = obj.getComm()
        inner.setdefault(communicator.tompi4py().py2f(), communicator)
    for communicator in inner.values():
        PETSc.garbage_cleanup(communicator)
    close_solvers()
    for obj in objects:
        obj.destroy()
    return len(objects)
