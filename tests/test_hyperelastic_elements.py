"""Element families on ``sphere-inflation``: each converges to the exact solution of the
thick incompressible neo-Hookean sphere at the rate its order allows; P1 with a bulk
penalty locks.

Reference: the exact radial solution (problems/reference/analytic.py; Ogden, *Non-linear elastic
deformations*, 1984, §5.3.2 — p = ∫_a^b 2μ/r (λ² − λ⁻⁴) dr). Error measure: the relative
L² error of the displacement against the exact field u = (r(R)/R − 1) X,
r³ = R³ − A³ + a³. Rates are measured per h_eff = N^(-1/3) (N = unknowns), since gmsh
tetrahedra do not refine by exact halving. Expected orders (smooth solution, L² norm):
3 for the quadratic-displacement stable pairs P2P1 and Q2P1, 2 for Q1P0 and P2P0 (the
piecewise-constant pressure limits them); we assert 80 % of these (short sequences
on coarse unstructured meshes are not yet asymptotic). P1: error stays above 10 % on
the inner radius and its rate is below 1 (volumetric locking, K/μ = 1000).
"""

from __future__ import annotations

import math

import pytest

from eyemech.problems import sphere_inflation as si
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError, build

OPTIONS = RunOptions(fields=False, pictures=False)
SEQUENCES = {"P2P1": (2.0, 1.0), "Q2P1": (2.0, 1.0), "Q1P0": (2.0, 1.0, 0.5),
             "P2P0": (2.0, 1.0), "P1": (2.0, 1.0)}
EXPECTED = {"P2P1": 3.0, "Q2P1": 3.0, "Q1P0": 2.0, "P2P0": 2.0}


def _solve(element: str, mesh_size: float) -> dict:
    params = si.Parameters(element=element, mesh_size=mesh_size, pressure=0.02)
    return si.run(params, options=OPTIONS).quantities


@pytest.fixture(scope="module")
def sequences() -> dict[str, list[dict]]:
    return {element: [_solve(element, h) for h in sizes] for element, sizes in SEQUENCES.items()}


def _rate(coarse: dict, fine: dict) -> float:
    h_ratio = (fine["dofs"] / coarse["dofs"]) ** (1.0 / 3.0)
    return math.log(coarse["displacement_error"] / fine["displacement_error"]) / math.log(h_ratio)


@pytest.mark.parametrize("element", sorted(EXPECTED))
def test_stable_families_converge_at_their_order(sequences, element):
    runs = sequences[element]
    rate = _rate(runs[-2], runs[-1])
    assert rate > 0.8 * EXPECTED[element], (element, rate, [r["displacement_error"] for r in runs])
    assert abs(runs[-1]["inner_radius_error"]) < 5e-3


def test_p1_locks(sequences):
    runs = sequences["P1"]
    assert all(abs(r["inner_radius_error"]) > 0.10 for r in runs)  # far too stiff
    assert _rate(runs[0], runs[1]) < 1.0
    best_mixed = min(sequences["Q1P0"][0]["displacement_error"], sequences["P2P1"][0]["displacement_error"])
    assert runs[-1]["displacement_error"] > 10 * best_mixed


def test_hexahedral_octant_is_valid_and_curved():
    import dolfinx
    import numpy as np
    import ufl

    from eyemech.meshes import spherical_shell

    shell = spherical_shell(10.0, 12.0, 2.0, order=2, hexahedra=True)
    assert shell.mesh.topology.cell_name() == "hexahedron"
    one = dolfinx.fem.Constant(shell.mesh, 1.0)
    volume = dolfinx.fem.assemble_scalar(dolfinx.fem.form(one * ufl.dx(domain=shell.mesh)))
    area = dolfinx.fem.assemble_scalar(dolfinx.fem.form(one * shell.ds()(shell.tag("cavity_wall"))))
    # second-order geometry on the spheres: volume and area within 1e-5 of the exact octant
    assert volume == pytest.approx(np.pi / 6 * (12**3 - 10**3), rel=1e-5)
    assert area == pytest.approx(np.pi / 2 * 10**2, rel=1e-5)


@pytest.mark.parametrize("overrides, key", [({"element": "Q9P7"}, "element"),
                                           ({"bulk_modulus": "0"}, "bulk_modulus"),
                                           ({"bulk_modulus": "-5"}, "bulk_modulus")])
def test_bad_input(overrides, key):
    with pytest.raises(ParameterError) as err:
        build(si.Parameters, overrides)
    assert err.value.key == key


def test_unknown_element_rejected_when_constructed_directly():
    with pytest.raises(ParameterError, match="P2P1, P2P0, Q1P0, Q2P1, P1"):
        si.Parameters(element="Q9P7").validate()


def test_materials_by_cell_tag_sum_to_the_single_law():
    """{tag: law} over dx(tag) is the same residual as the law over dx when the tag
    covers the mesh (with p = 0, twice the modulus gives twice the residual)."""
    import dolfinx
    import numpy as np
    import ufl

    from eyemech.forms import NeoHooke
    from eyemech.meshes import spherical_shell
    from eyemech.problems.solid.residual import solid_residual
    from eyemech.problems.solid.spaces import ELEMENTS, solid_fields

    shell = spherical_shell(10.0, 12.0, 4.0, order=1, hexahedra=True)
    family = ELEMENTS["Q1P0"]
    fields, tests = solid_fields(shell.mesh, family)
    fields[0].interpolate(lambda x: 0.01 * x)  # a uniform stretch
    dx = shell.dx({"quadrature_degree": 2})
    tag = shell.tag("wall")

    def vector(material):
        form = ufl.extract_blocks(solid_residual(material, family, fields, tests, dx))[0]
        return dolfinx.fem.assemble_vector(dolfinx.fem.form(form)).array.copy()

    single = vector(NeoHooke(0.05))
    assert np.allclose(vector({tag: NeoHooke(0.05)}), single, rtol=1e-12, atol=1e-14)
    assert np.allclose(vector({tag: NeoHooke(0.1)}), 2 * single, rtol=1e-12, atol=1e-14)
