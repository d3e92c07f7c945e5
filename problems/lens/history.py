"""The record of a lens time march (fold or injection), one for the P2 and the P1 lens:
per converged step its time, Newton iterations, cuts, Δt, deepest wall penetration, largest
haptic strain and the lens' distance to itself; and the run's totals."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from eyemech.problems.lens.time_error import TimeErrorTally
from eyemech.problems.run.output import PyvistaSeries


@dataclasses.dataclass
class InjectionHistory:
    """Per converged step of a lens march, and its totals (``quantities``)."""

    time: list[float] = dataclasses.field(default_factory=list)
    newton: list[int] = dataclasses.field(default_factory=list)
    cuts: list[int] = dataclasses.field(default_factory=list)
    dt: list[float] = dataclasses.field(default_factory=list)
    penetration: list[float] = dataclasses.field(default_factory=list)
    strain: list[float] = dataclasses.field(default_factory=list)
    self_distance: list[float] = dataclasses.field(default_factory=list)
    intersecting: list[bool] = dataclasses.field(default_factory=list)
    time_error: TimeErrorTally = dataclasses.field(default_factory=TimeErrorTally)
    frames: list[Path] = dataclasses.field(default_factory=list)  # the P2 scene's PNGs
    series: PyvistaSeries | None = None  # the P2 scene's .vtu frames
    wall: float = 0.0  # seconds of time stepping
    cpu: float = 0.0  # CPU seconds of time stepping (the P1 lens')
    end: float = 0.0  # simulated time at the end, s
    solver_seconds: float = 0.0  # assembly + factorisation + solves, contact hooks included (P2)
    contact_seconds: float = 0.0  # the nodal wall and plunger contact hooks (P2)
    counts: dict = dataclasses.field(default_factory=dict)  # the P1 solver's factorisations, …

    def add(self, time: float, dt: float, iterations: int, cuts: int, penetration: float,
            strain: float) -> None:
        """One converged step (its self-distance and intersection are appended apart, where measured)."""
        self.time.append(time)
        self.newton.append(iterations)
        self.cuts.append(cuts)
        self.dt.append(dt)
        self.penetration.append(penetration)
        self.strain.append(strain)

    def quantities(self) -> dict:
        """The step counts, Newton work, penetration, strain, self-distance and time error of the
        march (and the per-step series ``time``, ``penetration_mm``, ``self_distance_mm``)."""
        distances = [d for d in self.self_distance if np.isfinite(d)]
        steps = len(self.time)
        return dict(
            steps=steps, newton_iterations_total=int(sum(self.newton)),
            newton_iterations_per_step=float(np.mean(self.newton)) if steps else 0.0,
            step_cuts=int(sum(self.cuts)), min_time_step_s=float(min(self.dt, default=0.0)),
            steps_per_second=steps / max(self.wall, 1e-12), wall_seconds=self.wall,
            max_penetration_mm=float(max(self.penetration, default=0.0)),
            haptic_max_strain=float(max(self.strain, default=0.0)),
            min_self_distance_mm=float(min(distances)) if distances else None,
            self_intersecting=bool(any(self.intersecting)),
            time=self.time, penetration_mm=self.penetration, self_distance_mm=self.self_distance,
            **self.time_error.quantities())
