"""Richardson's estimate of a run's discretisation error (``--set error_estimate=true``).

A scene that offers it solves its problem a second time on a mesh ``ratio`` times coarser
(the same parameters with its resolution parameter divided by ``ratio``: ``Refinement``)
and reports, for each main quantity q, with q_h the run's value, q_H the coarse one,
r = H/h the ratio of their element sizes and p the order at which q converges (measured
in the scene's convergence study; where that order varies over the parameter range, the
lowest measured):

    q_extrapolated   = q_h + (q_h − q_H) / (r^p − 1)     (Richardson)
    q_error_estimate = |q_h − q_H| / (r^p − 1)            (≈ |q_converged − q_h|)

as flat quantities beside q in results.json (so that ``eyemech sweep`` puts them in
sweep.csv), with ``error_estimate_ratio`` (r) and ``error_estimate_order`` (p). The
coarse solve is counted in the run's solver counts and timed as ``error_estimate``; it
writes no fields or pictures. Should it fail (Newton), the estimates are null and
``error_estimate_note`` says why; the run's own quantities stand. docs/cli.md, "Error
estimates", lists the scenes and their quantities. A scene whose meshes form a fixed
ladder, or whose quantities are not in their asymptotic range, reports Roache's grid
convergence index instead (:func:`grid_convergence_index`: scleral-buckling), from a second
solve made by :func:`solve_again`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable

from eyemech.problems.run.parameters import SOLVER, field

RICHARDSON_HELP = ("also solve on a coarser mesh and report Richardson's estimate of the "
                   "discretisation error of the main quantities as <quantity>_error_estimate and "
                   "<quantity>_extrapolated (docs/cli.md, Error estimates)")


def error_estimate_field(help: str = RICHARDSON_HELP) -> Any:
    """The ``error_estimate`` parameter of the scenes that offer the estimate."""
    return field(False, help, group=SOLVER)


@dataclasses.dataclass(frozen=True)
class Refinement:
    """How a scene's estimate is made: ``keys`` are the parameters that set the mesh, each
    coarsened by ``ratio`` for the second solve: an element size (a name ending in
    ``size``) multiplied, a resolution (cells per a length, divisions) divided (an integer
    rounded, at least 1). ``overrides`` are pairs (key, other): where ``other`` is set
    (> 0) it sets the mesh instead of ``key`` and is coarsened in its place. ``order`` is
    the convergence order of ``quantities`` in the element size; ``size(params)``, when
    given, is the element size the parameters give, and the actual ratio is that of the
    two sizes (a rounded number of divisions). ``extrapolate`` False leaves out
    ``<quantity>_extrapolated`` where the two solves are not in the asymptotic range (the
    estimate then only bounds the error)."""

    keys: tuple[str, ...]
    order: float
    quantities: tuple[str, ...]
    ratio: float = 2.0
    overrides: tuple[tuple[str, str], ...] = ()
    size: Callable[[Any], float] | None = None
    extrapolate: bool = True

    def coarse(self, params):
        """``params`` on the coarser mesh, without the estimate."""
        overrides = dict(self.overrides)
        changes = {}
        for key in self.keys:
            other = overrides.get(key)
            name = other if other is not None and getattr(params, other) > 0 else key
            changes[name] = _coarsen(name, getattr(params, name), self.ratio)
        return dataclasses.replace(params, **changes, error_estimate=False)

    def actual_ratio(self, params, coarse) -> float:
        if self.size is not None:
            return self.size(coarse) / self.size(params)
        return self.ratio


def _coarsen(name: str, value, ratio: float):
    if name.endswith("size"):
        return value * ratio
    return max(1, round(value / ratio)) if isinstance(value, int) else value / ratio


def richardson(fine: float, coarse: float, ratio: float, order: float) -> tuple[float, float]:
    """(extrapolated value, error estimate |q_converged − fine|) from two solutions whose
    element sizes differ by ``ratio``, for a quantity converging at ``order``."""
    correction = (fine - coarse) / (ratio ** order - 1.0)
    return fine + correction, abs(correction)


def estimate_errors(ctx, run: Callable, params, refinement: Refinement) -> dict[str, Any]:
    """Solve ``run`` again at the coarse resolution (same communicator, quietly) and add
    the estimates of ``refinement.quantities`` to ``ctx.result.quantities``. Returns what
    was added."""
    coarse = refinement.coarse(params)
    ratio = refinement.actual_ratio(params, coarse)
    added: dict[str, Any] = {"error_estimate_ratio": ratio, "error_estimate_order": refinement.order}
    quantities = ctx.result.quantities
    coarse_quantities, note = solve_again(ctx, run, coarse)
    for name in refinement.quantities:
        fine, rough = quantities.get(name), coarse_quantities.get(name)
        if is_number(fine) and is_number(rough) and ratio > 1.0:
            extrapolated, estimate = richardson(fine, rough, ratio, refinement.order)
        else:
            extrapolated = estimate = None
        added[f"{name}_error_estimate"] = estimate
        if refinement.extrapolate:
            added[f"{name}_extrapolated"] = extrapolated
    if note:
        added["error_estimate_note"] = note
    quantities.update(added)
    return added


def solve_again(ctx, run: Callable, params) -> tuple[dict[str, Any], str]:
    """(quantities, "") of ``run`` with ``params`` on the run's communicator, quietly and
    without fields or pictures, timed as ``error_estimate``; ({}, why) when its Newton
    solve fails (the run's own quantities stand)."""
    from eyemech.problems.run.context import RunOptions  # the context imports this module's users
    from eyemech.problems.run.newton import SolveFailure

    options = RunOptions(quiet=True, fields=False, pictures=False, newton=ctx.options.newton)
    with ctx.timings("error_estimate"):
        try:
            return run(params, comm=ctx.comm, out=None, options=options).quantities, ""
        except SolveFailure as failure:
            return {}, f"the coarse solve failed: {failure}"


def grid_convergence_index(fine: float, coarse: float, ratio: float, order: float,
                           safety: float = 3.0, of: str = "fine") -> float:
    """Roache's grid convergence index (Roache 1994, J. Fluids Eng. 116:405; ASME V&V
    20-2009 §2-4): a band |q − q_converged| ≤ GCI about the value on the ``fine`` (default)
    or the ``coarse`` mesh of two solutions whose element sizes differ by ``ratio`` > 1,
    for a quantity converging at ``order``: GCI_fine = Fs |fine − coarse| / (r^p − 1),
    GCI_coarse = r^p GCI_fine; ``safety`` Fs = 3 for two grids (1.25 needs three, with the
    observed order). Richardson's estimate (:func:`richardson`) is the fine one with Fs = 1."""
    if not ratio > 1.0:
        raise ValueError(f"the meshes' size ratio must be > 1, got {ratio}")
    fine_band = safety * abs(fine - coarse) / (ratio ** order - 1.0)
    if of == "fine":
        return fine_band
    if of == "coarse":
        return fine_band * ratio ** order
    raise ValueError(f"of must be 'fine' or 'coarse', got {of!r}")


def is_number(value: Any) -> bool:
    """A finite number (not a bool, not None)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def extrapolate(values, sizes, order: float = 2.0, bounds: tuple[float, float] = (1.0, 4.0)
                ) -> tuple[float, float]:
    """(extrapolated value, order) from solutions on meshes of element ``sizes`` (any
    order of listing): with three or more, the finest three give the observed order
    (clipped to ``bounds``) where they converge monotonically, else ``order`` is used;
    with two, ``order``. The reference of a convergence study."""
    pairs = sorted(zip(sizes, values), reverse=True)[-3:]
    h = [p[0] for p in pairs]
    q = [p[1] for p in pairs]
    if len(q) < 2:
        raise ValueError("Richardson's extrapolation needs two solutions at least")
    if len(q) == 3 and (q[0] - q[1]) * (q[1] - q[2]) > 0:
        observed = math.log((q[0] - q[1]) / (q[1] - q[2])) / math.log(math.sqrt(h[0] / h[2]))
        order = min(bounds[1], max(bounds[0], observed))
    value, _ = richardson(q[-1], q[-2], h[-2] / h[-1], order)
    return value, order
