"""Q1P0 with its DG0 pressure condensed cell by cell (the mean-dilatation method,
problems/solid/mean_dilatation.py; docs/hyperelastic.md, "Condensed Q1P0").

- Taylor tests on a distorted 2×2×2 hexahedral cube: the residual is the gradient of the
  energy ∫ W dX + Σ_K |K| κ/2 (J̄_K − 1)², and the tangent (UFL's, p̄ fixed, plus the cells'
  rank-one κ/|K| b_K b_Kᵀ) is the residual's derivative: both remainders fall 4× per halving
  of the step (second order); without the rank-one terms they would fall 2× (first order).
- The thick neo-Hookean sphere (``sphere-inflation``, exact incompressible solution): the
  condensed element against the exact inner radius and against mixed Q1P0 on the same
  mesh, the difference O(μ/κ).
"""

from __future__ import annotations

import numpy as np
import pytest
import ufl

from eyemech.problems import sphere_inflation as si
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError


def _distorted_cube():
    import dolfinx
    from mpi4py import MPI

    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 2, 2, 2, dolfinx.mesh.CellType.hexahedron)
    rng = np.random.default_rng(1)
    x = mesh.geometry.x
    inner = np.all(np.abs(x - 0.5) < 0.4, axis=1)  # the centre node moves: no parallelepipeds
    x[inner] += 0.08 * rng.standard_normal(x[inner].shape)
    return mesh, rng


@pytest.fixture(scope="module")
def cube():
    """A distorted cube, clamped at x = 0, condensed Q1P0, at a random displacement."""
    import dolfinx
    import dolfinx.fem.petsc

    from eyemech.forms import NeoHooke
    from eyemech.problems.solid.mean_dilatation import MeanDilatation
    from eyemech.problems.solid.residual import solid_residual
    from eyemech.problems.solid.spaces import ELEMENTS, solid_fields

    mesh, rng = _distorted_cube()
    family = ELEMENTS["Q1P0"]
    fields, tests = solid_fields(mesh, family, condensed=True)
    u = fields[0]
    V = u.function_space
    dx = ufl.dx(domain=mesh, metadata={"quadrature_degree": 2})
    clamped = dolfinx.mesh.locate_entities_boundary(mesh, 2, lambda X: np.isclose(X[0], 0.0))
    bcs = [dolfinx.fem.dirichletbc(np.zeros(3), dolfinx.fem.locate_dofs_topological(V, 2, clamped), V)]
    law = NeoHooke(0.5)
    condensed = MeanDilatation(u, 50.0, dx, bcs)  # κ/μ = 50: J̄'s nonlinearity visible
    residual = solid_residual(law, family, fields, tests, dx, condensed_pressure=condensed.pressure)
    u.x.array[:] = 0.05 * rng.standard_normal(u.x.array.shape)
    direction = rng.standard_normal(u.x.array.shape)
    for bc in bcs:
        bc.set(direction, alpha=0.0)
    return dict(u=u, V=V, law=law, dx=dx, bcs=bcs, condensed=condensed, direction=direction,
                residual=dolfinx.fem.form(residual),
                tangent=dolfinx.fem.form(ufl.derivative(residual, u, ufl.TrialFunction(V))))


def _residual(c) -> np.ndarray:
    import dolfinx.fem.petsc

    c["condensed"].update()
    return dolfinx.fem.assemble_vector(c["residual"]).array.copy()


def _remainders(c, value, slope, steps=(1e-2, 5e-3, 2.5e-3, 1.25e-3)) -> list[float]:
    """‖f(u + ε d) − f(u) − ε f'(u) d‖ over ε."""
    u0 = c["u"].x.array.copy()
    f0 = value()
    out = []
    for eps in steps:
        c["u"].x.array[:] = u0 + eps * c["direction"]
        out.append(float(np.linalg.norm(np.atleast_1d(value() - f0 - eps * slope))))
    c["u"].x.array[:] = u0
    c["condensed"].update()
    return out


def _orders(remainders: list[float]) -> list[float]:
    return [float(np.log2(a / b)) for a, b in zip(remainders, remainders[1:])]


def test_condensed_residual_is_the_energy_gradient(cube):
    import dolfinx

    from eyemech.forms import deformation_gradient, mean_dilatation_energy_density

    c = cube
    mesh = c["u"].function_space.mesh
    mean_j = dolfinx.fem.Function(c["condensed"].pressure.function_space)
    energy = dolfinx.fem.form(mean_dilatation_energy_density(
        c["law"], deformation_gradient(c["u"]), mean_j, 50.0) * c["dx"])

    def value() -> float:
        c["condensed"].update()
        mean_j.x.array[: c["condensed"].cells] = c["condensed"].mean_jacobian()
        return dolfinx.fem.assemble_scalar(energy)

    # Σ_K |K| U(J̄_K) through the form equals the module's sum
    value()
    volumetric = c["condensed"].volumetric_energy()
    isochoric = dolfinx.fem.assemble_scalar(dolfinx.fem.form(
        c["law"].strain_energy(deformation_gradient(c["u"])) * c["dx"]))
    assert value() == pytest.approx(isochoric + volumetric, rel=1e-12)
    assert mesh.comm.size == 1
    slope = float(_residual(c) @ c["direction"])
    orders = _orders(_remainders(c, value, slope))
    assert min(orders) > 1.9, orders  # measured 2.003–2.012


def test_condensed_tangent_is_the_residual_derivative(cube):
    import dolfinx.fem.petsc

    c = cube
    c["condensed"].update()
    A = dolfinx.fem.petsc.assemble_matrix(c["tangent"], bcs=c["bcs"])
    A.assemble()
    free = np.ones(len(c["direction"]), dtype=bool)
    for bc in c["bcs"]:
        free[bc.dof_indices()[0]] = False
    d = A.createVecRight()
    d.array[:] = c["direction"]
    without = A.createVecLeft()
    A.mult(d, without)
    c["condensed"].jacobian_hook(None, A)
    full = A.createVecLeft()
    A.mult(d, full)

    def value() -> np.ndarray:
        return _residual(c)[free]

    orders = _orders(_remainders(c, value, full.array[free]))
    assert min(orders) > 1.9, orders  # measured 2.002–2.009
    # the rank-one cell terms are what makes it second order: without them, first order
    orders_without = _orders(_remainders(c, value, without.array[free]))
    assert max(orders_without) < 1.2, orders_without  # measured 1.005–1.019


def _sphere(dg0_pressure: str, bulk_modulus: float = 100.0) -> dict:
    params = si.Parameters(element="Q1P0", mesh_size=1.0, pressure=0.02,
                           dg0_pressure=dg0_pressure, bulk_modulus=bulk_modulus)
    return si.run(params, options=RunOptions(fields=False, pictures=False, quiet=True)).quantities


def test_condensed_sphere_against_the_exact_radius_and_mixed_q1p0():
    """κ/μ = 1000 and 10,000 (μ = 2 c10 = 0.1 MPa): the condensed sphere is within 5e-3 of the
    exact inner radius, as mixed Q1P0 on this mesh, and differs from mixed by O(μ/κ)."""
    mixed = _sphere("mixed")
    soft, stiff = _sphere("condensed", 100.0), _sphere("condensed", 1000.0)
    assert mixed["dofs"] - soft["dofs"] > 0  # the DG0 pressure is gone from the system
    assert abs(soft["inner_radius_error"]) < 5e-3  # measured −1.64e-3 (mixed −2.11e-3)
    # measured +4.70e-4 at κ/μ = 1000 and +4.69e-5 at 10,000: O(μ/κ), ≈ 0.5 μ/κ
    differences = [c["inner_radius_deformed"] / mixed["inner_radius_deformed"] - 1
                   for c in (soft, stiff)]
    assert 0 < differences[0] < 1e-3, differences
    assert 0 < differences[1] < 1.5 * differences[0] / 10, differences


def test_condensed_needs_q1p0():
    with pytest.raises(ParameterError, match="dg0_pressure"):
        si.Parameters(element="P2P1", dg0_pressure="condensed").validate()


def test_condensed_eye_gives_the_mixed_eye():
    """The coarse eye's three steps (docs/scleral_buckling.md, "Condensed Q1P0"): the
    condensed Q1P0 at κ/μ = 1,000 per tissue (the default 300 moves the coarse rim gap after
    buckling by 0.0098 mm, at the tolerance) against the mixed one, after buckling and after
    suturing, within 1 % and the rim gap within 0.01 mm."""
    from eyemech.problems import scleral_buckling as sb

    def run(dg0_pressure: str) -> dict:
        params = sb.Parameters(resolution="coarse", settle=False, dg0_pressure=dg0_pressure,
                               condensed_bulk_ratio=1000.0, **sb.PAPER_OPERATION)
        return sb.run(params, options=RunOptions(fields=False, pictures=False, quiet=True)).quantities

    mixed, condensed = run("mixed"), run("condensed")
    assert mixed["dofs"] - condensed["dofs"] == 802  # one pressure per cell: the coarse eye has 802 hexahedra
    for stage in ("after_buckling", "after_suturing"):
        for key in ("axial_length_change_mm", "refraction_change_D", "iop_mmHg"):
            # measured ≤ 0.14 % (IOP); 0.07 % axial length, 0.10 % refraction
            assert condensed[stage][key] == pytest.approx(mixed[stage][key], rel=0.01), (stage, key)
        # measured +0.003 / +0.001 mm
        assert abs(condensed[stage]["tear_rim_gap_max_mm"]
                   - mixed[stage]["tear_rim_gap_max_mm"]) < 0.01


def test_condensed_eye_bad_input():
    from eyemech.problems import scleral_buckling as sb

    with pytest.raises(ParameterError, match="dg0_pressure"):
        sb.Parameters(element="Q2P1", dg0_pressure="condensed").validate()
    with pytest.raises(ParameterError, match="condensed_bulk_ratio"):
        sb.Parameters(condensed_bulk_ratio=-1.0).validate()
