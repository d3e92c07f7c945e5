"""Newton directions from the current Jacobian, solved by FGMRES preconditioned with the
last LU factorisation of an earlier Jacobian (``NewtonOptions.linear_reuse = "krylov"``).

The idea behind PETSc's ``-snes_lag_preconditioner``, with an adaptive refresh: the
Jacobian J_k is assembled at every Newton iteration and is the Krylov operator, so the
direction solves J_k δ = −F_k to the Krylov tolerance and Newton keeps its convergence
(quadratic for a fixed tolerance well below the Newton tolerance); only the
preconditioner, an LU factorisation of a copy P of some earlier J_j, is kept. It is
refreshed (P ← J_k, one numeric factorisation) when

- FGMRES has not converged within ``max_it`` iterations (or broke down): the solve is
  repeated on the fresh factorisation, never handed to Newton as failed (only a failure
  on a fresh factorisation is);
- FGMRES is predicted not to converge within ``max_it`` (``predict_after`` = k > 0): after
  k iterations on a kept factorisation, the contraction of the last half of them,
  ρ = (‖r_k‖/‖r_h‖)^(1/(k−h)) with h = ⌊k/2⌋ (GMRES accelerates as it resolves the
  preconditioned operator's outlying eigenvalues, so the mean from ‖r_0‖ is pessimistic),
  extrapolated to the tolerance, k + log(rtol‖r_0‖/‖r_k‖)/log ρ, exceeds ``max_it``; the
  solve stops there (its k iterations counted) and is repeated as after a failure, so a
  factorisation too stale to pay costs k iterations instead of ``max_it``;
- the Jacobian's nonzero pattern grew since P was copied (contact pairs insert entries):
  P is copied anew with the new pattern (a symbolic analysis and a numeric factorisation);
- there is no factorisation yet.

P is a matrix of its own: SNES assembles into J at every iteration, and PCSetUp compares
the state of P, not of J, so an unchanged P keeps its factorisation. FGMRES (right
preconditioning) measures the true residual ‖J_k δ + F_k‖ against ``rtol``·‖F_k‖; with
Eisenstat–Walker (``snes_ksp_ew``) SNES sets that rtol per iteration on the outer KSP,
which is read here.

Implementation: the SNES's KSP is a petsc4py "python" KSP whose :meth:`StaleFactorisation.
solve` runs an inner FGMRES+LU KSP with operators (J, P) under the solver's own options
prefix (so MUMPS reads its ICNTLs and ``--petsc`` overrides as with the direct solver).
The inner iterations, failed attempts included, are reported as the outer KSP's
iteration count, which SNES sums into its linear iterations (``krylov_iterations`` in the
solver counts). Factorisations are counted by PETSc's log events like every other.
"""

from __future__ import annotations

import logging
import math

from petsc4py import PETSc

from eyemech.problems.solve.callbacks import petsc_callback

log = logging.getLogger("eyemech")


class StaleFactorisation:
    """Python context of the outer KSP; see the module docstring."""

    def __init__(self, ksp: PETSc.KSP, prefix: str, refresh_above: int = 0,
                 predict_after: int = 0) -> None:
        self.inner = PETSc.KSP().create(ksp.comm)
        self.inner.setOptionsPrefix(prefix)
        self.inner.setFromOptions()  # fgmres, its tolerances, LU with the factor package
        _rtol, self.atol, _dtol, self.max_it = self.inner.getTolerances()
        self.inner.setConvergenceTest(petsc_callback(self._converged))
        # the early refresh's k (0: off): see the module docstring
        self.predict_after = predict_after
        self.early_refreshes = 0  # of the refreshes after failure, those predicted after k
        self.early_iterations = 0  # FGMRES iterations of the solves stopped by the prediction
        self.iterations = 0  # FGMRES iterations of every solve, stopped and failed ones included
        self._rtol = 0.0
        self._initial = 0.0  # ‖r_0‖ = ‖b‖ (FGMRES starts from x = 0)
        self._on_kept = False  # the solve runs on a kept factorisation (may stop early)
        self._history: list[float] = []  # ‖r_0‖, ‖r_1‖, … of the current solve
        self.pmat: PETSc.Mat | None = None
        self._pattern = -1  # nonzeros of J when P was copied
        self.refreshes = 0  # P ← J copies (each costs one numeric factorisation)
        self.refreshes_after_failure = 0  # of which after FGMRES did not converge
        # a solve that converged in more iterations than this refreshes P before the next
        # (0: never): the next Jacobian is rarely nearer the kept one
        self.refresh_above = refresh_above
        self._refresh_due = False
        ksp.setType(PETSc.KSP.Type.PYTHON)
        ksp.setPythonContext(self)
        ksp.getPC().setType(PETSc.PC.Type.NONE)

    def free(self) -> None:
        """Destroy the inner KSP (with its factorisation) and P now (collective). Not
        named ``destroy``: petsc4py calls a Python context's ``destroy(ksp)`` itself."""
        self.inner.destroy()
        if self.pmat is not None:
            self.pmat.destroy()
            self.pmat = None

    def factor_matrix(self) -> PETSc.Mat | None:
        try:
            return self.inner.getPC().getFactorMatrix()
        except PETSc.Error:
            return None

    def _refresh(self, jacobian: PETSc.Mat, nonzeros: int) -> None:
        """P ← J: in place when the pattern is P's (PCSetUp then factorises numerically
        only), else a new copy (a symbolic analysis too)."""
        if self.pmat is not None and nonzeros == self._pattern:
            jacobian.copy(self.pmat, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        else:
            if self.pmat is not None:
                self.pmat.destroy()
            self.pmat = jacobian.duplicate(copy=True)
            self._pattern = nonzeros
        self.inner.setOperators(jacobian, self.pmat)
        self.refreshes += 1

    def _solve_inner(self, rtol: float, b: PETSc.Vec, x: PETSc.Vec,
                     on_kept: bool) -> tuple[int, int]:
        self.inner.setTolerances(rtol=rtol, atol=self.atol, max_it=self.max_it)
        self._rtol, self._initial, self._on_kept = rtol, b.norm(), on_kept
        early = self.early_refreshes
        self.inner.solve(b, x)
        iterations = self.inner.getIterationNumber()
        self.iterations += iterations
        if self.early_refreshes > early:
            self.early_iterations += iterations
        return iterations, int(self.inner.getConvergedReason())

    def _converged(self, _ksp: PETSc.KSP, its: int, rnorm: float) -> int:
        """PETSc's default test (‖r‖ ≤ max(rtol ‖b‖, atol), at most ``max_it``) and, on a
        kept factorisation, the early refresh's prediction at iteration ``predict_after``."""
        reason = PETSc.KSP.ConvergedReason
        if not math.isfinite(rnorm):
            return reason.DIVERGED_NANORINF
        target = max(self._rtol * self._initial, self.atol)
        if rnorm <= target:
            return reason.CONVERGED_RTOL if rnorm > self.atol else reason.CONVERGED_ATOL
        if its >= self.max_it:
            return reason.DIVERGED_MAX_IT
        if its == 0:
            self._history = []
        self._history.append(rnorm)
        if self._on_kept and its == self.predict_after > 0 and target > 0:
            half = its // 2  # the rate of the last half: GMRES's convergence accelerates
            rate = (rnorm / self._history[half]) ** (1.0 / (its - half))
            if rate >= 1.0 or its + math.log(target / rnorm) / math.log(rate) > self.max_it:
                self.early_refreshes += 1
                return reason.DIVERGED_MAX_IT
        return reason.ITERATING

    # petsc4py's KSP python interface
    def setUp(self, ksp: PETSc.KSP) -> None:  # noqa: N802
        pass

    def solve(self, ksp: PETSc.KSP, b: PETSc.Vec, x: PETSc.Vec) -> None:
        jacobian, _ = ksp.getOperators()
        nonzeros = int(jacobian.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"])
        fresh = self.pmat is None or nonzeros != self._pattern or self._refresh_due
        if fresh:
            self._refresh(jacobian, nonzeros)
        else:
            self.inner.setOperators(jacobian, self.pmat)
        rtol = ksp.getTolerances()[0]  # Eisenstat–Walker's, when on
        iterations, reason = self._solve_inner(rtol, b, x, on_kept=not fresh)
        if reason <= 0 and not fresh:
            log.debug("FGMRES on the kept factorisation: reason %d after %d iterations, "
                      "refactorising", reason, iterations)
            self.refreshes_after_failure += 1
            self._refresh(jacobian, nonzeros)
            more, reason = self._solve_inner(rtol, b, x, on_kept=False)
            iterations += more
        self._refresh_due = 0 < self.refresh_above < iterations and reason > 0
        ksp.setIterationNumber(iterations)
        ksp.setConvergedReason(reason if reason != 0 else PETSc.KSP.ConvergedReason.DIVERGED_MAX_IT)
