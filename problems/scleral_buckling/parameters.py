"""The parameters of the scleral-buckling scene: the eye, its mesh and the operation's
physics here (groups "physics" and "geometry and mesh"), the solver's and the path
follower's settings apart in :mod:`.settings` ("solver and stepping"). Every key is a
``--set`` key and a TOML key; :meth:`Parameters.validate` refuses a bad value, naming
it, before anything is meshed."""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

from eyemech.forms.buckle import KINDS, ORIENTATIONS, BuckleShape
from eyemech.meshes.eye import RESOLUTIONS, TISSUES, EyeGeometry
from eyemech.problems.run.parameters import GEOMETRY, PHYSICS, ParameterError, SceneParameters, field
from eyemech.problems.scleral_buckling import error_estimate
from eyemech.problems.scleral_buckling.settings import NumericalSettings

# the calibrated coats (material = "calibrated"): c20 of the sclera fitted by least squares to
# Pallikaris et al. 2005 (IOVS 46:409), ln(P/10 mmHg) = K ΔV with their in vivo mean
# K = 0.0126 µL⁻¹, over 15-40 mmHg on the default eye (`eyemech study eye-calibration`,
# docs/scleral_buckling.md "Calibrated eye"); the cornea keeps Table 1's ratio to the sclera
CALIBRATED_C20_SCLERA = 56.7
CORNEA_TO_SCLERA = 0.0333 / 0.0833
# the fibre coats (material = "fibres"): c4 = 4.5 c20 stores the calibrated coats' energy in
# the coat's equibiaxial stretch (inflation) to leading order (forms/hyperelastic.py,
# TangentialFibres; docs/scleral_buckling.md, "A living eye's wall")
FIBRES_PER_YEOH = 4.5
# MPa/mm: the frictionless buckle's regularising spring, 3.5 times the slide's own
# stiffness (≈ 8.5e-4 MPa/mm on the coarse eye): docs/scleral_buckling.md,
# "The frictionless buckle's spring"
FRICTIONLESS_SLIP_STIFFNESS = 0.003

# hexahedra through the sclera: 8 layers of the 0.5 mm equator are 0.06 mm thick, in-plane
# sizes 36 (coarse) to 11 (paper) times that; more would only add cells
MAX_COAT_LAYERS = 8

# a segmental tire's second suture meridian, as a fraction of its half arc: inside the tire's
# end by a fifth of the half arc, so that the bite (1 mm grip) stays on the tire
SEGMENTAL_SUTURE_SPREAD = 0.8

# the keys a buckle's placement problem names (forms/buckle.py, BuckleShape.placement_problem)
PLACEMENT_KEYS = {"position": "buckle_position", "length": "tire_length"}

# the elastic band (buckle_control = shortening): Young's modulus of silicone rubber of
# Shore A 55 by Gent's relation E = 0.0981 (56 + 7.62 S)/(0.1375 (254 − 2.54 S)) MPa
# (Gent 1958, Trans. IRI 34:46), 2.5 MPa at S = 50 and 3.6 MPa at S = 60. The default
# shortening, 25 % of the loop, is the least of 20 / 25 / 30 % that closes the tear after
# suturing on the coarse and default meshes of the living eye (docs/scleral_buckling.md,
# "The defaults: a living eye, vented, a shortened band"); surgical texts advise ≈ 10 %,
# which on this eye leaves the band 0.4 mm deep and the tear open
# mattress sutures: the knot's share of the sclera between bite and element, and a leg's
# stiffness (docs/scleral_buckling.md, Mattress sutures)
MATTRESS_TIE_FRACTION = 0.5
MATTRESS_LEG_STIFFNESS = 20.0
BAND_MODULUS = 3.0
BAND_SHORTENING_PERCENT = 25.0

# the paper's operation (seed 002): Table 1's neo-Hookean coats, the optic nerve's end
# clamped, the rigid buckle (a 1.0 mm tire on the band) moved in by ``indentation``, the
# liquid's volume conserved, no pump (the paper has none). ``eyemech run scleral-buckling
# --set material=table-1 --set optic_nerve_end_spring=0 --set buckle_control=travel --set
# venting=false --set tire_height=1 --set subretinal_pump_mmHg=0`` (docs/scleral_buckling.md)
PAPER_OPERATION = {"material": "table-1", "optic_nerve_end_spring": 0.0,
                   "buckle_control": "travel", "venting": False, "tire_height": 1.0,
                   "subretinal_pump_mmHg": 0.0}
# the same as `--set` / TOML strings (for ``build``, sweeps and command lines)
PAPER_SETTINGS = {key: str(value) for key, value in PAPER_OPERATION.items()}
# the optic nerve's end spring of the living eye: within 4 % of the free eye's settled axial
# change and 0.004-0.011 N on the nerve (docs/scleral_buckling.md, "A living eye's wall")
OPTIC_NERVE_END_SPRING = 0.001


@dataclasses.dataclass(frozen=True)
class EyeParameters(SceneParameters):
    """The eye, its mesh and the operation: what is modelled."""

    resolution: Literal["coarse", "default", "paper"] = field(
        "default", "mesh: coarse (tests), default, paper (>= the paper's 7,421 hexahedra); "
                   "1.06, 1.59 and 3.45 cells per scleral bending length", group=GEOMETRY)
    cells_per_bending_length: float = field(
        0.0, "in-plane cells of the eye wall per scleral bending length √(R t) (R = 11.5 mm, "
             "t = 0.5 mm at the equator: 2.40 mm), rounded up to an even cube-edge count; "
             "0 = the named resolution", group=GEOMETRY)
    mesh_size: float = field(0.0, "in-plane element size of the eye wall, rounded down to an even "
                                  "cube-edge count; 0 = from cells_per_bending_length or resolution",
                             "mm", group=GEOMETRY)
    max_cells: int = field(30_000, "refuse a mesh estimated above this many hexahedra (before "
                                   "meshing; the paper resolution has 8,150)", group=GEOMETRY)
    element: Literal["Q1P0", "Q2P1"] = field(
        "Q1P0", "element family (Q1P0 as in the paper). Q2P1 resolves the retina's bending, "
        "which one Q1P0 cell locks: the check on a plan's tear verdict (docs/scleral_buckling.md, "
        "Q2P1 on the coarse eye, the rim node by node)", group=GEOMETRY)
    coat_layers: int = field(
        2, "hexahedra through the sclera (1-8; the cornea has 2 more); more do not relieve "
           "Q1P0's bending locking, which is in-plane (ΔAL +0.3-0.5 % with 4 or 6): "
           "docs/scleral_buckling.md, Q2P1 and Q1P0 at equal accuracy", group=GEOMETRY)
    iop_mmHg: float = field(15.0, "intra-ocular pressure of step 1", "mmHg", group=PHYSICS)
    bulk_modulus: float = field(2083.3, "bulk modulus of the liquid (seed 002)", "MPa", group=PHYSICS)
    iop_limit_mmHg: float = field(
        79.0, "the IOP at which the central retinal artery closes: 48-110 mmHg, mean 79 "
        "(Gardner et al., Ophthalmology 1993). With venting the IOP is held at it in steps 2-3; "
        "every stage reports the fraction of its load spent above it; at least iop_mmHg",
        "mmHg", group=PHYSICS)
    venting: bool = field(
        True, "steps 2-3: the surgeon vents the eye (paracentesis, subretinal drainage): the "
        "liquid is held until the IOP reaches iop_limit_mmHg, then the IOP stays there and the "
        "liquid the wall displaces leaves; false: the liquid's volume is conserved (the paper's "
        "law) and the IOP may pass the limit (docs/scleral_buckling.md, Venting)", group=PHYSICS)
    c_cornea: float = field(0.0333, "neo-Hooke c of the cornea (Table 1)", "MPa", group=PHYSICS)
    c_sclera: float = field(0.0833, "neo-Hooke c of the sclera", "MPa", group=PHYSICS)
    c_ciliary_body: float = field(0.01, "neo-Hooke c of the ciliary body", "MPa", group=PHYSICS)
    c_choroid: float = field(0.0083, "neo-Hooke c of the choroid", "MPa", group=PHYSICS)
    c_retina: float = field(0.0008, "neo-Hooke c of the retina", "MPa", group=PHYSICS)
    c_optic_nerve: float = field(0.05, "neo-Hooke c of the optic nerve", "MPa", group=PHYSICS)
    c_lens: float = field(10.0, "neo-Hooke c of the lens (Table 1)", "MPa", group=PHYSICS)
    material: Literal["table-1", "calibrated", "fibres"] = field(
        "fibres", "laws of the coats: table-1, every tissue neo-Hookean with the c_* above "
        "(seed 002, Table 1); calibrated, the sclera and the cornea stiffen with strain by "
        "c20 (Ī1 − 3)² (fitted to the eye's pressure–volume curve, Pallikaris et al. 2005); "
        "fibres, the same curve from tension-only fibres along the coats' meridians and "
        "circles of latitude, c4 max(Ī4 − 1, 0)⁴, which leave the coats soft in compression "
        "(docs/scleral_buckling.md, A living eye's wall)", group=PHYSICS)
    c20_sclera: float = field(
        CALIBRATED_C20_SCLERA, "Yeoh c20 of the sclera (material=calibrated; fitted: "
        "docs/scleral_buckling.md, Calibrated eye)", "MPa", group=PHYSICS)
    c20_cornea: float = field(
        CORNEA_TO_SCLERA * CALIBRATED_C20_SCLERA, "Yeoh c20 of the cornea (material=calibrated; "
        "c20_sclera in Table 1's cornea/sclera ratio 0.4)", "MPa", group=PHYSICS)
    lens: bool = field(True, "model the lens and its zonules (off: the liquid fills its place)",
    group=PHYSICS)
    lens_diameter: float = field(9.0, "equatorial diameter of the lens (Rosen et al. 2006)", "mm",
    group=GEOMETRY)
    lens_thickness: float = field(4.0, "axial thickness of the lens (Atchison & Smith 2000)", "mm",
    group=GEOMETRY)
    zonule_modulus: float = field(100.0, "Young's modulus of the zonules' bars (seed 002)", "MPa",
    group=PHYSICS)
    zonule_area: float = field(
        0.008, "cross-section of one zonule bar (a 0.1 mm fibre bundle; not given in seed 002)",
        "mm²", group=PHYSICS)
    buckle: Literal[KINDS] = field(
        "encircling+segmental", "which buckle: a band all round, a silicone tire over the tear "
        "(segmental), or both (the paper's operation)", group=PHYSICS)
    buckle_attachment: Literal["sutured", "frictionless"] = field(
        "sutured", "sutured: the sclera under the buckle's footprint is tied to it tangentially "
        "from step 2 on; frictionless: it may slide along the buckle", group=PHYSICS)
    frictionless_slip_stiffness: float = field(
        FRICTIONLESS_SLIP_STIFFNESS, "frictionless: a weak tangential spring under the buckle's "
        "footprint from step 2 on, standing for the buckle's friction on the sclera (a "
        "regularisation: the slide along the buckle is a near-zero-stiffness mode, and at 0 "
        "Newton stalls on the coarse eye with 1 mm of travel; 0.003 holds about 4/5 of the "
        "slide, docs/scleral_buckling.md, \"The frictionless buckle's spring\")", "MPa/mm",
        group=PHYSICS)
    tire_arc_deg: float = field(90.0, "arc of the circumferential silicone tire about the optic "
                                "axis, centred on the tear's meridian (360: a full ring)", "deg",
                                group=GEOMETRY)
    tire_orientation: Literal[ORIENTATIONS] = field(
        "circumferential", "circumferential: the tire's long axis runs round the eye (arc "
        "tire_arc_deg); radial: along the tear's meridian (length tire_length, centred at "
        "buckle_position), tire_width across it, sutured either side; radial needs "
        "buckle=segmental and suture_azimuths=0 (docs/scleral_buckling.md, Radial tire)", group=PHYSICS)
    tire_length: float = field(12.0, "radial tire: its length along the meridian, measured on "
                               "the sclera", "mm", group=GEOMETRY)
    buckle_position: float = field(
        13.0, "buckle centre behind the limbus, along the sclera. 13.0: the tear (centre 11.5 mm "
        "behind the limbus) on the buckle's anterior slope, ≈ 0.4 mm of tire in front of it "
        "and ≈ 3.4 mm behind its posterior edge, as surgeons place a break (on the descending "
        "slope it leaks: fishmouthing). With 2.0 mm of travel it closes the tear after "
        "suturing on the coarse, default, n = 20 and paper meshes (docs/scleral_buckling.md, "
        "\"Operations searched with the rim on its circle\")", "mm", group=GEOMETRY)
    band_width: float = field(2.5, "encircling band width (axial)", "mm", group=GEOMETRY)
    band_thickness: float = field(0.6, "encircling band thickness", "mm", group=GEOMETRY)
    tire_width: float = field(7.0, "silicone tire width (axial; across the meridian for a radial "
                              "tire)", "mm", group=GEOMETRY)
    tire_height: float = field(
        2.0, "silicone tire height (radial). 2.0: the least of 1.0 / 1.5 / 2.0 that closes the "
        "tear after suturing and settled on the coarse, default and paper meshes (with 1.5 "
        "the paper mesh's rim is 0.054 mm open after suturing, with 1.0 it never seals), "
        "all Q1P0; with Q2P1 on the coarse eye the rim is 0.12 mm open at 1.0-2.0 alike "
        "(docs/scleral_buckling.md, The defaults)", "mm", group=GEOMETRY)
    buckle_corner_radius: float = field(0.3, "corner radius of the tire's and band's profiles "
                                        "(capped at half their height)", "mm", group=GEOMETRY)
    indentation: float = field(
        2.0, "radial inward travel of the rigid buckle in step 2 (buckle_control=travel, or a "
        "tire without a band). 2.0: on Table 1's eye (the paper's operation) with the buckle "
        "at 13.0 mm the least travel searched that closes the tear after suturing on every "
        "mesh; it costs an acute IOP of 49–58 mmHg and ΔAL ≈ +2.2–2.5 mm acute "
        "(docs/scleral_buckling.md, \"The paper's operation\")", "mm", group=PHYSICS)
    buckle_clearance: float = field(0.05, "gap between buckle and sclera before step 2", "mm", group=GEOMETRY)
    suture_width: float = field(8.9, "distance between the two bites of a suture (paper 8.90)", "mm",
    group=GEOMETRY)
    suture_force: float = field(0.2, "pull on each suture at the end of step 3", "N", group=PHYSICS)
    suture_bite_radius: float = field(1.0, "radius over which a suture grips the sclera", "mm",
    group=GEOMETRY)
    suture_azimuths: tuple[float, ...] = field(
        (), "suture meridians, degrees from the tear (0–180: the half eye). Empty (the "
        "default): across the buckle chosen, 0, 90 and 180 with a band all round, 0 and "
        f"{SEGMENTAL_SUTURE_SPREAD:g} of the tire's half arc on a segmental tire (0 and 36 on "
        "the default 90° tire), 0 on a radial tire (Parameters.suture_meridians)", "deg",
        group=GEOMETRY)
    suture_model: Literal["loop", "bites", "mattress"] = field(
        "loop", "loop: a suture is a loop over the tire; its tension pulls the bites and pushes "
        "the tire in, whose radial travel in steps 3-4 balances the sclera's contact force "
        "(a rigid band, buckle_control=travel, keeps its travel; the elastic band carries "
        "the tire at its own); bites: the pull acts on the bites only and "
        "the tire keeps the band's travel; mattress: each suture is tied to a length, its legs "
        "shortened by suture_tie_fraction of the sclera between its bites beyond the element's "
        "width, so that wider bites imbricate more sclera and raise the buckle; its tension "
        "follows (suture_force is refused: docs/scleral_buckling.md, Mattress sutures)", group=PHYSICS)
    suture_tie_fraction: float = field(
        MATTRESS_TIE_FRACTION, "suture_model=mattress: the knot shortens each leg by this "
        "fraction of (suture_width − the element's width)/2, the sclera between a bite and "
        "the element's edge (1: the bites drawn to the element's edges)", group=PHYSICS)
    suture_stiffness: float = field(
        MATTRESS_LEG_STIFFNESS, "suture_model=mattress: axial stiffness of one leg of a tied "
        "suture (EA/ℓ: 5-0 polyester, E ≈ 5 GPa over a 0.1 mm thread, ≈ 40 N, on a ≈ 2 mm "
        "leg; an estimate)", "N/mm", group=PHYSICS)
    drainage: Literal["none", "external"] = field(
        "none", "external (the subretinal fluid drained in step 4) is refused: the drained "
        "retina pressed on the choroid reaches no equilibrium in this model (it drifts "
        "along the choroid's facets; docs/scleral_buckling.md, Subretinal drainage)",
        group=PHYSICS)
    subretinal_pump_mmHg: float = field(
        0.3, "step 4: once the break is sealed (tear_closed_nts), the pigment epithelium pumps "
        "the subretinal fluid out, its pressure below the vitreous' by this much once the IOP "
        "is back (ramped with the rest of the IOP's return), on the detached retina's outer "
        "face and the choroid's inner face; through an open break the vitreous refills the "
        "space and no deficit builds up. Nothing to pump without a detachment, the settling "
        "or the retina's contact. 0.3: an assumed deficit (the clinic measures resorption times, "
        "not pressures); with 1 the settling fails on 9 of the planning map's 24 cases, "
        "the retina pressed onto the choroid's facets; 0: off "
        "(docs/scleral_buckling.md, The pigment epithelium's pump)",
        "mmHg", group=PHYSICS)
    detachment_height: float = field(0.5, "subretinal gap at the detachment's centre "
                                     "(0: the retina is attached)", "mm", group=GEOMETRY)
    tear_radius: float = field(1.6, "radius of the causative tear (0: no tear)", "mm", group=GEOMETRY)
    retina_thickness: float = field(0.2, "retina thickness", "mm", group=GEOMETRY)
    retina_contact: bool = field(True, "enforce retina–choroid contact (off: the gap is only "
                                 "measured and the retina may pass through the choroid)", group=PHYSICS)
    settle: bool = field(True, "step 4: the settled state hours after surgery; outflow returns "
                         "the IOP to its pre-operative value (the liquid volume is released)", group=PHYSICS)
    tear_closure_tolerance: float = field(0.05, "gap below which the tear's rim counts as closed",
                                          "mm", group=PHYSICS)
    retina_incompatible_modes: bool = field(
        False, "the retina's Q1 cells with Wilson-Taylor incompatible modes and a linear pressure "
        "per cell: its bending is not locked (Q1P0 one cell thick is 3.6-28x too stiff in bending on "
        "the paper to coarse meshes; with the modes within 2 %: tests/test_incompatible_modes.py); "
        "element Q1P0, dg0_pressure mixed, solver direct. Measured at the defaults: the tear's rim "
        "after suturing / settled 0.083 / 0.030 mm on the coarse eye and 0.720 / 0.494 mm on the "
        "default mesh (Q1P0 0.030 / 0.000 and 0.014 / 0.040; docs/scleral_buckling.md, A retina "
        "not locked in bending)", group=GEOMETRY)


@dataclasses.dataclass(frozen=True)
class Parameters(NumericalSettings, EyeParameters):
    """Every parameter of the scene: :class:`EyeParameters`, then the numerical settings,
    then the surgeon's controls of the buckle."""

    buckle_control: Literal["travel", "shortening"] = field(
        "shortening", "how step 2 tightens the buckle: shortening, an elastic silicone band "
        "(band_modulus_MPa, band_width x band_thickness) whose loop the surgeon shortens by "
        "band_shortening_mm or band_shortening_percent, its travel an unknown set by its "
        "hoop tension against the eye, the tire riding under it (docs/scleral_buckling.md, "
        "\"The elastic band\"); a tire without a band (buckle=segmental) moves in by "
        "indentation; travel, the rigid buckle moves in by indentation (the paper's "
        "operation)", group=PHYSICS)
    band_shortening_percent: float = field(
        BAND_SHORTENING_PERCENT, "with buckle_control=shortening, the length taken out of "
        "the band's loop, in % of its length as laid on the eye (used unless "
        "band_shortening_mm is set)", "%", group=PHYSICS)
    band_shortening_mm: float = field(
        0.0, "with buckle_control=shortening, the length taken out of the band's loop through its sleeve; 0: "
        "band_shortening_percent sets it", "mm", group=PHYSICS)
    band_modulus_MPa: float = field(
        BAND_MODULUS, "Young's modulus of the silicone band (buckle_control=shortening): 3.0, Gent's "
        "relation for silicone rubber of Shore A 55 (2.5-3.6 MPa over Shore A 50-60; an "
        "assumption: no measured modulus of a #240 band was found)", "MPa", group=PHYSICS)

    c4_sclera: float = field(
        FIBRES_PER_YEOH * CALIBRATED_C20_SCLERA, "fibre modulus c4 of the sclera "
        "(material=fibres; 4.5 c20_sclera: the calibrated coat's energy in inflation)", "MPa",
        group=PHYSICS)
    c4_cornea: float = field(
        FIBRES_PER_YEOH * CORNEA_TO_SCLERA * CALIBRATED_C20_SCLERA, "fibre modulus c4 of the "
        "cornea (material=fibres; c4_sclera in Table 1's cornea/sclera ratio 0.4)", "MPa",
        group=PHYSICS)
    optic_nerve_end_spring: float = field(
        OPTIC_NERVE_END_SPRING, "the optic nerve's cut end held by a spring of this stiffness per area (the "
        "orbit's soft hold on the globe) instead of clamped: the buckle then rides on the "
        "globe and the posterior segment may lengthen behind it; 0 = clamped (the paper). "
        "0.001: within 4 % of the free eye's settled axial change "
        "(docs/scleral_buckling.md, A living eye's wall)", "MPa/mm", group=PHYSICS)

    def validate(self) -> None:
        self._validate_signs()
        if not 1 <= self.coat_layers <= MAX_COAT_LAYERS:
            raise ParameterError("coat_layers", f"{self.coat_layers}: an integer from 1 to "
                                 f"{MAX_COAT_LAYERS} (hexahedra through the sclera)")
        self.validate_numerics()
        self._validate_retina_modes()
        self._validate_material()
        self._validate_drainage()
        self._validate_buckle()
        self._validate_geometry()
        self._validate_control()
        error_estimate.validate(self)  # the second solve's mesh, once the run's own are good

    def _validate_signs(self) -> None:
        self.require_positive("iop_mmHg", "bulk_modulus", "c_cornea", "c_sclera", "c_ciliary_body",
                              "c_choroid", "c_retina", "c_optic_nerve", "band_width",
                              "band_thickness", "tire_width", "suture_width", "penalty_factor",
                              "retina_penalty_factor", "c_lens", "lens_diameter",
                              "lens_thickness", "zonule_modulus", "zonule_area",
                              "suture_bite_radius", "tire_length", "augmented_penalty_scale",
                              "augmentation_tolerance", "max_augmentations",
                              "tear_closure_tolerance", "retina_thickness", "max_cells")
        self.require_nonnegative("cells_per_bending_length", "mesh_size")
        self._validate_sutures()
        self.require_positive("iop_limit_mmHg")
        if self.iop_limit_mmHg < self.iop_mmHg:
            raise ParameterError("iop_limit_mmHg", f"{self.iop_limit_mmHg:g} mmHg is below the "
                                 f"pre-operative IOP (iop_mmHg = {self.iop_mmHg:g} mmHg): the "
                                 "artery would be closed before surgery; the limit must be at "
                                 "least iop_mmHg")

    def _validate_sutures(self) -> None:
        """The tied (mattress) sutures' knot and thread only with them; their pull is not
        prescribed."""
        self.require_positive("suture_stiffness")
        if not 0 < self.suture_tie_fraction <= 1:
            raise ParameterError("suture_tie_fraction", f"{self.suture_tie_fraction:g}: a fraction "
                                 "in (0, 1] of the sclera between a bite and the element's edge")
        if self.suture_model == "mattress":
            if self.suture_force != EyeParameters.suture_force:
                raise ParameterError("suture_force", "is the loop's and the bites' prescribed pull; "
                                     "tied mattress sutures pull as the sclera resists "
                                     "(set suture_tie_fraction or suture_width)")
            return
        for key, default in (("suture_tie_fraction", MATTRESS_TIE_FRACTION),
                             ("suture_stiffness", MATTRESS_LEG_STIFFNESS)):
            if getattr(self, key) != default:
                raise ParameterError(key, f"is used only with suture_model=mattress (the sutures "
                                     f"are {self.suture_model}: their pull is suture_force)")

    def _validate_retina_modes(self) -> None:
        if self.retina_incompatible_modes and (self.element, self.dg0_pressure, self.solver) \
                != ("Q1P0", "mixed", "direct"):
            raise ParameterError("retina_incompatible_modes", "enriches Q1 cells with a mixed DG0 "
                                 "pressure, solved directly: it needs element=Q1P0, "
                                 "dg0_pressure=mixed and solver=direct, not "
                                 f"{self.element}, {self.dg0_pressure}, {self.solver}")

    def _validate_material(self) -> None:
        self.require_nonnegative("c20_sclera", "c20_cornea", "buckle_corner_radius", "tire_height",
                                 "contact_smoothing", "frictionless_slip_stiffness", "indentation",
                                 "suture_force", "detachment_height", "tear_radius")
        self.require_nonnegative("c4_sclera", "c4_cornea", "optic_nerve_end_spring",
                                 "subretinal_pump_mmHg", "cycle_max_period")
        for key, default, material in (
                ("c20_sclera", CALIBRATED_C20_SCLERA, "calibrated"),
                ("c20_cornea", CORNEA_TO_SCLERA * CALIBRATED_C20_SCLERA, "calibrated"),
                ("c4_sclera", FIBRES_PER_YEOH * CALIBRATED_C20_SCLERA, "fibres"),
                ("c4_cornea", FIBRES_PER_YEOH * CORNEA_TO_SCLERA * CALIBRATED_C20_SCLERA, "fibres")):
            if self.material != material and getattr(self, key) != default:
                raise ParameterError(key, f"is used only with material={material} (the coats "
                                     f"are {self.material}'s)")
        if self.buckle_attachment == "sutured" \
                and self.frictionless_slip_stiffness != FRICTIONLESS_SLIP_STIFFNESS:
            raise ParameterError("frictionless_slip_stiffness", "is used only with "
                                 "buckle_attachment=frictionless (the sutured buckle is tied)")
        if not 0 < self.tire_arc_deg <= 360:
            raise ParameterError("tire_arc_deg", f"{self.tire_arc_deg} degrees: the tire's arc must "
                                 "lie in (0, 360] degrees")

    def _validate_drainage(self) -> None:
        if self.drainage != "none":
            raise ParameterError("drainage", f"{self.drainage} is refused: the drained retina "
                                 "pressed on the choroid reaches no equilibrium in this model "
                                 "(a pseudo-time drag of 8 mmHg, half the IOP, is left after "
                                 "80 and after 300 solves on the coarse eye, and the default "
                                 "mesh's run fails at 70 % of the drainage; "
                                 "docs/scleral_buckling.md, Subretinal drainage)")

    def _validate_buckle(self) -> None:
        """The buckle's kind and orientation, its sutures, its travel and its place on the
        sclera."""
        if self.buckle_clearance < 0:
            raise ParameterError("buckle_clearance", "the buckle would start inside the eye "
                                 f"({self.buckle_clearance} mm); it must be >= 0")
        self._validate_orientation()
        shape = self.buckle_shape()
        meridians = self.suture_meridians()
        if any(shape.element_at(a) is None for a in meridians):
            raise ParameterError("suture_azimuths", "a suture lies off the segmental tire (its arc "
                                 f"is ±{self.tire_arc_deg / 2:g} degrees about the tear): "
                                 "nothing to hold there")
        widest = max((shape.element_at(a)[0] for a in meridians),
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
        problem = shape.placement_problem(self.buckle_position,
                                          arc_to_pole - 2 * geometry.optic_nerve_radius)
        if problem is not None:
            what, message = problem
            raise ParameterError(PLACEMENT_KEYS[what], message)
        if any(not 0 <= a <= 180 for a in meridians):
            raise ParameterError("suture_azimuths", "need angles in [0, 180] degrees (the half eye)")

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
            if tuple(self.suture_meridians()) != (0.0,):
                raise ParameterError("suture_azimuths", "a radial tire lies on the tear's meridian: "
                                     "its sutures cross it there (suture_azimuths=0)")
        elif self.tire_length != 12.0:
            raise ParameterError("tire_length", "sets a radial tire's length (tire_orientation="
                                 "radial); a circumferential tire's extent is tire_arc_deg")

    def _validate_geometry(self) -> None:
        try:
            self.geometry().validate()
        except Exception as err:
            key = "lens_diameter" if "lens" in str(err) else self.resolution_key()
            raise ParameterError(key, str(err)) from None

    def _validate_control(self) -> None:
        """The elastic band's shortening: only with a band and buckle_control=shortening,
        a positive length shorter than the band's loop; the rigid buckle's travel only
        where nothing is shortened (buckle_control=travel, or a tire without a band)."""
        self.require_positive("band_modulus_MPa")
        mm_set = self.band_shortening_mm != 0.0
        percent_set = self.band_shortening_percent != BAND_SHORTENING_PERCENT
        if not self.elastic_band():
            why = ("the rigid buckle moves in by indentation" if self.buckle_control == "travel"
                   else f"buckle={self.buckle} has no band to shorten: its tire moves in by "
                        "indentation")
            for key, is_set in (("band_shortening_mm", mm_set),
                                ("band_shortening_percent", percent_set),
                                ("band_modulus_MPa", self.band_modulus_MPa != BAND_MODULUS)):
                if is_set:
                    raise ParameterError(key, f"is used only with an elastic band shortened "
                                         f"(buckle_control=shortening): {why}")
            return
        if self.indentation != EyeParameters.indentation:
            raise ParameterError("indentation", "is the rigid buckle's travel "
                                 "(buckle_control=travel); with shortening the band's travel is "
                                 "an unknown")
        if mm_set and percent_set:
            raise ParameterError("band_shortening_mm", "and band_shortening_percent are both set: "
                                 "give the shortening one way")
        loop = self.band_loop_estimate()
        if mm_set:
            if not 0 < self.band_shortening_mm < loop:
                raise ParameterError("band_shortening_mm", f"{self.band_shortening_mm:g} mm: the "
                                     f"length taken out must be > 0 and below the band's loop "
                                     f"(≈ {loop:.1f} mm as laid on this eye)")
        elif not 0 < self.band_shortening_percent < 100:
            raise ParameterError("band_shortening_percent", f"{self.band_shortening_percent:g} %: "
                                 "a share of the band's loop, > 0 and < 100")

    def elastic_band(self) -> bool:
        """Whether step 2 shortens an elastic band (buckle_control = shortening, with a
        band); otherwise the rigid buckle (or a tire alone) moves in by ``indentation``."""
        return self.buckle_control == "shortening" and self.buckle_shape().has_band

    def band_loop_estimate(self) -> float:
        """The band's centreline length as laid on the eye before surgery, from the sclera's
        radius at rest (the inflated eye's, where the scene lays it, is ≈ 0.1 mm larger):
        2π (R + clearance + t/2) plus the tire's height over its arc."""
        shape = self.buckle_shape()
        radius = self.geometry().sclera_radius + self.buckle_clearance + 0.5 * self.band_thickness
        tire = self.tire_height * math.radians(min(self.tire_arc_deg, 360.0)) if shape.has_tire else 0.0
        return 2 * math.pi * radius + tire

    def band_shortening_fraction(self) -> float:
        """The shortening as a fraction of the loop (band_loop_estimate for a length in mm):
        sizes the buckling stage's steps; the scene takes the millimetres out of the loop
        it lays."""
        if self.band_shortening_mm > 0:
            return self.band_shortening_mm / self.band_loop_estimate()
        return self.band_shortening_percent / 100.0

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

    def suture_meridians(self) -> tuple[float, ...]:
        """The sutures' meridians (degrees from the tear): ``suture_azimuths`` when set, else
        across the buckle chosen -- a band all round is sewn at 0, 90 and 180 degrees; a
        segmental tire at 0 and within its end; a radial tire on the tear's meridian."""
        if self.suture_azimuths:
            return tuple(float(a) for a in self.suture_azimuths)
        if self.buckle != "segmental":
            return (0.0, 90.0, 180.0)
        if self.tire_orientation == "radial":
            return (0.0,)
        return (0.0, round(SEGMENTAL_SUTURE_SPREAD * min(self.tire_arc_deg, 360.0) / 2, 6))

    def buckle_shape(self) -> BuckleShape:
        return BuckleShape(self.band_width, self.band_thickness, self.tire_width, self.tire_height,
                           self.buckle_corner_radius, self.buckle, self.tire_arc_deg,
                           self.tire_orientation, self.tire_length, self.geometry().sclera_radius)

    def stiffness(self) -> dict[str, float]:
        return {t: getattr(self, f"c_{t}") for t in TISSUES}

    def stiffening(self) -> dict[str, float]:
        """Yeoh c20 per tissue of the calibrated coats (0 elsewhere)."""
        return {"sclera": self.c20_sclera, "cornea": self.c20_cornea}

    def fibre_stiffness(self) -> dict[str, float]:
        """Fibre modulus c4 per tissue of the fibre coats (0 elsewhere)."""
        return {"sclera": self.c4_sclera, "cornea": self.c4_cornea}
