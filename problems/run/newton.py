"""What a run knows of its Newton solvers, below the solvers themselves
(:mod:`eyemech.problems.solve.driver`): their settings (:class:`NewtonOptions`, which
``RunOptions.newton`` carries and ``--petsc`` overrides), their failure
(:class:`SolveFailure`, the run contract's status ``failed``) and which of them are open,
so that the run contract closes them on every rank as a run ends."""

from __future__ import annotations

import dataclasses
import weakref
from typing import Any, Literal

from eyemech.problems.run.parameters import ParameterError

FACTORISATIONS = ("auto", "lu", "ldlt")


class SolveFailure(RuntimeError):
    """Newton failed and step cutting is exhausted; the last converged state is kept.

    ``failed_step``: the failed step as ``results.json`` records a step (status ``failed``,
    its attempts' work), which the run contract adds to the run's ``steps``; None where
    the raiser keeps no such record."""

    failed_step: dict[str, Any] | None = None  # also for a subclass with an __init__ of its own

    def __init__(self, step: int, load: float, last_converged: float, residuals: list[float],
                 reason: str, quantity: str = "load factor", unit: str = "", *,
                 failed_step: dict[str, Any] | None = None):
        self.step, self.load, self.last_converged = step, load, last_converged
        self.failed_step = failed_step
        self.residuals, self.reason = residuals, reason
        self.quantity, self.unit = quantity, unit
        history = ", ".join(f"{r:.3e}" for r in residuals) or "none"
        with_unit = f" {unit}" if unit else ""
        super().__init__(
            f"Newton did not converge at step {step} trying {quantity} {load:.6g}{with_unit} "
            f"(SNES reason: {reason}); residual norms of the last attempt: [{history}]. "
            f"Last converged {quantity} {last_converged:.6g}{with_unit} is kept.")


@dataclasses.dataclass
class NewtonOptions:
    """SNES settings; ``petsc`` entries (without prefix) override everything else."""

    line_search: str = "basic"  # basic | bt | l2 | cp | nleqerr
    rtol: float = 1e-9
    atol: float = 1e-10
    stol: float = 0.0
    max_it: int = 15
    linear_solver: str = "mumps"  # mumps | superlu_dist | petsc (LU) | iterative via petsc
    # the direct factorisation: "lu", "ldlt" (MUMPS LDLᵀ of a symmetric indefinite Jacobian,
    # PETSc's cholesky; one triangle is read) or "auto" (the solver's scene choice, LU unless
    # it declares LDLᵀ measured to pay: docs/atlas/peer-comparison.md, "Symmetric factorisation")
    factorisation: str = "auto"
    petsc: dict[str, str] = dataclasses.field(default_factory=dict)
    # modified Newton: the last Jacobian (and its factorisation) is kept while Newton
    # contracts, ‖F_k‖ ≤ θ ‖F_k−1‖, and across solves until ``NonlinearSolver.
    # invalidate_jacobian``; 0 = a fresh Jacobian every iteration (full Newton)
    reuse_contraction: float = 0.0
    # ... and only near convergence, once ‖F_k‖ ≤ reuse_below · ‖F_0‖: earlier, while contact
    # switches, an iterate on a kept Jacobian led Newton into creeping (≈ 0.9 per iteration)
    # more often than it saved a factorisation (docs/bench/scleral-buckling.md)
    reuse_below: float = 1e-2
    # the iteration limit of a modified-Newton solve: its iterations on a kept
    # factorisation cost a residual and a back-substitution each
    reuse_max_it: int = 25
    # the contraction test measured against the step the line search took: after a step
    # λ·δ the linear model predicts ‖F_k‖ = (1 − λ)‖F_k−1‖, and the Jacobian is kept while
    # ‖F_k‖ ≤ (1 − λ(1 − θ))‖F_k−1‖ (at λ = 1 the test above). Backtracking that creeps at
    # λ = 0.1 across a contact's kink reduces ‖F‖ by the predicted 0.9 per iteration: the
    # Jacobian describes the step it was asked for, a fresh one would not lengthen it
    # (docs/scleral_buckling.md, "Newton's budget"). Off: the contraction is compared with θ.
    reuse_step_relative: bool = False
    # a modified-Newton solve that has iterated on a kept Jacobian and then creeps -- ‖F‖
    # falls at each of the last ``reuse_creep_window`` iterations, but by less than the
    # factor ``reuse_creep_factor`` over them -- is stopped as failed, to be repeated from
    # its start with fresh Jacobians (:meth:`NonlinearSolver.solve`'s retry) at once instead
    # of at ``reuse_max_it``, a factorisation per iteration: on the default eye a kept
    # Jacobian's step left the suturing's Newton creeping × 0.92 per iteration for 23
    # fresh-Jacobian iterations; the retry converged in 5 (docs/scleral_buckling.md, "Where
    # the time goes"). A solve without a kept Jacobian is never stopped by it, nor one with
    # bt, whose creep at its 0.1 floor across a contact's kink converges, the factorisation
    # kept by ``reuse_step_relative`` (tests/test_newton_counts.py). 0: off.
    reuse_creep_window: int = 4
    reuse_creep_factor: float = 0.5
    # keep the last converged solve's Jacobian for the next solve's first iteration (off:
    # on the eye a load step started on it failed more often than it saved, see
    # docs/bench/scleral-buckling.md)
    reuse_across_solves: bool = False
    # a solve that fails is repeated once from the same start with this line search (e.g.
    # "bt" behind "basic": full Newton steps cross a contact's kink where backtracking on
    # ‖F‖ creeps at its 0.1 floor, and the retry keeps a cycling active set from cutting
    # the step; "": no retry; docs/scleral_buckling.md, "Which contact chatters")
    fallback_line_search: str = ""
    # a solve with full steps (line search ``basic``) that fails because a Newton step made
    # the residual NaN or inf (inverted elements: the load step is too large for the mesh)
    # is not repeated with ``fallback_line_search``, so that its load step is cut at once:
    # at the paper's resolution the bt retry after such a failure crawled at its 0.1 floor
    # to the iteration limit before the cut (docs/scleral_buckling.md, "A NaN cuts the load
    # step"). False: such a solve is repeated with the fallback as any other failure.
    cut_on_nan: bool = False
    # a solve with backtracking (``bt``, whose residual falls at every accepted step) whose
    # residual fell by less than 1 − ``stagnation_factor`` over the last
    # ``stagnation_window`` iterations is stopped as failed before the next Jacobian
    # (0: never): backtracking that has stalled at λ ≪ 1 (e.g. a direction that inverts
    # elements at λ = 1) would otherwise spend a factorisation per iteration up to the
    # iteration limit before the load step is cut. Full steps and cp are not monotone in
    # ‖F‖ (semismooth Newton across a contact's kink rises before it settles), so the test
    # does not apply to them (docs/scleral_buckling.md, "Newton's budget")
    stagnation_window: int = 0
    stagnation_factor: float = 0.9
    # a solve with full steps (line search ``basic``) whose residual norms repeat a cycle
    # (:func:`~eyemech.problems.solve.driver.repeats_a_cycle`: the last ``period`` norms
    # equal, to ``cycle_rtol``, the ``period`` before them, for a period of 1 to
    # ``cycle_max_period`` iterations) is stopped as failed before its next Jacobian: full
    # Newton steps that hop between the same contact states revisit the same iterates and
    # would do so to the iteration limit, a factorisation per iteration (the paper mesh's
    # settling: periods 5 and 7, the norms equal to 4 digits; docs/scleral_buckling.md,
    # "Full steps that cycle"). 0: never.
    cycle_max_period: int = 0
    cycle_rtol: float = 1e-3
    # a solve that stops unconverged at a small finite residual (backtracking finds no
    # descent, or the iteration limit) is accepted as converged when ‖F‖ ≤
    # ``flat_residual_limit`` and the full Newton correction at its last iterate, from a fresh
    # Jacobian, moves no component of the first unknown (the displacement) by more than
    # ``increment_tolerance``: the displacement criterion of nonlinear finite-element codes,
    # for states whose residual cannot fall further along a soft mode (a detached flap of
    # retina at its contact's kink: docs/scleral_buckling.md, "A flat residual accepted by
    # its Newton correction"). 0: off, only ‖F‖ decides.
    increment_tolerance: float = 0.0
    flat_residual_limit: float = 1e-6
    # "krylov": every Newton direction from the current Jacobian by FGMRES preconditioned
    # with the last LU factorisation, refactorised only when FGMRES needs more than
    # ``krylov_max_it`` iterations or the Jacobian's pattern grew
    # (:mod:`~eyemech.problems.solve.stale_factorisation`), with ``reuse_contraction`` > 0
    # the assembled Jacobian kept too while Newton contracts (modified Newton on the kept
    # factorisation); "none": a factorisation per Jacobian (or per kept Jacobian with
    # ``reuse_contraction``)
    linear_reuse: Literal["none", "krylov"] = "none"
    krylov_max_it: int = 20
    # a solve that converged in more FGMRES iterations than this refactorises before the next
    # Newton iteration's (0: only a failed one does)
    krylov_refresh_above: int = 0
    # after this many FGMRES iterations on a kept factorisation, stop and refactorise when
    # their mean contraction predicts more than ``krylov_max_it`` (0: off; the iterations
    # spent are counted)
    krylov_predict_after: int = 0
    # FGMRES's relative tolerance on ‖J δ + F‖ / ‖F‖: far below the Newton tolerance's share
    # per iteration, so that the convergence stays quadratic (tests/test_newton_krylov.py)
    krylov_rtol: float = 1e-8
    # Eisenstat–Walker's tolerance per iteration (SNES's snes_ksp_ew) instead of krylov_rtol
    krylov_ew: bool = False

    def __post_init__(self) -> None:
        if self.factorisation not in FACTORISATIONS:
            raise ParameterError("factorisation", f"{self.factorisation!r} is not one of "
                                 + ", ".join(FACTORISATIONS))
        if self.stagnation_window < 0:
            raise ParameterError("stagnation_window", f"{self.stagnation_window}: must be >= 0")
        if not self.increment_tolerance >= 0:
            raise ParameterError("increment_tolerance", f"{self.increment_tolerance}: must be >= 0")
        if not self.flat_residual_limit > 0:
            raise ParameterError("flat_residual_limit", f"{self.flat_residual_limit}: must be > 0")
        if self.reuse_creep_window < 0:
            raise ParameterError("reuse_creep_window", f"{self.reuse_creep_window}: must be >= 0")
        if not 0 < self.reuse_creep_factor < 1:
            raise ParameterError("reuse_creep_factor", f"{self.reuse_creep_factor}: a reduction "
                                 "factor in (0, 1)")
        if self.cycle_max_period < 0:
            raise ParameterError("cycle_max_period", f"{self.cycle_max_period}: must be >= 0")
        if not 0 < self.stagnation_factor < 1:
            raise ParameterError("stagnation_factor", f"{self.stagnation_factor}: a reduction "
                                 "factor in (0, 1)")
        if self.linear_reuse not in ("none", "krylov"):
            raise ParameterError("linear_reuse", f"{self.linear_reuse!r} is not one of none, krylov")
        if self.krylov_max_it < 1:
            raise ParameterError("krylov_max_it", f"{self.krylov_max_it}: must be >= 1")
        if not 0 <= self.krylov_predict_after < self.krylov_max_it:
            raise ParameterError("krylov_predict_after", f"{self.krylov_predict_after}: must be "
                                 f"in [0, krylov_max_it = {self.krylov_max_it})")
        if not 0 < self.krylov_rtol < 1:
            raise ParameterError("krylov_rtol", f"{self.krylov_rtol}: a tolerance in (0, 1)")

    def as_petsc(self, linear: dict | None = None, auto: str = "lu") -> dict[str, str]:
        """SNES options, then the KSP/PC options: MUMPS LU or LDLᵀ (``factorisation``;
        ``auto`` is what "auto" selects), or ``linear`` (an iterative solver's, see
        :mod:`~eyemech.problems.solve.linear_solvers`); ``petsc`` overrides all."""
        factorisation = auto if self.factorisation == "auto" else self.factorisation
        options = {
            "snes_type": "newtonls",
            "snes_linesearch_type": self.line_search,
            "snes_rtol": self.rtol,
            "snes_atol": self.atol,
            "snes_stol": self.stol,
            "snes_max_it": self.reuse_max_it if self.reuse_contraction > 0 else self.max_it,
            "snes_error_if_not_converged": False,
            "ksp_type": "preonly",
            "pc_type": "cholesky" if factorisation == "ldlt" else "lu",
            "pc_factor_mat_solver_type": self.linear_solver,
            # MUMPS: more working space for the indefinite saddle-point systems; its other
            # options stay MUMPS's defaults (METIS at the eye's size): no ordering, scaling or
            # block low-rank setting was faster, docs/scleral_buckling.md, "MUMPS's options
            # at the paper's resolution"
            "mat_mumps_icntl_14": 100,
        }
        if self.linear_reuse == "krylov" and linear is None:
            # the inner KSP's (stale_factorisation.py): FGMRES without restart up to max_it
            options.update({"ksp_type": "fgmres", "ksp_rtol": self.krylov_rtol,
                            "ksp_atol": 0.0, "ksp_max_it": self.krylov_max_it,
                            "ksp_gmres_restart": self.krylov_max_it,
                            "snes_ksp_ew": self.krylov_ew})
        if linear is not None:
            for key in ("pc_factor_mat_solver_type", "mat_mumps_icntl_14"):
                del options[key]
            options.update(linear)
        elif factorisation == "ldlt":
            # MUMPS LDLᵀ orders the saddle point's [u, p] pairs together (ICNTL(12) = 2, the
            # compressed ordering, which needs ICNTL(6) = 5 to find the pairs): on the sphere's
            # Q2P1 half the factor and flops of its default ordering (5.2 M against 9.0 M
            # entries), docs/atlas/peer-comparison.md, "Symmetric factorisation"
            options.update({"mat_mumps_icntl_12": 2, "mat_mumps_icntl_6": 5})
        options.update(self.petsc)
        return {k: str(v) for k, v in options.items()}


# the solvers not closed yet, by serial; held weakly (a dropped solver is freed as usual)
_OPEN_SOLVERS: weakref.WeakValueDictionary[int, Any] = weakref.WeakValueDictionary()
# the parallel solvers an open run keeps until it closes them (:func:`hold_solvers`)
_HELD_SOLVERS: dict[int, Any] = {}
_runs_holding = 0
_created = 0


def register_solver(solver: Any) -> int:
    """Note a new solver as open; its serial, the order of creation (alike on every rank)."""
    global _created
    _created += 1
    _OPEN_SOLVERS[_created] = solver
    return _created


def hold_solver(solver: Any) -> None:
    """Keep the parallel ``solver`` (registered) to the end of the open run, if a run is
    open (:func:`hold_solvers`), so that the run closes it rather than Python's collector."""
    if _runs_holding:
        _HELD_SOLVERS[solver.serial] = solver


def forget_solver(serial: int) -> None:
    """The solver ``serial`` is closed: nothing left to close at the run's end."""
    _OPEN_SOLVERS.pop(serial, None)
    _HELD_SOLVERS.pop(serial, None)


def solvers_created() -> int:
    """How many solvers this process has created (the last serial)."""
    return _created


def hold_solvers() -> int:
    """From now until the matching :func:`close_solvers`, a solver on more than one rank
    is kept when its last reference is dropped, so that the run closes it; returns
    :func:`solvers_created`.

    A parallel PETSc object that Python frees goes to PETSc's garbage on its
    communicator (petsc4py cannot destroy it at once: destroying is collective, and the
    collector frees at a different moment on each rank). Nothing cleans that garbage up,
    so it keeps its communicators for the rest of the process: a 2-rank keratotomy run,
    whose solvers are locals of a function that returns before the run ends, kept 14
    (its two solvers' matrices, vectors and MUMPS instances) and a sweep of such runs
    stopped at MPICH's limit (tests/test_solver_lifetime.py)."""
    global _runs_holding
    _runs_holding += 1
    return solvers_created()


def close_solvers(created_after: int) -> None:
    """Close every open solver created after the ``created_after``-th and end a
    :func:`hold_solvers` (collective: the same solvers on every rank of their
    communicators, see :meth:`eyemech.problems.solve.driver.NonlinearSolver.close`)."""
    global _runs_holding
    for serial in sorted(serial for serial in list(_OPEN_SOLVERS) if serial > created_after):
        solver = _OPEN_SOLVERS.get(serial)
        if solver is not None:
            solver.close()
    _runs_holding = max(0, _runs_holding - 1)
