r"""Implicit time integration of  M ü + c M u̇ + f_int(u) = f_ext  on top of a static
residual f_int - f_ext (a UFL form solved by :class:`~eyemech.problems.solve.driver.NonlinearSolver`).

The inertia and damping enter as residual/Jacobian hooks with a mass matrix assembled
once, so the (expensive to compile) static shell form is the same compiled kernel in a
static and in a dynamic scene. Per step, with the known state (u_n, v_n, a_n):

    a(u) = α_u (u − u_n) − α_v v_n − α_a a_n,      v(u) = v_n + Δt ((1−γ) a_n + γ a(u))
    R(u) = f_int(u) − f_ext + M (a(u) + c v(u)),    ∂R/∂u = K(u) + (1 + c γ Δt) α_u M

- Newmark (β, γ): α_u = 1/(β Δt²), α_v = 1/(β Δt), α_a = 1/(2β) − 1. β = ¼, γ = ½ is the
  trapezoidal rule (energy conserving, no numerical damping, period elongation
  ω_h Δt = 2 atan(ω Δt/2)); γ > ½ damps high frequencies.
- Backward Euler: v = (u − u_n)/Δt, a = (v − v_n)/Δt, i.e. α_u = 1/Δt², α_v = 1/Δt, α_a = 0,
  γ = 1: first order, L-stable, strongly damped — the choice for a lens in viscous fluid.
- Generalised-α (Chung & Hulbert, J. Appl. Mech. 60, 1993) with high-frequency spectral
  radius ρ∞: α_m = (2ρ∞ − 1)/(ρ∞ + 1), α_f = ρ∞/(ρ∞ + 1), γ = ½ − α_m + α_f,
  β = ¼(1 − α_m + α_f)², the Newmark updates above and the balance
      M a_{n+1−α_m} + c M v_{n+1−α_f} + (1 − α_f) R(u_{n+1}) + α_f R(u_n) = 0
  (x_{n+1−α} = (1 − α) x_{n+1} + α x_n; the static residual R = f_int − f_ext is averaged
  rather than evaluated at an averaged u — the same method for linear systems, and what a
  hook can do without touching the compiled form). Second order, ρ∞ = 1 is the trapezoidal
  rule, ρ∞ < 1 damps the highest modes. ``generalized-alpha`` is ρ∞ = 0.8; R(u_n) is the
  last residual the solver evaluated, so the step must end with a residual evaluation at
  the accepted state (Newton's convergence check does; a single linearised iteration does not).
  Hooks after this one (contact) enter unaveraged, at t_{n+1}.

The Δt of each step is the increment that :func:`follow_path` passes to ``apply``, so
step cut-back works in time as it does in load. :func:`oscillator_response` runs the
same recurrence on one mode, M = 1 and f_int = ω² u: the discrete reference the
verification compares with.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import dolfinx.fem
import dolfinx.fem.petsc
import numpy as np
from petsc4py import PETSc

SchemeName = Literal["backward-euler", "newmark", "newmark-damped"]


@dataclasses.dataclass(frozen=True)
class Scheme:
    """Coefficients of a one-step scheme for second-order systems (see module doc)."""

    name: str
    beta: float | None  # None: backward Euler
    gamma: float
    alpha_m: float = 0.0  # generalised-α weights (0, 0: Newmark / backward Euler)
    alpha_f: float = 0.0

    def coefficients(self, dt: float) -> tuple[float, float, float]:
        """(α_u, α_v, α_a) for the step Δt."""
        if self.beta is None:
            return 1.0 / dt ** 2, 1.0 / dt, 0.0
        return 1.0 / (self.beta * dt ** 2), 1.0 / (self.beta * dt), 0.5 / self.beta - 1.0


def generalized_alpha(rho_infinity: float, name: str = "generalized-alpha") -> Scheme:
    """Chung–Hulbert parameters for the spectral radius ρ∞ ∈ [0, 1] at ωΔt → ∞."""
    if not 0.0 <= rho_infinity <= 1.0:
        raise ValueError(f"rho_infinity must lie in [0, 1], got {rho_infinity!r}")
    alpha_m = (2.0 * rho_infinity - 1.0) / (rho_infinity + 1.0)
    alpha_f = rho_infinity / (rho_infinity + 1.0)
    gamma = 0.5 - alpha_m + alpha_f
    return Scheme(name, 0.25 * (1.0 - alpha_m + alpha_f) ** 2, gamma, alpha_m, alpha_f)


SchemeName = Literal["backward-euler", "generalized-alpha", "newmark", "newmark-damped"]
SCHEMES = {"backward-euler": Scheme("backward-euler", None, 1.0),
           "generalized-alpha": generalized_alpha(0.8),
           "newmark": Scheme("newmark", 0.25, 0.5),
           # γ = 0.6, β = (γ + ½)²/4: second-order-accurate amplitude loss at high ω only
           "newmark-damped": Scheme("newmark-damped", 0.3025, 0.6)}


def scheme(name: str) -> Scheme:
    if name not in SCHEMES:
        raise ValueError(f"unknown time scheme {name!r}; choose from {sorted(SCHEMES)}")
    return SCHEMES[name]


def oscillator_response(omega: float, damping: float, dt: float, steps: int, name: str | Scheme,
                        u0: float = 1.0, v0: float = 0.0) -> np.ndarray:
    """u_0 … u_steps of ü + c u̇ + ω² u = 0 integrated by the scheme ``name``: the same
    recurrence as :class:`ImplicitDynamics`, solved exactly for one degree of freedom."""
    s = name if isinstance(name, Scheme) else scheme(name)
    state = np.array([u0, v0, -damping * v0 - omega ** 2 * u0])
    history = [u0]
    for _ in range(steps):
        state = oscillator_step(s, omega, damping, dt, state)
        history.append(state[0])
    return np.asarray(history)


def oscillator_exact(omega: float, damping: float, times, u0: float = 1.0) -> np.ndarray:
    """u(t) of ü + c u̇ + ω² u = 0 released at rest from u0, exactly: A e^{r₁t} + B e^{r₂t}
    with r = −c/2 ± √(c²/4 − ω²) (complex when underdamped), A + B = u0, r₁A + r₂B = 0."""
    root = np.sqrt(complex(0.25 * damping * damping - omega * omega))
    r1, r2 = -0.5 * damping + root, -0.5 * damping - root
    t = np.asarray(times, dtype=float)
    return u0 * ((r2 * np.exp(r1 * t) - r1 * np.exp(r2 * t)) / (r2 - r1)).real


def oscillator_step(s: Scheme, omega: float, damping: float, dt: float, state: np.ndarray) -> np.ndarray:
    """(u, v, a)_{n+1} from (u, v, a)_n for one mode (linear in the state: its amplification
    matrix is this applied to the unit states)."""
    a_u, a_v, a_a = s.coefficients(dt)
    am, af, g, c = s.alpha_m, s.alpha_f, s.gamma, damping
    u, v, a = state
    # k a' + α_m a + c v + c (1−α_f) Δt (1−γ) a + ω² ((1−α_f) u' + α_f u) = 0,
    # k = 1 − α_m + c (1−α_f) γ Δt,  a' = α_u (u' − u) − α_v v − α_a a
    k = 1.0 - am + c * (1.0 - af) * g * dt
    rhs = (k * (a_u * u + a_v * v + a_a * a) - am * a - c * v - c * (1.0 - af) * dt * (1.0 - g) * a
           - omega ** 2 * af * u)
    u_new = rhs / (k * a_u + omega ** 2 * (1.0 - af))
    a_new = a_u * (u_new - u) - a_v * v - a_a * a
    v_new = v + dt * ((1.0 - g) * a + g * a_new)
    return np.array([u_new, v_new, a_new])


ESTIMATED_SCHEMES = ("backward-euler", "newmark")


def _require_estimate(s: Scheme) -> None:
    if s.name not in ESTIMATED_SCHEMES:
        raise ValueError(f"no time-error estimate for scheme {s.name!r}: use one of "
                         f"{', '.join(ESTIMATED_SCHEMES)}")


def local_error_estimate(s: Scheme, dt: float, a_n, a_new) -> float:
    """The displacement error of one step (max over the dofs), from the accelerations at
    its ends: backward Euler against the trapezoidal rule on the same velocities,
    u_BE − u_TR = Δt/2 (v_{n+1} − v_n) = Δt²/2 a_{n+1} (first order: ∝ Δt²); a Newmark
    scheme, Zienkiewicz & Xie (Earthquake Eng. Struct. Dyn. 20, 1991):
    (β − 1/6) Δt² (a_{n+1} − a_n) (second order: ∝ Δt³). Verified against the exact
    oscillator in tests/test_adaptive_dynamics.py. Other schemes (γ ≠ ½, generalised-α)
    have other error constants and are refused."""
    _require_estimate(s)
    a_new = np.asarray(a_new, dtype=float)
    if s.beta is None:
        return 0.5 * dt * dt * float(np.max(np.abs(a_new), initial=0.0))
    jump = a_new - np.asarray(a_n, dtype=float)
    return abs(s.beta - 1.0 / 6.0) * dt * dt * float(np.max(np.abs(jump), initial=0.0))


class ImplicitDynamics:
    """Inertia and mass-proportional damping added to a static residual by hooks.

    ``mass_form`` is the bilinear form m(a, v); ``bcs`` the Dirichlet conditions of
    the static problem (their rows and columns of M are zeroed, so prescribed dofs
    keep the residual DOLFINx gives them). Call :meth:`set_step` from ``apply`` and
    :meth:`advance` after every converged step.
    """

    def __init__(self, u: dolfinx.fem.Function, mass_form, bcs=(), *, scheme_name: str = "newmark",
                 damping: float = 0.0):
        self.u, self.scheme, self.damping = u, scheme(scheme_name), float(damping)
        compiled = dolfinx.fem.form(mass_form)
        self.M = dolfinx.fem.petsc.assemble_matrix(compiled, bcs=list(bcs), diag=0.0)
        self.M.assemble()
        # M with unit diagonal on prescribed rows: invertible, for the initial acceleration
        self._M_solve = dolfinx.fem.petsc.assemble_matrix(compiled, bcs=list(bcs), diag=1.0)
        self._M_solve.assemble()
        self.u_n, self.v_n, self.a_n = (self.M.createVecRight() for _ in range(3))
        # generalised-α: the static residual R(u_n) and the last one the solver evaluated
        self._static_n, self._static = self.M.createVecRight(), self.M.createVecRight()
        self._work, self._Mw = self.M.createVecRight(), self.M.createVecRight()
        self._read(self.u_n)
        self.dt = np.nan
        self.coefficients = (np.nan, np.nan, np.nan)

    def _read(self, target: PETSc.Vec) -> None:
        owned = len(target.array)
        target.array[:] = self.u.x.array[:owned]

    # -- the state ----------------------------------------------------------------------
    def initial_acceleration(self, static_residual) -> None:
        """a_0 from M a_0 = −(f_int(u_0) − f_ext) − c M v_0 (needed by Newmark)."""
        compiled = dolfinx.fem.form(static_residual)
        F = dolfinx.fem.petsc.assemble_vector(compiled)
        F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        F.copy(self._static_n)
        self._read(self.u_n)
        self.M.mult(self.v_n, self._Mw)
        F.axpy(self.damping, self._Mw)
        F.scale(-1.0)
        ksp = PETSc.KSP().create(self.M.comm)
        ksp.setOperators(self._M_solve)
        ksp.setType("preonly")
        ksp.getPC().setType("lu")
        ksp.getPC().setFactorSolverType("mumps")
        ksp.solve(F, self.a_n)
        ksp.destroy()
        F.destroy()

    def set_step(self, dt: float) -> None:
        if not dt > 0.0:  # the path follower restoring the last converged state: nothing to set
            return
        self.dt = float(dt)
        self.coefficients = self.scheme.coefficients(self.dt)

    def velocity(self, x: PETSc.Vec, out: PETSc.Vec) -> None:
        """v(u) of the current step at the iterate x, into ``out``."""
        self._acceleration(x, out)
        g = self.scheme.gamma
        out.scale(g * self.dt)
        out.axpy(1.0, self.v_n)
        out.axpy((1.0 - g) * self.dt, self.a_n)

    def _acceleration(self, x: PETSc.Vec, out: PETSc.Vec) -> None:
        a_u, a_v, a_a = self.coefficients
        x.copy(out)
        out.axpy(-1.0, self.u_n)
        out.scale(a_u)
        out.axpy(-a_v, self.v_n)
        out.axpy(-a_a, self.a_n)

    def advance(self) -> None:
        """Accept the converged u of this step as u_{n+1} (and its v, a)."""
        x = self.M.createVecRight()
        self._read(x)
        a_new = self.M.createVecRight()
        self._acceleration(x, a_new)
        g = self.scheme.gamma
        self.v_n.axpy(self.dt * (1.0 - g), self.a_n)
        self.v_n.axpy(self.dt * g, a_new)
        a_new.copy(self.a_n)
        x.copy(self.u_n)
        if self.scheme.alpha_f:
            self._static.copy(self._static_n)
        x.destroy()
        a_new.destroy()

    def local_error(self) -> float:
        """:func:`local_error_estimate` of the step just solved (u holds u_{n+1}; call
        before :meth:`advance`), the max over all ranks' dofs."""
        _require_estimate(self.scheme)
        x, a_new = self.M.createVecRight(), self.M.createVecRight()
        self._read(x)
        self._acceleration(x, a_new)
        dt = self.dt
        if self.scheme.beta is None:
            error = 0.5 * dt * dt * a_new.norm(PETSc.NormType.NORM_INFINITY)
        else:
            a_new.axpy(-1.0, self.a_n)
            error = abs(self.scheme.beta - 1.0 / 6.0) * dt * dt * a_new.norm(PETSc.NormType.NORM_INFINITY)
        x.destroy()
        a_new.destroy()
        return float(error)

    def local_error_vector(self, out: PETSc.Vec) -> None:
        """The vector whose max norm is :meth:`local_error` (the same call order), into ``out``."""
        _require_estimate(self.scheme)
        self._read(self._work)
        self._acceleration(self._work, out)
        if self.scheme.beta is None:
            out.scale(0.5 * self.dt * self.dt)
        else:
            out.axpy(-1.0, self.a_n)
            out.scale((self.scheme.beta - 1.0 / 6.0) * self.dt * self.dt)

    def mass_factor(self) -> float:
        """m of the Jacobian's inertia term m M (:meth:`jacobian_hook`, not generalised-α)."""
        return (1.0 + self.damping * self.scheme.gamma * self.dt) * self.coefficients[0]

    @property
    def order(self) -> int:
        """Order of accuracy of an estimated scheme: 1 for backward Euler, 2 for Newmark."""
        _require_estimate(self.scheme)
        return 1 if self.scheme.beta is None else 2

    def kinetic_energy(self) -> float:
        self.M.mult(self.v_n, self._Mw)
        return 0.5 * self._Mw.dot(self.v_n)

    # -- hooks for NonlinearSolver ---------------------------------------------------------
    def residual_hook(self, x: PETSc.Vec, F: PETSc.Vec) -> None:
        """F += M ((1 + c γ Δt) a(x) + c (v_n + Δt (1−γ) a_n)); generalised-α:
        F ← (1−α_f) F + α_f R(u_n) + M ((1 − α_m + c (1−α_f) γ Δt) a(x) + α_m a_n
        + c v_n + c (1−α_f) Δt (1−γ) a_n)."""
        c, g = self.damping, self.scheme.gamma
        am, af = self.scheme.alpha_m, self.scheme.alpha_f
        if af:
            F.copy(self._static)
            F.scale(1.0 - af)
            F.axpy(af, self._static_n)
        w = self._work
        self._acceleration(x, w)
        w.scale(1.0 - am + c * (1.0 - af) * g * self.dt)
        if am:
            w.axpy(am, self.a_n)
        if c:
            w.axpy(c, self.v_n)
            w.axpy(c * (1.0 - af) * self.dt * (1.0 - g), self.a_n)
        self.M.mult(w, self._Mw)
        F.axpy(1.0, self._Mw)

    def jacobian_hook(self, _x: PETSc.Vec, J: PETSc.Mat) -> None:
        """J += (1 + c γ Δt) α_u M (M's pattern is a subset of the shell's); generalised-α:
        J ← (1−α_f) J + (1 − α_m + c (1−α_f) γ Δt) α_u M."""
        am, af = self.scheme.alpha_m, self.scheme.alpha_f
        if af:
            J.scale(1.0 - af)
        factor = (1.0 - am + self.damping * (1.0 - af) * self.scheme.gamma * self.dt) * self.coefficients[0]
        J.axpy(factor, self.M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
