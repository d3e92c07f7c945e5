"""Uzawa's outer loop of augmented Lagrangian contact, run by :func:`~eyemech.problems.
solve.driver.follow_path` after a load step's Newton solve has converged.

Each contact keeps multipliers λ (a contact pressure per node) that its residual holds
fixed, p = ⟨λ − α g⟩ (:func:`eyemech.forms.contact.augmented_gap`). After a converged
solve each contact computes its next multipliers λ ← p(g − λ/α) and their relative change
‖λ_new − λ‖/‖λ_new‖ (``trial``); when every change is at most ``tolerance`` the step is
done (the trial values are dropped, so that the state stays the equilibrium of the
multipliers it was solved with), otherwise all are committed and the step solved again
at the same load (an *augmentation*; FEBio's "augmented Lagrangian" with its augmentation
tolerance, Simo & Laursen 1992). Every augmentation's solve is an ordinary Newton solve:
its iterations and factorisations are counted with the step, a failed one cuts the step
as any failed solve (the multipliers then go back to the step's start through the
solver's ``memory_hooks``, where the scene registers them).
"""

from __future__ import annotations

import dataclasses
import logging
from typing import TYPE_CHECKING, Callable, Protocol, Sequence

import numpy as np
from mpi4py import MPI

if TYPE_CHECKING:
    from eyemech.problems.solve.driver import NonlinearSolver

log = logging.getLogger("eyemech")


def relative_change(new: np.ndarray, old: np.ndarray, comm: MPI.Comm) -> float:
    """‖new − old‖ / ‖new‖ over all ranks' entries (collective); 0 when both are zero,
    inf when only ``new`` is."""
    local = np.array([np.sum((new - old) ** 2), np.sum(new**2)])
    difference, size = comm.allreduce(local, op=MPI.SUM)
    if difference == 0.0:
        return 0.0
    return float(np.sqrt(difference / size)) if size > 0 else float("inf")


class Multipliers(Protocol):
    def trial_multipliers(self) -> float:
        """The next multipliers at the current unknowns, kept aside; their relative change
        (collective)."""

    def commit_multipliers(self) -> None:
        """The trial multipliers become the ones the residual holds."""


@dataclasses.dataclass
class Augmentation:
    """Which multipliers, when to augment, and when to stop.

    ``due(value)``: whether the step that converged at ``value`` is augmented (e.g. every
    step, or only at a stage's end); ``tolerance``: the largest relative change of the
    multipliers that ends the loop; ``max_updates``: augmentations per step at most (a
    step that reaches it is accepted, logged and counted in ``limit_reached``)."""

    multipliers: Sequence[Multipliers]
    due: Callable[[float], bool]
    tolerance: float = 0.05
    max_updates: int = 10
    updates: int = 0          # augmentations (Newton solves after a multiplier update), all steps
    limit_reached: int = 0    # steps accepted at max_updates

    def run(self, solver: "NonlinearSolver", iterations: int) -> tuple[bool, int, int]:
        """After a converged solve: update and re-solve until the multipliers settle.
        (converged, the converged solves' Newton iterations, augmentations of this step)."""
        performed = 0
        while True:
            change = max(m.trial_multipliers() for m in self.multipliers)
            if change <= self.tolerance:
                return True, iterations, performed
            if performed >= self.max_updates:
                log.info("augmentation limit (%d) reached with the multipliers still changing "
                         "by %.3g: the step is accepted", self.max_updates, change)
                self.limit_reached += 1
                return True, iterations, performed
            for m in self.multipliers:
                m.commit_multipliers()
            performed += 1
            self.updates += 1
            converged, more = solver.solve()
            if not converged:
                return False, iterations, performed
            iterations += more
