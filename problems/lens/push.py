"""The plunger's travel and the fluid it drives through the injector, shared by the P2
(``iol-injection``) and P1 (:mod:`eyemech.problems.lens.fast_injection`) injections."""

from __future__ import annotations

import dataclasses

import numpy as np


def axial_fluid_speed(x: np.ndarray, speed: float, bore, jet_length: float) -> np.ndarray:
    """``FluidDrag``'s fluid speed (mm/s) at axial positions x: plug flow
    speed (R_bore/R(x))² inside the injector, its jet decaying as exp(−(x − tip)/jet_length)
    beyond the nozzle tip."""
    inside = speed * (bore.radius / bore.wall_radius(np.minimum(x, bore.tip))) ** 2
    return np.where(x < bore.tip, inside, inside * np.exp(-np.maximum(x - bore.tip, 0.0) / jet_length))


@dataclasses.dataclass(frozen=True)
class PlungerMotion:
    """The plunger's travel: from rest, the speed grows linearly to ``speed`` over ``ramp``
    seconds, stays there, and stops once the plunger has travelled ``distance``.

    Why a ramp: a jump from rest to 40 mm/s puts the whole fluid drag c M v_f on the resting lens
    in the first step (and the plunger 0.4 mm into it): the first step was cut 3× (coarse) and 6×
    (paper resolution). A real push also starts from rest."""

    speed: float
    ramp: float
    distance: float

    @property
    def push_time(self) -> float:
        ramp_distance = 0.5 * self.speed * self.ramp
        if ramp_distance >= self.distance:  # still accelerating when it arrives
            return float(np.sqrt(2.0 * self.distance * self.ramp / self.speed))
        return self.ramp + (self.distance - ramp_distance) / self.speed

    def speed_at(self, t: float) -> float:
        if t > self.push_time + 1e-12:
            return 0.0
        return self.speed * min(t / self.ramp, 1.0) if self.ramp > 0.0 else self.speed

    def travel(self, t: float) -> float:
        t = min(max(t, 0.0), self.push_time)
        if self.ramp <= 0.0:
            return self.speed * t
        if t <= self.ramp:
            return 0.5 * self.speed * t * t / self.ramp
        return self.speed * (t - 0.5 * self.ramp)
