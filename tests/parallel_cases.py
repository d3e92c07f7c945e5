"""Every scene and benchmark at a coarse size for the 1/2/3-rank comparison
(tests/test_parallel.py, run by tests/mpi_scenes.py).

A case: the ``--set`` overrides that make the run take seconds, the quantities compared
with the node-to-surface contact tolerance (``CONTACT_RANKS_RTOL``) instead of the
default relative tolerance, and quantities not compared (with the reason).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path


@dataclasses.dataclass(frozen=True)
class Case:
    overrides: dict[str, object]
    contact: tuple[str, ...] = ()          # compared with CONTACT_RANKS_RTOL (relative)
    # contact quantities already relative to a mean (a spread (max - min) / mean): compared
    # with CONTACT_RANKS_RTOL as an absolute tolerance, i.e. relative to the mean
    contact_normalised: tuple[str, ...] = ()
    skip: dict[str, str] = dataclasses.field(default_factory=dict)  # key -> why not compared
    rtol: float = 1e-6
    # why the case runs only with EYEMECH_PARALLEL_SLOW=1 ("" = always)
    slow: str = ""
    xfail: dict[int, str] = dataclasses.field(default_factory=dict)  # ranks -> known reason
    # a scene that is serial by design: on more ranks it must refuse with exit code 2 (bad
    # input, before any solve) and this text in rank 0's message ("" = runs on any count)
    refused_on_more_ranks: str = ""
    ranks: tuple[int, ...] = (2, 3)  # rank counts compared with the serial run
    petsc: dict[str, object] = dataclasses.field(default_factory=dict)  # --petsc overrides


def wall_clock(key: str) -> bool:
    """Timings are not results: never compared."""
    return "seconds" in key or "per_second" in key


FOLDED_COARSE = Path(__file__).parent / "data" / "iol_folded_coarse.npz"

INJECTION_COST = ("the injection has no shorter form than the whole push (17.5 mm of plunger "
                  "travel at ≤ half the nozzle radius per step): from the committed coarse fold "
                  "it takes ≈ 10 min serially here (tests/test_iol_injection.py)")

PATCH_CONTACT = ("pressure_mean", "pressure_min", "pressure_max", "pressure_rms_error",
                 "contact_contact_normal_force", "contact_max_penetration",
                 "contact_contact_area", "contact_active_nodes")
RETINA_CONTACT = ("max_penetration", "min_gap", "contact_area", "contact_normal_force")


CASES: dict[str, Case] = {
    "cantilever-rolling": Case(dict(divisions=8, moment_fraction=0.25, load_steps=2)),
    "cantilever-vibration": Case(dict(divisions=4, periods=0.25, steps_per_period=16)),
    "contact-patch": Case(
        dict(master_size=0.5, slave_size=0.34), contact=PATCH_CONTACT,
        contact_normalised=("pressure_spread", "stress_spread_lower", "stress_spread_upper"),
        skip={"newton_iterations": "the blocks start touching (gaps exactly 0): round-off, "
                                   "which differs with the partition, decides the first "
                                   "active set, so the Newton path (10 or 12 iterations) "}),
    "cook-membrane": Case(dict(elements_per_side=4)),
    "hemisphere": Case(dict(divisions=6)),
    # P = 40 of Sze's 400 in 2 load steps: radial displacements 0.65 and 0.71 (16 R h), well
    # into the nonlinear range (linear theory: 1.9), 6 Newton iterations per step
    "hemisphere-nonlinear": Case(dict(divisions=4, force=40.0, load_steps=2)),
    "hertz": Case(dict(mesh_size=0.03, far_resolution=2.0, extent=20.0)),
    # the lens self-contact (ipctk on rank 0 of the gathered lens) in the coarse
    # fold's first 0.02 s: 9 steps, 107 Newton iterations (+ 6 cut attempts), the same on 1
    # and 2 ranks, the quantities 1e-13 apart. The first step needs 23 iterations: 30
    # allowed instead of 25, so round-off cannot decide a cut-back. 2 ranks only: 3 ranks
    # (without self-contact) took another step sequence (9 steps instead of
    # 7: an iteration count at a limit), and a third run of ≈ 60 s adds nothing the 2-rank
    # run does not check
    "iol-fold": Case(dict(resolution="coarse", fold_time=0.02, time_step=0.01, frames=1),
                     petsc=dict(snes_max_it=30), ranks=(2,),
                     skip={"ccd_limited_updates": "counts the CCD-shortened updates of the failed "
                           "(cut-back) attempts too, whose diverging Newton iterates round-off "
                           "steers: measured 36 vs 38 on 1 vs 2 ranks with the converged steps, "
                           "their iteration counts and all other quantities equal"}),
    "iol-injection": Case(dict(resolution="coarse", folded_state=FOLDED_COARSE, frames_every=1000),
                          slow=INJECTION_COST),
    # one core by design (it measures steps per second of one process): the 2/3-rank runs
    # check that it refuses cleanly (exit 2, one message, no rank hanging)
    "iol-speed": Case(dict(steps=2, mesh_scale=2.0), refused_on_more_ranks="measures one core"),
    "keratotomy": Case(dict(mesh_size=2.5, azimuthal_divisions=8, layers=1, t_end=1800.0,
                            first_dt=1800.0, dt_growth=1.0, time_stepping="fixed")),
    "liquid-sphere": Case(dict(mesh_size=6.0)),
    "plate-clamped": Case(dict(divisions=4)),
    "plate-simply-supported": Case(dict(divisions=4)),
    "retina-reattachment": Case(
        dict(mesh_size=0.8, half_angle=8.0, load_steps=2), contact=RETINA_CONTACT,
        skip={"contact_pairs_across_ranks": "a property of the partition (checked > 0 on 3 "
                                            "ranks)",
              "jacobian_nonzeros_with_contact": "PETSc's allocation after contact inserted "
              "new entries grows in chunks per rank and per diagonal/off-diagonal block: "
              "not a count of the pattern (measured 278391 on 1 rank, 277086 on 3); the "
              "finite-element pattern, jacobian_nonzeros_fe, is compared exactly"}),
    "scleral-buckling": Case(dict(resolution="coarse")),
    "scordelis-lo": Case(dict(divisions=4)),
    # 0.0005 N/mm (Sze's path ends at 0.8): tip deflection 0.044 mm = 1.5 thicknesses, so the
    # membrane terms act, in 2 load steps without cut-backs (at 0.002 N/mm the coarse ring
    # cuts steps, and the step sequence would then depend on round-off)
    "slit-annular-plate": Case(dict(divisions=12, radial_divisions=2, line_load=0.0005,
                                    load_steps=2)),
    "sls-creep": Case(dict(t_end=10.0, dt=2.0)),
    "sphere-inflation": Case(dict(mesh_size=3.0)),
    "tonometry": Case(dict(mesh_size=1.5, azimuthal_divisions=8, layers=1)),
    "uniaxial-relaxation": Case(dict(ramp_time=2.0, t_end=4.0, mesh_divisions=1)),
}

# scenes whose VTX field output is written and checked (the others run --no-fields)
WITH_FIELDS = ("sphere-inflation",)
# scenes that draw their pictures on N ranks (the others run --no-pictures): each kind of
# picture code -- a gathered grid rendered on rank 0 (sphere, retina, cornea, shells, Cook's
# panel), a gathered plot (hertz), rank 0's own chart (sls-creep) -- must keep the ranks'
# collective calls in step (tests/test_parallel.py)
WITH_PICTURES = ("sphere-inflation", "hertz", "retina-reattachment", "keratotomy",
                 "plate-clamped", "cook-membrane", "sls-creep")


def cli_arguments(name: str, out: Path) -> list[str]:
    """``eyemech run`` arguments of a case."""
    sets = [a for k, v in CASES[name].overrides.items() for a in ("--set", f"{k}={v}")]
    sets += [a for k, v in CASES[name].petsc.items() for a in ("--petsc", f"{k}={v}")]
    fields = [] if name in WITH_FIELDS else ["--no-fields"]
    pictures = [] if name in WITH_PICTURES else ["--no-pictures"]
    return ["-v", "run", name, *sets, "--out", str(out), "--json", "--quiet", *pictures,
            "--checkpoint-every", "0", *fields]
