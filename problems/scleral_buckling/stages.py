"""The operation as a list of stages: what each moves, what it switches, how it is
stepped and solved. :func:`operation` is the whole operation; adding a stage is adding
an entry there (its controls and switches come from the model's terms).

Each :class:`Stage` covers one unit of the load path, its fraction f from 0 to 1:

- ``ramps``: the controls it moves (:class:`Ramp`, a control of a term by name, from a
  number or another control's value to a number, linearly or linearly in ln);
- ``begin`` / ``end``: switches as it starts and after its last step converged (before
  that step is recorded): functions of the model, such as closing the liquid or placing
  the buckle; an ``end`` switch that solves is counted with the stage's last step and
  may report measurements of its own, recorded with it;
- ``largest_step`` (a fraction of the stage), ``predicts`` (its load steps start from the
  secant predictor) and ``newton`` (its line search, fallback, stagnation test and
  modified Newton's contraction test).

The path follower (:func:`eyemech.problems.solve.driver.follow_stages`) walks them;
:class:`Operation` binds them to a model and records every converged step.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Callable, Literal

from eyemech.problems.run.parameters import MMHG
from eyemech.problems.scleral_buckling.parameters import Parameters
from eyemech.problems.scleral_buckling.venting import PressureHistory
from eyemech.problems.solve.augmentation import Augmentation
from eyemech.problems.solve.driver import NewtonSettings, Stepping, StepRecord, follow_stages

if TYPE_CHECKING:
    from eyemech.problems.scleral_buckling.model import BucklingModel

FIRST_STEP = 0.25      # each stage's first load step at most, as a fraction of the stage
SMALLEST_STEP = 1e-4   # of the whole operation: a step cut below it ends the run
LARGEST_STEP = 0.75    # of a stage


def ramp_value(start: float, end: float, f: float, law: str) -> float:
    """The value at the fraction ``f`` of a ramp from ``start`` to ``end``: linear, or
    linear in ln (``log``, both positive: equal ratios per unit of the stage)."""
    if law == "log" and start > 0 and end > 0:
        return start ** (1.0 - f) * end ** f
    return (1.0 - f) * start + f * end


@dataclasses.dataclass(frozen=True)
class Ramp:
    """A control moved over a stage, from ``start`` to ``end`` (numbers, or names of
    controls whose value is read at each step); ``starts_unknown``: the unknown pinned to
    this control starts each load step at it."""

    control: str
    start: float | str
    end: float | str
    law: Literal["linear", "log"] = "linear"
    starts_unknown: bool = False

    def apply(self, controls: dict, fraction: float) -> None:
        def value(end: float | str) -> float:
            return controls[end].get() if isinstance(end, str) else end

        control = controls[self.control]
        control.set(ramp_value(value(self.start), value(self.end), fraction, self.law))
        if self.starts_unknown:
            control.start_unknown()


Switch = Callable[["BucklingModel"], "dict | None"]


@dataclasses.dataclass(frozen=True)
class Stage:
    """One stage of the operation (see the module docstring)."""

    name: str    # results.json's after_<name>
    title: str   # its pictures' name
    ramps: tuple[Ramp, ...] = ()
    begin: tuple[Switch, ...] = ()
    end: tuple[Switch, ...] = ()
    largest_step: float = LARGEST_STEP
    predicts: bool = True
    newton: NewtonSettings = NewtonSettings()


# -- switches ---------------------------------------------------------------------------
def close_the_liquid(model: BucklingModel) -> None:
    """The liquid law from here, V_ini and P_ini of the inflated eye (seed 002, eq. 5)."""
    model.liquid.close()


def tie_the_buckle(model: BucklingModel) -> None:
    """The sclera held tangentially under the buckle's footprint (sutured buckle)."""
    model.tie.tie()


def place_the_buckle(model: BucklingModel) -> None:
    """The buckle put ``buckle_clearance`` outside the inflated sclera under it."""
    model.buckle.place()


def record_the_eye_before_surgery(model: BucklingModel) -> None:
    """Every change is measured from the eye as it is now."""
    model.optics.record_preoperative(2.0 * model.liquid.volume(), model.liquid.pressure() / MMHG)


def hand_the_tire_to_the_sutures(model: BucklingModel) -> None:
    """The loop model's tire without a band: its travel free, held where buckling put it
    by a force the next stage releases."""
    model.tire.free()


def start_tying(model: BucklingModel) -> None:
    """Mattress sutures: each leg's length is measured from the eye as suturing begins."""
    model.sutures.start_tying()


def release_the_liquid(model: BucklingModel) -> None:
    """Aqueous outflow within hours of surgery: the liquid's volume is free, its pressure
    driven back from the acute one."""
    model.liquid.release()


# -- the operation -----------------------------------------------------------------------
def largest_step(params: Parameters, buckle_step: float = 0.25) -> float:
    """The largest load step as a fraction of a stage: three quarters of it, and never a
    buckle travel of more than ``buckle_step`` of the buckle's radial thickness. A deeper
    jump starts Newton with sclera nodes deep inside the buckle, and its first iterate
    throws them through it (measured: a 0.64 mm jump with the default 1.6 mm buckle left
    the sclera outside the tire, or "converged" in no iteration with the buckle inside
    the eye)."""
    thickness = params.tire_height + params.band_thickness
    travel = params.indentation
    if params.elastic_band():  # at most the slack band's: its radius' share
        travel = params.band_shortening_fraction() * params.band_loop_estimate() / (2 * math.pi)
    if travel <= 0:
        return LARGEST_STEP
    return min(LARGEST_STEP, buckle_step * thickness / travel)


def operation(params: Parameters) -> list[Stage]:
    """The operation of Sun & Makinouchi (seed 002, §3), stage by stage."""
    iop = params.iop_mmHg * MMHG
    largest = largest_step(params)
    stages = [
        # 15 mmHg ramped on every wetted face with P pinned to the ramp; at its end the eye
        # before surgery, the liquid closed and the buckle placed and tied
        Stage("iop", "IOP", ramps=(Ramp("pressure_target", 0.0, iop),),
              end=(close_the_liquid, tie_the_buckle, place_the_buckle,
                   record_the_eye_before_surgery),
              largest_step=largest),
        # the buckle moves radially inward by ``indentation`` against the closed liquid
        # (vented at ``iop_limit_mmHg`` with ``venting``, here and in suturing);
        # full Newton steps (a failed solve repeated with bt: plain Newton can cycle
        # between two active sets) or bt, which in the first stage would only cost
        # iterations (12-14 per step instead of 3-4)
        Stage("buckling", "buckling", ramps=(tightening(params),),
              end=(hand_the_tire_to_the_sutures,),
              largest_step=largest_step(params, params.buckle_step),
              newton=NewtonSettings(line_search=params.line_search)),
        # the sutures' pull, tangent to the buckle's outline; the instrument lets go of a
        # tire the sutures now hold. cp by default: bt creeps at its 0.1 floor here, full
        # steps cost more at the paper's resolution (docs/scleral_buckling.md, Newton's budget)
        Stage("suturing", "suturing",
              ramps=(Ramp("suture_tie", 0.0, 1.0) if params.suture_model == "mattress"
                     else Ramp("suture_force", 0.0, params.suture_force),
                     Ramp("tire_hold", "held_force", 0.0)),
              begin=(start_tying,) if params.suture_model == "mattress" else (),
              largest_step=largest, newton=NewtonSettings(line_search=params.suture_line_search)),
    ]
    if params.settle:
        stages.append(settling(params, iop, largest))
    return stages


def tightening(params: Parameters) -> Ramp:
    """How the buckling stage tightens the buckle (``buckle_control``): the rigid buckle's
    travel ramped to ``indentation``, or the elastic band's shortening taken out of its loop
    (control ``band_tightening``, the fraction of it, 0 to 1)."""
    if params.elastic_band():
        return Ramp("band_tightening", 0.0, 1.0)
    return Ramp("band_travel", 0.0, params.indentation)


def settling(params: Parameters, iop: float, largest: float) -> Stage:
    """Hours after surgery: the acute state keeps the liquid's volume (the paper's law);
    aqueous outflow returns the IOP to its pre-operative value. P is pinned again, its
    target ramped from the acute pressure back to the IOP. Stalled bt solves are stopped
    here only: its converged bt solves fall by 0.78 or less over any 3 iterations (default,
    coarse and paper meshes), while the buckling stage's with line_search = bt plateau at
    0.997 before they converge (docs/scleral_buckling.md, Stalled backtracking)."""
    ramps = (Ramp("pressure_target", "acute_pressure", iop, law=params.settle_ramp,
                  starts_unknown=params.settle_start == "target"),)
    step = min(largest, params.settle_step) if params.settle_step > 0 else largest
    retry = "basic" if params.settle_retry == "basic" and params.settle_line_search == "bt" else None
    return Stage("settling", "settled", ramps=ramps, begin=(release_the_liquid,),
                 largest_step=step, predicts=params.settle_predictor == "secant",
                 newton=NewtonSettings(line_search=params.settle_line_search,
                                       fallback_line_search=retry,
                                       stagnation_window=params.stagnation_window,
                                       reuse_step_relative=True if params.settle_reuse_test == "step"
                                       else None))


def stepping(params: Parameters, stages: int) -> Stepping:
    """The step sizes' rules common to every stage (``predictor``, ``step_effort``,
    ``hard_step_effort``), lengths as fractions of a stage."""
    return Stepping(initial_step=FIRST_STEP, min_step=SMALLEST_STEP * stages,
                    predictor=params.predictor, effort=params.step_effort,
                    hard_iterations=params.hard_step_effort or None)


class _Bound:
    """A stage bound to a model: what the path follower walks."""

    def __init__(self, stage: Stage, number: int, operation: "Operation"):
        self.stage, self.number, self.operation = stage, number, operation
        self.name, self.largest_step = stage.name, stage.largest_step
        self.predicts, self.newton = stage.predicts, stage.newton

    def begin(self) -> None:
        self.operation.switch(self.stage.begin)

    def apply(self, fraction: float) -> None:
        model = self.operation.model
        for ramp in self.stage.ramps:
            ramp.apply(model.controls, fraction)
        model.prepare()

    def finish(self) -> None:
        self.operation.switch(self.stage.end)


class Operation:
    """The stages bound to a model: followed along the path (:meth:`follow`), every
    converged step measured and recorded, each stage's end kept as ``after_<name>``,
    its state drawn (``writer``)."""

    def __init__(self, model: BucklingModel, ctx, writer=None, stages: list[Stage] | None = None):
        self.model, self.ctx, self.writer = model, ctx, writer
        params = model.params
        stages = operation(params) if stages is None else stages
        self.stages = [_Bound(stage, k + 1, self) for k, stage in enumerate(stages)]
        self.results: dict[str, dict] = {}  # the measurements at each stage's end
        self.pressures = PressureHistory(params.iop_limit_mmHg)
        self.reports: dict = {}             # what the last switches reported
        self.augmentation = None
        multipliers = model.multipliers()
        if multipliers:
            every_step = params.augment_at == "every-step"
            self.augmentation = Augmentation(multipliers, lambda value: every_step or self.ends_stage(value),
                                             tolerance=params.augmentation_tolerance,
                                             max_updates=params.max_augmentations)

    def ends_stage(self, value: float) -> bool:
        """Whether the path value ``value`` is a stage's end."""
        count = len(self.stages)
        return any(abs(value - k) <= 1e-12 * count for k in range(1, count + 1))

    def switch(self, switches) -> None:
        for switch in switches:
            self.reports |= switch(self.model) or {}

    def apply(self, value: float, _increment: float = 0.0) -> None:
        """The controls at the path value ``value`` (the stage it lies in, no switches):
        for a caller that follows a part of the path itself."""
        index = min(max(math.ceil(value) - 1, 0), len(self.stages) - 1)
        self.stages[index].apply(min(max(value - index, 0.0), 1.0))

    def follow(self, predictor=None, label: str = "scleral-buckling") -> list[StepRecord]:
        params = self.model.params
        return follow_stages(self.model.solver, self.stages, stepping(params, len(self.stages)),
                             on_converged=self.converged, label=label, quiet=self.ctx.options.quiet,
                             checkpoints=self.ctx.checkpoints, predictor=predictor,
                             augmentation=self.augmentation)

    def converged(self, record: StepRecord, stage: _Bound, ends: bool) -> None:
        values = self.model.measure() | self.reports
        self.reports = {}
        values |= self.pressures.passed(stage.number, record.load - (stage.number - 1),
                                        values["iop_mmHg"], values.get("vented_volume_uL", 0.0))
        self.ctx.record_step(step=record.step, load=record.load, stage=stage.number,
                             newton_iterations=record.iterations, cuts=record.cuts,
                             **record.counts(), krylov_iterations=record.linear_iterations,
                             residuals=record.residuals, **values)
        self.model.converged()
        if ends:
            self.results[stage.name] = values
        if self.writer is not None:
            self.writer.state(record.load, stage.number, stage.stage.title, picture=ends,
                              measured=values)

    def register(self, checkpoints) -> None:
        checkpoints.value("stage_results", lambda: self.results,
                          lambda saved: setattr(self, "results", dict(saved)))
        checkpoints.value("pressure_history", self.pressures.state, self.pressures.restore)
        if self.augmentation is not None:
            # the run's totals in the summary count the updates before the checkpoint too
            checkpoints.value("augmentation_counts", self._augmentation_counts,
                              self._restore_augmentation_counts)

    def _augmentation_counts(self) -> dict:
        return {"updates": self.augmentation.updates,
                "limit_reached": self.augmentation.limit_reached}

    def _restore_augmentation_counts(self, saved: dict) -> None:
        self.augmentation.updates = int(saved["updates"])
        self.augmentation.limit_reached = int(saved["limit_reached"])

    def summary(self) -> dict:
        out = {f"after_{name}": values for name, values in self.results.items()}
        out |= self.model.summary()
        if self.augmentation is not None:
            out["augmentations"] = self.augmentation.updates
            out["augmentation_limit_reached"] = self.augmentation.limit_reached
        return out
