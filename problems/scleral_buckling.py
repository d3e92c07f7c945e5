"""``scleral-buckling``: the encircling buckling operation of Sun & Makinouchi (seed
002, §3) on the layered half eye of :mod:`eyemech.meshes.eye`.

Three steps along one load path s ∈ [0, 3]:

1. s ∈ [0, 1] — intra-ocular pressure: 15 mmHg ramped as a follower pressure on every
   wetted face (vitreous side, subretinal space, tear edges). The Real-space pressure
   unknown P is pinned to the ramp.
2. s ∈ [1, 2] — buckling: the liquid is coupled (P_ini = IOP, V_ini = the volume after
   step 1, bulk modulus K; seed 002 eq. 5 as P's row) while the rigid buckle (tire on
   an encircling band) moves radially inward by ``indentation``; penalty contact on the
   sclera's outer surface.
3. s ∈ [2, 3] — suturing: forces at the suture points, tangent to the buckle's
   outline, directions from the last converged step (seed 002, §2.2), spread over each
   suture's bite (radius ``suture_bite_radius``) rather than put on one node, whose
   point-load response does not converge under mesh refinement.
4. s ∈ [3, 4] — settling (``settle``): the acute state of step 3 keeps the liquid's
   volume (the paper's law); within hours aqueous outflow returns the IOP to its
   pre-operative value. P's row is pinned again and its target ramped from the acute
   pressure back to the IOP of step 1: the liquid volume is released.

Every soft tissue is neo-Hookean, W = c (Ī1 − 3), with c per tissue (paper Table 1) held
in a cellwise-constant field (``material = "table-1"``). ``material = "calibrated"`` adds a
Yeoh term c20 (Ī1 − 3)² to the sclera and the cornea, fitted to the living human eye's
pressure–volume curve (Pallikaris et al. 2005; docs/scleral_buckling.md, "Calibrated
eye"). Incompressibility by a pressure multiplier (Q1P0 as in
the paper, or Q2P1). The eye is held at the end of the optic-nerve stub; the
symmetry plane x = 0 passes through the tear.

Retina–choroid contact (steps 2 and 3): penalty node to surface
(:class:`~eyemech.problems.contact.node_to_surface.NodeToSurfaceContact`), slave = the detached
retina's outer face (its nodes), master = the choroid's inner face (its quadrilaterals
split into triangles), α = ``retina_penalty_factor`` · 6 c_retina / h (6c = E of an
incompressible neo-Hooke solid, h the element size along the wall), searched at every
Newton iteration and coupled into the blocked [u, p, P] Jacobian.

The lens (neo-Hooke, c = ``c_lens``) floats in the liquid, wetted on all sides (its
surface is part of the cavity wall, so the liquid volume excludes it exactly), and
hangs on the zonules: linear-elastic bars (E = ``zonule_modulus``, cross-section
``zonule_area``) from its equatorial belt to the ciliary body's inner surface
(:class:`~eyemech.problems.solid.zonules.ZonuleBars`; why bars: see that module).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from typing import Literal

import dolfinx
import dolfinx.fem
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI

from eyemech.forms import (
    NeoHooke,
    Yeoh,
    cauchy_stress,
    deformation_gradient,
    enclosed_volume,
    follower_pressure,
    liquid_law_residual,
    von_mises,
)
from eyemech.forms.buckle import (
    Buckle,
    BuckleShape,
    BuckleSizes,
    band_stop_force,
    forward_slip,
    pinned_travel_residual,
    slip,
    tangential_tie_energy,
    tire_travel_residual,
)
from eyemech.forms.contact import default_penalty, penetration, smoothed_penalty_energy
from eyemech.forms.kinematics import without_variables
from eyemech.meshes.eye import RESOLUTIONS, TISSUES, EyeGeometry, half_eye, zonule_pairs
from eyemech.problems import buckling_output
from eyemech.problems.contact.node_to_surface import NodeToSurfaceContact
from eyemech.problems.contact.rigid import (
    FacePoints,
    NodalPenetration,
    ObstacleMultipliers,
    QuadraturePointMultipliers,
)
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.parameters import MMHG, ParameterError, SceneParameters, field
from eyemech.problems.run.scene import Scene
from eyemech.problems.solid.cavity import check_closed, real_pressure_space
from eyemech.problems.solid.mean_dilatation import MeanDilatation
from eyemech.problems.solid.probes import (
    CellField,
    NodeProbe,
    SurfacePairing,
    facet_nodes,
)
from eyemech.problems.solid.residual import solid_residual
from eyemech.problems.solid.spaces import (
    ELEMENTS,
    global_dofs,
    solid_fields,
    symmetry_bcs,
)
from eyemech.problems.solid.sutures import SutureForces, SuturePoint
from eyemech.problems.solid.zonules import ZonuleBars
from eyemech.problems.solve.augmentation import Augmentation
from eyemech.problems.solve.driver import (
    NonlinearSolver,
    SecantPredictor,
    SolveFailure,
    Stepping,
    StepRecord,
    follow_path,
)
from eyemech.problems.solve.linear_solvers import SolverChoice

log = logging.getLogger("eyemech")

# refraction from the geometry: diopters per mm of axial length (Gullstrand's schematic
# eye, emmetropic: ≈ 2.7 D/mm) and the keratometric index that turns the anterior
# corneal radius into power, K = (n_k − 1)/R (n_k = 1.3375, the keratometers' convention)
DIOPTRES_PER_MM = 2.7
KERATOMETRIC_INDEX = 1.3375
KERATOMETRY_ZONE = 3.0  # mm from the axis: the central cornea a keratometer reads

# the calibrated coats (material = "calibrated"): c20 of the sclera fitted by least squares to
# Pallikaris et al. 2005 (IOVS 46:409), ln(P/10 mmHg) = K ΔV with their in vivo mean
# K = 0.0126 µL⁻¹, over 15-40 mmHg on the default eye (`eyemech study eye-calibration`,
# docs/scleral_buckling.md "Calibrated eye"); the cornea keeps Table 1's ratio to the sclera
CALIBRATED_C20_SCLERA = 56.7
CORNEA_TO_SCLERA = 0.0333 / 0.0833
# MPa/mm: the frictionless buckle's regularising spring, 3.5 times the slide's own
# stiffness (≈ 8.5e-4 MPa/mm on the coarse eye): docs/scleral_buckling.md,
# "The frictionless buckle's spring"
FRICTIONLESS_SLIP_STIFFNESS = 0.003

# hexahedra through the sclera: 8 layers of the 0.5 mm equator are 0.06 mm thick, in-plane
# sizes 36 (coarse) to 11 (paper) times that; more would only add cells
MAX_COAT_LAYERS = 8

# `eyemech bench scleral-buckling`: the paper's resolution (>= 7,421 hexahedra) and its three
# steps (IOP, buckle, sutures), without the settling step
BENCHMARK = {"resolution": "paper", "settle": False}
# the retina's contact partners preallocated: the master triangles within half an element
# beyond the nearest one (docs/scleral_buckling.md, "The contact pattern, preallocated")
RETINA_PATTERN_REACH = 0.5


@dataclasses.dataclass(frozen=True)
class Parameters(SceneParameters, SolverChoice):
    resolution: Literal["coarse", "default", "paper"] = field(
        "default", "mesh: coarse (tests), default, paper (>= the paper's 7,421 hexahedra); "
                   "1.06, 1.59 and 3.45 cells per scleral bending length")
    cells_per_bending_length: float = field(
        0.0, "in-plane cells of the eye wall per scleral bending length √(R t) (R = 11.5 mm, "
             "t = 0.5 mm at the equator: 2.40 mm), rounded up to an even cube-edge count; "
             "0 = the named resolution")
    mesh_size: float = field(0.0, "in-plane element size of the eye wall, rounded down to an even "
                                  "cube-edge count; 0 = from cells_per_bending_length or resolution",
                             "mm")
    max_cells: int = field(30_000, "refuse a mesh estimated above this many hexahedra (before "
                                   "meshing; the paper resolution has 8,150)")
    element: Literal["Q1P0", "Q2P1"] = field("Q1P0", "element family (Q1P0 as in the paper)")
    dg0_pressure: Literal["mixed", "condensed"] = field(
        "mixed", "Q1P0's DG0 pressure: mixed (an unknown per cell, exactly incompressible) or "
                 "condensed (eliminated cell by cell, p = bulk_modulus (J̄ − 1): the mean-dilatation "
                 "method, a displacement system; docs/scleral_buckling.md, \"Condensed Q1P0\")")
    condensed_bulk_ratio: float = field(
        300.0, "dg0_pressure=condensed: each tissue's bulk modulus over its shear modulus μ = 2c "
               "(its volume change O(μ/κ) of its strain): 300 ends the paper's three steps within "
               "0.4 % of mixed; 100 moves the IOP 1.4 %; 1,000 fails in step 2 at the paper's "
               "resolution, 10,000 in step 1 (docs/scleral_buckling.md, \"Condensed Q1P0\")")
    coat_layers: int = field(
        2, "hexahedra through the sclera (1-8; the cornea has 2 more); more do not relieve "
           "Q1P0's bending locking, which is in-plane (ΔAL +0.3-0.5 % with 4 or 6): "
           "docs/scleral_buckling.md, Q2P1 and Q1P0 at equal accuracy")
    iop_mmHg: float = field(15.0, "intra-ocular pressure of step 1", "mmHg")
    bulk_modulus: float = field(2083.3, "bulk modulus of the liquid (seed 002)", "MPa")
    c_cornea: float = field(0.0333, "neo-Hooke c of the cornea (Table 1)", "MPa")
    c_sclera: float = field(0.0833, "neo-Hooke c of the sclera", "MPa")
    c_ciliary_body: float = field(0.01, "neo-Hooke c of the ciliary body", "MPa")
    c_choroid: float = field(0.0083, "neo-Hooke c of the choroid", "MPa")
    c_retina: float = field(0.0008, "neo-Hooke c of the retina", "MPa")
    c_optic_nerve: float = field(0.05, "neo-Hooke c of the optic nerve", "MPa")
    c_lens: float = field(10.0, "neo-Hooke c of the lens (Table 1)", "MPa")
    material: Literal["table-1", "calibrated"] = field(
        "table-1", "laws of the coats: table-1, every tissue neo-Hookean with the c_* above "
        "(seed 002, Table 1); calibrated, the sclera and the cornea stiffen with strain by "
        "c20 (Ī1 − 3)² (fitted to the eye's pressure–volume curve, Pallikaris et al. 2005)")
    c20_sclera: float = field(
        CALIBRATED_C20_SCLERA, "Yeoh c20 of the sclera (material=calibrated; fitted: "
        "docs/scleral_buckling.md, Calibrated eye)", "MPa")
    c20_cornea: float = field(
        CORNEA_TO_SCLERA * CALIBRATED_C20_SCLERA, "Yeoh c20 of the cornea (material=calibrated; "
        "c20_sclera in Table 1's cornea/sclera ratio 0.4)", "MPa")
    lens: bool = field(True, "model the lens and its zonules (off: the liquid fills its place)")
    lens_diameter: float = field(9.0, "equatorial diameter of the lens (Rosen et al. 2006)", "mm")
    lens_thickness: float = field(4.0, "axial thickness of the lens (Atchison & Smith 2000)", "mm")
    zonule_modulus: float = field(100.0, "Young's modulus of the zonules' bars (seed 002)", "MPa")
    zonule_area: float = field(
        0.008, "cross-section of one zonule bar (a 0.1 mm fibre bundle; not given in seed 002)",
        "mm²")
    buckle: Literal["encircling+segmental", "encircling", "segmental"] = field(
        "encircling+segmental", "which buckle: a band all round, a silicone tire over the tear "
        "(segmental), or both (the paper's operation)")
    buckle_attachment: Literal["sutured", "frictionless"] = field(
        "sutured", "sutured: the sclera under the buckle's footprint is tied to it tangentially "
        "from step 2 on; frictionless: it may slide along the buckle")
    frictionless_slip_stiffness: float = field(
        FRICTIONLESS_SLIP_STIFFNESS, "frictionless: a weak tangential spring under the buckle's footprint from step 2 "
        "on, standing for the buckle's friction on the sclera (a regularisation: the slide "
        "along the buckle is a near-zero-stiffness mode, and at 0 Newton stalls on the coarse "
        "eye with 1 mm of travel; 0.003 holds about 4/5 of the slide, "
        "docs/scleral_buckling.md, \"The frictionless buckle's spring\")", "MPa/mm")
    tire_arc_deg: float = field(90.0, "arc of the circumferential silicone tire about the optic "
                                "axis, centred on the tear's meridian (360: a full ring)", "deg")
    tire_orientation: Literal["circumferential", "radial"] = field(
        "circumferential", "circumferential: the tire's long axis runs round the eye (arc "
        "tire_arc_deg); radial: along the tear's meridian (length tire_length, centred at "
        "buckle_position), tire_width across it, sutured either side; radial needs "
        "buckle=segmental and suture_azimuths=0 (docs/scleral_buckling.md, Radial tire)")
    tire_length: float = field(12.0, "radial tire: its length along the meridian, measured on "
                               "the sclera", "mm")
    buckle_position: float = field(
        13.0, "buckle centre behind the limbus, along the sclera. 13.0: the tear (centre 11.5 mm "
        "behind the limbus) on the buckle's anterior slope, ≈ 0.4 mm of tire in front of it "
        "and ≈ 3.4 mm behind its posterior edge, as surgeons place a break (on the descending "
        "slope it leaks: fishmouthing). With 2.0 mm of travel it closes the tear after "
        "suturing on the coarse, default, n = 20 and paper meshes (docs/scleral_buckling.md, "
        "\"Operations searched with the rim on its circle\")", "mm")
    band_width: float = field(2.5, "encircling band width (axial)", "mm")
    band_thickness: float = field(0.6, "encircling band thickness", "mm")
    tire_width: float = field(7.0, "silicone tire width (axial; across the meridian for a radial "
                              "tire)", "mm")
    tire_height: float = field(1.0, "silicone tire height (radial)", "mm")
    buckle_corner_radius: float = field(0.3, "corner radius of the tire's and band's profiles "
                                        "(capped at half their height)", "mm")
    indentation: float = field(
        2.0, "radial inward travel of the buckle in step 2. 2.0: with the buckle at 13.0 mm the "
        "least travel searched that closes the tear after suturing on every mesh (1.5 mm leaves "
        "the default mesh's anterior rim 0.065 mm open); it costs an acute IOP of 49–58 "
        "mmHg and ΔAL ≈ +2.2–2.5 mm acute (docs/scleral_buckling.md, \"The tear at the "
        "defaults\")", "mm")
    buckle_clearance: float = field(0.05, "gap between buckle and sclera before step 2", "mm")
    suture_width: float = field(8.9, "distance between the two bites of a suture (paper 8.90)", "mm")
    suture_force: float = field(0.2, "pull on each suture at the end of step 3", "N")
    suture_bite_radius: float = field(1.0, "radius over which a suture grips the sclera", "mm")
    suture_azimuths: tuple[float, ...] = field((0.0, 90.0, 180.0),
                                               "suture meridians, degrees from the tear", "deg")
    suture_model: Literal["loop", "bites"] = field(
        "loop", "loop: a suture is a loop over the tire; its tension pulls the bites and pushes "
        "the tire in, whose radial travel in steps 3-4 balances the sclera's contact force "
        "(the band keeps its prescribed travel); bites: the pull acts on the bites only and "
        "the tire keeps the band's travel")
    drainage: Literal["none", "external"] = field(
        "none", "external: the subretinal fluid is drained in step 4 (with the settled state): "
        "the subretinal faces lose the liquid pressure, the vitreous pressure presses the "
        "detached retina onto the choroid; the retina's snap onto the choroid is followed in "
        "pseudo-time (drainage_drag_step), then solved once without the drag; where that "
        "fails (the coarse and default eyes) the dragged state is kept and its drag traction "
        "reported (docs/scleral_buckling.md, Subretinal drainage)")
    drainage_drag_step: float = field(
        0.05, "drainage: the retina's largest pseudo-time move per solve under the full IOP "
        "(drag η = IOP / this on its subretinal face, relative to the last solved state; "
        "switched off for the final solve of step 4)", "mm")
    detachment_height: float = field(0.5, "subretinal gap at the detachment's centre "
                                     "(0: the retina is attached)", "mm")
    tear_radius: float = field(1.6, "radius of the causative tear (0: no tear)", "mm")
    retina_thickness: float = field(0.2, "retina thickness", "mm")
    penalty_factor: float = field(
        30.0, "buckle–sclera penalty α = factor · E_sclera / h (30: the hertz study's choice; "
        "100 halves the penetration and doubles the Newton iterations)")
    retina_penalty_factor: float = field(
        100.0, "retina–choroid penalty α = factor · E_retina / h (E = 6 c_retina)")
    contact_method: Literal["penalty", "augmented-lagrangian"] = field(
        "penalty", "the buckle–sclera and retina–choroid contact: penalty, p = α⟨−g⟩; "
        "augmented-lagrangian, p = ⟨λ − α g⟩ with multipliers λ at the buckle integral's Gauss "
        "points and at the retina's nodes, updated after a converged solve (Uzawa) until they "
        "change by at most augmentation_tolerance: the zero-penetration answer, which the "
        "penalty misses by 0.5 % in the axial-length change on the default mesh, for 21 % more "
        "factorisations, hence not the default (docs/scleral_buckling.md, Augmented Lagrangian "
        "contact; docs/contact.md, Augmented Lagrangian)")
    augmented_penalty_scale: float = field(
        1.0, "augmented-lagrangian: both contacts' α as this fraction of the penalty's "
        "(penalty_factor, retina_penalty_factor; the tangential tie and the tire's rows keep "
        "the penalty's). 0.1 made Uzawa's multipliers converge too slowly to pay (coarse eye: "
        "30 augmentations per stage without reaching 0.005)")
    augmentation_tolerance: float = field(
        0.05, "augmented-lagrangian: the multipliers of a step are settled when they change by at "
        "most this fraction, ‖λ_new − λ‖/‖λ_new‖ (FEBio's augmentation tolerance; 0.05 puts the "
        "axial-length change within 0.01 % of 0.01's on the default mesh)")
    max_augmentations: int = field(
        10, "augmented-lagrangian: multiplier updates per load step at most (the step is then "
        "accepted and counted in augmentation_limit_reached)")
    augment_at: Literal["stage-end", "every-step"] = field(
        "stage-end", "augmented-lagrangian: where the multipliers are updated: at the end of each "
        "step of the operation only (the penalty along the path, the multipliers of the last "
        "stage's end carried), or after every converged load step (carried to the next as the "
        "predictor of the contact pressure: 103 factorisations on the coarse eye against 71)")
    contact_smoothing: float = field(
        0.0, "penalty kink rounded off over gaps |g| < ε (buckle and retina contact; "
        "0 = plain kink)", "mm")
    contact_integration: Literal["gauss", "nodal"] = field(
        "gauss", "buckle–sclera penalty evaluated at Gauss points or at the nodes (trapezoidal "
        "rule: node-to-rigid-surface contact)")
    retina_contact: bool = field(True, "enforce retina–choroid contact (off: the gap is only "
                                 "measured and the retina may pass through the choroid)")
    retina_contact_method: Literal["node-to-surface", "segment-to-segment"] = field(
        "node-to-surface", "the retina–choroid pair: retina nodes on choroid triangles, or "
        "segment-to-segment (mortar integration over the retina's facets: passes the contact "
        "patch test, docs/contact.md; its cost in the eye: docs/scleral_buckling.md, "
        "Segment-to-segment retina contact)")
    settle: bool = field(True, "step 4: the settled state hours after surgery; outflow returns "
                         "the IOP to its pre-operative value (the liquid volume is released)")
    tear_closure_tolerance: float = field(0.05, "gap below which the tear's rim counts as closed",
                                          "mm")
    # Newton's budget (docs/bench/scleral-buckling.md); the reference method: predictor=none,
    # jacobian_reuse=0, buckle_step=0.25, step_effort=iterations, hard_step_effort=0,
    # line_search=bt, suture_line_search=bt, settle_line_search=bt (settle_retry=none)
    predictor: Literal["secant", "none"] = field(
        "secant", "start each load step from the secant through the stage's last two converged "
        "states (none: from the last converged state)")
    jacobian_reuse: float = field(
        0.5, "modified Newton: keep the Jacobian and its factorisation while each iteration "
        "reduces the residual by this factor or more, once it is below 1 % of the solve's "
        "first (0: full Newton, a fresh factorisation every iteration)")
    jacobian_reuse_test: Literal["residual", "step"] = field(
        "residual", "modified Newton's contraction test: residual = the residual's reduction "
        "against jacobian_reuse; step = against what the step the line search took predicts, "
        "1 - lambda (1 - jacobian_reuse), so that backtracking's short steps keep the "
        "factorisation (docs/scleral_buckling.md, Newton's budget)")
    linear_reuse: Literal["none", "krylov"] = field(
        "none", "krylov = every Newton direction from the current Jacobian by FGMRES "
        "preconditioned with the last LU factorisation, refactorised only when FGMRES needs "
        "more than krylov_max_it iterations or contact grows the Jacobian's pattern (Newton's "
        "convergence kept; jacobian_reuse is then ignored, krylov_jacobian_reuse used): 2-5x "
        "fewer factorisations on every mesh, but not measurably faster at the paper's "
        "resolution on 2 ranks (slower alone, within 3 % with krylov_predict_after=5), "
        "hence not the default; "
        "none = a factorisation per Jacobian (docs/scleral_buckling.md, Krylov on a kept "
        "factorisation)")
    krylov_max_it: int = field(20, "linear_reuse=krylov: FGMRES iterations on the kept "
                               "factorisation before it is refreshed and the solve repeated")
    krylov_refresh_above: int = field(
        0, "linear_reuse=krylov: a Newton iteration whose FGMRES needed more iterations than "
        "this refactorises before the next one (0: only a failed FGMRES solve does)")
    krylov_rtol: float = field(1e-8, "linear_reuse=krylov: FGMRES's relative tolerance per Newton "
                               "iteration (1e-6 at the paper's resolution: 57 factorisations "
                               "against 60-61, the same quantities to 3e-7; docs/scleral_buckling.md, "
                               "Krylov on a kept factorisation, with the NaN cut)")
    krylov_ew: bool = field(False, "linear_reuse=krylov: Eisenstat-Walker's FGMRES tolerance "
                            "per Newton iteration instead of krylov_rtol")
    krylov_predict_after: int = field(
        0, "linear_reuse=krylov: after this many FGMRES iterations on a kept factorisation, "
        "refactorise at once when their mean contraction predicts more than krylov_max_it "
        "(0: off)")
    krylov_jacobian_reuse: float = field(
        0.0, "linear_reuse=krylov: keep the assembled Jacobian too while each Newton iteration "
        "reduces the residual by this factor or more, below 1 % of the solve's first "
        "(modified Newton on the kept factorisation, as jacobian_reuse; 0: a Jacobian every "
        "iteration)")
    buckle_step: float = field(
        0.125, "largest buckle travel per load step of step 2, as a fraction of the buckle's "
        "radial thickness (the other steps keep a quarter)")
    step_effort: Literal["iterations", "factorisations"] = field(
        "factorisations", "what sizes the next load step: grown after <= 6, halved after > "
        "hard_step_effort of the step's Newton iterations or its factorisations")
    line_search: Literal["basic", "bt", "cp"] = field(
        "basic", "Newton's line search while the buckle moves in (step 2): basic = the full step "
        "(a failed solve repeated once with bt before the load step is cut); bt = backtracking "
        "on the residual's norm, which creeps at its 0.1 floor where a step crosses the "
        "contact's kink. Step 3 as suture_line_search says, step 4 as settle_line_search "
        "(docs/scleral_buckling.md, Which contact chatters); cp: as in suture_line_search")
    full_step_nan: Literal["cut", "retry"] = field(
        "cut", "a solve with full steps (line_search=basic) whose Newton step makes the "
        "residual NaN or inf (inverted elements: the load step is too large for the mesh): "
        "cut = its load step is cut at once; retry = the solve is repeated with bt first, "
        "which crawled at its 0.1 floor to the iteration limit at the paper's resolution "
        "(docs/scleral_buckling.md, A NaN cuts the load step)")
    suture_line_search: Literal["cp", "bt", "basic"] = field(
        "cp", "Newton's line search in step 3 (the sutures' pull): cp = the step length where "
        "the energy's directional derivative F(u + a du).du vanishes (no rejection of a step "
        "that raises the residual's norm where retina pairs switch; a failed solve repeated "
        "once with bt); bt = backtracking on the residual's norm, which creeps at its 0.1 "
        "floor there; basic = full steps (docs/scleral_buckling.md, Newton's budget)")
    settle_ramp: Literal["linear", "log"] = field(
        "linear", "step 4's pressure ramp from the acute IOP to the pre-operative one: linear in "
        "P, or log (linear in ln P: equal pressure ratios per unit of load)")
    settle_start: Literal["target", "converged"] = field(
        "target", "step 4's load steps start with P at its pinned target (the pressure drop "
        "then loads the wall at the start, and bt accepts Newton's full first step) or at "
        "the last converged (or predicted) P (converged), where bt sees only P's row and "
        "creeps at its 0.1 floor (docs/scleral_buckling.md, The settling step)")
    settle_reuse_test: Literal["step", "residual"] = field(
        "step", "modified Newton's contraction test in step 4 (settling): step = against what "
        "the step the line search took predicts, 1 - lambda (1 - jacobian_reuse), so that bt's "
        "creep at its 0.1 floor keeps the factorisation; residual = as in the other steps, "
        "jacobian_reuse_test (docs/scleral_buckling.md, The settling step)")
    settle_line_search: Literal["bt", "basic", "cp"] = field(
        "bt", "Newton's line search in step 4: basic = full steps (a failed solve repeated "
        "once with bt): fewer factorisations on the default and coarse meshes, where bt creeps "
        "at its 0.1 floor in the first settling load step, more at the paper's resolution; "
        "cp as in suture_line_search (docs/scleral_buckling.md, Newton's budget)")
    settle_retry: Literal["none", "basic"] = field(
        "none", "step 4 with settle_line_search=bt: basic = a solve that fails (bt's step "
        "below its floor) is repeated once from its start with full steps before the load "
        "step is cut: fewer factorisations, but a settled eye 2 % from the reference method's "
        "at the paper's resolution; none = cut at once (docs/scleral_buckling.md, Newton's "
        "budget)")
    hard_step_effort: int = field(10, "effort above which the next load step is halved "
                                  "(0: only a failed solve cuts it)")
    settle_predictor: Literal["secant", "none"] = field(
        "secant", "step 4's load steps start from the secant (with predictor = secant) or "
        "from the last converged state (none; docs/scleral_buckling.md, Newton's budget)")
    settle_step: float = field(
        0.125, "largest load step of step 4 (settling) as a fraction of the step: 1/8 keeps "
        "the settled eye within 0.6 % of 20 equal load steps' (coarse and default meshes), "
        "larger steps moved it up to 1.4 %. 0, and always with drainage: as the other steps, "
        "three quarters of a step or the buckle_step = 0.25 travel's share "
        "(docs/scleral_buckling.md, The settling step)")
    restore_contact_memory: bool = field(
        False, "a cut load step or a retried Newton solve starts from the retina contact's "
        "sticky triangles of its start (off: from those of the failed attempt's last iterate). "
        "On: the result no longer depends on where a failed attempt stopped, but at the "
        "paper's resolution the path moved and cost 154 factorisations instead of 116 "
        "(docs/scleral_buckling.md, Stalled backtracking)")
    stagnation_window: int = field(
        0, "step 4: a Newton solve with bt whose residual fell by less than 10 % over this "
        "many iterations is stopped as failed and its load step cut (0: only the iteration "
        "limit or a failed line search stops it; with 3, settling steps of 1/8 that creep "
        "for 3 iterations and then converge were cut until the run failed: "
        "docs/scleral_buckling.md, Stalled backtracking, The settling step)")

    def validate(self) -> None:
        self.require_positive("iop_mmHg", "bulk_modulus", "c_cornea", "c_sclera", "c_ciliary_body",
                              "c_choroid", "c_retina", "c_optic_nerve", "band_width",
                              "band_thickness", "tire_width", "suture_width", "penalty_factor",
                              "retina_penalty_factor", "c_lens", "lens_diameter",
                              "lens_thickness", "zonule_modulus", "zonule_area",
                              "suture_bite_radius", "tire_length", "augmented_penalty_scale",
                              "augmentation_tolerance", "max_augmentations",
                              "tear_closure_tolerance", "retina_thickness", "max_cells")
        self.require_nonnegative("cells_per_bending_length", "mesh_size")
        if not self.condensed_bulk_ratio > 0:
            raise ParameterError("condensed_bulk_ratio", f"{self.condensed_bulk_ratio}: must be > 0")
        if self.dg0_pressure == "condensed" and (self.element != "Q1P0" or self.solver != "direct"):
            raise ParameterError("dg0_pressure", "condensed needs element Q1P0 and solver direct "
                                 f"(the iterative solver splits [u, p]), not {self.element}, "
                                 f"{self.solver}")
        if not 1 <= self.coat_layers <= MAX_COAT_LAYERS:
            raise ParameterError("coat_layers", f"{self.coat_layers}: an integer from 1 to "
                                 f"{MAX_COAT_LAYERS} (hexahedra through the sclera)")
        if not 0 <= self.jacobian_reuse < 1:
            raise ParameterError("jacobian_reuse", f"{self.jacobian_reuse}: a contraction factor "
                                 "in [0, 1) (0: full Newton)")
        if not 0 < self.buckle_step <= 0.25:
            raise ParameterError("buckle_step", f"{self.buckle_step}: a fraction in (0, 0.25] of "
                                 "the buckle's thickness (deeper jumps throw the sclera through it)")
        if not 0 < self.krylov_rtol < 1:
            raise ParameterError("krylov_rtol", f"{self.krylov_rtol}: a tolerance in (0, 1)")
        if self.krylov_max_it < 1:
            raise ParameterError("krylov_max_it", f"{self.krylov_max_it}: must be >= 1")
        if not 0 <= self.krylov_predict_after < self.krylov_max_it:
            raise ParameterError("krylov_predict_after", f"{self.krylov_predict_after}: must be "
                                 f"in [0, krylov_max_it = {self.krylov_max_it})")
        if not 0 <= self.krylov_jacobian_reuse < 1:
            raise ParameterError("krylov_jacobian_reuse", f"{self.krylov_jacobian_reuse}: a "
                                 "contraction factor in [0, 1)")
        if self.linear_reuse == "krylov" and self.solver == "iterative":
            raise ParameterError("linear_reuse", "krylov keeps a direct factorisation: "
                                 "not with solver=iterative")
        if self.contact_method == "augmented-lagrangian" \
                and self.retina_contact_method == "segment-to-segment":
            raise ParameterError("contact_method", "augmented-lagrangian keeps a multiplier per "
                                 "retina node: with retina_contact_method=node-to-surface only")
        if self.hard_step_effort < 0:
            raise ParameterError("hard_step_effort", f"{self.hard_step_effort}: must be >= 0")
        if self.stagnation_window < 0:
            raise ParameterError("stagnation_window", f"{self.stagnation_window}: must be >= 0")
        if not 0 <= self.settle_step <= 0.75:
            raise ParameterError("settle_step", f"{self.settle_step}: a fraction in [0, 0.75] "
                                 "of step 4 (0: the other steps' largest)")
        self.require_nonnegative("c20_sclera", "c20_cornea", "buckle_corner_radius", "tire_height",
                                 "contact_smoothing", "frictionless_slip_stiffness", "indentation", "suture_force",
                                 "detachment_height", "tear_radius")
        if self.material == "table-1":
            for key, default in (("c20_sclera", CALIBRATED_C20_SCLERA),
                                 ("c20_cornea", CORNEA_TO_SCLERA * CALIBRATED_C20_SCLERA)):
                if getattr(self, key) != default:
                    raise ParameterError(key, "is used only with material=calibrated (table-1 "
                                         "is neo-Hookean)")
        if self.buckle_attachment == "sutured" and self.frictionless_slip_stiffness != FRICTIONLESS_SLIP_STIFFNESS:
            raise ParameterError("frictionless_slip_stiffness", "is used only with "
                                 "buckle_attachment=frictionless (the sutured buckle is tied)")
        if not 0 < self.tire_arc_deg <= 360:
            raise ParameterError("tire_arc_deg", f"{self.tire_arc_deg} degrees: the tire's arc must "
                                 "lie in (0, 360] degrees")
        if self.drainage != "none" and self.detachment_height == 0:
            raise ParameterError("drainage", "there is no subretinal fluid to drain: the retina "
                                 "is attached (detachment_height = 0)")
        if self.drainage_drag_step <= 0:
            raise ParameterError("drainage_drag_step", "must be positive")
        if self.drainage != "none" and not self.settle:
            raise ParameterError("drainage", "drainage acts in step 4 (the settled state, where "
                                 "the liquid volume is free): it needs settle = true")
        if self.buckle_clearance < 0:
            raise ParameterError("buckle_clearance", "the buckle would start inside the eye "
                                 f"({self.buckle_clearance} mm); it must be >= 0")
        self._validate_orientation()
        shape = self.buckle_shape()
        if self.suture_azimuths and any(shape.element_at(a) is None for a in self.suture_azimuths):
            raise ParameterError("suture_azimuths", "a suture lies off the segmental tire (its arc "
                                 f"is ±{self.tire_arc_deg / 2:g} degrees about the tear): "
                                 "nothing to hold there")
        widest = max((shape.element_at(a)[0] for a in self.suture_azimuths),
                     default=shape.footprint)
        if self.suture_width < widest:
            raise ParameterError("suture_width", f"{self.suture_width} mm is narrower than the buckle "
                                 f"({widest} mm): the sutures would pass through it")
        if self.suture_width > shape.footprint + 8.0:
            raise ParameterError("suture_width", f"{self.suture_width} mm is wider than the buckle "
                                 f"region (buckle {shape.footprint} mm + 4 mm each side)")
        geometry = self.geometry()
        if self.indentation >= geometry.sclera_radius:
            raise ParameterError("indentation", f"{self.indentation} mm would push the buckle "
                                 f"through the eye's axis (sclera radius {geometry.sclera_radius} mm)")
        arc_to_pole = math.radians(180.0 - geometry.limbus_angle) * geometry.sclera_radius
        if shape.radial:
            self._validate_radial_extent(arc_to_pole - 2 * geometry.optic_nerve_radius)
        elif not shape.footprint < self.buckle_position < arc_to_pole - 2 * geometry.optic_nerve_radius:
            raise ParameterError("buckle_position", f"must put the buckle on the sclera between the "
                                 f"limbus and the optic nerve ({shape.footprint:.1f}–"
                                 f"{arc_to_pole - 2 * geometry.optic_nerve_radius:.1f} mm)")
        if any(not 0 <= a <= 180 for a in self.suture_azimuths) or not self.suture_azimuths:
            raise ParameterError("suture_azimuths", "need angles in [0, 180] degrees (the half eye)")
        try:
            geometry.validate()
        except Exception as err:
            key = "lens_diameter" if "lens" in str(err) else self.resolution_key()
            raise ParameterError(key, str(err)) from None

    def _validate_orientation(self) -> None:
        """A radial tire is used alone (segmental: a band all round would run across it,
        and the tie and the band's stop act about one axis); its sutures cross it on the
        tear's meridian; tire_arc_deg and tire_length belong each to one orientation."""
        if self.tire_orientation == "radial":
            if self.buckle != "segmental":
                raise ParameterError("tire_orientation", f"radial with buckle={self.buckle}: a "
                                     "radial tire is a segmental buckle (set buckle=segmental)")
            if self.tire_arc_deg != 90.0:
                raise ParameterError("tire_arc_deg", "sets a circumferential tire's arc; a radial "
                                     "tire's extent is tire_length")
            if tuple(self.suture_azimuths) != (0.0,):
                raise ParameterError("suture_azimuths", "a radial tire lies on the tear's meridian: "
                                     "its sutures cross it there (suture_azimuths=0)")
        elif self.tire_length != 12.0:
            raise ParameterError("tire_length", "sets a radial tire's length (tire_orientation="
                                 "radial); a circumferential tire's extent is tire_arc_deg")

    def _validate_radial_extent(self, meridian: float) -> None:
        """The radial tire on the sclera between the limbus and the optic nerve's margin
        (``meridian`` mm of arc from the limbus)."""
        if self.tire_length >= meridian:
            raise ParameterError("tire_length", f"{self.tire_length} mm is longer than the meridian "
                                 f"from the limbus to the optic nerve ({meridian:.1f} mm)")
        half = 0.5 * self.tire_length
        if not half < self.buckle_position < meridian - half:
            raise ParameterError("buckle_position", f"puts the {self.tire_length} mm radial tire "
                                 f"off the sclera: its centre must lie {half:.1f}–{meridian - half:.1f} "
                                 "mm behind the limbus")

    def resolution_key(self) -> str:
        if self.mesh_size > 0:
            return "mesh_size"
        return "cells_per_bending_length" if self.cells_per_bending_length > 0 else "resolution"

    @property
    def cells_per_edge(self) -> int:
        """The cube-edge count of the wall's mesh: from ``mesh_size``, else from
        ``cells_per_bending_length`` (the bending length of the default geometry), else
        the named ``resolution`` (8, 12, 26)."""
        reference = EyeGeometry()
        if self.mesh_size > 0:
            return reference.cells_per_edge_for(self.mesh_size)
        if self.cells_per_bending_length > 0:
            return reference.cells_per_edge_for(reference.bending_length
                                                / self.cells_per_bending_length)
        return RESOLUTIONS[self.resolution]

    @property
    def estimated_cells(self) -> int:
        return self.geometry().estimated_cells

    def geometry(self) -> EyeGeometry:
        return EyeGeometry(cells_per_edge=self.cells_per_edge, coat_layers=self.coat_layers,
                           detachment_height=self.detachment_height,
                           retina_thickness=self.retina_thickness, lens=self.lens,
                           tear_radius=self.tear_radius,
                           lens_diameter=self.lens_diameter, lens_thickness=self.lens_thickness)

    def buckle_shape(self) -> BuckleShape:
        return BuckleShape(self.band_width, self.band_thickness, self.tire_width, self.tire_height,
                           self.buckle_corner_radius, self.buckle, self.tire_arc_deg,
                           self.tire_orientation, self.tire_length, self.geometry().sclera_radius)

    def stiffness(self) -> dict[str, float]:
        return {t: getattr(self, f"c_{t}") for t in TISSUES}

    def stiffening(self) -> dict[str, float]:
        """Yeoh c20 per tissue of the calibrated coats (0 elsewhere)."""
        return {"sclera": self.c20_sclera, "cornea": self.c20_cornea}


def run(params: Parameters, comm: MPI.Comm | None = None, out: str | Path | None = None,
        options: RunOptions | None = None):
    with RunContext(SCENE.name, params, comm, out, options) as ctx:
        model = BucklingModel(params, ctx)
        writer = buckling_output.Writer(model, ctx)
        writer.state(0.0, stage=0)
        model.register_checkpoint(ctx.checkpoints)
        predictor = SecantPredictor(model.solver) if params.predictor == "secant" else None
        if predictor is not None:
            predictor.register(ctx.checkpoints)
        try:
            follow_path(model.solver, model.apply, _stepping(params), predictor=predictor,
                        on_converged=lambda record: _converged(model, ctx, writer, record),
                        label=SCENE.name, quiet=ctx.options.quiet, checkpoints=ctx.checkpoints,
                        augmentation=model.augmentation)
        except SolveFailure as failure:
            measured = model.measure()
            ctx.result.quantities.update(measured)
            if params.buckle_attachment == "frictionless":
                failure.args = (f"{failure.args[0]} {slide_note(measured, params)}",)
            raise
        finally:
            writer.close()
        ctx.result.quantities.update(model.measure())
        ctx.result.quantities.update(model.summary())
    return ctx.result


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


def _stepping(params: Parameters) -> Stepping:
    """The load path 0 → ``_span`` with a stop at each stage's end, stepped as the
    budget parameters (``predictor``, ``buckle_step``, ``step_effort``,
    ``hard_step_effort``) say."""
    largest = _max_step(params)
    stages = [largest] * int(_span(params))
    stages[1] = _max_step(params, params.buckle_step)
    # with drainage step 4 is also the retina's pseudo-time settling, measured with the other
    # steps' load steps (docs/scleral_buckling.md, The settling step)
    if params.settle and params.settle_step > 0 and params.drainage == "none":
        stages[3] = min(largest, params.settle_step / _span(params))
    predicts = (True, True, True, params.settle_predictor == "secant")
    return Stepping(0.0, _span(params), initial_step=min(0.25 / _span(params), largest),
                    max_step=largest, stops=(1.0, 2.0, 3.0), stage_max_steps=tuple(stages),
                    stage_names=("IOP", "buckling", "suturing", "settling")[:int(_span(params))],
                    stage_predicts=predicts[:int(_span(params))],
                    predictor=params.predictor, effort=params.step_effort,
                    hard_iterations=params.hard_step_effort or None)


def _max_step(params: Parameters, buckle_step: float = 0.25) -> float:
    """Largest step as a fraction of the path (``span`` stages): three quarters of a stage, and
    never a buckle travel of more than ``buckle_step`` (a quarter) of the buckle's radial
    thickness. A deeper jump starts Newton with sclera nodes deep inside the buckle, and its
    first iterate throws them through it (measured: a 0.64 mm jump with the default
    1.6 mm buckle left the sclera outside the tire, or "converged" in no iteration
    with the buckle inside the eye). Step 2's own limit is ``buckle_step``'s
    (:func:`_stepping`)."""
    thickness = params.tire_height + params.band_thickness
    span = _span(params)
    if params.indentation <= 0:
        return 0.75 / span
    return min(0.75 / span, buckle_step * thickness / params.indentation / span)


def settle_pressure(acute: float, iop: float, f: float, ramp: str) -> float:
    """Step 4's pressure target at the fraction ``f`` of the step: linear in P, or in
    ln P (``log``; both positive pressures)."""
    if ramp == "log" and acute > 0 and iop > 0:
        return acute ** (1.0 - f) * iop ** f
    return (1.0 - f) * acute + f * iop


def _span(params: Parameters) -> float:
    """Length of the load path: 3 stages, 4 with the settling step."""
    return 4.0 if params.settle else 3.0


def _contact_quadrature(integration: str, family) -> dict:
    """Quadrature of the buckle's penalty integral. ``nodal``: Gauss–Lobatto of degree 1
    (the trapezoidal rule, points at the face's vertices; Q1 faces only), so the
    penalty acts on the sclera's nodes as in a node-to-rigid-surface scheme."""
    if integration == "gauss":
        return {"quadrature_degree": family.quadrature_degree}
    if family.displacement_degree != 1:
        raise ParameterError("contact_integration", "nodal contact needs a Q1 displacement")
    return {"quadrature_rule": "GLL", "quadrature_degree": 1}


def _converged(model: "BucklingModel", ctx: RunContext, writer, record) -> None:
    stage = model.stage_of(record.load)
    if abs(record.load - 1.0) < 1e-12:
        model.couple_liquid()
    if abs(record.load - 2.0) < 1e-12:
        model.use_suture_line_search()
    if abs(record.load - 2.0) < 1e-12 and model.tire_loop:
        model.free_tire()
    if abs(record.load - 3.0) < 1e-12 and model.last_stage > 3:
        model.release_liquid()
    counts, settling = record.counts(), {}
    if abs(record.load - 4.0) < 1e-12 and model.params.drainage != "none":
        before = model.solver.counts.copy()
        settling = model.settle_retina()
        extra = StepRecord.work(model.solver.counts - before)  # counted with this step
        counts = {"attempts": counts["attempts"] + extra["attempts"],
                  "newton_iterations_all": counts["newton_iterations_all"] + extra["iterations_all"],
                  **{k: counts[k] + extra[k] for k in ("jacobians", "factorisations",
                                                      "symbolic_factorisations",
                                                      "krylov_iterations_all",
                                                      "matrix_mallocs")},
                  "augmentations": counts["augmentations"]}
    values = model.measure() | settling
    ctx.record_step(step=record.step, load=record.load, stage=stage,
                    newton_iterations=record.iterations, cuts=record.cuts, **counts,
                    krylov_iterations=record.linear_iterations,
                    residuals=record.residuals, **values)
    model.sutures.update_directions(model.u, model.suture_anchors())
    model.update_suture_pull()
    if record.load >= 2.0 - 1e-12:
        model.release_tire_from_band()
    if abs(record.load - round(record.load)) < 1e-12:
        model.stage_results[int(round(record.load))] = values
    if record.load >= 3.0 - 1e-12:  # the drainage's drag pulls towards this state
        model.drag_reference.x.array[:] = model.u.x.array
    writer.state(record.load, stage, picture=abs(record.load - round(record.load)) < 1e-12)


class BucklingModel:
    """Everything the path follower and the measurements need, built once."""

    def __init__(self, params: Parameters, ctx: RunContext):
        self.params, self.ctx = params, ctx
        self.geometry = params.geometry()
        with ctx.timings("mesh"):
            self.eye = half_eye(self.geometry, ctx.comm)
        family = ELEMENTS[params.element]
        self.family = family
        mesh = self.eye.mesh
        # [u, p, P, δ_tire]: the cavity pressure and the tire's radial travel are Real unknowns
        condensed = params.dg0_pressure == "condensed"
        fields, tests = solid_fields(mesh, family, real_pressure_space(mesh),
                                     real_pressure_space(mesh), condensed=condensed)
        self.fields, self.u, self.P, self.tire_travel = fields, fields[0], fields[-2], fields[-1]
        self.P.name, self.tire_travel.name = "P", "tire_travel"
        metadata = {"quadrature_degree": family.quadrature_degree}
        dx, ds = self.eye.dx(metadata), self.eye.ds(metadata)
        self.wall = ds(self.eye.tag("cavity_wall"))
        self.stiffness = self._cell_field("c", params.stiffness())
        self.law = self._material_law()

        # step 1 pins P to the ramp; from step 2 on P obeys the liquid law
        self.iop = params.iop_mmHg * MMHG
        self.pressure_target = dolfinx.fem.Constant(mesh, 0.0)
        self.acute_pressure = dolfinx.fem.Constant(mesh, self.iop)  # end of step 3
        self.coupled = dolfinx.fem.Constant(mesh, 0.0)
        self.initial_volume = dolfinx.fem.Constant(mesh, 1.0)
        self.initial_pressure = dolfinx.fem.Constant(mesh, self.iop)
        volume0 = check_closed(self.u, self.wall, "cavity wall of the eye")
        self.initial_volume.value = volume0
        area = ctx.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(
            dolfinx.fem.Constant(mesh, 1.0) * self.wall)), op=MPI.SUM)
        # Constants: the area follows the mesh, and either as a literal compiles the residual anew
        self.wall_area = dolfinx.fem.Constant(mesh, area)
        self.bulk_modulus = dolfinx.fem.Constant(mesh, params.bulk_modulus)

        # the buckle: placed after step 1 at the clearance from the inflated sclera
        self.axial_position, self.buckle_angle = self._buckle_axial_position()
        self.base_radius = dolfinx.fem.Constant(mesh, 2 * self.geometry.sclera_radius)
        self.indentation = dolfinx.fem.Constant(mesh, 0.0)  # the band's (prescribed) travel
        # its sizes and axial position as Constants: a sweep over them (buckling-planning)
        # reuses the compiled residual; which elements there are and whether the tire is
        # arc-limited change the forms' structure (docs/atlas/peer-comparison.md)
        shape = params.buckle_shape()
        self.buckle = Buckle(shape, dolfinx.fem.Constant(mesh, self.axial_position), self.base_radius,
                             self.indentation, tire_indentation=self.tire_travel,
                             sizes=BuckleSizes.of(shape, lambda value: dolfinx.fem.Constant(mesh, value)),
                             polar_angle=dolfinx.fem.Constant(mesh, math.radians(self.buckle_angle)))
        # the force-driven tire (suture_model = loop): its travel is free from step 3 on
        self.tire_loop = params.suture_model == "loop" and params.buckle_shape().has_tire
        self.tire_free = dolfinx.fem.Constant(mesh, 0.0)
        self.tire_hold = dolfinx.fem.Constant(mesh, 0.0)    # no band: released over step 3
        self.suture_pull = dolfinx.fem.Constant(mesh, 0.0)  # sutures' inward resultant
        self.held_force = 0.0  # the sclera's force on the tire at the end of step 2
        self.drained = dolfinx.fem.Constant(mesh, 0.0)      # subretinal pressure removed
        # the retina's pseudo-time drag in step 4 (drainage): η and the last solved state
        self.retina_drag = dolfinx.fem.Constant(mesh, 0.0)
        self.drag_reference = dolfinx.fem.Function(self.u.function_space, name="u_drag_reference")
        self.retina_face_dofs = np.zeros(0, dtype=np.int32)  # set when there is a detachment
        if "retina_detached" in self.eye.names:
            blocks = facet_nodes(self.u.function_space, self.eye.facets("retina_detached"))
            self.retina_face_dofs = (3 * blocks[:, None] + np.arange(3)).ravel()
        element_size = 0.5 * math.pi * self.geometry.sclera_radius / self.geometry.cells_per_edge
        self.penalty = params.penalty_factor * 6.0 * params.c_sclera / element_size
        self.augmented = params.contact_method == "augmented-lagrangian"
        # the buckle's normal contact: the penalty's α, or the augmented Lagrangian's lower one
        self.normal_penalty = self.penalty * (params.augmented_penalty_scale if self.augmented else 1.0)
        # a Constant, not a literal: the penalty follows the mesh size and the sclera's
        # modulus, and a literal would compile the eye's residual anew for each of them
        self.contact_penalty = dolfinx.fem.Constant(mesh, self.normal_penalty)
        # the tangential tie keeps the penalty's α (the same Constant with the penalty method)
        self.tie_penalty = dolfinx.fem.Constant(mesh, self.penalty) if self.augmented \
            else self.contact_penalty
        self.buckle_multipliers: QuadraturePointMultipliers | ObstacleMultipliers | None = None
        self.sclera_nodes = facet_nodes(self.u.function_space, self.eye.facets("sclera_outer"))
        # the sutured buckle: the sclera's displacement when it is tied (end of step 1)
        self.u_tied = dolfinx.fem.Function(self.u.function_space, name="u_tied")
        self.tied = dolfinx.fem.Constant(mesh, 0.0)
        self.sutures = SutureForces(mesh, self.u.function_space, self._suture_points(),
                                    self.sclera_nodes, params.suture_bite_radius)
        self._tire_scales(ds(self.eye.tag("sclera_outer")))
        self.bcs = self._boundary_conditions()
        # the tissues' pressure: Q1P0's mixed DG0 unknown, or its condensed p̄ = κ (J̄ − 1)
        # with κ a fixed multiple of each tissue's shear modulus (condensed_bulk_ratio)
        self.mean_dilatation = MeanDilatation(
            self.u, params.condensed_bulk_ratio * 2 * self.stiffness, dx, self.bcs,
            block_spaces=[f.function_space for f in fields]) if condensed else None
        self.pressure = self.mean_dilatation.pressure if condensed else fields[1]
        residual = self.residual(tests, dx, ds)

        # μ = 2c per cell weights the iterative solver's pressure mass matrix
        krylov = params.linear_reuse == "krylov"
        newton = dataclasses.replace(ctx.options.newton,
                                     reuse_contraction=params.krylov_jacobian_reuse if krylov
                                     else params.jacobian_reuse,
                                     linear_reuse=params.linear_reuse,
                                     krylov_max_it=params.krylov_max_it,
                                     krylov_rtol=params.krylov_rtol,
                                     krylov_ew=params.krylov_ew,
                                     krylov_refresh_above=params.krylov_refresh_above,
                                     krylov_predict_after=params.krylov_predict_after,
                                     reuse_step_relative=params.jacobian_reuse_test == "step",
                                     cut_on_nan=params.full_step_nan == "cut",
                                     fallback_line_search="bt" if {
                                         params.line_search, params.suture_line_search,
                                         params.settle_line_search} != {"bt"}
                                     else ctx.options.newton.fallback_line_search)
        self.solver = NonlinearSolver(list(ufl.extract_blocks(residual)), fields, self.bcs,
                                      options=newton, timings=ctx.timings,
                                      iterative=params.linear_solver(2 * self.stiffness, dx))
        if self.mean_dilatation is not None:
            self.solver.state_hooks.append(self.mean_dilatation.update)
            self.solver.jacobian_hooks.append(self.mean_dilatation.jacobian_hook)
        # a load step may not carry the sclera through the rigid buckle (Stepping.depth_limit)
        self._outer_owned: tuple[np.ndarray, np.ndarray] | None = None
        self.solver.depth_hooks.append(self.depth_through_buckle)
        self.element_size = element_size
        self._fe_nonzeros = self.solver.jacobian_nonzeros()  # before any hook inserts entries
        self.zonules = self._zonules() if params.lens else None
        self.detached = "retina_detached" in self.eye.names  # false: detachment_height = 0
        self.retina = self._retina_contact() if params.retina_contact and self.detached else None
        # the formulation's pattern (solid, liquid row and column, zonule bars), before
        # any contact pair: the retina's preallocated pairs and those added at a solve's
        # start depend on the load path (and differ in a run resumed from a checkpoint)
        # (DOLFINx's exact preallocation plus the bars' couplings, counted: PETSc's own
        # allocation grows by chunks when the bars are inserted, differently on 1 and 2 ranks)
        self.pattern_nonzeros = self._fe_nonzeros + (
            self.zonules.coupling_entries() if self.zonules is not None else 0)
        self.augmentation = self._augmentation()
        self.buckle_penetration = NodalPenetration(self.buckle, self.u, self.eye, "sclera_outer")
        self._buckle_points = FacePoints(self.eye, "sclera_outer", family.quadrature_degree)
        self._buckle_point_penetration = dolfinx.fem.Expression(
            without_variables(penetration(self.buckle, self.u)), self._buckle_points.reference_points)
        self._probes()
        self.volume_form = dolfinx.fem.form(enclosed_volume(self.u, self.wall))
        self.von_mises = CellField(_von_mises(self.u, self.law), mesh, "von_mises")
        self.stage_results: dict[int, dict] = {}
        self.reference_positions: dict[str, np.ndarray] = {}
        # the eye before surgery (end of step 1): every change is measured from it
        self.preoperative: dict[str, float] = {}

    def residual(self, tests, dx, ds):
        """The eye's residual, all of it but the node-wise terms:

        R = R_solid(u, p)                    incompressible tissues, neo-Hooke or Yeoh (Q1P0 …;
                                             or p̄ = κ (J̄ − 1) condensed, dg0_pressure)
          + ∫ P J F⁻ᵀN·v dA                 the vitreous pressure P on the cavity wall
          + c · R_liquid + (1 − c) · R_pin   P's row: the liquid law from step 2 (c = 1),
                                             P pinned to the IOP ramp in step 1 (c = 0)
          + δΠ_buckle                        smoothed penalty contact with the rigid buckle
          + δΠ_tie                           sutured buckle: the sclera under its footprint
                                             tied tangentially (from step 2 on)
          + R_sutures                        suture forces at the bites (lagged directions)
          + r_δ                              the tire's travel δ: prescribed (steps 1-2, and
                                             always with suture_model = bites), or the
                                             balance of the sclera's contact force with the
                                             sutures' loop and the band (steps 3-4, loop)
          − ∫ d w P J F⁻ᵀN·v dA             drainage: the subretinal faces lose the liquid
                                             pressure over step 4 (d from 0 to 1), all but
                                             the choroid under the tear (w = 0, :meth:`_dried`)
          + ∫ η (u − u_last)·v dA             drainage: pseudo-time drag on the retina's
                                             subretinal face (step 4; off for the final
                                             solve, :meth:`settle_retina`)

        The zonule bars and the retina–choroid contact are added node-wise by hooks of the
        nonlinear solver (:meth:`_zonules`, :meth:`_retina_contact`)."""
        params, family = self.params, self.family
        v, qP, q_tire = tests[0], tests[-2], tests[-1]
        liquid = liquid_law_residual(self.P, qP, self.u, self.wall, self.wall_area, self.initial_volume,
                                     self.initial_pressure, self.bulk_modulus)
        pinned = self.initial_volume / self.bulk_modulus * (self.P - self.pressure_target) \
            / self.wall_area * qP * self.wall
        condensed = getattr(self.mean_dilatation, "pressure", None)
        residual = (solid_residual(self.law, family, self.fields, tests, dx,
                                   condensed_pressure=condensed)
                    + follower_pressure(self.P, self.u, v, self.wall)
                    + self.coupled * liquid + (1 - self.coupled) * pinned)
        contact_ds = self.eye.ds(_contact_quadrature(params.contact_integration, family))
        # ε = 0 and ε > 0 are two forms; ε's value is a Constant
        smoothing = dolfinx.fem.Constant(self.eye.mesh, params.contact_smoothing) \
            if params.contact_smoothing > 0 else 0.0
        if self.augmented and params.contact_integration == "gauss":
            # λ where the penalty acts: Uzawa's fixed point is then its constraint, g ≥ 0 at
            # the contact integral's points, whatever α (docs/contact.md, Augmented Lagrangian)
            self.buckle_multipliers = QuadraturePointMultipliers(
                self.buckle, self.u, self.eye, "sclera_outer", self.contact_penalty,
                family.quadrature_degree, smoothing, name="buckle_contact_pressure")
        elif self.augmented:  # nodal integration: the points are the nodes
            self.buckle_multipliers = ObstacleMultipliers(
                self.buckle, self.u, self.eye, "sclera_outer", self.contact_penalty, smoothing,
                name="buckle_contact_pressure")
        contact = smoothed_penalty_energy(
            self.buckle, self.u, self.contact_penalty, smoothing,
            contact_ds(self.eye.tag("sclera_outer")),
            multiplier=None if self.buckle_multipliers is None else self.buckle_multipliers.function)
        self.contact_energy = contact
        residual += ufl.derivative(contact, self.u, v)
        residual += self._tire_row(contact, q_tire, contact_ds(self.eye.tag("sclera_outer")))
        if params.drainage != "none":
            subretinal = ds(tuple(self.eye.tag(name) for name in ("retina_detached",
                                                                  "choroid_detached")))
            residual += follower_pressure(-self.drained * self._dried() * self.P, self.u, v,
                                          subretinal)
            retina_face = ds(self.eye.tag("retina_detached"))
            residual += self.retina_drag * ufl.inner(self.u - self.drag_reference, v) * retina_face
        if params.buckle_attachment == "sutured":
            tie = tangential_tie_energy(self.buckle, self.u, self.u_tied, self.tied * self.tie_penalty,
                                        contact_ds(self.eye.tag("sclera_outer")))
            residual += ufl.derivative(tie, self.u, v)
        elif params.frictionless_slip_stiffness > 0:
            # a weak spring for the buckle's friction on the sclera: it removes the
            # frictionless slide's near-zero stiffness (docs/scleral_buckling.md, "The frictionless
            # buckle's spring")
            spring = dolfinx.fem.Constant(self.eye.mesh, params.frictionless_slip_stiffness)
            tie = tangential_tie_energy(self.buckle, self.u, self.u_tied, self.tied * spring,
                                        contact_ds(self.eye.tag("sclera_outer")))
            residual += ufl.derivative(tie, self.u, v)
        residual += self.sutures.residual(v, ds(self.eye.tag("sclera_outer")))
        return residual

    def _dried(self) -> dolfinx.fem.Function:
        """1 on the cells whose subretinal face drainage dries, 0 on the choroid's cells
        under the tear's hole: the vitreous keeps wetting the choroid there through the
        hole. Under the hole: the cell's midpoint within ``tear_radius`` (arc on the
        sclera's radius) of the tear's centre, as the mesh removes the retina's cells."""
        mesh, geo = self.eye.mesh, self.geometry
        weight = dolfinx.fem.Function(dolfinx.fem.functionspace(mesh, ("DG", 0)), name="dried")
        weight.x.array[:] = 1.0
        if geo.tear_radius > 0:
            cells = np.arange(len(weight.x.array), dtype=np.int32)
            mid = dolfinx.mesh.compute_midpoints(mesh, mesh.topology.dim, cells)
            unit = mid / np.linalg.norm(mid, axis=1, keepdims=True)
            centre = np.array([0.0, math.sin(math.radians(geo.tear_angle)),
                               math.cos(math.radians(geo.tear_angle))])
            arc = geo.sclera_radius * np.arccos(np.clip(unit @ centre, -1.0, 1.0))
            weight.x.array[arc < geo.tear_radius] = 0.0
        return weight

    def _tire_row(self, contact, test, measure):
        """The tire travel's row: free = 1 (loop) balances the sclera's contact force on
        the tire, ∂Π_c/∂δ, against the sutures' inward resultant and the band's push on
        it (the band keeps its prescribed travel; :meth:`release_tire_from_band`); a tire
        without a band is free from the end of step 2, held by a force released over
        step 3 (the surgeon's instrument handing the tire over to the sutures).
        free = 0 pins δ to the band's travel."""
        inward = self.suture_pull + self.tire_hold
        if self.params.buckle_shape().has_band:
            inward = inward + band_stop_force(self.tire_travel, self.indentation, self.tire_stiffness)
        free = tire_travel_residual(contact, self.tire_travel, test, inward, measure, self.sclera_area)
        pinned = pinned_travel_residual(self.tire_travel, self.indentation, test,
                                        self.tire_stiffness, measure, self.sclera_area)
        return self.tire_free * free + (1 - self.tire_free) * pinned

    def _tire_scales(self, measure) -> None:
        """Constants of the tire's row, from the reference configuration: the sclera's
        outer area (the row's constant terms are spread over it), the stiffness of the
        band's push and of the pinned row (the buckle's penalty over the tire's
        footprint: as stiff as the sclera's contact with it), and the normalised
        ∫ s_s w_s dA of each suture's bite (the share of its pull the half model
        carries: ½ on the symmetry plane), which makes the reaction on the tire the
        exact opposite of the bite loads."""
        # Constants, not literals: the mesh and the penalty set them, and a literal would
        # compile the eye's residual anew for every mesh size and penalty factor
        mesh = self.eye.mesh
        X = ufl.SpatialCoordinate(mesh)
        one = dolfinx.fem.Constant(mesh, 1.0)
        self.sclera_area = dolfinx.fem.Constant(mesh, _assemble(one * measure, self.ctx.comm))
        footprint = _assemble(self.buckle.footprint_weight(X) * measure, self.ctx.comm)
        self.tire_stiffness = dolfinx.fem.Constant(mesh, self.penalty * max(footprint, 1.0))
        # each bite normalised on this mesh: the half model carries exactly its share
        self.sutures.normalise(measure, self.ctx.comm)
        self.bite_shares = self.sutures.shares
        shape = self.params.buckle_shape()
        self.on_tire = np.array([shape.on_tire(p.azimuth_deg) for p in self.sutures.points])

    def tire_contact_force(self) -> float:
        """∂Π_c/∂δ: the sclera's contact force on the tire along its inward travel (half
        model, N)."""
        if not hasattr(self, "_tire_force_form"):
            direction = dolfinx.fem.Function(self.tire_travel.function_space)
            direction.x.array[:] = 1.0
            self._tire_force_form = dolfinx.fem.form(
                ufl.derivative(self.contact_energy, self.tire_travel, direction))
        return _assemble(self._tire_force_form, self.ctx.comm)

    def update_suture_pull(self) -> None:
        """The sutures' inward radial resultant on the tire (half model, N): each tire
        suture's loop turns over the tire, which takes the opposite of its bite loads,
        −F_s ∫s_s w_s dA, whose inward (−e_ρ) component is |F| ∫s_s w_s dA d_s·e_ρ at its
        meridian (d_s from the bite to the tire's corner: lagged, as the bite loads)."""
        pull = 0.0
        for point, direction, share, on_tire in zip(self.sutures.points, self.sutures.directions,
                                                    self.bite_shares, self.on_tire):
            if on_tire:  # the loop's reaction on the tire: −F_s, along the inward direction
                pull -= self.sutures.magnitude * share * float(direction @ self._inward(point))
        self.suture_pull.value = pull if self.tire_loop else 0.0

    def free_tire(self) -> None:
        """End of step 2 (loop, no band): the tire's travel becomes an unknown; the force
        that holds it there is measured, to be released over step 3. A tire that does not
        touch the sclera (travel within the clearance) has no contact force to balance
        its row (∂Π_c/∂δ ≡ 0 would make the Jacobian singular): it keeps its travel."""
        if self.params.buckle_shape().has_band:
            return  # the band holds it: see release_tire_from_band
        force = self.tire_contact_force()
        if force <= 0.0:
            return
        self.held_force = force
        self.tire_free.value = 1.0
        self.tire_hold.value = self.held_force

    def release_tire_from_band(self) -> None:
        """With a band (loop): the band holds the tire at its travel while the sclera
        pushes the tire out harder than the sutures pull it in. Once the pull exceeds the
        sclera's contact force (checked after every converged step of steps 3-4, lagged
        by one step as the suture directions are), the tire's travel is free and the
        band's push becomes the unilateral stop of its row, which takes the tire back if
        the pull drops. Freed on the stop's kink with the pull winning, Newton starts on
        the side where the stop is inactive; freed with the contact winning, Newton
        stalled there on the default mesh (residual constant at 2.3e-4), and a
        frictionless 1 mm buckle stalled in step 3 on the coarse eye."""
        if not (self.tire_loop and self.params.buckle_shape().has_band) \
                or float(self.tire_free.value) == 1.0:
            return
        if float(self.suture_pull.value) > self.tire_contact_force():
            self.tire_free.value = 1.0

    # -- set-up pieces --------------------------------------------------------------
    def _cell_field(self, name: str, values: dict[str, float]) -> dolfinx.fem.Function:
        """A cellwise-constant coefficient from per-tissue values (0 where none given)."""
        space = dolfinx.fem.functionspace(self.eye.mesh, ("DG", 0))
        c = dolfinx.fem.Function(space, name=name)
        for tissue, value in values.items():
            if tissue in self.eye.names:
                cells = self.eye.cells(tissue)
                c.x.array[space.dofmap.list[cells, 0]] = value
        return c

    def _material_law(self):
        """The tissues' isochoric law: neo-Hooke with c per tissue (Table 1), or, calibrated,
        Yeoh with c10 = c and the stiffening c20 (Ī1 − 3)² in the sclera and the cornea.
        Both coefficients are cellwise fields: new values compile nothing."""
        if self.params.material == "table-1":
            return NeoHooke(self.stiffness)
        return Yeoh(self.stiffness, self._cell_field("c20", self.params.stiffening()))

    def _buckle_axial_position(self) -> tuple[float, float]:
        angle = self.geometry.limbus_angle + math.degrees(self.params.buckle_position
                                                          / self.geometry.sclera_radius)
        return self.geometry.sclera_radius * math.cos(math.radians(angle)), angle

    def _boundary_conditions(self):
        V = self.u.function_space
        bcs = symmetry_bcs(V, self.eye, {"symmetry": 0})
        held = dolfinx.fem.locate_dofs_topological(V, 2, self.eye.facets("optic_nerve_end"))
        bcs.append(dolfinx.fem.dirichletbc(np.zeros(3), held, V))
        return bcs

    def _zonules(self) -> ZonuleBars:
        with self.ctx.timings("mesh"):
            pairs = zonule_pairs(self.geometry)
        bars = ZonuleBars(self.u, pairs, self.params.zonule_modulus, self.params.zonule_area,
                          self.bcs, block_spaces=[f.function_space for f in self.fields])
        self.solver.residual_hooks.append(bars.residual_hook)
        self.solver.jacobian_hooks.append(bars.jacobian_hook)
        bars.allow_new_nonzeros(self.solver.problem.A)
        return bars

    def _retina_contact(self) -> NodeToSurfaceContact:
        """Retina (slave nodes) on choroid (master triangles), penalty scaled from the
        softer tissue: its penetration under a contact pressure p is p/α =
        (p/E_retina) h / factor."""
        alpha = default_penalty(6.0 * self.params.c_retina, self.element_size,
                                self.params.retina_penalty_factor)
        if self.augmented:
            alpha *= self.params.augmented_penalty_scale
        # deeper than the choroid is thick, a pair is on the wrong side (not contact)
        contact = NodeToSurfaceContact(self.u, self.eye, "retina_detached", "choroid_detached",
                                       alpha, self.bcs, search_depth=self.geometry.choroid_thickness,
                                       smoothing=self.params.contact_smoothing,
                                       timings=self.ctx.timings,
                                       block_spaces=[f.function_space for f in self.fields],
                                       method=self.params.retina_contact_method,
                                       pattern_reach=RETINA_PATTERN_REACH * self.element_size)
        # segments are measured between flat facets of two curved surfaces that meet at the
        # rim: up to a chord's sagitta h²/8R apart where the surfaces touch
        sagitta = self.element_size ** 2 / (8 * self.geometry.sclera_radius)
        contact.refuse_initial_penetration(
            "detachment_height",
            tolerance=sagitta if self.params.retina_contact_method == "segment-to-segment" else 0.0)
        self.solver.residual_hooks.append(contact.residual_hook)
        self.solver.jacobian_hooks.append(contact.jacobian_hook)
        if self.params.restore_contact_memory:
            self.solver.memory_hooks.append((contact.memory, contact.restore_memory))
        contact.allow_new_nonzeros(self.solver.problem.A)
        self.solver.pattern_hooks.append(contact.grow_pattern)
        return contact

    def _augmentation(self) -> Augmentation | None:
        """Uzawa's loop over the buckle's and the retina's multipliers (augmented Lagrangian),
        after every converged load step or at the end of each step of the operation
        (``augment_at``); the multipliers go back with a cut step (memory hooks)."""
        if not self.augmented:
            return None
        multipliers = [self.buckle_multipliers]
        self.solver.memory_hooks.append((self.buckle_multipliers.memory,
                                         self.buckle_multipliers.restore))
        if self.retina is not None:
            multipliers.append(self.retina)
            self.solver.memory_hooks.append((self.retina.multiplier_memory,
                                             self.retina.restore_multipliers))
        if self.params.augment_at == "every-step":
            def due(_value: float) -> bool:
                return True
        else:
            def due(value: float) -> bool:
                return abs(value - round(value)) < 1e-12
        return Augmentation(multipliers, due, tolerance=self.params.augmentation_tolerance,
                            max_updates=self.params.max_augmentations)

    def _probes(self) -> None:
        V, geo = self.u.function_space, self.geometry
        outer = self.sclera_nodes
        cornea = facet_nodes(V, self.eye.facets("cornea_outer"))
        inner = facet_nodes(V, self.eye.facets("retina_inner"))
        apex = np.array([[0.0, 0.0, geo.cornea_center + geo.cornea_radius]])
        pole = np.array([[0.0, 0.0, -geo.sclera_radius]])
        self.apex = NodeProbe(V, apex, cornea)
        # the central cornea a keratometer reads (ρ ≤ 3 mm; at least 4 nodes)
        X = V.tabulate_dof_coordinates()
        owned = V.dofmap.index_map.size_local
        mine = cornea[cornea < owned]
        rho = np.hypot(X[mine, 0], X[mine, 1])
        for zone in (KERATOMETRY_ZONE, 4.0, 5.0):
            central = mine[rho <= zone]
            if self.ctx.comm.allreduce(len(central), op=MPI.SUM) >= 4:
                break
        self.central_cornea = central.astype(np.int32)
        self.pole = NodeProbe(V, pole, inner)
        theta = math.radians(self.buckle_angle)
        under = np.array([[0.0, geo.sclera_radius * math.sin(theta), self.axial_position]])
        self.under_buckle = NodeProbe(V, under, outer)
        if not self.detached:
            self.pairing, self.tear_rim = None, np.zeros(0, bool)
            return
        self.pairing = SurfacePairing(V, self.eye.facets("retina_detached"),
                                      self.eye.facets("choroid_detached"))
        if "tear_edge" not in self.eye.names:
            self.tear_rim = np.zeros(len(self.pairing.slave_g), bool)
            return
        tear = facet_nodes(V, self.eye.facets("tear_edge"))
        owned = V.dofmap.index_map.size_local
        tear_global = V.dofmap.index_map.local_to_global(tear[tear < owned].astype(np.int32))
        tear_global = set(np.concatenate(self.ctx.comm.allgather(tear_global)).tolist())
        self.tear_rim = np.array([g in tear_global for g in self.pairing.slave_g])

    def _suture_points(self) -> list[SuturePoint]:
        """Both bites of each suture, ``suture_width`` apart along the meridian,
        centred on the buckle, on the sclera's outer surface."""
        geo, theta = self.geometry, math.radians(self.buckle_angle)
        if self.params.tire_orientation == "radial":
            return self._radial_suture_points(theta)
        half = self.params.suture_width / 2 / geo.sclera_radius
        points = []
        for azimuth in self.params.suture_azimuths:
            psi = math.radians(azimuth)
            for side in (-1, 1):
                t = theta - side * half  # anterior (+1) is the smaller polar angle
                rho = geo.sclera_radius * math.sin(t)
                centre = (rho * math.sin(psi), rho * math.cos(psi), geo.sclera_radius * math.cos(t))
                points.append(SuturePoint(azimuth, side, centre))
        return points

    def _radial_suture_points(self, theta: float) -> list[SuturePoint]:
        """A radial tire's sutures cross it at a quarter of its length either side of
        its centre, each with its bites ``suture_width`` apart across the meridian: the
        bite at x = +w/2 is in the half model (side +1), its mirror at −w/2 is the
        symmetry's (the half model carries half of each suture)."""
        radius = self.geometry.sclera_radius
        across = 0.5 * self.params.suture_width
        ring = math.sqrt(radius**2 - across**2)  # the bite's distance from the x axis
        quarter = 0.25 * self.params.tire_length / radius
        return [SuturePoint(0.0, 1, (across, ring * math.sin(t), ring * math.cos(t)))
                for t in (theta - quarter, theta + quarter)]

    # -- the load path --------------------------------------------------------------
    @staticmethod
    def stage_of(load: float) -> int:
        return min(4, max(1, math.ceil(load - 1e-12)))

    @property
    def last_stage(self) -> float:
        return _span(self.params)

    def apply(self, load: float, _increment: float) -> None:
        if load <= 3.0 + 1e-12:
            self.pressure_target.value = min(load, 1.0) * self.iop
        else:  # step 4: the IOP returns from its acute value to the pre-operative one
            f = min(load - 3.0, 1.0)
            self.pressure_target.value = settle_pressure(float(self.acute_pressure.value),
                                                         self.iop, f, self.params.settle_ramp)
            if self.params.settle_start == "target":
                self._start_at_pressure_target()
        # step 4's contraction test; set here, not when step 4 begins, so that a run resumed
        # inside step 4 (apply is called again with the checkpoint's load) has it too
        self.solver.options.reuse_step_relative = self.params.jacobian_reuse_test == "step" \
            or (load > 3.0 + 1e-12 and self.params.settle_reuse_test == "step")
        self.indentation.value = float(np.clip(load - 1.0, 0.0, 1.0)) * self.params.indentation
        self.sutures.set_magnitude(float(np.clip(load - 2.0, 0.0, 1.0)) * self.params.suture_force)
        self.update_suture_pull()
        if float(self.tire_free.value) == 0.0:  # prescribed: start Newton at the target
            self.tire_travel.x.array[:] = float(self.indentation.value)
        else:
            self.tire_hold.value = (1.0 - float(np.clip(load - 2.0, 0.0, 1.0))) * self.held_force
        self.drained.value = float(np.clip(load - 3.0, 0.0, 1.0)) \
            if self.params.drainage != "none" else 0.0
        self.retina_drag.value = self.drag_coefficient() if self.drained.value > 0 else 0.0

    def _start_at_pressure_target(self) -> None:
        """Step 4: P starts a load step at its pinned value, as the prescribed tire travel
        does. Newton's full first step is the same as from the last P (P's pinned row is
        linear in P), but the start's residual is then the pressure drop's load on the wall,
        not P's row alone, so backtracking on ‖F‖ accepts that step instead of creeping at
        its 0.1 floor (docs/scleral_buckling.md, The settling step). A P already at its
        target (a converged or restored state: relative difference below 1e-6) is left
        bitwise as it is, so a resumed run repeats the uninterrupted one."""
        target = float(self.pressure_target.value)
        if abs(self.cavity_pressure() - target) > 1e-6 * abs(target):
            self.P.x.array[:] = target
            self.P.x.scatter_forward()

    def drag_coefficient(self) -> float:
        """η (MPa/mm) such that the full IOP moves a free retina by ``drainage_drag_step``
        per solve: a 0.5 mm blister snaps onto the choroid in about ten solves instead of
        in one Newton step that load control cannot take (a shallow dome pressed on its
        convex side; docs/scleral_buckling.md, Subretinal drainage)."""
        return self.iop / self.params.drainage_drag_step

    def settle_retina(self, tolerance: float = 1e-4, max_solves: int = 80) -> dict:
        """End of step 4 with drainage: pseudo-time solves at full drainage, each dragged
        towards the last, until the largest nodal move is below ``tolerance`` (mm); a
        failed solve is restored and retried with the drag doubled (a shorter pseudo-time
        step), an easy one (≤ 4 iterations) halves it (down to base/1024). Then
        the drag is switched off and the eye solved once more, so that the state reported
        is an equilibrium of the undragged residual. If that last solve fails, the dragged
        state is kept and ``retina_drag_free`` says so."""
        base = self.drag_coefficient()
        solves, move, retina_move, eta = 0, math.inf, math.inf, base
        while solves < max_solves and move > tolerance and eta <= 1024 * base:
            self.drag_reference.x.array[:] = self.u.x.array
            self.retina_drag.value = eta
            state = self.solver.save_state()
            converged, iterations = self.solver.solve()
            solves += 1
            if not converged:
                log.info("retina settling solve %d: η = %.3g MPa/mm failed (%s)", solves, eta,
                         self.solver.reason())
                self.solver.restore_state(state)
                eta *= 2.0
                continue
            if iterations <= 4:  # a longer pseudo-time step: the tail of the settling
                eta = max(base / 1024, 0.5 * eta)
            move = self.ctx.comm.allreduce(float(np.abs(self.u.x.array
                                                        - self.drag_reference.x.array).max()),
                                           op=MPI.MAX)
            change = self.u.x.array - self.drag_reference.x.array
            retina_move = self.ctx.comm.allreduce(
                float(np.abs(change[self.retina_face_dofs]).max(initial=0.0)), op=MPI.MAX)
            log.info("retina settling solve %d: η = %.3g MPa/mm, %d iterations, move %.3g mm "
                     "(retina's subretinal face %.3g mm)", solves, eta, iterations, move,
                     retina_move)
        self.drag_reference.x.array[:] = self.u.x.array
        state = self.solver.save_state()
        self.retina_drag.value = 0.0
        free, _ = self.solver.solve()
        log.info("retina settling: drag-free solve %s (%s)", "converged" if free else "failed",
                 self.solver.reason())
        if not free:
            self.solver.restore_state(state)
            self.retina_drag.value = eta
        # the drag's traction left in a kept dragged state: η times the retina face's last
        # move (a component's largest; the drag acts on that face only)
        traction = 0.0 if free else eta * retina_move
        return {"retina_settling_solves": solves + 1, "retina_settling_last_move_mm": move,
                "retina_settling_last_retina_move_mm": retina_move,
                "retina_drag_free": bool(free),
                "retina_drag_traction_max_mmHg": traction / MMHG}

    def couple_liquid(self) -> None:
        """End of step 1: V_ini and P_ini from the inflated eye, liquid law on, and the
        buckle put ``buckle_clearance`` outside the sclera under it."""
        self.initial_volume.value = self.volume()
        self.initial_pressure.value = self.cavity_pressure()
        if "snes_linesearch_type" not in self.ctx.options.newton.petsc:
            # step 2 (the buckle's travel) ``line_search``: full steps (a failed solve repeated
            # with bt: plain Newton can cycle between two active sets, seen at 85 % of a 0.1 N
            # pull) or bt, which in step 1 would only cost iterations (12-14 per step
            # instead of 3-4)
            self.solver.snes.getLineSearch().setType(self.params.line_search)
        self.coupled.value = 1.0
        self.u_tied.x.array[:] = self.u.x.array
        self.tied.value = 1.0
        self.base_radius.value = self._sclera_radius_under_buckle() + self.params.buckle_clearance
        self.reference_positions = {"apex": self.apex.positions(self.u),
                                    "pole": self.pole.positions(self.u),
                                    "under_buckle": self.under_buckle.positions(self.u)}
        self.preoperative = self._optics() | {"volume_mm3": 2.0 * self.volume(),
                                              "iop_mmHg": self.cavity_pressure() / MMHG}

    def use_suture_line_search(self) -> None:
        """End of step 2: step 3's line search, ``suture_line_search`` (cp by default: bt
        creeps at its 0.1 floor there, full steps cost more at the paper's resolution;
        docs/scleral_buckling.md, Newton's budget); step 4's line search is
        ``settle_line_search`` (:meth:`release_liquid`)."""
        if "snes_linesearch_type" not in self.ctx.options.newton.petsc:
            self.solver.snes.getLineSearch().setType(self.params.suture_line_search)

    def release_liquid(self) -> None:
        """End of step 3 (the acute state): from here the liquid's volume is free and its
        pressure is driven back to the pre-operative IOP, as aqueous outflow does within
        hours of surgery; P's row is pinned to the ramp again. Newton's line search from here:
        ``settle_line_search``, a failed bt solve repeated with full steps as ``settle_retry``
        says (docs/scleral_buckling.md, Newton's budget)."""
        self.acute_pressure.value = self.cavity_pressure()
        self.coupled.value = 0.0
        if "snes_linesearch_type" not in self.ctx.options.newton.petsc:
            self.solver.snes.getLineSearch().setType(self.params.settle_line_search)
        if self.params.settle_retry == "basic" and self.params.settle_line_search == "bt":
            self.solver.options.fallback_line_search = "basic"
        # stalled bt solves are stopped in step 4 only: there its converged bt solves fall by
        # 0.78 or less over any 3 iterations (default, coarse and paper meshes), while step 2's
        # with line_search = bt plateau at 0.997 before they converge (docs/scleral_buckling.md,
        # Stalled backtracking)
        self.solver.options.stagnation_window = self.params.stagnation_window

    def _sclera_radius_under_buckle(self) -> float:
        """Largest distance from the buckle's axis (the optic axis; x for a radial tire)
        of the deformed sclera within the buckle's span: the buckle's flat inner face
        must clear all of it."""
        x = self._sclera_outer_positions()
        if self.buckle.shape.radial:  # the tire's flat inner face clears its whole footprint
            near = self.buckle.footprint_mask(x)
        else:
            near = np.abs(x[:, 2] - self.axial_position) <= 0.5 * self.params.buckle_shape().footprint
        local = float(self.buckle.axis_distance(x[near]).max()) if near.any() else 0.0
        return self.ctx.comm.allreduce(local, op=MPI.MAX)

    def _sclera_outer_positions(self) -> np.ndarray:
        """Deformed positions of this rank's owned nodes on the sclera's outer surface (their
        reference coordinates tabulated once: the mesh does not change)."""
        if self._outer_owned is None:
            V = self.u.function_space
            blocks = self.sclera_nodes[self.sclera_nodes < V.dofmap.index_map.size_local]
            self._outer_owned = (blocks, V.tabulate_dof_coordinates()[blocks])
        blocks, X = self._outer_owned
        return X + self.u.x.array.reshape(-1, 3)[blocks]

    def depth_through_buckle(self) -> float:
        """Largest depth of the sclera's outer nodes beyond the buckle's contact face, as a
        fraction of the element's thickness (forms/buckle.py, Buckle.depth_through)."""
        depth = self.buckle.depth_through(self._sclera_outer_positions(), self.tire_travel_value())
        return self.ctx.comm.allreduce(float(depth.max()) if len(depth) else -np.inf, op=MPI.MAX)

    def suture_anchors(self) -> np.ndarray:
        """Where each suture leaves the buckle: the tire's outer corner on its side,
        in the suture's meridional plane (directions for the next step)."""
        shape = self.params.buckle_shape()
        if shape.radial:
            return self._radial_suture_anchors()
        anchors = []
        for point in self.sutures.points:
            width, height = shape.element_at(point.azimuth_deg)
            rho = float(self.base_radius.value) - float(self.indentation.value) + height
            psi = math.radians(point.azimuth_deg)
            if self.tire_loop and shape.on_tire(point.azimuth_deg):  # the tire's own travel
                rho += float(self.indentation.value) - self.tire_travel_value()
            z = self.axial_position + point.side * 0.5 * width
            anchors.append([rho * math.sin(psi), rho * math.cos(psi), z])
        return np.array(anchors)

    def _radial_suture_anchors(self) -> np.ndarray:
        """A radial tire's suture leaves it at its outer corner on the bite's side
        (x = +w/2), in the plane through the x axis and the bite."""
        shape = self.params.buckle_shape()
        rho = float(self.base_radius.value) + shape.tire_height
        rho -= self.tire_travel_value() if self.tire_loop else float(self.indentation.value)
        anchors = []
        for point in self.sutures.points:
            t = math.atan2(point.centre[1], point.centre[2])
            anchors.append([0.5 * shape.tire_width, rho * math.sin(t), rho * math.cos(t)])
        return np.array(anchors)

    def _inward(self, point: SuturePoint) -> np.ndarray:
        """The tire's inward travel direction at a suture's meridian: towards the optic
        axis (−e_ρ about z), or for a radial tire towards the x axis in the bite's plane."""
        if self.buckle.shape.radial:
            t = math.atan2(point.centre[1], point.centre[2])
            return -np.array([0.0, math.sin(t), math.cos(t)])
        psi = math.radians(point.azimuth_deg)
        return -np.array([math.sin(psi), math.cos(psi), 0.0])

    def register_checkpoint(self, checkpoints) -> None:
        """Everything a restart needs besides the load (docs/restart.md): the unknowns,
        the liquid's P_ini/V_ini and switch, the buckle, the sutures' directions, the
        stage's line search and its retry's, the contact's sticky memory, the stage results."""
        for name, f in (("u", self.u), ("p", self.pressure), ("P", self.P),
                        ("tire_travel", self.tire_travel)):
            checkpoints.function(name, f)
        checkpoints.function("u_tied", self.u_tied)
        checkpoints.function("u_drag_reference", self.drag_reference)
        for name in ("pressure_target", "coupled", "initial_volume", "initial_pressure",
                     "base_radius", "indentation", "tied", "acute_pressure", "tire_free",
                     "tire_hold", "suture_pull", "drained", "retina_drag"):
            checkpoints.constant(name, getattr(self, name))
        checkpoints.value("sutures", lambda: {"directions": self.sutures.directions,
                                              "magnitude": self.sutures.magnitude},
                          self._restore_sutures)
        checkpoints.value("reference_positions", lambda: self.reference_positions,
                          lambda saved: setattr(self, "reference_positions", saved))
        checkpoints.value("held_force", lambda: self.held_force,
                          lambda saved: setattr(self, "held_force", float(saved)))
        checkpoints.value("preoperative", lambda: self.preoperative,
                          lambda saved: setattr(self, "preoperative", dict(saved)))
        checkpoints.value("stage_results", lambda: self.stage_results,
                          lambda saved: setattr(self, "stage_results",
                                                {int(k): v for k, v in saved.items()}))
        line_search = self.solver.snes.getLineSearch()
        checkpoints.value("line_search", line_search.getType, line_search.setType)
        options = self.solver.options
        checkpoints.value("fallback_line_search", lambda: options.fallback_line_search,
                          lambda saved: setattr(options, "fallback_line_search", str(saved)))
        checkpoints.value("stagnation_window", lambda: options.stagnation_window,
                          lambda saved: setattr(options, "stagnation_window", int(saved)))
        if self.retina is not None:
            checkpoints.value("retina_sticky", self.retina.sticky_state,
                              self.retina.restore_sticky_state)
        if self.buckle_multipliers is not None:
            checkpoints.function("buckle_contact_pressure", self.buckle_multipliers.function)
        if self.retina is not None and self.augmented:
            checkpoints.value("retina_multipliers", self.retina.multiplier_state,
                              self.retina.restore_multiplier_state)
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

    def _restore_sutures(self, saved: dict) -> None:
        self.sutures.directions = np.asarray(saved["directions"], dtype=float)
        self.sutures.set_magnitude(saved["magnitude"])

    # -- measurements ---------------------------------------------------------------
    def volume(self) -> float:
        return self.ctx.comm.allreduce(dolfinx.fem.assemble_scalar(self.volume_form), op=MPI.SUM)

    def tire_travel_value(self) -> float:
        owned = self.tire_travel.function_space.dofmap.index_map.size_local
        return float(self.ctx.comm.allreduce(float(np.sum(self.tire_travel.x.array[:owned])),
                                             op=MPI.SUM))

    def cavity_pressure(self) -> float:
        owned = self.P.function_space.dofmap.index_map.size_local
        return float(self.ctx.comm.allreduce(float(np.sum(self.P.x.array[:owned])), op=MPI.SUM))

    def measure(self) -> dict:
        with self.ctx.timings("contact_search"):
            # an attached retina (detachment_height = 0): no subretinal gap to measure
            gaps = self.pairing.gaps(self.u) if self.pairing is not None else np.zeros(1)
        optics = self._optics()
        axial = optics["axial_length_mm"]
        reference_axial = self.apex.nodes[0][2] - self.pole.nodes[0][2]
        under = self.under_buckle.positions(self.u)[0]
        before = self.reference_positions.get("under_buckle", self.under_buckle.nodes)[0]
        indentation = float(self.buckle.axis_distance(before) - self.buckle.axis_distance(under))
        in_contact = gaps < self.params.tear_closure_tolerance
        detached_area = self.detached_area()
        zonules = self.zonules.summary() if self.zonules is not None else {}
        return self._retina_contact_measures() | zonules | self._changes(optics) | self._slip() | {
            "axial_length_mm": axial,
            "corneal_radius_mm": optics["corneal_radius_mm"],
            "corneal_power_D": optics["corneal_power_D"],
            # the inflation from the unloaded mesh is not a surgical change; kept under
            # its own name (the mesh is the eye at zero pressure)
            "axial_length_change_from_unloaded_mm": axial - reference_axial,
            "buckle_indentation_mm": indentation,
            "buckle_travel_mm": float(self.indentation.value),
            # the deepest sclera node inside the buckle (the penalty's penetration; → 0 with
            # the augmented Lagrangian's multipliers)
            "buckle_penetration_max_mm": self.buckle_penetration(),
            # ... at the contact integral's points, where the penalty acts (Gauss points)
            "buckle_penetration_points_max_mm": self.ctx.comm.allreduce(float(np.max(
                self._buckle_points.values(self._buckle_point_penetration), initial=0.0)),
                op=MPI.MAX),
            # the tire's radial travel (= the band's unless the sutures' loop drives it), the
            # sclera's contact force on it and the sutures' inward pull (whole eye)
            "tire_travel_mm": self.tire_travel_value(),
            "tire_contact_force_N": 2.0 * self.tire_contact_force(),
            "tire_suture_pull_N": 2.0 * float(self.suture_pull.value),
            "tire_free": bool(float(self.tire_free.value)),
            "subretinal_drained": float(self.drained.value),
            "iop_mmHg": self.cavity_pressure() / MMHG,
            "cavity_volume_mm3": 2.0 * self.volume(),
            "retina_choroid_gap_min_mm": float(gaps.min()),
            "retina_choroid_gap_max_mm": float(gaps.max()),
            # nodal estimate: the share of lifted retina nodes back on the choroid
            "retina_contact_area_mm2": 2.0 * detached_area * float(in_contact.mean()),
            "retina_choroid_gap_mean_mm": float(gaps.mean()),
            # closed: every lifted retina node on the tear's rim is back on the choroid
            "tear_closed": bool(self.tear_rim.any() and self.pairing is not None
                                and np.all(gaps[self.tear_rim] < self.params.tear_closure_tolerance)),
            "von_mises_max_MPa": self.von_mises.update(),
            "suture_force_N": float(self.sutures.magnitude),
        }

    def _optics(self) -> dict:
        """Axial length (corneal apex to the retina's posterior pole) and the central
        cornea's radius of curvature: a sphere fitted (least squares) to the deformed
        anterior corneal nodes within the keratometry zone, with its keratometric power
        (n_k − 1)/R."""
        apex, pole = self.apex.positions(self.u)[0], self.pole.positions(self.u)[0]
        V = self.u.function_space
        x = V.tabulate_dof_coordinates()[self.central_cornea] \
            + self.u.x.array.reshape(-1, 3)[self.central_cornea]
        x = np.vstack(self.ctx.comm.allgather(x))
        # |x|² = 2 y y_c + 2 z z_c + (R² − y_c² − z_c²): linear in the centre and R² − |c|²;
        # the centre is free in the symmetry plane (x_c = 0), so a buckle that pushes the
        # cornea sideways (a segmental tire) does not read as a change of curvature
        A = np.column_stack([2.0 * x[:, 1], 2.0 * x[:, 2], np.ones(len(x))])
        (yc, zc, k), *_ = np.linalg.lstsq(A, np.einsum("ij,ij->i", x, x), rcond=None)
        radius = math.sqrt(k + yc**2 + zc**2)
        return {"axial_length_mm": float(apex[2] - pole[2]), "corneal_radius_mm": radius,
                "corneal_power_D": 1000.0 * (KERATOMETRIC_INDEX - 1.0) / radius}

    def _changes(self, optics: dict) -> dict:
        """Changes from the eye before surgery (the end of step 1): axial length, corneal
        power, refraction, IOP, whole-eye liquid volume. Refraction (spherical
        equivalent at the cornea): ΔSE = −D_AL ΔAL − ΔK, D_AL = 2.7 D per mm of axial
        length (Gullstrand's schematic eye, emmetropic) and ΔK the keratometric power
        change; negative = myopic shift. Zero by definition at the end of step 1; absent
        before it."""
        pre = self.preoperative
        if not pre:
            return {}
        axial = optics["axial_length_mm"] - pre["axial_length_mm"]
        power = optics["corneal_power_D"] - pre["corneal_power_D"]
        return {"axial_length_change_mm": axial,
                "corneal_power_change_D": power,
                "refraction_change_D": -DIOPTRES_PER_MM * axial - power,
                "iop_change_mmHg": self.cavity_pressure() / MMHG - pre["iop_mmHg"],
                "volume_change_mm3": 2.0 * self.volume() - pre["volume_mm3"]}

    def _slip(self) -> dict:
        """Tangential motion (axial and circumferential) of the sclera's outer nodes under
        the buckle's footprint since the buckle was placed (end of step 1): the buckle
        moves only radially, so this is the slip along it. ``buckle_slip_axial_mean_mm``
        > 0: the sclera moved forward (towards the cornea) under the buckle (along the
        optic axis; along the meridian under a radial tire)."""
        if not self.preoperative:
            return {}
        V = self.u.function_space
        owned = V.dofmap.index_map.size_local
        nodes = self.sclera_nodes[self.sclera_nodes < owned]
        tied = self.u_tied.x.array.reshape(-1, 3)[nodes]
        x0 = V.tabulate_dof_coordinates()[nodes] + tied
        under = self.buckle.footprint_mask(x0)
        du = self.u.x.array.reshape(-1, 3)[nodes][under] - tied[under]
        values = slip(x0[under], du, self.buckle.shape.axis)
        comm = self.ctx.comm
        count = comm.allreduce(int(under.sum()), op=MPI.SUM)
        return {"buckle_slip_max_mm": comm.allreduce(float(values.max(initial=0.0)), op=MPI.MAX),
                "buckle_slip_axial_mean_mm": comm.allreduce(float(forward_slip(
                    x0[under], du, self.buckle.shape.axis).sum()), op=MPI.SUM)
                / max(count, 1),
                "buckle_footprint_nodes": count}

    def _retina_contact_measures(self) -> dict:
        """The penalty contact's own view (whole eye: twice the half model's area and
        force); max_penetration_mm is the deepest retina node under the choroid."""
        if self.retina is None:
            return {}
        with self.ctx.timings("contact_search"):
            self.retina.state = self.retina.search()
            summary = self.retina.summary()
            rim = self.retina.gaps_of(self.pairing.slave_g[self.tear_rim])
            closed = bool(len(rim) and np.all(rim[np.isfinite(rim)] < self.params.tear_closure_tolerance)
                          and np.isfinite(rim).any())
            widest = self._widest_rim_node(rim)
            gap_min = self.retina.min_gap()
            # nodes the penalty presses (g < ε: with the round-off a very soft retina can
            # rest at 0 < g < ε on a pressure ≤ αε/4 without ever crossing g = 0)
            pressed = self.retina.slave_gaps < max(self.retina.smoothing, 0.0)
            pressed_area = self.ctx.comm.allreduce(float(self.retina.slave_weights[pressed].sum()),
                                                   op=MPI.SUM)
        return {"max_penetration_mm": summary["max_penetration"],
                # the normal gap of the retina's nodes to the choroid's surface (the twin-node
                # retina_choroid_gap_* measure along the radius to the node they started above)
                "retina_choroid_gap_nts_min_mm": gap_min,
                "tear_closed_nts": closed,
                # the widest node-to-surface gap of the paired nodes on the tear's rim
                # (those tear_closed_nts looks at): closed when below the tolerance
                "tear_rim_gap_max_mm": float(rim[np.isfinite(rim)].max())
                if np.isfinite(rim).any() else float("nan"),
                # where that widest gap is: the node's polar angle from the anterior pole in
                # the reference mesh (the tear's centre at tear_angle, 88°: a smaller angle
                # is the rim's anterior edge, next to the detached flap's root)
                "tear_rim_widest_polar_deg": widest,
                "retina_contact_nodes": summary["active_nodes"],
                "retina_pressed_nodes": self.ctx.comm.allreduce(int(pressed.sum()), op=MPI.SUM),
                "retina_penalty_contact_area_mm2": 2.0 * pressed_area,
                "retina_contact_force_N": 2.0 * summary["contact_normal_force"]}

    def _widest_rim_node(self, rim: np.ndarray) -> float:
        """Reference polar angle (degrees from the anterior pole) of the tear-rim node with
        the widest node-to-surface gap ``rim`` (ordered as the pairing's rim nodes; nan
        when none is paired). The same on every rank: the pairing is gathered. Gaps within
        ``RIM_TIE`` (mm) of the widest count as tied (a closed rim's nodes all sit at the
        penalty's penetration, and their order there is round-off, which differs between
        partitions): of those, the anterior-most node is reported."""
        paired = np.isfinite(rim)
        if not paired.any():
            return float("nan")
        x = self.pairing.slave_x[self.tear_rim][paired]
        polar = np.degrees(np.arccos(x[:, 2] / np.linalg.norm(x, axis=1)))
        tied = rim[paired] >= rim[paired].max() - self.RIM_TIE
        return float(polar[tied].min())

    RIM_TIE = 1e-4

    def detached_area(self) -> float:
        if not self.detached:
            return 0.0
        if not hasattr(self, "_detached_area"):
            form = dolfinx.fem.form(dolfinx.fem.Constant(self.eye.mesh, 1.0)
                                    * self.eye.ds()(self.eye.tag("retina_detached")))
            self._detached_area = self.ctx.comm.allreduce(dolfinx.fem.assemble_scalar(form),
                                                          op=MPI.SUM)
        return self._detached_area

    def summary(self) -> dict:
        names = {1: "iop", 2: "buckling", 3: "suturing", 4: "settling"}
        out = {f"after_{names[k]}": v for k, v in sorted(self.stage_results.items())}
        out["dofs"] = global_dofs(*self.fields)
        out["cells"] = self.eye.mesh.topology.index_map(3).size_global
        out["jacobian_nonzeros"] = self.pattern_nonzeros
        out["contact_penalty"] = self.normal_penalty
        if self.retina is not None:
            out["retina_contact_penalty"] = self.retina.penalty
        if self.augmentation is not None:
            out["augmentations"] = self.augmentation.updates
            out["augmentation_limit_reached"] = self.augmentation.limit_reached
        return out


def _assemble(form, comm: MPI.Comm) -> float:
    compiled = form if isinstance(form, dolfinx.fem.Form) else dolfinx.fem.form(form)
    return comm.allreduce(dolfinx.fem.assemble_scalar(compiled), op=MPI.SUM)


def _von_mises(u, law):
    """Von Mises stress of the tissues' isochoric law: the deviator of σ is that of the
    isochoric part (neo-Hooke: (2c/J) dev(b̄)); the pressure multiplier drops out."""
    return von_mises(cauchy_stress(law, deformation_gradient(u)))


SCENE = Scene(name="scleral-buckling", kind="scene", parameters=Parameters, run=run,
              summary="encircling scleral buckling on a half eye: IOP, buckle, sutures (seed 002)")
