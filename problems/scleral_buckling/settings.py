"""The scleral-buckling scene's numerical settings, apart from its physics: Q1P0's
pressure, the contact's enforcement, Newton's budget and the path follower's
step sizes (group "solver and stepping" in ``eyemech list -v`` and docs/parameters.md).
Each choice is measured in docs/scleral_buckling.md where its help says."""

from __future__ import annotations

import dataclasses
from typing import Literal

from eyemech.problems.run.error_estimate import error_estimate_field
from eyemech.problems.run.parameters import SOLVER, ParameterError, field
from eyemech.problems.solve.linear_solvers import SolverChoice


@dataclasses.dataclass(frozen=True)
class NumericalSettings(SolverChoice):
    dg0_pressure: Literal["mixed", "condensed"] = field(
        "mixed", "Q1P0's DG0 pressure: mixed (an unknown per cell, exactly incompressible) or "
                 "condensed (eliminated cell by cell, p = bulk_modulus (J̄ − 1): the mean-dilatation "
                 "method, a displacement system; docs/scleral_buckling.md, \"Condensed Q1P0\")", group=SOLVER)
    condensed_bulk_ratio: float = field(
        300.0, "dg0_pressure=condensed: each tissue's bulk modulus over its shear modulus μ = 2c "
               "(its volume change O(μ/κ) of its strain): 300 ends the paper's three steps within "
               "0.4 % of mixed; 100 moves the IOP 1.4 %; 1,000 fails in step 2 at the paper's "
               "resolution, 10,000 in step 1 (docs/scleral_buckling.md, \"Condensed Q1P0\")", group=SOLVER)
    penalty_factor: float = field(
        30.0, "buckle–sclera penalty α = factor · E_sclera / h (30: the hertz study's choice; "
        "100 halves the penetration and doubles the Newton iterations)", group=SOLVER)
    retina_penalty_factor: float = field(
        100.0, "retina–choroid penalty α = factor · E_retina / h (E = 6 c_retina)", group=SOLVER)
    contact_method: Literal["penalty", "augmented-lagrangian"] = field(
        "penalty", "the buckle–sclera and retina–choroid contact: penalty, p = α⟨−g⟩; "
        "augmented-lagrangian, p = ⟨λ − α g⟩ with multipliers λ at the buckle integral's Gauss "
        "points and at the retina's nodes, updated after a converged solve (Uzawa) until they "
        "change by at most augmentation_tolerance: the zero-penetration answer, which the "
        "penalty misses by 0.5 % in the axial-length change on the default mesh, for 21 % more "
        "factorisations, hence not the default (docs/scleral_buckling.md, Augmented Lagrangian "
        "contact; docs/contact.md, Augmented Lagrangian)", group=SOLVER)
    augmented_penalty_scale: float = field(
        1.0, "augmented-lagrangian: both contacts' α as this fraction of the penalty's "
        "(penalty_factor, retina_penalty_factor; the tangential tie and the tire's rows keep "
        "the penalty's). 0.1 made Uzawa's multipliers converge too slowly to pay (coarse eye: "
        "30 augmentations per stage without reaching 0.005)", group=SOLVER)
    augmentation_tolerance: float = field(
        0.05, "augmented-lagrangian: the multipliers of a step are settled when they change by at "
        "most this fraction, ‖λ_new − λ‖/‖λ_new‖ (FEBio's augmentation tolerance; 0.05 puts the "
        "axial-length change within 0.01 % of 0.01's on the default mesh)", group=SOLVER)
    max_augmentations: int = field(
        10, "augmented-lagrangian: multiplier updates per load step at most (the step is then "
        "accepted and counted in augmentation_limit_reached)", group=SOLVER)
    augment_at: Literal["stage-end", "every-step"] = field(
        "stage-end", "augmented-lagrangian: where the multipliers are updated: at the end of each "
        "step of the operation only (the penalty along the path, the multipliers of the last "
        "stage's end carried), or after every converged load step (carried to the next as the "
        "predictor of the contact pressure: 103 factorisations on the coarse eye against 71)", group=SOLVER)
    contact_smoothing: float = field(
        0.0, "penalty kink rounded off over gaps |g| < ε (buckle and retina contact; "
        "0 = plain kink)", "mm", group=SOLVER)
    contact_integration: Literal["gauss", "nodal"] = field(
        "gauss", "buckle–sclera penalty evaluated at Gauss points or at the nodes (trapezoidal "
        "rule: node-to-rigid-surface contact)", group=SOLVER)
    retina_contact_method: Literal["node-to-surface", "segment-to-segment"] = field(
        "node-to-surface", "the retina–choroid pair: retina nodes on choroid triangles, or "
        "segment-to-segment (mortar integration over the retina's facets: passes the contact "
        "patch test, docs/contact.md; its cost in the eye: docs/scleral_buckling.md, "
        "Segment-to-segment retina contact)", group=SOLVER)
    # Newton's budget (docs/bench/scleral-buckling.md); the reference method: predictor=none,
    # jacobian_reuse=0, buckle_step=0.25, step_effort=iterations, hard_step_effort=0,
    # line_search=bt, suture_line_search=bt, settle_line_search=bt (settle_retry=none)
    predictor: Literal["secant", "none"] = field(
        "secant", "start each load step from the secant through the stage's last two converged "
        "states (none: from the last converged state)", group=SOLVER)
    jacobian_reuse: float = field(
        0.5, "modified Newton: keep the Jacobian and its factorisation while each iteration "
        "reduces the residual by this factor or more, once it is below 1 % of the solve's "
        "first (0: full Newton, a fresh factorisation every iteration)", group=SOLVER)
    jacobian_reuse_test: Literal["residual", "step"] = field(
        "residual", "modified Newton's contraction test: residual = the residual's reduction "
        "against jacobian_reuse; step = against what the step the line search took predicts, "
        "1 - lambda (1 - jacobian_reuse), so that backtracking's short steps keep the "
        "factorisation (docs/scleral_buckling.md, Newton's budget)", group=SOLVER)
    linear_reuse: Literal["none", "krylov"] = field(
        "none", "krylov = every Newton direction from the current Jacobian by FGMRES "
        "preconditioned with the last LU factorisation, refactorised only when FGMRES needs "
        "more than krylov_max_it iterations or contact grows the Jacobian's pattern (Newton's "
        "convergence kept; jacobian_reuse is then ignored, krylov_jacobian_reuse used): 2-5x "
        "fewer factorisations on every mesh, but not measurably faster at the paper's "
        "resolution on 2 ranks (slower alone, within 3 % with krylov_predict_after=5), "
        "hence not the default; "
        "none = a factorisation per Jacobian (docs/scleral_buckling.md, Krylov on a kept "
        "factorisation)", group=SOLVER)
    krylov_max_it: int = field(20, "linear_reuse=krylov: FGMRES iterations on the kept "
                               "factorisation before it is refreshed and the solve repeated", group=SOLVER)
    krylov_refresh_above: int = field(
        0, "linear_reuse=krylov: a Newton iteration whose FGMRES needed more iterations than "
        "this refactorises before the next one (0: only a failed FGMRES solve does)", group=SOLVER)
    krylov_rtol: float = field(1e-8, "linear_reuse=krylov: FGMRES's relative tolerance per Newton "
                               "iteration (1e-6 at the paper's resolution: 57 factorisations "
                               "against 60-61, the same quantities to 3e-7; docs/scleral_buckling.md, "
                               "Krylov on a kept factorisation, with the NaN cut)", group=SOLVER)
    krylov_ew: bool = field(False, "linear_reuse=krylov: Eisenstat-Walker's FGMRES tolerance "
                            "per Newton iteration instead of krylov_rtol", group=SOLVER)
    krylov_predict_after: int = field(
        0, "linear_reuse=krylov: after this many FGMRES iterations on a kept factorisation, "
        "refactorise at once when their mean contraction predicts more than krylov_max_it "
        "(0: off)", group=SOLVER)
    krylov_jacobian_reuse: float = field(
        0.0, "linear_reuse=krylov: keep the assembled Jacobian too while each Newton iteration "
        "reduces the residual by this factor or more, below 1 % of the solve's first "
        "(modified Newton on the kept factorisation, as jacobian_reuse; 0: a Jacobian every "
        "iteration)", group=SOLVER)
    buckle_step: float = field(
        0.125, "largest buckle travel per load step of step 2, as a fraction of the buckle's "
        "radial thickness (the other steps keep a quarter)", group=SOLVER)
    step_effort: Literal["iterations", "factorisations"] = field(
        "factorisations", "what sizes the next load step: grown after <= 6, halved after > "
        "hard_step_effort of the step's Newton iterations or its factorisations", group=SOLVER)
    line_search: Literal["basic", "bt", "cp"] = field(
        "basic", "Newton's line search while the buckle moves in (step 2): basic = the full step "
        "(a failed solve repeated once with bt before the load step is cut); bt = backtracking "
        "on the residual's norm, which creeps at its 0.1 floor where a step crosses the "
        "contact's kink. Step 3 as suture_line_search says, step 4 as settle_line_search "
        "(docs/scleral_buckling.md, Which contact chatters); cp: as in suture_line_search", group=SOLVER)
    full_step_nan: Literal["cut", "retry"] = field(
        "cut", "a solve with full steps (line_search=basic) whose Newton step makes the "
        "residual NaN or inf (inverted elements: the load step is too large for the mesh): "
        "cut = its load step is cut at once; retry = the solve is repeated with bt first, "
        "which crawled at its 0.1 floor to the iteration limit at the paper's resolution "
        "(docs/scleral_buckling.md, A NaN cuts the load step)", group=SOLVER)
    suture_line_search: Literal["cp", "bt", "basic"] = field(
        "cp", "Newton's line search in step 3 (the sutures' pull): cp = the step length where "
        "the energy's directional derivative F(u + a du).du vanishes (no rejection of a step "
        "that raises the residual's norm where retina pairs switch; a failed solve repeated "
        "once with bt); bt = backtracking on the residual's norm, which creeps at its 0.1 "
        "floor there; basic = full steps (docs/scleral_buckling.md, Newton's budget)", group=SOLVER)
    settle_ramp: Literal["linear", "log"] = field(
        "linear", "step 4's pressure ramp from the acute IOP to the pre-operative one: linear in "
        "P, or log (linear in ln P: equal pressure ratios per unit of load)", group=SOLVER)
    settle_start: Literal["target", "converged"] = field(
        "target", "step 4's load steps start with P at its pinned target (the pressure drop "
        "then loads the wall at the start, and bt accepts Newton's full first step) or at "
        "the last converged (or predicted) P (converged), where bt sees only P's row and "
        "creeps at its 0.1 floor (docs/scleral_buckling.md, The settling step)", group=SOLVER)
    settle_reuse_test: Literal["step", "residual"] = field(
        "step", "modified Newton's contraction test in step 4 (settling): step = against what "
        "the step the line search took predicts, 1 - lambda (1 - jacobian_reuse), so that bt's "
        "creep at its 0.1 floor keeps the factorisation; residual = as in the other steps, "
        "jacobian_reuse_test (docs/scleral_buckling.md, The settling step)", group=SOLVER)
    settle_line_search: Literal["bt", "basic", "cp"] = field(
        "basic", "Newton's line search in step 4: basic = full steps (a failed solve repeated "
        "once with bt), with cycle_max_period and retina_step_depth the settling with the "
        "pump finishes on the coarse, default and paper meshes; bt = backtracking on the "
        "residual's norm, which creeps at its 0.1 floor in the first settling load step and "
        "with the pump stalls (the band alone at 99.5 % of the settling); cp as in "
        "suture_line_search (docs/scleral_buckling.md, Newton's budget, The pigment "
        "epithelium's pump)", group=SOLVER)
    settle_retry: Literal["none", "basic"] = field(
        "none", "step 4 with settle_line_search=bt: basic = a solve that fails (bt's step "
        "below its floor) is repeated once from its start with full steps before the load "
        "step is cut: fewer factorisations, but a settled eye 2 % from the reference method's "
        "at the paper's resolution; none = cut at once (docs/scleral_buckling.md, Newton's "
        "budget)", group=SOLVER)
    hard_step_effort: int = field(10, "effort above which the next load step is halved "
                                  "(0: only a failed solve cuts it)", group=SOLVER)
    settle_predictor: Literal["secant", "none"] = field(
        "secant", "step 4's load steps start from the secant (with predictor = secant) or "
        "from the last converged state (none; docs/scleral_buckling.md, Newton's budget)", group=SOLVER)
    settle_step: float = field(
        0.125, "largest load step of step 4 (settling) as a fraction of the step: 1/8 keeps "
        "the settled eye within 0.6 % of 20 equal load steps' (coarse and default meshes), "
        "larger steps moved it up to 1.4 %. 0: as the other steps, "
        "three quarters of a step or the buckle_step = 0.25 travel's share "
        "(docs/scleral_buckling.md, The settling step)", group=SOLVER)
    restore_contact_memory: bool = field(
        False, "a cut load step or a retried Newton solve starts from the retina contact's "
        "sticky triangles of its start (off: from those of the failed attempt's last iterate). "
        "On: the result no longer depends on where a failed attempt stopped, but at the "
        "paper's resolution the path moved and cost 154 factorisations instead of 116 "
        "(docs/scleral_buckling.md, Stalled backtracking)", group=SOLVER)
    stagnation_window: int = field(
        0, "step 4: a Newton solve with bt whose residual fell by less than 10 % over this "
        "many iterations is stopped as failed and its load step cut (0: only the iteration "
        "limit or a failed line search stops it; with 3, settling steps of 1/8 that creep "
        "for 3 iterations and then converge were cut until the run failed: "
        "docs/scleral_buckling.md, Stalled backtracking, The settling step)", group=SOLVER)
    cycle_max_period: int = field(
        8, "a Newton solve with full steps (line_search, settle_line_search or suture_line_search "
        "basic, or the bt solves' basic retry) whose residual norms repeat a cycle of 1 to this "
        "many iterations (each within 1e-3 of the norm a period before) is stopped as "
        "failed, and retried or its load step cut as any failed solve, before it spends a "
        "factorisation per iteration to the iteration limit (0: off; docs/scleral_buckling.md, "
        "Full steps that cycle)", group=SOLVER)
    creep_window: int = field(
        4, "a modified-Newton solve (jacobian_reuse) that has iterated on a kept Jacobian and "
        "whose residual then falls at each of this many iterations but by less than half over "
        "them is stopped and repeated from its start with fresh Jacobians, as it would be at "
        "the iteration limit; not with bt (0: off; docs/scleral_buckling.md, Where the time "
        "goes)", group=SOLVER)
    retina_step_depth: float = field(
        0.5, "step 4 (settling): the Newton update shortened where it would carry a retina "
        "node deeper through the choroid than this fraction of the choroid's thickness (a "
        "node beyond the whole thickness is unpaired: the load step is cut). With 0.5 the "
        "settling finishes on the coarse, default and paper meshes with the pump at 0.3 and at "
        "1 mmHg, within 4 factorisations of the cheapest of 0 / 0.25 / 0.5 / 0.9 at 0.3 mmHg; "
        "0 and 0.25 each fail on one mesh at 1 mmHg, 0.9 costs 30 more on the paper mesh. "
        "Not in steps 2-3, where a shortened update stalled a radial tire's suturing; 0: off "
        "(docs/scleral_buckling.md, Full steps through the choroid)", group=SOLVER)
    retina_contact_prediction: bool = field(
        False, "at Newton iterates with a residual of at most flat_residual_limit, a retina "
        "node open there that Newton's full step would carry into the choroid gets the "
        "penalty's stiffness and the step is solved again (a primal-dual active-set step; "
        "docs/scleral_buckling.md, A flat residual accepted by its Newton correction)",
        group=SOLVER)
    increment_tolerance: float = field(
        0.0, "a Newton solve stopped at a flat residual (at most flat_residual_limit) is "
        "accepted when the Newton correction there, from a fresh Jacobian, moves no node by "
        "more than this (0: off, the residual alone decides; docs/scleral_buckling.md, A flat "
        "residual accepted by its Newton correction)", "mm", group=SOLVER)
    flat_residual_limit: float = field(
        1e-5, "the largest residual norm a flat-residual solve may be accepted at "
        "(increment_tolerance; the IOP's load on the half eye is about 1.5 N)", "N", group=SOLVER)

    error_estimate: bool = error_estimate_field(
        "also solve the operation on the neighbouring mesh of the ladder coarse, default, "
        "n = 20, paper (the next coarser; the next finer from the coarsest) and report Roache's "
        "grid convergence index of ΔAL, ΔSE and the tear's rim gap at each stage's end as "
        "<quantity>_error_estimate, and the rim's verdict closed / open / uncertain "
        "(docs/scleral_buckling.md, Discretisation error)")

    def validate_numerics(self) -> None:
        self._validate_discretisation()
        self._validate_solver()

    def _validate_discretisation(self) -> None:
        """Q1P0's pressure."""
        if not self.condensed_bulk_ratio > 0:
            raise ParameterError("condensed_bulk_ratio", f"{self.condensed_bulk_ratio}: must be > 0")
        if self.dg0_pressure == "condensed" and (self.element != "Q1P0" or self.solver != "direct"):
            raise ParameterError("dg0_pressure", "condensed needs element Q1P0 and solver direct "
                                 f"(the iterative solver splits [u, p]), not {self.element}, "
                                 f"{self.solver}")

    def _validate_solver(self) -> None:
        """Newton's budget, the Krylov reuse, the contact's method and the stepping."""
        if not 0 <= self.jacobian_reuse < 1:
            raise ParameterError("jacobian_reuse", f"{self.jacobian_reuse}: a contraction factor "
                                 "in [0, 1) (0: full Newton)")
        if not 0 < self.buckle_step <= 0.25:
            raise ParameterError("buckle_step", f"{self.buckle_step}: a fraction in (0, 0.25] of "
                                 "the buckle's thickness (deeper jumps throw the sclera through it)")
        self._validate_krylov()
        if self.contact_method == "augmented-lagrangian" \
                and self.retina_contact_method == "segment-to-segment":
            raise ParameterError("contact_method", "augmented-lagrangian keeps a multiplier per "
                                 "retina node: with retina_contact_method=node-to-surface only")
        if self.hard_step_effort < 0:
            raise ParameterError("hard_step_effort", f"{self.hard_step_effort}: must be >= 0")
        if self.stagnation_window < 0:
            raise ParameterError("stagnation_window", f"{self.stagnation_window}: must be >= 0")
        if self.creep_window < 0:
            raise ParameterError("creep_window", f"{self.creep_window}: must be >= 0")
        if self.retina_contact_prediction and self.retina_contact_method != "node-to-surface":
            raise ParameterError("retina_contact_prediction", "predicts node-to-surface pairs: "
                                 "with retina_contact_method=node-to-surface only")
        if not 0 <= self.retina_step_depth < 1:
            raise ParameterError("retina_step_depth", f"{self.retina_step_depth}: a fraction in "
                                 "[0, 1) of the choroid's thickness (0: off)")
        if not self.increment_tolerance >= 0:
            raise ParameterError("increment_tolerance", f"{self.increment_tolerance} mm: must be >= 0")
        if not self.flat_residual_limit > 0:
            raise ParameterError("flat_residual_limit", f"{self.flat_residual_limit} N: must be > 0")
        if not 0 <= self.settle_step <= 0.75:
            raise ParameterError("settle_step", f"{self.settle_step}: a fraction in [0, 0.75] "
                                 "of step 4 (0: the other steps' largest)")

    def _validate_krylov(self) -> None:
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
