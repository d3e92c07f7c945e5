r"""Implicit time integration of  M ü + c M u̇ + f_int(u) = f_ext  on top of a static
residual f_int - f_ext (a UFL form solved by :class:`~eyemech.problems.driver.NonlinearSolver`).

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

The Δt of each step is the increment that :func:`follow_path` passes to ``apply``, so
step cut-back works in time as it does in load. :func:`oscillator_response` runs the
same recurrence on one mode, M = 1 and f_int = ω² u: the discrete reference the
verification compares with.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np

try:
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass
import dolfinx.fem
import dolfinx.fem.petsc
from petsc4py import PETSc

SchemeName = Literal["backward-euler", "newmark", "newmark-damped"]


@dataclasses.dataclass(frozen=True)
class Scheme:
    """Coefficients of a one-step scheme for second-order systems (see module doc)."""

    name: str
    beta: float | None  # None: backward Euler
    gamma: float

    def coefficients(self, dt: float) -> tuple[float, float, float]:
        """(α_u, α_v, α_a) for the step Δt."""
        if self.beta is None:
            return 1.0 / dt ** 2, 1.0 / dt, 0.0
        return 1.0 / (self.beta * dt ** 2), 1.0 / (self.beta * dt), 0.5 / self.beta - 1.0


SCHEMES = {"backward-euler": Scheme("backward-euler", None, 1.0),
           "newmark": Scheme("newmark", 0.25, 0.5),
           # γ = 0.6, β = (γ + ½)²/4: second-order-accurate amplitude loss at high ω only
           "newmark-damped": Scheme("newmark-damped", 0.3025, 0.6)}


def scheme(name: str) -> Scheme:
    if name not in SCHEMES:
        raise ValueError(f"unknown time scheme {name!r}; choose from {sorted(SCHEMES)}")
    return SCHEMES[name]


def oscillator_response(omega: float, damping: float, dt: float, steps: int, name: str,
                        u0: float = 1.0, v0: float = 0.0) -> np.ndarray:
    """u_0 … u_steps of ü + c u̇ + ω² u = 0 integrated by the scheme ``name``: the same
    recurrence as :class:`ImplicitDynamics`, solved exactly for one degree of freedom."""
    s = scheme(name)
    a_u, a_v, a_a = s.coefficients(dt)
    u, v = u0, v0
    a = -damping * v - omega ** 2 * u
    history = [u]
    for _ in range(steps):
        # (1 + c γ Δt)(α_u (u' − u) − α_v v − α_a a) + c (v + Δt (1−γ) a) + ω² u' = 0
        k = (1.0 + damping * s.gamma * dt)
        rhs = k * (a_u * u + a_v * v + a_a * a) - damping * (v + dt * (1.0 - s.gamma) * a)
        u_new = rhs / (k * a_u + omega ** 2)
        a_new = a_u * (u_new - u) - a_v * v - a_a * a
        v = v + dt * ((1.0 - s.gamma) * a + s.gamma * a_new)
        u, a = u_new, a_new
        history.append(u)
    return np.asarray(history)


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
        self._work, self._Mw = self.M.createVecRight(), self.M.createVecRight()
        self._read(self.u_n)
        self.dt = np.nan
        self.coefficients = (np.nan, np.nan, np.nan)

    def _read(self, target: PETSc.Vec) -> None:
        owned = len(target.array)
        target.array[:] = self.u.x.array[:owned]

    # -- the state ----------------------------------------------------------------------
    def set_velocity(self, values: np.ndarray) -> None:
        """Initial velocity, as an array over the (local, ghosted) dofs of u."""
        self.v_n.array[:] = values[: len(self.v_n.array)]

    def initial_acceleration(self, static_residual) -> None:
        """a_0 from M a_0 = −(f_int(u_0) − f_ext) − c M v_0 (needed by Newmark)."""
        compiled = dolfinx.fem.form(static_residual)
        F = dolfinx.fem.petsc.assemble_vector(compiled)
        F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
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
        x.destroy()
        a_new.destroy()

    def kinetic_energy(self) -> float:
        self.M.mult(self.v_n, self._Mw)
        return 0.5 * self._Mw.dot(self.v_n)

    # -- hooks for NonlinearSolver ---------------------------------------------------------
    def residual_hook(self, x: PETSc.Vec, F: PETSc.Vec) -> None:
        """F += M ((1 + c γ Δt) a(x) + c (v_n + Δt (1−γ) a_n))."""
        c, g = self.damping, self.scheme.gamma
        w = self._work
        self._acceleration(x, w)
        w.scale(1.0 + c * g * self.dt)
        if c:
            w.axpy(c, self.v_n)
            w.axpy(c * self.dt * (1.0 - g), self.a_n)
        self.M.mult(w, self._Mw)
        F.axpy(1.0, self._Mw)

    def jacobian_hook(self, _x: PETSc.Vec, J: PETSc.Mat) -> None:
        """J += (1 + c γ Δt) α_u M (M's pattern is a subset of the shell's)."""
        factor = (1.0 + self.damping * self.scheme.gamma * self.dt) * self.coefficients[0]
        J.axpy(factor, self.M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
