"""The injector's and the eye's rigid parts that the lens meets, as analytic signed-gap
obstacles for :class:`eyemech.problems.contact.rigid_wall.NodalContact`: the tapered
cartridge bore, the plunger, the capsular bag; and the rigid turn of a twisted injector.

Each obstacle gives, at deformed node positions x (n, 3), a signed gap g (> 0 free,
< 0 penetrating; a distance in mm, first-order accurate near the surface), its unit
normal n = ∇g, and a mask of where it acts."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np


def _radial(x: np.ndarray, axis_point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ρ about the x-directed axis through ``axis_point`` and the unit radial direction."""
    d = x[:, 1:] - axis_point[1:]
    rho = np.sqrt(np.sum(d ** 2, axis=1) + 1e-24)
    e = np.zeros_like(x)
    e[:, 1:] = d / rho[:, None]
    return rho, e


@dataclasses.dataclass
class TaperedBore:
    """The cartridge bore: axis along +x through ``axis_point``; radius ``radius`` up to
    ``taper_start``, then linear down to ``nozzle_radius`` at ``taper_end``, straight to the
    nozzle tip ``tip``. Acts for x < tip (the body is inside). ``scale`` shrinks the whole
    bore towards ``radius`` (the closing loading chamber of the folding stage)."""

    axis_point: np.ndarray
    radius: float
    nozzle_radius: float
    taper_start: float
    taper_end: float
    tip: float
    opening: float = 0.0  # extra radius (mm) added everywhere: the chamber before it closes
    lip: float = 0.0  # radius (mm) of the rounded nozzle exit (0: a sharp edge)

    def wall_radius(self, x: np.ndarray) -> np.ndarray:
        s = np.clip((x - self.taper_start) / (self.taper_end - self.taper_start), 0.0, 1.0)
        return self.radius + (self.nozzle_radius - self.radius) * s + self.opening

    def gap_normal(self, x):
        """Inside the bore g = R(x) − ρ, n = −e_ρ. With a ``lip``, the last ``lip`` mm are the
        inside of a torus (tube radius ``lip``) that turns the wall from axial to radial at the
        tip: g = D − lip, n = (x − x_c, ρ − ρ_c)/D from the lip's centre circle (x_c, ρ_c).
        Why: with a sharp edge the wall's force on a node at the nozzle radius jumps from
        k (ρ − R) to 0 as the node crosses x = tip, and Newton cycled between two states
        (residuals 4e-3 / 5e-4 for 25 iterations, the optic leaving the nozzle)."""
        rho, e = _radial(x, self.axis_point)
        gap, normal, acts = self.wall_radius(x[:, 0]) - rho, -e, x[:, 0] < self.tip
        if self.lip > 0.0:
            x_c, rho_c = self.tip - self.lip, self.nozzle_radius + self.opening + self.lip
            dx, drho = x[:, 0] - x_c, rho - rho_c
            on_lip = (dx > 0.0) & (drho < 0.0)
            D = np.sqrt(dx ** 2 + drho ** 2) + 1e-300
            gap = np.where(on_lip, D - self.lip, gap)
            normal = np.where(on_lip[:, None], (dx / D)[:, None] * np.array([1.0, 0.0, 0.0])
                              + (drho / D)[:, None] * e, normal)
            acts = np.where(dx > 0.0, on_lip, acts)
        return gap, normal, acts


def turn_about_x(axis_point: np.ndarray, angle: float) -> Callable[[np.ndarray], np.ndarray]:
    """The rigid turn by ``angle`` (rad, right-handed about +x) about the x-directed line
    through ``axis_point``: the motion of a twisted injector's wall over one step."""
    cos, sin = np.cos(angle), np.sin(angle)

    def turned(x: np.ndarray) -> np.ndarray:
        y, z = x[:, 1] - axis_point[1], x[:, 2] - axis_point[2]
        return np.column_stack([x[:, 0], axis_point[1] + cos * y - sin * z,
                                axis_point[2] + sin * y + cos * z])
    return turned


@dataclasses.dataclass
class Plunger:
    """A flat plunger head x = ``position`` of ``radius`` about the x-directed axis through
    ``axis_point``, pushing along +x (the body lies at larger x)."""

    position: float
    axis_point: np.ndarray
    radius: float

    def gap_normal(self, x):
        normal = np.zeros_like(x)
        normal[:, 0] = 1.0
        rho, _ = _radial(x, self.axis_point)
        return x[:, 0] - self.position, normal, rho < self.radius


@dataclasses.dataclass
class Capsule:
    """A rigid ellipsoidal bag (semi-axes ``semi_axes`` along x, y, z about ``center``); the
    body is inside. Acts where x > ``entry`` (outside the injector). Gap ≈ (1 − s)/|∇s|,
    s = |A⁻¹(x − c)|: exact on the surface to first order."""

    center: np.ndarray
    semi_axes: np.ndarray
    entry: float

    def gap_normal(self, x):
        y = (x - self.center) / self.semi_axes
        s = np.sqrt(np.sum(y ** 2, axis=1) + 1e-24)
        grad_s = y / self.semi_axes / s[:, None]
        norm = np.linalg.norm(grad_s, axis=1) + 1e-24
        return (1.0 - s) / norm, -grad_s / norm[:, None], x[:, 0] > self.entry
