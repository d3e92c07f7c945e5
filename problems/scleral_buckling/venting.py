"""What the operating surgeon's venting costs, stage by stage: how the vented liquid
would leave the eye (:func:`venting_route`), and the IOP along each stage's load path, its
peak and the fraction of the stage spent above the central retinal artery's closing
pressure (:class:`PressureHistory`). The vent itself is the cavity liquid's
(:class:`~eyemech.problems.solid.cavity.VentedCavity`, docs/scleral_buckling.md, Venting)."""

from __future__ import annotations

# µL one anterior-chamber paracentesis takes: 0.1-0.2 mL (the chamber holds about 0.2 mL)
PARACENTESIS_UL = 200.0
# a pressure counts as above the limit beyond this fraction of it: a vented state sits on
# the limit to the Newton solve's tolerance (docs/scleral_buckling.md, Venting)
ABOVE_TOLERANCE = 1e-6


def venting_route(vented_uL: float, subretinal_uL: float) -> str:
    """How ``vented_uL`` (whole eye) would be vented: one paracentesis up to
    ``PARACENTESIS_UL``, then the subretinal fluid drained, up to ``subretinal_uL``;
    beyond both the surgeon would need more than the standard routes."""
    if vented_uL <= 0.0:
        return "none"
    if vented_uL <= PARACENTESIS_UL:
        return "paracentesis"
    if vented_uL <= PARACENTESIS_UL + subretinal_uL:
        return "paracentesis and subretinal drainage"
    return "exceeds paracentesis and subretinal drainage"


def above(start: tuple[float, float], end: tuple[float, float], limit: float) -> float:
    """The length of [f0, f1] where the pressure, linear between (f0, p0) and (f1, p1),
    lies above ``limit``."""
    (f0, p0), (f1, p1) = start, end
    high0, high1 = p0 > limit, p1 > limit
    if high0 and high1:
        return f1 - f0
    if not (high0 or high1):
        return 0.0
    crossing = f0 + (limit - p0) / (p1 - p0) * (f1 - f0)
    return f1 - crossing if high1 else crossing - f0


class PressureHistory:
    """The IOP (mmHg) and the vented volume (µL) at each converged step, stage by stage:
    :meth:`passed` returns the stage's ``peak_iop_mmHg``, ``stage_fraction_above_limit``
    (of the stage's load, the IOP linear between steps) and ``stage_vented_volume_uL``
    so far. A stage starts where the last one ended (the unloaded eye for the first)."""

    def __init__(self, limit_mmHg: float):
        self.limit = limit_mmHg * (1.0 + ABOVE_TOLERANCE)
        self.stage = 0
        self.last = (0.0, 0.0, 0.0)  # (fraction of its stage, IOP, vented) of the last step
        self.peak, self.fraction_above, self.vented_at_start = 0.0, 0.0, 0.0

    def passed(self, stage: int, fraction: float, iop_mmHg: float, vented_uL: float) -> dict:
        if stage != self.stage:  # a new stage starts at the last one's end
            self.stage, self.last = stage, (0.0, self.last[1], self.last[2])
            self.peak, self.fraction_above, self.vented_at_start = self.last[1], 0.0, self.last[2]
        self.fraction_above += above(self.last[:2], (fraction, iop_mmHg), self.limit)
        self.peak = max(self.peak, iop_mmHg)
        self.last = (fraction, iop_mmHg, vented_uL)
        return {"peak_iop_mmHg": self.peak, "stage_fraction_above_limit": self.fraction_above,
                "stage_vented_volume_uL": vented_uL - self.vented_at_start}

    def state(self) -> list:
        return [self.stage, list(self.last), self.peak, self.fraction_above, self.vented_at_start]

    def restore(self, saved: list) -> None:
        self.stage, last, self.peak, self.fraction_above, self.vented_at_start = saved
        self.last = tuple(last)
