"""``liquid-sphere``: cavity pressure as a Real-space unknown and substituted, against
the exact answer (problems/reference/analytic.py ``liquid_sphere``: the thick-sphere wall relation
P − p_ext = ∫_a^b 2μ/r (λ² − λ⁻⁴) dr closed by the liquid law of seed 002 eq. 5,
P = P_ini − K ((a/A)³ − 1)). Tolerance 0.5 % (the issue's), met by ~1e-4 in practice.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from eyemech.meshes.tagged import MeshError
from eyemech.problems import liquid_sphere as ls
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError, build

OPTIONS = RunOptions(fields=False, pictures=False)
CASES = [(e, f) for e in ("P2P1", "Q2P1") for f in ("real", "substituted")]


@pytest.fixture(scope="module")
def results() -> dict:
    return {case: ls.run(ls.Parameters(element=case[0], cavity_formulation=case[1]),
                         options=OPTIONS).quantities for case in CASES}


@pytest.mark.parametrize("case", CASES, ids=lambda c: "-".join(c))
def test_matches_exact(results, case):
    q = results[case]
    assert abs(q["cavity_pressure_error"]) < 5e-3
    assert abs(q["inner_radius_error"]) < 5e-3
    # the displacement itself (a − A ≈ −6 % of A), not only the radius, within 0.5 %
    moved, exact_move = q["inner_radius_deformed"] - 10.0, q["inner_radius_exact"] - 10.0
    assert moved == pytest.approx(exact_move, rel=5e-3)
    assert q["cavity_volume"] == pytest.approx(4 / 3 * np.pi * q["inner_radius_exact"] ** 3, rel=5e-3)


@pytest.mark.parametrize("element", ["P2P1", "Q2P1"])
def test_formulations_agree_and_real_is_sparse(results, element):
    real, substituted = results[(element, "real")], results[(element, "substituted")]
    assert real["cavity_pressure"] == pytest.approx(substituted["cavity_pressure"], rel=1e-7)
    assert real["inner_radius_deformed"] == pytest.approx(substituted["inner_radius_deformed"], rel=1e-9)
    # same Newton path: the substituted Jacobian is exact too (quadratic convergence kept)
    assert real["newton_iterations"] == substituted["newton_iterations"]
    assert substituted["jacobian_nonzeros"] > 2 * real["jacobian_nonzeros"]


def test_two_ranks_same_numbers(results, tmp_path):
    bindir = Path(sys.executable).parent
    command = [str(bindir / "mpiexec"), "-n", "2", str(bindir / "eyemech"), "run", "liquid-sphere",
               "--set", "cavity_formulation=substituted", "--json", "--quiet", "--out", str(tmp_path)]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    done = subprocess.run(command, capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    parallel = json.loads(done.stdout.strip().splitlines()[-1])["quantities"]
    serial = results[("P2P1", "substituted")]
    for key in ("cavity_pressure", "inner_radius_deformed", "cavity_volume"):
        assert parallel[key] == pytest.approx(serial[key], rel=1e-6), key


def test_open_wall_is_refused_before_solving():
    # the plane x = 0 bounds no volume with the other symmetry planes
    with pytest.raises(MeshError, match="does not enclose a volume"):
        ls.run(ls.Parameters(cavity_tag="symmetry_x", mesh_size=4.0), options=OPTIONS)


def test_axis_volumes_detect_an_open_box():
    import dolfinx
    import ufl
    from mpi4py import MPI

    from eyemech.problems.solid.cavity import check_closed

    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 2, 2, 2)
    fdim = mesh.topology.dim - 1
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    u = dolfinx.fem.Function(V)

    def wall(*axes):
        facets = dolfinx.mesh.locate_entities_boundary(
            mesh, fdim, lambda x: np.any([np.isclose(x[a], 1.0) for a in axes], axis=0))
        tags = dolfinx.mesh.meshtags(mesh, fdim, np.sort(facets), np.ones(len(facets), np.int32))
        return ufl.Measure("ds", domain=mesh, subdomain_data=tags)(1)

    # faces x = 1, y = 1, z = 1 close the unit cube with the three symmetry planes;
    # here the mesh is the cavity itself, so its facet normal is the cavity's outward one
    assert check_closed(u, wall(0, 1, 2), outward_sign=1.0) == pytest.approx(1.0)
    with pytest.raises(MeshError, match="does not enclose"):
        check_closed(u, wall(0, 1), outward_sign=1.0)


@pytest.mark.parametrize("overrides, key", [({"bulk_modulus": "0"}, "bulk_modulus"),
                                           ({"bulk_modulus": "-1"}, "bulk_modulus"),
                                           ({"element": "P3P2"}, "element"),
                                           ({"cavity_formulation": "lagrange"}, "cavity_formulation")])
def test_bad_input(overrides, key):
    with pytest.raises(ParameterError) as err:
        build(ls.Parameters, overrides)
    assert err.value.key == key
