"""The intra-ocular lens (issue 8): mesh, rigid contact, self distance, bad input, a short fold.

References
- Seed 000 (Comas, Cotin & Duriez 2010, §3): the lens mesh had 743 triangles and 473 nodes;
  optic Ø 6 mm, 13 mm overall; E = 1 MPa, ν = 0.42, ρ = 1.2 g/cm³.
- The optic rolled isometrically onto a cylinder of radius R closes on itself when its
  width 6 mm exceeds the circumference 2πR (R < 0.955 mm): geometry, exact.
- Nodal penalty: a node pressed by a force f into a rigid wall of nodal stiffness k sits
  f/k inside it (the definition of the penalty).
"""

from __future__ import annotations

import numpy as np
import pytest

try:
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass
import basix.ufl
import dolfinx.fem

from eyemech.meshes import MeshError
from eyemech.meshes.iol import LensGeometry, intraocular_lens
from eyemech.problems import iol_fold, iol_injection
from eyemech.problems.lens.injector import Capsule, Plunger, TaperedBore
from eyemech.problems.lens.model import LensParameters, rolled
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError

QUIET = RunOptions(fields=False, pictures=False)


@pytest.fixture(scope="module")
def lens():
    return intraocular_lens(LensGeometry())


def test_lens_mesh_is_the_papers_size_and_graded(lens):
    mesh = lens.mesh
    triangles = mesh.topology.index_map(2).size_global
    nodes = mesh.geometry.index_map().size_global
    assert abs(triangles - 743) < 0.05 * 743 and abs(nodes - 473) < 0.05 * 473
    assert lens.count("optic") > 0 and lens.count("haptic") > 0
    assert lens.count("tip_1") > 0 and lens.count("tip_2") > 0
    x = mesh.geometry.x
    assert np.max(np.hypot(x[:, 0], x[:, 1])) == pytest.approx(6.5, abs=0.02)  # 13 mm overall
    assert np.allclose(x[:, 2], 0.0)
    # graded: triangles at the junctions are smaller than in the optic's middle
    geo = LensGeometry()
    nodes_of = mesh.geometry.dofmaps[0]
    centres = x[nodes_of].mean(axis=1)
    sizes = np.linalg.norm(x[nodes_of[:, 1]] - x[nodes_of[:, 0]], axis=1)
    junction = np.min(np.linalg.norm(centres[:, None, :2] - geo.junction_points()[None], axis=2), axis=1)
    assert np.mean(sizes[junction < 0.4]) < 0.5 * np.mean(sizes[np.hypot(*centres[:, :2].T) < 1.5])


def test_bad_lens_geometry_is_refused():
    with pytest.raises(MeshError, match="overall_length"):
        intraocular_lens(LensGeometry(overall_length=6.5))


def test_rigid_bodies_gap_and_normals():
    axis = np.array([0.0, 0.0, 1.0])
    bore = TaperedBore(axis, 1.25, 1.05, 6.5, 9.5, 11.0)
    x = np.array([[0.0, 1.0, 1.0], [0.0, 1.3, 1.0], [8.0, 1.2, 1.0], [12.0, 2.0, 1.0]])
    gap, normal, acts = bore.gap_normal(x)
    assert gap[:3] == pytest.approx([0.25, -0.05, 1.15 - 1.2])
    assert np.allclose(normal[1], [0.0, -1.0, 0.0]) and list(acts) == [True, True, True, False]
    gap, normal, acts = Plunger(2.0, axis, 1.0).gap_normal(np.array([[1.9, 0.0, 1.0], [1.9, 0.0, 3.0]]))
    assert gap[0] == pytest.approx(-0.1) and list(acts) == [True, False]
    capsule = Capsule(np.array([15.0, 0.0, 1.0]), np.array([5.0, 5.0, 2.0]), 11.0)
    gap, normal, acts = capsule.gap_normal(np.array([[15.0, 0.0, 3.1], [19.0, 0.0, 1.0]]))
    assert gap == pytest.approx([-0.1, 1.0])  # exact on the axes
    assert np.allclose(normal[0], [0.0, 0.0, -1.0])


def test_self_distance_sees_the_rolled_optic_close(lens):
    pytest.importorskip("ipctk")
    from eyemech.problems.contact.self_distance import SelfDistance

    V = dolfinx.fem.functionspace(lens.mesh, basix.ufl.element("Lagrange", "triangle", 2, shape=(3,)))
    u = dolfinx.fem.Function(V)
    probe = SelfDistance(u)
    flat, crossing = probe()
    assert flat > 0.25 and not crossing  # nothing distant within the search radius
    X = V.tabulate_dof_coordinates()
    u.x.array[:] = (rolled(X, 1.0 / 0.9) - X).ravel()  # 2π · 0.9 < 6: the optic overlaps
    _, crossing = probe()
    assert crossing


def test_bad_input_is_refused_before_any_solve():
    with pytest.raises(ParameterError, match="fold_radius"):  # folded lens does not fit the bore
        iol_fold.Parameters(fold_radius=1.5, bore_radius=1.25).validate()
    with pytest.raises(ParameterError, match="fold_radius"):  # optic would overlap itself
        LensParameters(fold_radius=0.8).validate()
    with pytest.raises(ParameterError, match="plunger_speed"):  # steps over the contact
        iol_injection.Parameters(plunger_speed=200.0).validate()
    with pytest.raises(ParameterError, match="optic_diameter"):  # capsule smaller than the optic
        iol_injection.Parameters(optic_diameter=11.0, overall_length=14.0).validate()


def test_a_folded_state_that_passes_through_itself_is_refused(tmp_path):
    """The barrier cannot start from an intersecting state: refused before any solve."""
    pytest.importorskip("ipctk")
    from mpi4py import MPI

    from eyemech.problems.lens.model import LensShell, save_state

    params = iol_injection.Parameters()
    shell = LensShell(params, MPI.COMM_WORLD)
    X = shell.node_coordinates()
    shell.u.x.array[:] = (rolled(X, 1.0 / 0.9) - X).ravel()  # 2π · 0.9 < 6: overlaps
    save_state(tmp_path / "bad.npz", shell, MPI.COMM_WORLD)
    with pytest.raises(ParameterError, match="folded_state.*intersects"):
        iol_injection.run(iol_injection.Parameters(folded_state=str(tmp_path / "bad.npz")), options=QUIET)
    with pytest.raises(ParameterError, match="self_contact_distance"):
        LensParameters(self_contact_distance=0.5).validate()


def test_short_fold_keeps_the_lens_out_of_the_chamber_wall():
    """0.03 s of iol-fold (the compiled lens form is shared with the scenes)."""
    params = iol_fold.Parameters(fold_time=0.03, frames=1)
    q = iol_fold.run(params, options=QUIET).quantities
    assert q["steps"] >= 3  # the first steps are cut back (the roll starts against the haptics)
    # the penalty's penetration f/k: shell forces are ~1e-4 N, k = 1 N/mm
    assert q["max_penetration_mm"] < 1e-3
    assert not q["self_intersecting"]
    assert q["min_self_distance_mm"] > 0.0
