"""``scleral-buckling``: the encircling buckling operation of Sun & Makinouchi (seed 002,
§3) on the layered half eye of :mod:`eyemech.meshes.eye`.

The operation is four stages along one load path (:mod:`.stages`, one unit of the path
each):

1. iop — intra-ocular pressure: 15 mmHg ramped as a follower pressure on every wetted face
   (vitreous side, subretinal space, tear edges), the cavity's pressure P pinned to the
   ramp. At its end the eye before surgery is recorded, the liquid closed (P_ini = IOP,
   V_ini = the volume then, bulk modulus K; seed 002 eq. 5 as P's row), the buckle placed
   ``buckle_clearance`` outside the sclera and tied to it.
2. buckling — the rigid buckle (a tire on an encircling band) moves radially inward by
   ``indentation`` (``buckle_control = travel``) or as far as an elastic band shortened by
   ``band_shortening_percent`` pulls it (``buckle_control = shortening``: the band's hoop
   tension against the eye's contact force), against the closed liquid, vented at
   ``iop_limit_mmHg`` (``venting``: the surgeon's paracentesis); penalty contact on the
   sclera's outer surface.
3. suturing — forces at the suture bites, tangent to the buckle's outline, directions from
   the last converged step (seed 002, §2.2), spread over each bite (radius
   ``suture_bite_radius``; a point load's response does not converge under refinement).
4. settling (``settle``) — the acute state of step 3 keeps the liquid's volume (the
   paper's law); within hours aqueous outflow returns the IOP to its pre-operative value:
   P is pinned again and its target ramped back, the liquid's volume released.

The model (:mod:`.model`) is a sum of terms (:mod:`.terms`, :mod:`.buckle_terms`): the
tissues (neo-Hooke per tissue, paper Table 1; the calibrated Yeoh coats; or tension-only
fibres in the coats' plane, ``material = fibres``; the retina optionally with incompatible
modes, ``retina_incompatible_modes``), the cavity's liquid, the buckle's contact, the tie
under its footprint, the tire's (or the elastic band's) row, the sutures, the lens'
zonules, the retina's contact with the choroid and, with ``optic_nerve_end_spring`` > 0,
the spring on the optic nerve's end. The eye is held at the end of the optic-nerve stub
(clamped, or on that spring so that it may lengthen); the symmetry plane x = 0 passes
through the tear. Its parameters: :mod:`.parameters` (physics and geometry) and :mod:`.settings`
(solver and stepping); its reference: docs/scleral_buckling.md.
"""

from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from eyemech.problems.run.checkpoint import CheckpointError
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.parameters import MMHG
from eyemech.problems.run.scene import Scene
from eyemech.problems.scleral_buckling import error_estimate
from eyemech.problems.scleral_buckling.measures import DIOPTRES_PER_MM
from eyemech.problems.scleral_buckling.model import BucklingModel
from eyemech.problems.scleral_buckling.output import Writer, bench_outcome, headline
from eyemech.problems.scleral_buckling.parameters import (
    CALIBRATED_C20_SCLERA,
    CORNEA_TO_SCLERA,
    PAPER_OPERATION,
    PAPER_SETTINGS,
    Parameters,
)
from eyemech.problems.scleral_buckling.stages import Operation, largest_step, ramp_value
from eyemech.problems.solve.driver import SecantPredictor, SolveFailure

__all__ = ["BENCHMARK", "CALIBRATED_C20_SCLERA", "CORNEA_TO_SCLERA", "DIOPTRES_PER_MM", "MMHG",
           "PAPER_OPERATION", "PAPER_SETTINGS", "SCENE", "BucklingModel", "Operation",
           "Parameters", "SolveFailure", "Writer", "bench_operation", "bench_outcome", "largest_step",
           "ramp_value", "run", "slide_note"]

# `eyemech bench scleral-buckling`: the whole operation (IOP, buckling, suturing, settling)
# at the paper's resolution (>= 7,421 hexahedra); `make bench` adds the default mesh's row
BENCHMARK = {"resolution": "paper"}


def bench_operation(params: Parameters) -> str:
    """A benchmark row's operation in words: the eye, how the buckle is set, the venting."""
    eye = {"table-1": "Table 1 eye", "calibrated": "calibrated eye", "fibres": "living eye"}
    tightening = (f"band shortened {100 * params.band_shortening_fraction():.0f} %"
                  if params.elastic_band() else f"travel {params.indentation:g} mm")
    vent = f"vented at {params.iop_limit_mmHg:g} mmHg" if params.venting else "not vented"
    return (f"{eye[params.material]}, {params.buckle}, {tightening}, {vent}, "
            + ("settled" if params.settle else "not settled"))


# what this scene's checkpoints hold: one written with another state is refused
STATE_LAYOUT = "terms-and-stages-2"


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        _refuse_other_layouts(ctx)
        model = BucklingModel(params, ctx)
        writer = Writer(model, ctx)
        writer.state(0.0, stage=0)
        operation = Operation(model, ctx, writer)
        model.register(ctx.checkpoints)
        operation.register(ctx.checkpoints)
        ctx.checkpoints.value("state_layout", lambda: STATE_LAYOUT, lambda _saved: None)
        predictor = SecantPredictor(model.solver) if params.predictor == "secant" else None
        if predictor is not None:
            predictor.register(ctx.checkpoints)
        try:
            operation.follow(predictor, label=SCENE.name)
        except SolveFailure as failure:
            measured = model.measure()
            ctx.result.quantities.update(measured)
            if params.buckle_attachment == "frictionless":
                failure.args = (f"{failure.args[0]} {slide_note(measured, params)}",)
            raise
        finally:
            writer.close()
        ctx.result.quantities.update(model.measure())
        ctx.result.quantities.update(operation.summary())
        if params.error_estimate:
            error_estimate.estimate(ctx, run, params)
    return ctx.result


def _refuse_other_layouts(ctx: RunContext) -> None:
    """A run resumed from a checkpoint of this scene whose state is laid out otherwise
    (other terms, other names) is refused before anything is built."""
    meta = ctx.checkpoints.resume_meta
    if meta is None:
        return
    saved = meta.get("values", {}).get("state_layout")
    if saved != STATE_LAYOUT:
        # the folder stays the interrupted run's (problems/run/identity.py): a new run goes
        # elsewhere or after its checkpoints are removed
        folder = Path(meta.get("_folder", ctx.out / "checkpoints" / "ckpt")).parent
        raise CheckpointError(
            f"checkpoint {meta.get('_folder')} was written with another layout of "
            f"scleral-buckling's state ({saved or 'unnamed'}; this version reads "
            f"{STATE_LAYOUT}) and cannot be resumed: start the run again in another "
            f"folder, or remove {folder}")


def slide_note(measured: dict, params: Parameters) -> str:
    """What a failed frictionless run did: the sclera's slide along the buckle at the last
    converged state, and the spring that holds it (docs/scleral_buckling.md, "The
    frictionless buckle's spring")."""
    spring = (f"frictionless_slip_stiffness = {params.frictionless_slip_stiffness:g} MPa/mm; "
              f"without the spring the slide is a near-zero-stiffness mode (about 8.5e-4 "
              f"MPa/mm on the coarse eye) and Newton stalls or the slide flips from step to step "
              f"(docs/scleral_buckling.md, \"The frictionless buckle's spring\").")
    if "buckle_slip_max_mm" not in measured:
        return f"The frictionless buckle: {spring}"
    return (f"The frictionless buckle: at the last converged state the sclera had slid "
            f"{measured['buckle_slip_axial_mean_mm']:+.3f} mm forward on average along it "
            f"({measured['buckle_slip_max_mm']:.3f} mm at most); {spring}")


SCENE = Scene(name="scleral-buckling", kind="scene", parameters=Parameters, run=run,
              summary="encircling scleral buckling on a half eye: IOP, buckle, sutures (seed 002)",
              headline=headline)
