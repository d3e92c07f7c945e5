"""A model as a sum of terms: one object per physical contribution.

A :class:`Term` owns everything of one contribution to a model (a tissue's elasticity,
a liquid's pressure, a contact, a suture): its share of the weak form's residual, what it
adds node by node after the assembly (a solver's hooks), the state a restart needs, the
numbers it reports, and the controls an operation moves. The model's residual is the sum
of its terms' residuals; a term reads no other term's attributes (what two terms share,
the model builds and gives to both).

Every method has a default that adds nothing, so a term writes only what it has.
:class:`Control` is a number an operation moves through a stage (a pressure, a travel, a
force), read and set by name.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any, Callable, Sequence

if TYPE_CHECKING:
    import ufl

    from eyemech.problems.run.checkpoint import Checkpoints
    from eyemech.problems.solve.driver import NonlinearSolver


@dataclasses.dataclass(frozen=True)
class Control:
    """A number a stage moves: ``get`` and ``set`` its value; ``start_unknown`` (when the
    control is the target an unknown is pinned to) starts that unknown at it."""

    get: Callable[[], float]
    set: Callable[[float], None]
    start_unknown: Callable[[], None] | None = None

    @classmethod
    def of(cls, constant, start_unknown: Callable[[], None] | None = None) -> Control:
        """The control that reads and sets a scalar dolfinx Constant."""
        return cls(lambda: float(constant.value), lambda value: setattr(constant, "value", value),
                   start_unknown)


class Term:
    """One physical contribution to a model (see the module docstring)."""

    def residual(self, tests: Sequence) -> ufl.Form | None:
        """Its contribution to the residual F(u; v) with the test functions ``tests`` of
        the model's unknowns (None: it adds nothing in UFL)."""
        return None

    def install(self, solver: NonlinearSolver) -> None:
        """What it adds to the assembled system and the solver's bookkeeping: residual and
        Jacobian hooks, matrix entries it may need, state it keeps between iterates."""

    def register(self, checkpoints: Checkpoints) -> None:
        """Its state that a restart needs."""

    def controls(self) -> dict[str, Control]:
        """The numbers an operation moves, by name."""
        return {}

    def prepare(self) -> None:
        """Before each attempt of a load step, after the stage set its controls."""

    def converged(self) -> None:
        """After each converged load step (history, lagged directions)."""

    def measure(self) -> dict[str, Any]:
        """Its measurements at the current state (collective)."""
        return {}

    def multipliers(self) -> list:
        """The augmented Lagrangian multipliers it keeps, if any: Uzawa's loop
        (:mod:`~eyemech.problems.solve.augmentation`) updates them."""
        return []


def total_residual(terms: Sequence[Term], tests: Sequence) -> ufl.Form:
    """The sum of the terms' residuals in the terms' order: the order is the integrals'
    order in the form, which its compiled code (and so its round-off) follows."""
    total = None
    for term in terms:
        form = term.residual(tests)
        if form is not None:
            total = form if total is None else total + form
    if total is None:
        raise ValueError("no term contributes to the residual")
    return total
