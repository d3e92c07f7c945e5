"""The end of a run frees the parallel PETSc objects the run made.

When Python frees a petsc4py object on more than one rank, petsc4py does not destroy it:
destroying can be collective (a MUMPS factorisation ends on every rank together) and
Python's cycle collector frees at a different moment on each rank, so the object is parked
in PETSc's garbage on its communicator until a collective ``PetscGarbageCleanup`` of that
communicator. Nothing else calls it, and once the DOLFINx mesh or index map whose
communicator PETSc duplicated is gone nothing can: each parked object keeps PETSc's inner
communicator (and a MUMPS factorisation its own four) for the rest of the process. MPICH
has 2,048 communicators a process, and a process that runs out aborts or crashes where the
next ``MPI_Comm_dup`` fails (docs/parallel.md, "Long processes").

The run contract (``RunContext``) calls :func:`start_run` as a run starts and
:func:`release_run_objects` as it ends, on every rank at the same point. The run's solvers
are kept to its end (``newton.hold_solvers``) and closed there; the objects parked on the
communicators of the objects the run still holds are destroyed by PETSc's clean-up; the
objects it still holds (a time integrator's mass matrix, a contact term's matrix) are
destroyed in the order PETSc made them, the same order on every rank. An object that a
scene drops before the end on a communicator where nothing of the run is left at the end
is out of reach (no key names a communicator alike on every rank): such an object is
destroyed by whoever drops it (``obj.destroy()``, as the scenes do).
"""

from __future__ import annotations

import gc
import logging
from typing import Callable

from mpi4py import MPI
from petsc4py import PETSc

log = logging.getLogger("eyemech")


def start_run(comm: MPI.Comm) -> int:
    """The id of the first PETSc object a run on ``comm`` will make (ids grow by one per
    object and process). On more than one rank, the Python objects that exist now are
    moved out of the cycle collector's generations until :func:`release_run_objects`
    (``gc.freeze``): the collection and the search there then look at the run's own
    objects (0.42 s a run of a one-step cantilever-vibration on 2 ranks over the whole
    heap of 115,000 objects, under load)."""
    probe = PETSc.IS().createGeneral([], comm=PETSc.COMM_SELF)
    first_id = probe.getId() + 1
    probe.destroy()
    if comm.size > 1:
        gc.freeze()
    return first_id


def _parallel_objects(first_id: int) -> list[PETSc.Object]:
    """The petsc4py objects Python holds whose PETSc object was made at or after
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
    """End a run started with :func:`start_run` (``first_id``): ``close_solvers()`` closes
    its solvers; on more than one rank, the garbage of the communicators the run's objects
    are on is cleaned up first, and the objects Python still holds after the solvers are
    closed are destroyed last. Returns how many objects Python still held.

    Collective on ``comm``, the run's communicator. The objects are destroyed only if
    every rank holds as many: a rank that holds others made them on its own, and
    destroying a different set on each rank could hang in MUMPS's collective end (they are
    left to petsc4py's garbage then, and a warning says so)."""
    if comm.size == 1:  # petsc4py destroys a serial object as soon as Python frees it
        close_solvers()
        return 0
    try:
        gc.collect()
        objects = _parallel_objects(first_id)
        counts = comm.allgather(len(objects))
        if min(counts) != max(counts):
            close_solvers()
            log.warning("the ranks hold %s PETSc objects of this run: left to petsc4py's "
                        "garbage (they keep their communicators)", counts)
            return 0
        # each inner communicator once, in the order of its first object (alike on every
        # rank), while the objects on it keep it alive
        inner: dict[int, PETSc.Comm] = {}
        for obj in objects:
            communicator = obj.getComm()
            inner.setdefault(communicator.tompi4py().py2f(), communicator)
        for communicator in inner.values():
            PETSc.garbage_cleanup(communicator)
        close_solvers()
        for obj in objects:
            obj.destroy()
        return len(objects)
    finally:
        gc.unfreeze()
