"""The solve driver every scene uses: SNES Newton with MUMPS, timed, and a path
follower (load or time stepping) that cuts the step on divergence and grows it
after easy steps.

Design notes
- The residual and Jacobian callbacks are DOLFINx's own (the residual without lifting
  conditions the iterate already satisfies: problems/solve/residual.py); we wrap them only to
  time assembly and to let a scene add global terms (contact forces, a
  substituted cavity pressure) after the local assembly.
- A failed Newton solve restores the last converged unknowns before retrying, so
  the caller never sees a half-updated state; when cutting is exhausted
  :class:`SolveFailure` reports the step, the load and the residual history.
- Every solve counts its work (:class:`~eyemech.problems.run.results.SolverCounts`):
  Newton iterations, Jacobians, numeric and symbolic factorisations, failed attempts
  included; per solver (``counts``), per step (:class:`StepRecord`) and per process
  (``results.SOLVER_COUNTS``, which ``results.json`` reports as ``solver_counts``).
- A solver's PETSc options are in PETSc's options database, under the solver's own
  prefix, while it is set up and during each of its solves: PETSc objects read some of
  them only when a solve sets them up (MUMPS reads its ICNTLs when PCSetUp creates the
  factor matrix, at the first factorisation and again whenever the matrix pattern
  changes, e.g. when contact pairs change; a fieldsplit's inner solvers and GAMG's
  levels at their set-up). In between they are removed, so that they do not pile up over
  a study's many solvers and options an override made moot are not reported as unused.
- Fewer factorisations, each piece off by default (measured on the eye in
  docs/scleral_buckling.md, "Newton's budget"): a secant predictor per load step
  (:class:`SecantPredictor`) whose solve keeps the unpredicted start's tolerance; modified
  Newton (``NewtonOptions.reuse_contraction``: the Jacobian callback leaves the matrix as it
  is, so PCSetUp keeps the factorisation; ``reuse_step_relative`` measures the contraction
  against the line search's step length); load steps sized by the step's factorisations
  (``Stepping.effort``) and a largest step per stage (``Stepping.stage_max_steps``); a
  failed solve repeated with another line search (``NewtonOptions.fallback_line_search``:
  full steps settle a contact's kink where backtracking on ‖F‖ creeps, docs/scleral_buckling.md,
  "Which contact chatters"); the exact Jacobian every iteration solved by FGMRES on the last
  LU factorisation, refactorised only when FGMRES needs more than ``krylov_max_it``
  iterations (``NewtonOptions.linear_reuse = "krylov"``, :mod:`~eyemech.problems.solve.
  stale_factorisation`; docs/scleral_buckling.md, "Krylov on a kept factorisation").
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import time
from typing import TYPE_CHECKING, Callable, Literal, Protocol, Sequence

import dolfinx
import dolfinx.fem.petsc
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from eyemech.problems.run.faults import RAISE_ENV, plant_divergence, raise_test_error, test_raise_rank  # noqa: F401
from eyemech.problems.run.lockstep import Lockstep, all_left_with_an_error, label_code
from eyemech.problems.run.newton import (  # noqa: F401  (scenes import these from the driver)
    FACTORISATIONS,
    NewtonOptions,
    SolveFailure,
    close_solvers,
    forget_solver,
    hold_solver,
    register_solver,
    solvers_created,
)
from eyemech.problems.run.parameters import ParameterError
from eyemech.problems.run.results import (
    SOLVER_COUNTS,
    SolverCounts,
    Timings,
    record_stopping_criterion,
)
from eyemech.problems.solve.callbacks import petsc_callback
from eyemech.problems.solve.residual import Residual
from eyemech.problems.solve.stale_factorisation import StaleFactorisation
from eyemech.problems.solve.stepping import StepController

if TYPE_CHECKING:
    from eyemech.problems.run.checkpoint import Checkpoints
    from eyemech.problems.solve.augmentation import Augmentation

log = logging.getLogger("eyemech")

# PETSc log events of the factorisations, whatever preconditioner performs them (LU,
# Cholesky, ILU/ICC, a sub-solver's or a coarse grid's LU); ILU's numeric is MatLUFactorNum
NUMERIC_FACTORISATION_EVENTS = ("MatLUFactorNum", "MatCholFctrNum")
SYMBOLIC_FACTORISATION_EVENTS = ("MatLUFactorSym", "MatCholFctrSym", "MatILUFactorSym",
                                 "MatICCFactorSym")


# The log events count only while PETSc's logging is on: turned on here, at import, on
# every rank alike (the default handler's bookkeeping costs microseconds per event)
if not PETSc.Log.isActive():
    PETSc.Log.begin()


class _Problem(dolfinx.fem.petsc.NonlinearProblem):
    """DOLFINx's problem, but freeing its PETSc objects as petsc4py frees any other.

    DOLFINx's ``__del__`` destroys the SNES, matrices and vectors at once. When the
    collector frees a solver held in a cycle it does so at a different moment on each
    rank, and destroying a MUMPS factorisation is collective: on 3 ranks two waited in
    MUMPS's end while the third was in another collective call (a hang, seen in
    tests/mpi_scenes.py). Dropped without ``__del__``, the objects go to petsc4py, which
    destroys a serial object at once and parks a parallel one until PETSc's collective
    garbage clean-up. :meth:`NonlinearSolver.close` destroys them explicitly (the run
    contract calls it on every rank at the end of a run)."""

    def __del__(self) -> None:
        pass


class FactorisationCounter:
    """Numeric and symbolic factorisations PETSc has performed in this process so far,
    from its log events."""

    def __init__(self) -> None:
        self.numeric = [PETSc.Log.Event(name) for name in NUMERIC_FACTORISATION_EVENTS]
        self.symbolic = [PETSc.Log.Event(name) for name in SYMBOLIC_FACTORISATION_EVENTS]

    def __call__(self) -> tuple[int, int]:
        count = lambda events: sum(int(e.getPerfInfo()["count"]) for e in events)
        return count(self.numeric), count(self.symbolic)


ResidualHook = Callable[[PETSc.Vec, PETSc.Vec], None]
JacobianHook = Callable[[PETSc.Vec, PETSc.Mat], None]


def creeps(norms: Sequence[float], window: int, factor: float) -> bool:
    """Whether the last ``window`` iterations each lowered the residual norm but all of
    them together by less than ``factor``: linear convergence too slow to reach a Newton
    tolerance (× 0.84 per iteration or slower with a window of 4 and a factor of 0.5)."""
    if window < 1 or len(norms) < window + 1:
        return False
    last = np.asarray(norms[-window - 1:])
    return bool(np.all(np.diff(last) < 0) and last[-1] > factor * last[0])


def repeats_a_cycle(norms: Sequence[float], max_period: int, rtol: float) -> bool:
    """Whether the last residual norms repeat a cycle: for some period p in 1 … ``max_period``
    the last max(p, 2) norms each equal, to ``rtol``, the one p iterations before it. A
    converging or diverging solve changes its norm by far more than ``rtol`` between
    iterations; full Newton steps that hop between the same states revisit the same norms."""
    for period in range(1, max_period + 1):
        span = max(period, 2)
        if len(norms) < span + period:
            break
        latest = np.asarray(norms[-span:])
        earlier = np.asarray(norms[-span - period:len(norms) - period])
        if np.all(np.abs(latest - earlier) <= rtol * np.abs(earlier)):
            return True
    return False


class NonlinearSolver:
    """A residual F(u) = 0 on one function or a block of functions, solved by SNES.

    ``residual`` is a UFL form or a list of block forms (``ufl.extract_blocks``).
    Hooks run after DOLFINx has assembled the residual or the Jacobian, on the
    same vector or matrix, e.g. to add node-to-surface contact.
    ``iterative``: a Krylov solver with a block preconditioner instead of MUMPS LU
    (:class:`~eyemech.problems.solve.linear_solvers.IterativeSolver`: its ``options``,
    ``install(solver)`` after the options are set, ``update(x, A)`` after every
    Jacobian and its hooks).
    ``auto_factorisation``: "lu" or "ldlt", what ``options.factorisation = "auto"`` selects;
    "ldlt" only for a Jacobian that is symmetric (an energy's Hessian) and where LDLᵀ was
    measured faster than LU.
    """

    def __init__(self, residual, unknowns, bcs: Sequence = (), *, jacobian=None,
                 options: NewtonOptions | None = None, timings: Timings | None = None,
                 residual_hooks: Sequence[ResidualHook] = (),
                 jacobian_hooks: Sequence[JacobianHook] = (),
                 matrix_kind: str | None = None, iterative=None, auto_factorisation: str = "lu"):
        self.iterative = iterative
        self.auto_factorisation = auto_factorisation  # what options.factorisation "auto" selects
        self.options = options or NewtonOptions()
        self.timings = timings or Timings()
        self.unknowns = list(unknowns) if isinstance(unknowns, (list, tuple)) else [unknowns]
        blocked = isinstance(residual, (list, tuple))
        self.serial = register_solver(self)  # the order of creation, alike on every rank
        self.closed = False  # :meth:`close` destroyed the PETSc objects
        self.stale: StaleFactorisation | None = None
        prefix = f"eyemech{self.serial}_"
        start = time.perf_counter()
        self.problem = _Problem(
            residual, self.unknowns if blocked else self.unknowns[0], bcs=list(bcs), J=jacobian,
            petsc_options_prefix=prefix, kind=(matrix_kind or "mpi") if blocked else matrix_kind)
        if self.unknowns[0].function_space.mesh.comm.size > 1:
            hold_solver(self)
        self.timings.add("form_compilation", time.perf_counter() - start)
        self._set_up_hooks(residual_hooks, jacobian_hooks)
        self.rejected_predictions = 0  # predicted starts refused for their depth
        self.through_obstacle = False  # the last converged solve was refused for its depth
        self._jacobians = 0  # Jacobian assemblies so far
        self._jacobian_valid = False  # the matrix holds a Jacobian a next solve may keep
        self._kept_iterations = 0  # Newton iterations on a kept Jacobian, this solve
        self._reuse_enabled = True  # off for the fresh-Jacobian retry of a failed solve
        # the last iterate and the step length λ the line search took from it to x
        self._last_iterate: PETSc.Vec | None = None
        self._last_step_length = 1.0
        self._wrap_callbacks()
        self._set_options(prefix)
        if iterative is not None:
            iterative.install(self)
        if self.options.linear_reuse == "krylov":
            if iterative is not None:
                raise ParameterError("linear_reuse", "krylov keeps a direct factorisation: "
                                     "not with an iterative linear solver")
            self.stale = StaleFactorisation(self.snes.getKSP(), prefix,
                                            self.options.krylov_refresh_above,
                                            self.options.krylov_predict_after)
        self._forget_options()
        rtol, atol, stol, _max_it = self.snes.getTolerances()
        record_stopping_criterion("SNES Newton", rtol, atol, "l2 norm of the assembled residual", stol)
        self.residual_history: list[float] = []
        self.linear_iterations = 0  # Krylov iterations of the last Newton solve (all its steps)
        self.counts = SolverCounts()       # work of all solves of this solver
        self.last_counts = SolverCounts()  # work of the last solve
        self._factorisations = FactorisationCounter()
        self.stagnated = False  # the last solve was stopped by the stagnation test
        self.cycled = False     # ... by the cycle test (options.cycle_max_period)
        self.crept = False      # ... by the creep test after a kept Jacobian (options.reuse_creep_window)
        self.snes.setMonitor(petsc_callback(self._monitor))
        # Newton iterations begun: SNES calls its update at the start of every iteration,
        # the one that fails in its line search (a NaN residual) or in a callback included,
        # while its iteration number counts the completed ones only
        self._iterations_begun = 0
        self.snes.setUpdate(petsc_callback(self._begin_iteration))

    def _set_up_hooks(self, residual_hooks: Sequence[ResidualHook],
                      jacobian_hooks: Sequence[JacobianHook]) -> None:
        """The places where terms outside the forms join the solve (empty, or as given)."""
        self.residual_hooks = list(residual_hooks)
        self.jacobian_hooks = list(jacobian_hooks)
        # run with the unknowns at x before the residual and the Jacobian are assembled, and
        # after a state is restored: fields computed from the unknowns that the forms read
        # as coefficients (e.g. the condensed pressure, problems/solid/mean_dilatation.py)
        self.state_hooks: list[Callable[[], None]] = []
        # (save, restore) pairs of the hooks' memory between iterates (:meth:`save_memory`)
        self.memory_hooks: list[tuple[Callable[[], object], Callable[[object], None]]] = []
        self._start_memory: list = []
        # each returns the largest depth of a point through a rigid obstacle at the current
        # unknowns, as a fraction of the obstacle's thickness (collective; e.g.
        # forms/buckle.py's Buckle.depth_through): :func:`follow_path` refuses a predicted
        # start and a converged state that went through an obstacle (``Stepping.depth_limit``)
        self.depth_hooks: list[Callable[[], float]] = []
        # the same question asked of converged states only, not of predicted starts (e.g. a
        # deformable obstacle's, the retina through the choroid: a refused start there left
        # Newton 13-18 iterations a step and the load steps at 4e-4)
        self.converged_depth_hooks: list[Callable[[], float]] = []
        # each inserts (as zeros) the matrix entries the next solve may need beyond the
        # finite-element pattern, at the solve's start (collective; e.g. contact pairs
        # that may form in it): the pattern, and so MUMPS's symbolic analysis, then stays
        # fixed through the solve (NodeToSurfaceContact.grow_pattern)
        self.pattern_hooks: list[Callable[[PETSc.Mat], None]] = []
        # SNES's line-search pre-check (x, y) -> None, which may change the direction y
        # (the update is x − λ y) before the line search: e.g. a contact's predicted active
        # set (NodeToSurfaceContact.predict_active_set); None: none
        self.line_search_precheck: Callable[[PETSc.Vec, PETSc.Vec], None] | None = None

    def _begin_iteration(self, _snes: PETSc.SNES, _iteration: int) -> None:
        self._iterations_begun += 1

    def _monitor(self, snes: PETSc.SNES, _iteration: int, norm: float) -> None:
        """Records ‖F_k‖; stops as failed a stagnating backtracking solve
        (``options.stagnation_window``), full steps that cycle (``cycle_max_period``) and a
        modified-Newton solve that creeps after a kept Jacobian (``reuse_creep_window``). SNES
        calls the monitor after its convergence test and breaks out when a reason is set,
        so a stop costs no further Jacobian."""
        self.residual_history.append(float(norm))
        options, history = self.options, self.residual_history
        if snes.getConvergedReason() != 0:
            return
        window, line_search = options.stagnation_window, snes.getLineSearch().getType()
        if (window > 0 and len(history) > window and line_search == "bt"
                and history[-1] > options.stagnation_factor * history[-1 - window]):
            self.stagnated = True
            snes.setConvergedReason(PETSc.SNES.ConvergedReason.DIVERGED_DTOL)
        elif (options.cycle_max_period > 0 and line_search == "basic"
              and repeats_a_cycle(history, options.cycle_max_period, options.cycle_rtol)):
            self.cycled = True
            snes.setConvergedReason(PETSc.SNES.ConvergedReason.DIVERGED_DTOL)
        elif (self._kept_iterations > 0 and self._reuse_enabled and line_search != "bt"
              and creeps(history, options.reuse_creep_window, options.reuse_creep_factor)):
            self.crept = True
            snes.setConvergedReason(PETSc.SNES.ConvergedReason.DIVERGED_DTOL)

    # -- set-up -----------------------------------------------------------------
    @property
    def snes(self) -> PETSc.SNES:
        if self.closed:
            raise RuntimeError(f"solver {self.serial} is closed: its PETSc objects are destroyed")
        return self.problem.solver

    def close(self) -> None:
        """Destroy the SNES, its KSP and factorisation, and the matrices and vectors, now.

        Destroying a MUMPS factorisation is collective (MUMPS ends its instance on every
        rank together), so a parallel run must not leave it to Python's cycle collector,
        which runs at a different moment on each rank: the run contract closes a run's
        solvers as it ends, on every rank at once (:func:`close_solvers`). The solver
        cannot solve again (:attr:`snes` raises)."""
        if self.closed:
            return
        self.closed = True
        if self.stale is not None:
            self.stale.free()
        problem = getattr(self, "problem", None)  # None: its set-up failed before PETSc's objects
        if problem is None:
            forget_solver(self.serial)
            return
        for obj in (problem.solver, problem.A, problem.P_mat, problem.b, problem.x):
            if obj is not None:
                obj.destroy()
        if getattr(self, "residual_assembly", None) is not None:
            self.residual_assembly.destroy()
        forget_solver(self.serial)

    def _wrap_callbacks(self) -> None:
        b, (f_call, f_args, f_kargs) = self.snes.getFunction()
        if f_call is dolfinx.fem.petsc.assemble_residual:
            # the same residual without lifting conditions the iterate already satisfies
            self.residual_assembly = Residual()
            f_call = self.residual_assembly
        self._assemble_residual = (f_call, f_args, f_kargs)
        A, P, self._assemble_jacobian = self.snes.getJacobian()
        self._raise_on = test_raise_rank(self.unknowns[0].function_space.mesh.comm)
        self._residual_calls = 0
        self.snes.setFunction(petsc_callback(self._residual), b)
        self.snes.setJacobian(petsc_callback(self._jacobian), A, P)

    def _residual(self, snes: PETSc.SNES, x: PETSc.Vec, vec: PETSc.Vec) -> None:
        start = time.perf_counter()
        f_call, f_args, f_kargs = self._assemble_residual
        with self._remember_errors():
            self._residual_calls += 1
            if self._raise_on and self._residual_calls == 2:  # test hook (problems/run/faults.py)
                raise_test_error(snes.comm.tompi4py().rank)
            self._update_state(x)
            f_call(snes, x, vec, *(f_args or ()), **(f_kargs or {}))
            for hook in self.residual_hooks:
                hook(x, vec)
        self.timings.add("assembly", time.perf_counter() - start)

    def _jacobian(self, snes: PETSc.SNES, x: PETSc.Vec, mat: PETSc.Mat, pmat: PETSc.Mat) -> None:
        self._measure_step(snes, x)
        if self._keep_jacobian():
            # the matrix is left as it is: PCSetUp sees its state unchanged and
            # keeps the factorisation (counted by PETSc's events, not here)
            self._kept_iterations += 1
            return
        start = time.perf_counter()
        self._jacobians += 1
        self._jacobian_valid = True
        j_call, j_args, j_kargs = self._assemble_jacobian
        with self._remember_errors():
            self._update_state(x)
            j_call(snes, x, mat, pmat, *(j_args or ()), **(j_kargs or {}))
            for hook in self.jacobian_hooks:
                hook(x, mat)
            if self.iterative is not None:
                self.iterative.update(x, mat)
        self.timings.add("assembly", time.perf_counter() - start)

    def _update_state(self, x: PETSc.Vec) -> None:
        """The unknowns set to x (as DOLFINx's assembly callbacks set them), then the
        ``state_hooks``."""
        if not self.state_hooks:
            return
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        dolfinx.fem.petsc.assign(x, self.unknowns if len(self.unknowns) > 1 else self.unknowns[0])
        for u in self.unknowns:
            u.x.scatter_forward()
        for hook in self.state_hooks:
            hook()

    @contextlib.contextmanager
    def _remember_errors(self):
        """SNES turns an exception in a callback into a bare PETSc error; keep the
        original so that :meth:`solve` re-raises it (a bug is not a divergence)."""
        try:
            yield
        except Exception as err:
            if not isinstance(err, PETSc.Error):
                self._callback_error = err
            raise

    def _set_options(self, prefix: str) -> None:
        linear = None if self.iterative is None else self.iterative.options(len(self.unknowns))
        self._petsc_options = {f"{prefix}{key}": value
                               for key, value in self.options.as_petsc(
                                   linear, self.auto_factorisation).items()}
        self._insert_options()
        self.snes.setFromOptions()
        self.snes.getKSP().setFromOptions()

    def _insert_options(self) -> None:
        """Put this solver's options in PETSc's options database (under its own prefix:
        no other solver reads them)."""
        opts = PETSc.Options()
        for name, value in self._petsc_options.items():
            opts[name] = value

    def _forget_options(self) -> None:
        """Remove this solver's entries from PETSc's options database."""
        opts = PETSc.Options()
        for name in self._petsc_options:
            if opts.hasName(name):
                opts.delValue(name)

    def factor_matrix(self) -> PETSc.Mat | None:
        """The factored matrix of a direct solver's last factorisation (None before the
        first solve, or when the preconditioner does not factor)."""
        if self.closed:
            return None
        if self.stale is not None:
            return self.stale.factor_matrix()
        pc = self.snes.getKSP().getPC()
        if pc.getType() not in (PETSc.PC.Type.LU, PETSc.PC.Type.CHOLESKY):
            return None
        try:
            return pc.getFactorMatrix()
        except PETSc.Error:
            return None

    # -- state ------------------------------------------------------------------
    def save_state(self) -> list[np.ndarray]:
        return [u.x.array.copy() for u in self.unknowns]

    def save_memory(self) -> list:
        """What the hooks remember between iterates (``memory_hooks``: e.g. a contact
        search's sticky triangles), to be put back with the unknowns when a failed solve is
        repeated or its load step cut: the retry then starts where the failed attempt
        started, not where it stopped."""
        return [save() for save, _restore in self.memory_hooks]

    def restore_memory(self, saved: list) -> None:
        for (_save, restore), value in zip(self.memory_hooks, saved):
            restore(value)

    def restore_state(self, state: list[np.ndarray]) -> None:
        for u, values in zip(self.unknowns, state):
            u.x.array[:] = values
            u.x.scatter_forward()
        for hook in self.state_hooks:
            hook()

    def jacobian_nonzeros(self) -> int:
        """Nonzeros allocated in the Jacobian (global)."""
        info = self.problem.A.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)
        return int(info["nz_allocated"])

    # -- modified Newton --------------------------------------------------------
    def invalidate_jacobian(self) -> None:
        """The system changed beyond what the kept Jacobian describes (a new stage, a
        switched constraint): the next iteration assembles and factorises afresh."""
        self._jacobian_valid = False

    def _measure_step(self, snes: PETSc.SNES, x: PETSc.Vec) -> None:
        """λ of the step that led to ``x`` (iteration k ≥ 1): ‖x_k − x_k−1‖ / ‖δ_k−1‖, with
        δ the Newton direction SNES keeps as its solution update until the next linear
        solve; 1 at k = 0. Only with ``options.reuse_step_relative``."""
        if not self.options.reuse_step_relative or self.options.reuse_contraction <= 0:
            return
        if len(self.residual_history) < 2 or self._last_iterate is None:
            self._last_step_length = 1.0
        else:
            direction = snes.getSolutionUpdate().norm()
            self._last_iterate.axpy(-1.0, x)
            moved = self._last_iterate.norm()
            self._last_step_length = min(1.0, moved / direction) if direction > 0 else 1.0
        if self._last_iterate is None:
            self._last_iterate = x.duplicate()
        x.copy(self._last_iterate)

    def _keep_jacobian(self) -> bool:
        """Modified Newton's choice at the Jacobian of iteration k (``residual_history``
        holds ‖F_0‖ … ‖F_k‖ by then): at k = 0 keep the matrix if ``reuse_across_solves``
        and it is still valid (a converged solve's last Jacobian); later while the last
        iteration contracted the residual by θ = ``options.reuse_contraction`` or better
        (with ``reuse_step_relative``: by 1 − λ(1 − θ) after a step of length λ) and
        ‖F_k‖ ≤ ``reuse_below`` ‖F_0‖."""
        theta = self.options.reuse_contraction
        if theta <= 0 or not self._reuse_enabled or not self._jacobian_valid:
            return False
        history = self.residual_history
        if len(history) < 2:
            return self.options.reuse_across_solves
        contraction = 1.0 - self._last_step_length * (1.0 - theta) \
            if self.options.reuse_step_relative else theta
        return (history[-1] <= contraction * history[-2]
                and history[-1] <= self.options.reuse_below * history[0])

    def residual_norm(self) -> float:
        """‖F‖ at the current unknowns (one residual assembly, its hooks included)."""
        x = self.problem.x
        dolfinx.fem.petsc.assign(self.problem.u, x)
        b = self.snes.getFunction()[0]
        self.snes.computeFunction(x, b)
        return float(b.norm())

    def depth_through_obstacles(self, converged: bool = False) -> float:
        """The largest of ``depth_hooks``' depths at the current unknowns (−inf: none), and
        of ``converged_depth_hooks``' for a ``converged`` state."""
        hooks = self.depth_hooks + (self.converged_depth_hooks if converged else [])
        return max((float(hook()) for hook in hooks), default=-np.inf)

    def reject_last_solve(self) -> None:
        """Counts the last solve, which converged, as failed (its state went through an
        obstacle): its iterations move from ``newton_iterations`` to the failed attempts'
        (``newton_iterations_all`` keeps them), and its Jacobian is not kept."""
        work = SolverCounts(failed_newton_solves=1,
                            newton_iterations=-self.last_counts.newton_iterations)
        self.last_counts = self.last_counts + work
        self.counts.add(work)
        SOLVER_COUNTS.add(work)
        self.through_obstacle = True
        self._jacobian_valid = False

    # -- solve ------------------------------------------------------------------
    def solve(self, reference_norm: float | None = None) -> tuple[bool, int]:
        """One Newton solve from the current unknowns; (converged, iterations).

        ``reference_norm``: converge at ‖F‖ ≤ rtol · reference_norm (the residual the
        reference method would start from, e.g. before a predictor moved the unknowns)
        rather than rtol · ‖F_0‖; a predicted start is not held to a tighter tolerance.
        With modified Newton (``options.reuse_contraction``), a solve that fails after
        keeping a Jacobian is repeated once from the same start with fresh Jacobians
        (both attempts counted); one that still fails, once more with
        ``options.fallback_line_search`` if given (counted too)."""
        retries = self.options.reuse_contraction > 0 or self.options.fallback_line_search
        start_state = self.save_state() if retries else None
        self._start_memory = self.save_memory() if retries else []
        converged, iterations = self._solve_once(reference_norm)
        if not converged and self._kept_iterations and start_state is not None:
            log.info("modified Newton failed (%s) after %d kept Jacobians, residuals %s: "
                     "fresh Jacobians", self.reason(), self._kept_iterations,
                     " ".join(f"{r:.2e}" for r in self.residual_history))
            self.restore_state(start_state)
            self.restore_memory(self._start_memory)
            self._jacobian_valid = False
            self._reuse_enabled = False
            try:
                converged, iterations = self._solve_once(reference_norm)
            finally:
                self._reuse_enabled = True
        if not converged and start_state is not None:
            converged, iterations = self._retry_with_fallback(start_state, reference_norm)
        if not converged:
            self._jacobian_valid = False
        return converged, iterations

    def _retry_with_fallback(self, start_state: list[np.ndarray],
                             reference_norm: float | None) -> tuple[bool, int]:
        """The failed solve once more from ``start_state`` with
        ``options.fallback_line_search`` and fresh Jacobians (counted as its own solve)."""
        line_search = self.snes.getLineSearch()
        fallback, current = self.options.fallback_line_search, line_search.getType()
        if not fallback or fallback == current:
            return False, self.snes.getIterationNumber()
        if self.options.cut_on_nan and current == "basic" and self.diverged_to_nan():
            log.info("Newton with full steps failed (%s), residuals %s: the load step is cut "
                     "(cut_on_nan)", self.reason(),
                     " ".join(f"{r:.2e}" for r in self.residual_history))
            return False, self.snes.getIterationNumber()
        log.info("Newton with line search %s failed (%s), residuals %s: again with %s", current,
                 self.reason(), " ".join(f"{r:.2e}" for r in self.residual_history), fallback)
        self.restore_state(start_state)
        self.restore_memory(self._start_memory)
        self._jacobian_valid = False
        line_search.setType(fallback)
        try:
            return self._solve_once(reference_norm)
        finally:
            line_search.setType(current)

    def _solve_once(self, reference_norm: float | None) -> tuple[bool, int]:
        """One SNES solve; its work, converged or not, is added to ``counts`` and to the
        process's ``SOLVER_COUNTS``."""
        self.residual_history = []
        self.stagnated = self.cycled = self.crept = False
        self.through_obstacle = False
        self._kept_iterations = 0
        self._iterations_begun = 0
        self.flat_acceptance: tuple[float, float] | None = None
        start = time.perf_counter()
        assembly_before = self.timings.seconds["assembly"]
        self._callback_error = None
        numeric_before, symbolic_before = self._factorisations()
        jacobians_before = self._jacobians
        mallocs_before = self._matrix_mallocs()
        for hook in self.pattern_hooks:
            hook(self.problem.A)
        if self.line_search_precheck is not None:
            # installed at every solve, whatever a stage's Newton settings did to the line
            # search between solves (cheap: a pointer)
            self.snes.setLineSearchPreCheck(self.line_search_precheck)
        converged = False
        # PCSetUp reads the factor matrix's options (MUMPS ICNTLs) inside the solve
        self._insert_options()
        rtol, atol, stol, max_it = self.snes.getTolerances()
        if reference_norm is not None:
            self.snes.setTolerances(atol=max(atol, rtol * reference_norm))
        raising = True  # an error leaves this solve (possibly on this rank only)
        try:
            self.problem.solve()
            reason = self.snes.getConvergedReason()
            converged = reason > 0 and all(np.isfinite(self.residual_history))
            if not converged and self.options.increment_tolerance > 0:
                converged = self._accept_flat_residual()
            raising = False
        except PETSc.Error:  # e.g. a zero pivot from an inverted element
            if self._callback_error is not None:
                raise self._callback_error from None
            # cut the step only when every rank left the solve with the error (the
            # others could still be inside SNES's collective calls)
            all_left_with_an_error(self.snes.comm.tompi4py(), "a Newton solve")
            raising = False
        finally:
            self.snes.setTolerances(atol=atol)
            self._forget_options()
            self._tally(converged, numeric_before, symbolic_before, jacobians_before,
                        None if raising else mallocs_before)
        elapsed = time.perf_counter() - start
        # assembly inside SNES is timed by the callbacks; "solve" is the rest
        # (factorisation, triangular solves, line search bookkeeping)
        assembly = self.timings.seconds["assembly"] - assembly_before
        self.timings.add("solve", elapsed - assembly)
        iterations = self.snes.getIterationNumber()
        self.linear_iterations = self.snes.getLinearSolveIterations()
        return converged, iterations

    def _accept_flat_residual(self) -> bool:
        """Whether the unconverged solve's last iterate is accepted as converged
        (``options.increment_tolerance``): its residual finite and at most
        ``options.flat_residual_limit``, and the full Newton correction there, from a fresh
        Jacobian (one more assembly and factorisation, counted with the solve), moving no
        component of the first unknown by more than ``options.increment_tolerance``. Sets
        ``flat_acceptance`` to (‖F‖, the largest such component). Collective."""
        snes, options = self.snes, self.options
        if self.diverged_to_nan():
            return False
        x, residual = self.problem.x, self.problem.b
        snes.computeFunction(x, residual)
        norm = residual.norm()
        if not np.isfinite(norm) or norm > options.flat_residual_limit:
            return False
        jacobian, preconditioner, _ = snes.getJacobian()
        self._iterations_begun += 1  # a Newton linearisation (Jacobian, factorisation, solve)
        self._reuse_enabled = False
        try:
            snes.computeJacobian(x, jacobian, preconditioner)
        finally:
            self._reuse_enabled = True
        correction = x.duplicate()
        try:
            snes.getKSP().solve(residual, correction)
            if self.line_search_precheck is not None:  # e.g. the contact's predicted active set
                self.line_search_precheck(x, correction)
            parts = [dolfinx.fem.Function(u.function_space) for u in self.unknowns]
            dolfinx.fem.petsc.assign(correction, parts if len(parts) > 1 else parts[0])
        finally:
            correction.destroy()
        first = parts[0]
        owned = first.function_space.dofmap.index_map.size_local * first.function_space.dofmap.index_map_bs
        largest = float(np.max(np.abs(first.x.array[:owned]), initial=0.0))
        largest = first.function_space.mesh.comm.allreduce(largest, op=MPI.MAX)
        if not largest <= options.increment_tolerance:
            log.info("a flat residual %.3e not accepted: Newton's correction moves %.3e > %.3e",
                     norm, largest, options.increment_tolerance)
            return False
        log.info("a flat residual %.3e (%s) accepted: Newton's correction there moves at most "
                 "%.3e <= %.3e", norm, self.reason(), largest, options.increment_tolerance)
        self.flat_acceptance = (float(norm), largest)
        return True

    def _tally(self, converged: bool, numeric_before: int, symbolic_before: int,
               jacobians_before: int, mallocs_before: int | None) -> None:
        """The last solve's work, also when it raised (a callback's error included).
        ``mallocs_before`` None: an error is leaving the solve, maybe on this rank alone,
        so the reallocations (a reduction over the ranks) are not counted: a collective
        call here would wait for ranks that are still inside SNES (tests/test_faults.py)."""
        numeric, symbolic = self._factorisations()
        iterations = self.snes.getIterationNumber()
        work = SolverCounts(newton_solves=1, failed_newton_solves=0 if converged else 1,
                            newton_iterations=iterations if converged else 0,
                            newton_iterations_all=max(iterations, self._iterations_begun),
                            jacobians=self._jacobians - jacobians_before,
                            factorisations=numeric - numeric_before,
                            symbolic_factorisations=symbolic - symbolic_before,
                            krylov_iterations=self._krylov_iterations(),
                            matrix_mallocs=0 if mallocs_before is None
                            else self._matrix_mallocs() - mallocs_before,
                            flat_residual_acceptances=int(self.flat_acceptance is not None))
        self.last_counts = work
        self.counts.add(work)
        SOLVER_COUNTS.add(work)

    def _matrix_mallocs(self) -> int:
        """Reallocations of the Jacobian's storage so far, all ranks (collective)."""
        matrix = self.snes.getJacobian()[0]
        return int(matrix.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["mallocs"])

    def _krylov_iterations(self) -> int:
        """Krylov iterations of the last SNES solve, failed ones included (0 for a direct
        solve: preonly's one application per Newton iteration is no Krylov iteration)."""
        if self.stale is None and self.iterative is None:
            return 0
        return int(self.snes.getLinearSolveIterations())

    def diverged_to_nan(self) -> bool:
        """The last solve failed because a residual was NaN or inf (SNES's
        DIVERGED_FUNCTION_NANORINF, or a non-finite norm in ``residual_history``)."""
        local = (self.snes.getConvergedReason() == PETSc.SNES.ConvergedReason.DIVERGED_FUNCTION_NANORINF
                 or not all(np.isfinite(self.residual_history)))
        # one answer on all ranks: the retry that follows, or not, is collective
        return bool(self.snes.comm.tompi4py().allreduce(local, op=MPI.LOR))

    def reason(self) -> str:
        if self.stagnated:
            return "STAGNATED (stagnation_window)"
        if self.cycled:
            return "CYCLED (cycle_max_period)"
        if self.crept:
            return "CREPT (reuse_creep_window)"
        if self.through_obstacle:
            return "THROUGH_OBSTACLE (depth_limit)"
        code = self.snes.getConvergedReason()
        names = {v: k for k, v in vars(PETSc.SNES.ConvergedReason).items() if isinstance(v, int)}
        return names.get(code, str(code))


@dataclasses.dataclass
class Stepping:
    """Path following from ``start`` to ``end`` (a load factor or a time)."""

    start: float = 0.0
    end: float = 1.0
    initial_step: float = 0.25
    min_step: float = 1e-4
    max_step: float = 1.0
    grow: float = 1.5
    easy_iterations: int = 6
    max_cuts: int = 10
    # a converged step whose effort exceeds ``hard_iterations`` shrinks the next increment
    # by ``shrink`` (None: only a failed solve cuts it); the effort that ``easy_iterations``
    # and ``hard_iterations`` bound is the step's Newton iterations, or its numeric
    # factorisations, failed attempts included (``effort="factorisations"``: with modified
    # Newton an iteration on a kept factorisation costs a residual and a back-substitution)
    hard_iterations: int | None = None
    shrink: float = 0.5
    effort: Literal["iterations", "factorisations"] = "iterations"
    # start each load step from a prediction: "secant" extrapolates the last two converged
    # states of the stage linearly in the path value ("none": from the last converged state)
    predictor: Literal["none", "secant"] = "none"
    stops: tuple[float, ...] = ()  # values the path must land on exactly (outputs, stages)
    stage_names: tuple[str, ...] = ()  # the stages' names, in order (progress lines, bar)
    # the largest step of each stage (the intervals between the stops, in order), as a
    # fraction of the span like max_step; () = max_step everywhere
    stage_max_steps: tuple[float, ...] = ()
    # whether each stage's load steps start from the predictor (in order; () = all of them):
    # a stage whose secant was measured to start farther from the solution than no
    # prediction opts out
    stage_predicts: tuple[bool, ...] = ()
    # what the path value is, for the failure message: "load factor", "time" (unit "s"),
    # "depth" ("mm"); None: "load factor" on the default path 0 -> 1, else "path value"
    quantity: str | None = None
    unit: str = ""
    # a point deeper through a rigid obstacle than this fraction of its thickness
    # (NonlinearSolver.depth_hooks): a predicted start is refused (the step starts
    # unpredicted), a converged state is refused (the step is cut). Half: a point in
    # contact is beyond the contact face only by the penalty's penetration, hundredths of
    # a mm; one beyond the far face (fraction > 1) is pushed by the penalty no more
    # (docs/scleral_buckling.md, "Newton's budget")
    depth_limit: float = 0.5

    def describe(self) -> tuple[str, str]:
        if self.quantity is not None:
            return self.quantity, self.unit
        if (self.start, self.end) == (0.0, 1.0):
            return "load factor", self.unit
        return "path value", self.unit

    def effort_of(self, record: "StepRecord") -> int:
        return record.factorisations if self.effort == "factorisations" else record.iterations

    def largest_step(self, value: float) -> float:
        """max_step, or the stage's own, for the step that starts at ``value``."""
        if not self.stage_max_steps:
            return self.max_step
        return self.stage_max_steps[min(self._stage(value), len(self.stage_max_steps) - 1)]

    def _stage(self, value: float) -> int:
        """Index of the stage (interval between the stops) a step starting at ``value`` is in."""
        span = self.end - self.start
        return sum(1 for s in sorted(self.stops) if s <= value + 1e-12 * span)

    def predicts(self, value: float) -> bool:
        """Whether the step that starts at ``value`` starts from the predictor."""
        if not self.stage_predicts:
            return True
        return self.stage_predicts[min(self._stage(value), len(self.stage_predicts) - 1)]

    def first_step(self, value: float) -> float:
        """A stage's first step: ``initial_step``, within the stage's own largest step
        when ``stage_max_steps`` gives one (otherwise as given, even above max_step)."""
        if not self.stage_max_steps:
            return self.initial_step
        return min(self.initial_step, self.largest_step(value))

    def controller(self) -> StepController:
        """The step controller of this path, its lengths in the path's unit, at the first
        step."""
        span = self.end - self.start
        return StepController(self.first_step(self.start) * span, largest=self.max_step * span,
                              smallest=self.min_step * span, max_cuts=self.max_cuts,
                              grow_factor=self.grow, easy_effort=self.easy_iterations,
                              hard_effort=self.hard_iterations, shrink_factor=self.shrink)

    def accept(self, controller: StepController, record: "StepRecord", value: float) -> None:
        """The controller told that the step ``record`` converged at ``value``: the next
        step grown after an easy step (no cut), shrunk after a hard one, within
        [min_step, largest_step] (the largest of the stage the next step is in)."""
        controller.largest = self.largest_step(value) * (self.end - self.start)
        controller.accept(self.effort_of(record))
        if self.stage_max_steps:
            # a stage of its own limit (the next one, at a stop) caps what was carried over
            controller.limit(controller.largest)

    def next_increment(self, increment: float, record: "StepRecord", value: float) -> float:
        """The increment after a converged step of length ``increment`` that ended at
        ``value`` (:meth:`accept` on a controller at that step)."""
        controller = self.controller()
        controller.step, controller.cuts = increment, record.cuts
        self.accept(controller, record, value)
        return controller.step


@dataclasses.dataclass
class StepRecord:
    step: int
    load: float
    increment: float
    iterations: int  # Newton iterations of the converged solve
    cuts: int
    residuals: list[float]
    linear_iterations: int = 0  # Krylov iterations of the converged solve
    # the step's whole work, its failed (cut) attempts included
    attempts: int = 1                 # Newton solves: cuts + 1
    iterations_all: int = 0           # Newton iterations of all attempts
    jacobians: int = 0                # Jacobian assemblies
    factorisations: int = 0           # numeric factorisations
    symbolic_factorisations: int = 0  # symbolic analyses
    krylov_iterations_all: int = 0    # Krylov iterations of all attempts (0: direct solve)
    matrix_mallocs: int = 0           # reallocations of the Jacobian's storage
    augmentations: int = 0            # Newton solves after a multiplier update, all attempts
    flat_residual_acceptances: int = 0  # solves accepted by their Newton correction

    @staticmethod
    def work(counts: SolverCounts) -> dict[str, int]:
        """The fields above from the solver's counts over the step's attempts."""
        return {"attempts": counts.newton_solves, "iterations_all": counts.newton_iterations_all,
                "jacobians": counts.jacobians, "factorisations": counts.factorisations,
                "symbolic_factorisations": counts.symbolic_factorisations,
                "krylov_iterations_all": counts.krylov_iterations,
                "matrix_mallocs": counts.matrix_mallocs,
                "flat_residual_acceptances": counts.flat_residual_acceptances}

    def with_work(self, counts: SolverCounts) -> "StepRecord":
        """This record with more work of the step added (solves after its converged one:
        the attempts, iterations, Jacobians, factorisations they took)."""
        extra = StepRecord.work(counts)
        return dataclasses.replace(
            self, attempts=self.attempts + extra["attempts"],
            iterations_all=self.iterations_all + extra["iterations_all"],
            **{key: getattr(self, key) + extra[key]
               for key in ("jacobians", "factorisations", "symbolic_factorisations",
                           "krylov_iterations_all", "matrix_mallocs", "flat_residual_acceptances")})

    def counts(self) -> dict[str, int]:
        """The step's work under the names of ``results.json``'s step records:
        ``ctx.record_step(..., **record.counts())``."""
        return {"attempts": self.attempts, "newton_iterations_all": self.iterations_all,
                "jacobians": self.jacobians, "factorisations": self.factorisations,
                "symbolic_factorisations": self.symbolic_factorisations,
                "krylov_iterations_all": self.krylov_iterations_all,
                "matrix_mallocs": self.matrix_mallocs, "augmentations": self.augmentations,
                "flat_residual_acceptances": self.flat_residual_acceptances}


def follow_path(solver: NonlinearSolver, apply: Callable[[float, float], None],
                stepping: Stepping, *, on_converged: Callable[[StepRecord], None] | None = None,
                label: str = "", quiet: bool = False,
                checkpoints: "Checkpoints | None" = None,
                predictor: SecantPredictor | None = None,
                augmentation: "Augmentation | None" = None) -> list[StepRecord]:
    """Solve along the path: ``apply(value, increment)`` sets loads (or time) for the
    target value, Newton solves, and ``on_converged`` records and updates history
    variables. A failed solve restores the last converged state and cuts the step
    (:class:`~eyemech.problems.solve.stepping.StepController`); easy solves grow it.

    With ``checkpoints`` (``ctx.checkpoints``) a checkpoint is written after a step when
    due, SIGINT/SIGTERM stop the run after the current step (raising ``Interrupted``),
    and a resumed run skips the paths finished before its checkpoint and continues the
    path it is in. ``apply`` must then depend on its arguments only (it is called again
    with the checkpoint's value); any other state must be registered with the
    checkpoints, the predictor's too (``stepping.predictor = "secant"``: pass a
    :class:`SecantPredictor` registered with them; one made here starts a resumed path
    without a secant).

    The predictor (``stepping.predictor``) moves the unknowns before each attempt; its
    solve then converges at ‖F‖ ≤ rtol ‖F(u_n, target)‖, the residual the unpredicted
    start has (:meth:`NonlinearSolver.solve`'s ``reference_norm``).

    ``augmentation`` (augmented Lagrangian contact, :mod:`~eyemech.problems.solve.augmentation`):
    a step that converged where ``augmentation.due`` says is solved again with updated
    contact multipliers until they settle; those solves are the step's work (counted in
    its record, ``augmentations``), and a failed one cuts the step."""
    walk = _Walk(solver, stepping, label=label, quiet=quiet, checkpoints=checkpoints,
                 predictor=predictor, augmentation=augmentation)
    return walk.run(apply, on_converged)


@dataclasses.dataclass(frozen=True)
class NewtonSettings:
    """What a stage changes of its solver's Newton options for its own solves; None keeps
    the solver's as it was built (a stage's settings do not carry over to the next).
    A line search given with ``--petsc snes_linesearch_type=...`` wins over every stage's."""

    line_search: str | None = None           # basic | bt | cp | l2 | nleqerr
    fallback_line_search: str | None = None  # NewtonOptions.fallback_line_search
    stagnation_window: int | None = None     # NewtonOptions.stagnation_window
    reuse_step_relative: bool | None = None  # NewtonOptions.reuse_step_relative

    @staticmethod
    def of(solver: NonlinearSolver) -> "NewtonSettings":
        """The solver's current settings."""
        options = solver.options
        return NewtonSettings(solver.snes.getLineSearch().getType(), options.fallback_line_search,
                              options.stagnation_window, options.reuse_step_relative)

    def apply(self, solver: NonlinearSolver, built: "NewtonSettings") -> None:
        """Set these on ``solver``, ``built``'s where these say None."""
        def pick(name: str):
            mine = getattr(self, name)
            return getattr(built, name) if mine is None else mine

        if "snes_linesearch_type" not in solver.options.petsc:
            solver.snes.getLineSearch().setType(pick("line_search"))
        solver.options.fallback_line_search = pick("fallback_line_search")
        solver.options.stagnation_window = pick("stagnation_window")
        solver.options.reuse_step_relative = pick("reuse_step_relative")


class PathStage(Protocol):
    """One stage of an operation as :func:`follow_stages` walks it: one unit of the path,
    its own controls, step sizes and Newton settings."""

    name: str
    largest_step: float       # the largest load step, as a fraction of the stage
    predicts: bool            # whether its load steps start from the predictor
    newton: NewtonSettings    # set when the stage starts, and when a run resumes in it

    def begin(self) -> None:
        """Switches as the stage starts (once: a run resumed inside the stage has their
        effect from its checkpoint)."""

    def apply(self, fraction: float) -> None:
        """The controls at ``fraction`` ∈ [0, 1] of the stage, before an attempt."""

    def finish(self) -> None:
        """After the stage's last step converged, before it is recorded (its solves, if
        any, are counted with that step)."""


def follow_stages(solver: NonlinearSolver, stages: Sequence[PathStage], stepping: Stepping, *,
                  on_converged: Callable[[StepRecord, PathStage, bool], None] | None = None,
                  label: str = "", quiet: bool = False,
                  checkpoints: "Checkpoints | None" = None,
                  predictor: SecantPredictor | None = None,
                  augmentation: "Augmentation | None" = None) -> list[StepRecord]:
    """Follow an operation made of ``stages``, one after another: stage k (from 0) covers
    the path values [k, k + 1], its load steps as long as its ``largest_step`` allows,
    started from the predictor where it ``predicts``, solved with its ``newton``
    settings; :meth:`PathStage.begin` as it starts, :meth:`PathStage.finish` after its
    last step. ``stepping``'s ``initial_step`` (each stage's first step at most) and
    ``min_step`` are fractions of one stage; its growth and effort rules apply to every
    stage. ``on_converged(record, stage, ends)``: after each converged step, ``ends`` when
    it ends its stage. Checkpoints, predictor and augmentation as in :func:`follow_path`."""
    count = len(stages)
    span = float(count)
    path = dataclasses.replace(
        stepping, start=0.0, end=span, stops=tuple(float(k) for k in range(1, count + 1)),
        initial_step=stepping.initial_step / span, min_step=stepping.min_step / span,
        max_step=max(s.largest_step for s in stages) / span,
        stage_max_steps=tuple(s.largest_step / span for s in stages),
        stage_predicts=tuple(s.predicts for s in stages), stage_names=tuple(s.name for s in stages))
    walk = _Walk(solver, path, label=label, quiet=quiet, checkpoints=checkpoints,
                 predictor=predictor, augmentation=augmentation, stages=stages)

    def apply(value: float, _increment: float) -> None:
        index = walk.stage_index
        stages[index].apply(min(max(value - index, 0.0), 1.0))

    def converged(record: StepRecord) -> None:
        if on_converged is not None:
            on_converged(record, stages[walk.stage_index], walk.at_stop(record.load))

    return walk.run(apply, converged)


class _Walk:
    """One walk along a path: :func:`follow_path`'s and :func:`follow_stages`' loop."""

    def __init__(self, solver: NonlinearSolver, stepping: Stepping, *, label: str, quiet: bool,
                 checkpoints: "Checkpoints | None", predictor: SecantPredictor | None,
                 augmentation: "Augmentation | None",
                 stages: Sequence[PathStage] | None = None):
        span = stepping.end - stepping.start
        if span <= 0:
            raise ValueError("stepping.end must be greater than stepping.start")
        self.solver, self.stepping, self.span = solver, stepping, span
        self.label, self.quiet, self.checkpoints = label, quiet, checkpoints
        self.augmentation, self.stages = augmentation, stages
        self.stops = sorted(s for s in set(stepping.stops) | {stepping.end}
                            if stepping.start < s <= stepping.end)
        self.controller = stepping.controller()
        if stepping.predictor == "none":
            predictor = None
        elif predictor is None:
            predictor = SecantPredictor(solver)
        self.predictor = predictor
        self.built = NewtonSettings.of(solver) if stages is not None else None
        self.value, self.step = stepping.start, 0
        self.records: list[StepRecord] = []
        self.stage_index = 0
        self.lockstep: Lockstep | None = None

    def at_stop(self, value: float) -> bool:
        return any(abs(value - s) <= 1e-12 * self.span for s in self.stops)

    def run(self, apply: Callable[[float, float], None],
            on_converged: Callable[[StepRecord], None] | None) -> list[StepRecord]:
        stepping, checkpoints = self.stepping, self.checkpoints
        resumed = checkpoints.enter_path(self.label) if checkpoints is not None else None
        if resumed is not None and "skip" in resumed:  # finished before the checkpoint
            self.records = [StepRecord(**r) for r in resumed["skip"]]
            self._enter_stage(stepping.end, fresh=False)
            apply(stepping.end, self.records[-1].increment if self.records else 0.0)
            checkpoints.leave_path([dataclasses.asdict(r) for r in self.records])
            return self.records
        if resumed is not None:
            self.value, self.controller.step = resumed["value"], resumed["increment"]
            self.step = resumed["step"]
            self.records = [StepRecord(**r) for r in resumed["records"]]
            self._enter_stage(self.value, fresh=False)
            apply(self.value, self.records[-1].increment if self.records else 0.0)
        else:
            self._enter_stage(self.value, fresh=True)
            if self.predictor is not None:
                self.predictor.restart(self.value)
        self.bar = _progress(self.solver, self.label, self.quiet, self.stepping, self.records)
        # a run with checkpoints checks that its ranks are in step at each step's end
        # (Checkpoints.step_done); a walk without them checks it here
        comm = self.solver.unknowns[0].function_space.mesh.comm
        self.lockstep = Lockstep(comm) if checkpoints is None and comm.size > 1 else None
        try:
            while self.value < stepping.end - 1e-12 * self.span:
                self._next_step(apply, on_converged)
        finally:
            self.bar.close()
            if self.lockstep is not None:
                self.lockstep.free()
        if checkpoints is not None:
            checkpoints.leave_path([dataclasses.asdict(r) for r in self.records])
        return self.records

    def _enter_stage(self, value: float, fresh: bool) -> None:
        """The stage the steps from ``value`` are in: its Newton settings, and on a fresh
        entry its switches."""
        if self.stages is None:
            return
        self.stage_index = min(self.stepping._stage(value), len(self.stages) - 1)
        stage = self.stages[self.stage_index]
        stage.newton.apply(self.solver, self.built)
        if fresh:
            stage.begin()

    def _next_step(self, apply, on_converged) -> None:
        """One load step: attempts until one converges (cuts between them), then the
        bookkeeping of a converged step."""
        solver, stepping = self.solver, self.stepping
        self.step += 1
        state, memory = solver.save_state(), solver.save_memory()
        counts_before = solver.counts.copy()
        if self.checkpoints is not None:
            self.checkpoints.watch_step(solver)
        while True:
            next_stop = next(s for s in self.stops if s > self.value + 1e-12 * self.span)
            target = self.controller.target(self.value, next_stop)
            apply(target, target - self.value)
            converged, iterations, augmented = self._attempt(target, state)
            if converged:
                break
            history = list(solver.residual_history)
            log.info("step %d: no convergence at %.6g (%s), cutting", self.step, target,
                     solver.reason())
            solver.restore_state(state)
            solver.restore_memory(memory)
            if not self.controller.cut():
                apply(self.value, 0.0)
                raise SolveFailure(self.step, target, self.value, history, solver.reason(),
                                   *stepping.describe(),
                                   failed_step=self._failed_step(target, counts_before, history))
        record = StepRecord(self.step, target, target - self.value, iterations,
                            self.controller.cuts, list(solver.residual_history),
                            solver.linear_iterations,
                            **StepRecord.work(solver.counts - counts_before),
                            augmentations=augmented)
        sized = record  # the next step is sized by the step's own work
        if self.stages is not None and self.at_stop(target):
            # the stage's closing work (e.g. solves to an equilibrium) is counted with its
            # last step, whose converged solve the record still describes
            finishing = solver.counts.copy()
            self.stages[self.stage_index].finish()
            record = record.with_work(solver.counts - finishing)
        self._converged(record, sized, state, on_converged)

    def _failed_step(self, target: float, counts_before: SolverCounts,
                     history: list[float]) -> dict:
        """The step whose cuts are exhausted, as ``results.json`` records a step: every
        attempt failed (``newton_iterations`` 0, ``cuts`` the failed attempts), its work
        counted as a converged step's, the residuals of its last attempt."""
        solver = self.solver
        record = StepRecord(self.step, target, target - self.value, 0, self.controller.cuts,
                            history, solver.linear_iterations,
                            **StepRecord.work(solver.counts - counts_before))
        stage = {} if self.stages is None else {"stage": self.stage_index + 1}
        return {"step": record.step, "load": record.load, **stage, "status": "failed",
                "newton_iterations": 0, "cuts": record.cuts, **record.counts(),
                "krylov_iterations": record.linear_iterations, "residuals": record.residuals}

    def _attempt(self, target: float, state: list[np.ndarray]) -> tuple[bool, int, int]:
        """One attempt at ``target`` from ``state``: the predictor's start, Newton, the
        multipliers' updates, the obstacle's depth check. (converged, iterations,
        augmentations)."""
        solver, stepping, predictor = self.solver, self.stepping, self.predictor
        reference = None
        if predictor is not None and predictor.ready and stepping.predicts(self.value):
            # the tolerance of a start without prediction: ‖F‖ ≤ rtol ‖F(u_n, target)‖
            reference = solver.residual_norm()
            reference = _predict(solver, predictor, target, state, stepping.depth_limit, reference)
        converged, iterations = solver.solve(reference) if reference is not None \
            else solver.solve()
        augmented = 0
        if converged and self.augmentation is not None and self.augmentation.due(target):
            converged, iterations, augmented = self.augmentation.run(solver, iterations)
        if converged and (solver.depth_hooks or solver.converged_depth_hooks):
            depth = solver.depth_through_obstacles(converged=True)
            if depth > stepping.depth_limit:
                log.info("step %d: converged at %.6g with a point %.2f of an obstacle's "
                         "thickness through it, cutting", self.step, target, depth)
                solver.reject_last_solve()
                converged = False
        return converged, iterations, augmented

    def _converged(self, record: StepRecord, sized: StepRecord, state: list[np.ndarray],
                   on_converged: Callable[[StepRecord], None] | None) -> None:
        """A converged step: recorded, the next step sized, a stop's new stage entered,
        a checkpoint written when due."""
        stepping, solver, predictor = self.stepping, self.solver, self.predictor
        self.value = record.load
        self.records.append(record)
        if on_converged is not None:
            on_converged(record)
        self.bar.update((record.load - stepping.start) / self.span - self.bar.n)
        stepping.accept(self.controller, sized, self.value)
        if predictor is not None:
            predictor.converged(self.value, state)
        if self.at_stop(record.load):
            # a new stage (or output interval) starts: its difficulty is not the last one's,
            # its path not the last one's continuation, its system perhaps not the last one's
            # (on_converged may switch terms on): no secant across it, no kept Jacobian
            self.controller.at_least(stepping.first_step(self.value) * self.span)
            solver.invalidate_jacobian()
            if predictor is not None:
                predictor.restart(self.value)
            if self.value < stepping.end - 1e-12 * self.span:
                self._enter_stage(self.value, fresh=True)
        if self.checkpoints is not None:
            self.checkpoints.step_done({"label": self.label, "step": self.step, "value": self.value,
                                        "increment": self.controller.step,
                                        "records": [dataclasses.asdict(r) for r in self.records]})
        elif self.lockstep is not None:
            decision = [0.0, label_code(self.label), float(self.step), float(self.step),
                        self.value, self.controller.step, float(record.iterations),
                        float(record.cuts)]
            plant_divergence(self.solver.unknowns[0].function_space.mesh.comm, self.step, decision)
            self.lockstep.check(f"the end of step {self.step} (path '{self.label}')",
                                tuple(decision))


def _predict(solver: NonlinearSolver, predictor: "SecantPredictor", target: float,
             state: list[np.ndarray], depth_limit: float, reference: float) -> float | None:
    """Moves the unknowns to the predictor's start; one whose point lies deeper through an
    obstacle than ``depth_limit`` of its thickness is refused (counted in
    ``solver.rejected_predictions``) and the unknowns put back: Newton from there may
    converge on the obstacle's far side. The reference residual, None when refused."""
    unpredicted = solver.save_state() if solver.depth_hooks else None
    predictor.predict(target, state)
    if unpredicted is None:
        return reference
    depth = solver.depth_through_obstacles()
    if depth <= depth_limit:
        return reference
    log.info("the predicted start at %.6g puts a point %.2f of an obstacle's thickness "
             "through it: starting unpredicted", target, depth)
    solver.restore_state(unpredicted)
    solver.rejected_predictions += 1
    return None


class SecantPredictor:
    """u(s) ≈ u_n + (s − s_n)/(s_n − s_n−1) · (u_n − u_n−1): the line through the last
    two converged states of the current stage, evaluated at the target.

    u_n is the solver's unknowns at the step's start; u_n−1 is kept in Functions of the
    unknowns' spaces, so that :meth:`register` can put it in a checkpoint and a resumed
    run predicts its first step as the uninterrupted run did."""

    def __init__(self, solver: NonlinearSolver) -> None:
        self.solver = solver
        self.previous = [dolfinx.fem.Function(u.function_space) for u in solver.unknowns]
        self.values = [float("nan"), float("nan")]  # s_n−1 (nan: none in this stage), s_n

    def register(self, checkpoints: "Checkpoints", name: str = "predictor") -> None:
        for i, f in enumerate(self.previous):
            checkpoints.function(f"{name}_{i}", f)
        checkpoints.value(f"{name}_values", lambda: list(self.values),
                          lambda saved: setattr(self, "values", [float(v) for v in saved]))

    @property
    def ready(self) -> bool:
        return bool(np.isfinite(self.values).all())

    def converged(self, value: float, state: list[np.ndarray]) -> None:
        """A step converged at ``value``; ``state``: the unknowns at its start (u_n−1)."""
        for f, values in zip(self.previous, state):
            f.x.array[:] = values
        self.values = [self.values[1], value]

    def restart(self, value: float) -> None:
        """A new stage starts at ``value``: no secant across its start."""
        self.values = [float("nan"), value]

    def predict(self, target: float, start: list[np.ndarray]) -> None:
        """Moves the unknowns to the secant's value at ``target``. ``start`` is u_n as the
        step began, before ``apply`` set the load: an ``apply`` that also moves an unknown
        to its prescribed value (the eye's pinned tire travel) would otherwise be
        extrapolated once more from there (an overshoot of one step)."""
        (s0, s1), x1 = self.values, start
        factor = (target - s1) / (s1 - s0)
        self.solver.restore_state([b + factor * (b - a.x.array)
                                   for a, b in zip(self.previous, x1)])


def _progress(solver: NonlinearSolver, label: str, quiet: bool, stepping: Stepping,
              records: list[StepRecord]):
    """The bar on a terminal, a line per step off it, Newton iterations under -v
    (problems/run/progress.py); ``update`` after each step, ``records[-1]`` its record."""
    from eyemech.problems.run.progress import path_progress

    return path_progress(solver, label, quiet, stepping, records)
