"""The rotation-free P1 lens shell (``problems/lens/rotation_free.py``, issue 23).

References and tolerances
- Kernels: gradient and Hessian against central differences of the energy / gradient
  (step 1e-6 on O(0.1) displacements of O(1) energies: truncation ~1e-12, round-off
  ~1e-16/1e-6 relative: 1e-7 relative asserted; measured 4e-11–1.6e-10).
- Rigid motions cost nothing (the fit commutes with rotations): energy ≤ 1e-20 against
  O(1) energies of a deformed patch (measured 7e-31).
- Patch test: the quadratic fit reproduces any quadratic field, so on an unstructured
  gmsh mesh every triangle with a full patch gets the exact second derivatives (1e-9
  relative: round-off of the inverted 6×6 fit matrices, condition ≲ 1e5).
- Plates: Timoshenko & Woinowsky-Krieger (1959), centre deflection of the square plate
  under uniform load, 0.00406235 (simply supported) and 0.00126532 (clamped) q L⁴/D, with
  the default ``bending="edge"`` curvature on one-diagonal, alternating-diagonal and gmsh
  meshes; second order. Asserted: the error at 32 divisions below 0.5 % (simply supported)
  / 3 % (clamped) and smaller than at 16 (measured at 32: +0.13 / +0.18 / +0.004 % and
  +1.15 / +1.21 / +0.75 %). ``bending="patch"`` on the alternating-diagonal mesh is +74 %:
  a strict xfail recording that defect.
- Mesh direction: a cylinder (R = 4) rolled along and across the direction-biased mesh
  (every square cut along the same diagonal) and across an unstructured mesh: bending
  energies within 2 % of each other (issue 23; measured 0 % and 0.2 %).
- Cantilever rolled to a half circle by M = π E I / L (the exact arc, Sze, Liu & Lo 2004
  problem 3.1 at half its moment): tip within 1 % of L at 32 × 2 squares and 0.35 % at
  64 × 2 (the P2 model's own criterion; measured 0.79 %, 0.21 %: second order); the full
  circle M = 2π E I / L on the centre-line-symmetric mesh 64 × 4 within 1 % of L (measured
  0.70 %; 2.75 % at 32 × 4: second order).
- Scordelis–Lo roof: 0.3024 (MacNeal & Harder 1985), linear. The constant-strain membrane
  locks on the curved roof, so the deflection converges from below at ≈ O(h^1.5)
  (structured 16/32/64: −13.4/−4.4/−1.6 %; gmsh −8.3/−2.8/−1.2 %); asserted at 32: within
  6 % (structured) / 4 % (gmsh) and closer than at 16.
- Cantilever vibration: Euler–Bernoulli ω₁ = 1.8751² √(EI/ρA)/L² = 105.8 rad/s (ν = 0, so the
  plate strip's first mode is the beam's); asserted within 0.5 % at 24 × 4 (measured
  −0.08 % structured, −0.06 % gmsh; second order).
- Solver structure (coarse lens, 250 triangles, 10 steps of the release): PETSc's log counts
  one symbolic Cholesky factorisation per run and as many numeric ones as the run reports,
  for fresh and lagged factors. Converged answer: the tip at the Newton tolerance rtol 1e-6
  against rtol 1e-10 within 1e-8 mm with fresh factors (measured 2.5e-10) and 1e-6 mm with
  lagged ones (measured 1.5e-8: linear convergence), while the tip moves 0.09 mm.
- Self-contact on the P1 surface (ipctk): a U-folded strip pressed onto itself by 5× the
  load that brings its tip to the bottom layer intersects itself without the barrier and
  never with it (ipctk's exact check after every step), resting within d̂.
- Rigid obstacles (nodal penalty on the P1 vertices): gradient and Hessian blocks against
  central differences (1e-6; measured 5e-11, 6e-12), and a sheet pressed onto a floor: the
  reactions carry the load to 1e-6 (measured 2.4e-13).
- Newton's extrapolated start: the Lagrange polynomial through the past positions, exact for
  a quartic (degree 4) / quadratic (degree 2) motion with unequal steps (1e-12 relative:
  round-off). The release's Newton count from the least-potential start (30 steps, fresh):
  69 iterations, 71 factorisations (bounds + 3), one iteration a step from the 18th.
- Lens release (``iol-speed``, paper resolution, Δt = 0.01 s): tip and optic-centre
  displacement histories within 0.05 mm of the P2 C0-IP run at every one of 20 steps
  (issue 23; measured ≤ 0.037 mm tip, ≤ 0.009 mm optic).
"""

from __future__ import annotations

import numpy as np
import pytest

from eyemech.problems.lens import rotation_free as rf
from eyemech.problems.run.parameters import ParameterError


def _bumpy_patch(clamped: bool, bending: str = "edge"):
    points, tris = rf.rectangle_mesh(1.0, 1.0, 4, 4, "structured")
    rng = np.random.default_rng(0)
    points[:, 2] = 0.1 * rng.standard_normal(len(points))
    boundary = (lambda m: ["clamped"] * len(m)) if clamped else None
    return rf.RotationFreeShell(points, tris, 0.1, rf.Material(1.0, 0.3, 1.0), boundary=boundary,
                                bending=bending), rng


@pytest.mark.parametrize("bending", ["edge", "patch"])
@pytest.mark.parametrize("clamped", [False, True])
def test_gradient_and_hessian_against_central_differences(clamped, bending):
    shell, rng = _bumpy_patch(clamped, bending)
    u = 0.05 * rng.standard_normal(shell.n_dofs)
    grad, data = np.zeros(shell.n_dofs), shell.new_data()
    shell.evaluate(u, grad, data)
    K = shell.matrix(data).toarray()
    eps = 1e-6
    fd_grad, fd_hess = np.zeros_like(grad), np.zeros_like(K)
    for i in range(shell.n_dofs):
        d = np.zeros_like(u)
        d[i] = eps
        fd_grad[i] = (shell.energy(u + d) - shell.energy(u - d)) / (2 * eps)
        g_plus, g_minus = np.zeros_like(u), np.zeros_like(u)
        shell.evaluate(u + d, g_plus)
        shell.evaluate(u - d, g_minus)
        fd_hess[:, i] = (g_plus - g_minus) / (2 * eps)
    assert np.abs(grad - fd_grad).max() < 1e-7 * np.abs(grad).max()
    assert np.abs(K - fd_hess).max() < 1e-7 * np.abs(K).max()
    assert np.abs(K - K.T).max() < 1e-12 * np.abs(K).max()
    # the upper-triangle assembly (what the LDLᵀ solves read): the same entries (round-off apart)
    upper = np.zeros(len(shell.upper["indices"]))
    shell.evaluate(u, np.zeros(shell.n_dofs), upper, upper=True)
    import scipy.sparse

    U = scipy.sparse.csr_matrix((upper, shell.upper["indices"], shell.upper["indptr"]),
                                shape=K.shape).toarray()
    assert np.abs(U - np.triu(K)).max() < 1e-13 * np.abs(K).max()


@pytest.mark.parametrize("bending", ["edge", "patch"])
def test_rigid_motion_costs_nothing(bending):
    shell, _ = _bumpy_patch(False, bending)
    a, b = 0.7, 1.1
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]) @ \
        np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    X = shell.X
    assert shell.energy((X @ R.T + 3.0 - X).ravel()) < 1e-20


@pytest.mark.parametrize("bending", ["edge", "patch"])
def test_quadratic_fields_are_reproduced_on_an_unstructured_mesh(bending):
    points, tris = rf.rectangle_mesh(1.0, 1.0, 8, 8, "unstructured")
    shell = rf.RotationFreeShell(points, tris, 0.01, rf.Material(1.0, 0.3), bending=bending)
    full = np.all(shell.opposite >= 0, axis=1)
    if bending == "edge":  # the neighbours' patches must be full too
        full &= np.array([np.all(shell.opposite[shell.neighbour[t]] >= 0) if full[t] else False
                          for t in range(len(full))])
    assert full.sum() > 0.5 * len(full)
    x, y = points[:, 0], points[:, 1]
    w = 0.3 * x * x + 0.5 * x * y - 0.2 * y * y  # Hessian [[0.6, 0.5], [0.5, -0.4]]
    for t in np.flatnonzero(full):
        e1 = points[shell.tri[t, 1]] - points[shell.tri[t, 0]]
        e1 /= np.linalg.norm(e1)
        e2 = np.cross([0, 0, 1.0], e1)  # the triangles are oriented +z
        F = np.array([e1[:2], e2[:2]])
        exact = F @ np.array([[0.6, 0.5], [0.5, -0.4]]) @ F.T
        H = shell.B[t] @ w[shell.nodes[t]]  # ∂₁₁, ∂₂₂, ∂₁₂ in the triangle's frame
        assert np.allclose(H, [exact[0, 0], exact[1, 1], exact[0, 1]], rtol=0, atol=1e-9)


@pytest.mark.parametrize("support", ["simply", "clamped"])
@pytest.mark.parametrize("kind", ["structured", "crossed", "unstructured"])
def test_square_plate_converges_to_timoshenko(support, kind):
    reference = rf.PLATE_REFERENCE[support]
    errors = [abs(rf.plate_centre_deflection(support, n, kind) / reference - 1) for n in (16, 32)]
    assert errors[1] < {"simply": 0.005, "clamped": 0.03}[support]
    assert errors[1] < errors[0]


@pytest.mark.xfail(strict=True, reason="known defect of bending=patch: on the alternating-diagonal "
                   "('crossed') mesh the 6-node fits let an oscillation lower the bending energy: +74 % "
                   "(simply supported), not converging (docs/iol.md §4b); bending=edge is the fix")
def test_patch_curvature_on_crossed_mesh():
    errors = [abs(rf.plate_centre_deflection("simply", n, "crossed", bending="patch")
                  / rf.PLATE_REFERENCE["simply"] - 1) for n in (16, 32)]
    assert errors[1] < 0.005


@pytest.mark.parametrize("kind, tolerance", [("structured", 0.06), ("unstructured", 0.04)])
def test_scordelis_lo_converges_from_below(kind, tolerance):
    errors = [rf.scordelis_lo_deflection(n, kind) / rf.SCORDELIS_LO_REFERENCE - 1 for n in (16, 32)]
    assert -tolerance < errors[1] < 0.0
    assert abs(errors[1]) < abs(errors[0])


@pytest.mark.parametrize("kind, tolerance", [("structured", 0.005), ("unstructured", 0.005)])
def test_cantilever_first_frequency(kind, tolerance):
    assert abs(rf.cantilever_frequency(24, 4, kind)["error"]) < tolerance


@pytest.mark.parametrize("kind", ["structured", "unstructured"])
def test_rolled_cylinder_energy_does_not_depend_on_the_mesh_direction(kind):
    ratios = rf.rolled_energy_ratio(16, kind, angles=(0.0, 90.0))
    assert abs(ratios[0.0] / ratios[90.0] - 1) < 0.02


@pytest.mark.parametrize("divisions, tolerance", [(32, 0.01), (64, 0.0035)])
def test_cantilever_rolled_to_a_half_circle(divisions, tolerance):
    result = rf.cantilever_rolling(divisions, 2, moment_fraction=0.5, load_steps=16)
    assert result["tip_error"] < tolerance


def test_cantilever_rolled_to_a_full_circle():
    # the mesh symmetric about the strip's centre line (alternating diagonals, 4 across): on the
    # one-diagonal mesh the end drifts sideways past ≈ 160° and Newton fails near 225°
    result = rf.cantilever_rolling(64, 4, moment_fraction=1.0, load_steps=32, kind="crossed")
    assert result["tip_error"] < 0.01


def test_bad_meshes_and_thickness_are_refused():
    points, tris = rf.rectangle_mesh(1.0, 1.0, 2, 2)
    material = rf.Material(1.0, 0.3)
    extra = np.vstack([points, [[0.5, 0.5, 1.0]]])
    edge = tris[0][[1, 2]]  # a third triangle on an interior edge: non-manifold
    with pytest.raises(rf.MeshInputError, match="non-manifold"):
        rf.RotationFreeShell(extra, np.vstack([tris, [[edge[0], edge[1], len(points)]]]), 0.1, material)
    inverted = tris.copy()
    inverted[3] = inverted[3][[0, 2, 1]]
    with pytest.raises(rf.MeshInputError, match="inverted"):
        rf.RotationFreeShell(points, inverted, 0.1, material)
    with pytest.raises(ValueError, match="thickness"):
        rf.RotationFreeShell(points, tris, 0.0, material)


def test_iol_speed_refuses_what_the_fast_model_cannot_do():
    from eyemech.problems import iol_speed

    with pytest.raises(ParameterError, match="method"):
        iol_speed.Parameters(model="p1-rotation-free", method="linearised").validate()
    with pytest.raises(ParameterError, match="method"):
        iol_speed.Parameters(model="p1-rotation-free", jacobian="matrix-free").validate()
    with pytest.raises(ParameterError, match="surface_contact"):
        iol_speed.Parameters(surface_contact=True).validate()
    with pytest.raises(ParameterError, match="stall"):
        iol_speed.Parameters(model="p1-rotation-free", jacobian="lagged", stall=1.5).validate()
    with pytest.raises(ParameterError, match="haptic_thickness"):
        iol_speed.Parameters(model="p1-rotation-free", haptic_thickness=-0.1).validate()
    from mpi4py import MPI

    from eyemech.problems.run.context import RunOptions

    # Newton cannot take it in 25 iterations (it stalls at 1e-4 of the start residual); with the
    # inertia correction Δt = 0.2 s converges in 18 (docs/iol.md §4b)
    with pytest.raises(ParameterError, match="time_step"):
        iol_speed.run(iol_speed.Parameters(model="p1-rotation-free", steps=2, time_step=5.0),
                      comm=MPI.COMM_SELF, options=RunOptions(fields=False, pictures=False))


def _coarse_lens_release(**changes):
    from eyemech.problems import iol_speed

    params = iol_speed.Parameters(model="p1-rotation-free", mesh_scale=2.0, **changes)  # 250 triangles
    return params, rf.FastLens.build(params)


def test_one_symbolic_factorisation_per_run():
    import eyemech.meshes  # noqa: F401, I001  (first: it orders MPI ahead of PETSc)
    from petsc4py import PETSc

    PETSc.Log.begin()
    count = lambda name: PETSc.Log.Event(name).getPerfInfo()["count"]  # noqa: E731
    params, lens = _coarse_lens_release()
    for stall in (None, 0.2):
        symbolic, numeric = count("MatCholFctrSym"), count("MatCholFctrNum")
        run = rf.release(params, 10, lens, stall)
        assert count("MatCholFctrSym") - symbolic == 1
        assert count("MatCholFctrNum") - numeric == run["counts"]["factorisations"]
        assert run["counts"]["iterations"] == sum(run["history"]["iterations"])
        # fresh: one factorisation per iteration and one more per shift of an indefinite Hessian
        # (measured 44 + 3, the first Hessian shifted once: 3 tries); lagged: fewer than iterations
        made = run["counts"]["factorisations"] - run["counts"]["iterations"]
        assert run["counts"]["shifted"] >= 1
        assert (made >= run["counts"]["shifted"]) if stall is None else made < 0


def test_newton_tolerance_and_lagged_factors_give_the_converged_answer():
    # the release's tip over 10 steps (it moves 0.09 mm) at rtol 1e-6 (fresh and lagged factors)
    # against rtol 1e-10: measured 3.9e-7 mm (fresh: the first step stops just under the
    # tolerance after the shifted iterations; 2.5e-10 without the inertia correction) and
    # 1.5e-8 mm (lagged)
    params, lens = _coarse_lens_release()
    tight, _ = _coarse_lens_release(rtol=1e-10)
    reference = np.asarray(rf.release(tight, 10, lens)["history"]["tip"])
    for stall, bound in ((None, 1e-6), (0.2, 1e-6)):
        tip = np.asarray(rf.release(params, 10, lens, stall)["history"]["tip"])
        assert np.abs(tip - reference).max() < bound
    assert np.linalg.norm(reference[-1] - reference[0]) > 0.05  # the lens has moved (measured 0.09 mm)


def _folded_strip(nx: int = 40, ny: int = 10, length: float = 2.0, width: float = 0.5, flat: float = 0.7,
                  radius: float = 0.1):
    """A strip folded into a U at rest: a bottom layer (x < ``flat``, z = 0), a half circle of
    ``radius`` and a top layer at z = 2 radius running back over the bottom one."""
    points, tris = rf.rectangle_mesh(length, width, nx, ny)
    s = points[:, 0]
    bend = flat + np.pi * radius
    x = np.where(s < flat, s,
                 np.where(s < bend, flat + radius * np.sin((s - flat) / radius), flat - (s - bend)))
    z = np.where(s < flat, 0.0, np.where(s < bend, radius * (1 - np.cos((s - flat) / radius)), 2 * radius))
    return np.column_stack([x, points[:, 1], z]), tris, s < flat - 1e-9


@pytest.mark.parametrize("with_contact", [True, False])
def test_folded_strip_pressed_onto_itself_does_not_penetrate(with_contact):
    # the U-folded strip (h 0.05, E 1, bottom layer held) with its top layer pressed down by
    # 1e-4 N/mm² (5× what brings its tip to the bottom layer: q L⁴/(8D) = 0.2 mm at 1.8e-5);
    # without contact it passes through (ipctk finds intersections; the top dips to z ≈ −0.22),
    # with the barrier (d̂ 0.02 mm), CCD-limited updates and the energy line search no step
    # intersects (measured: the smallest distance ≈ 0.019 mm; 11 Newton iterations in the first step)
    pytest.importorskip("ipctk")
    from eyemech.problems.lens.surface_contact import SurfaceSelfContact

    points, tris, bottom = _folded_strip()
    shell = rf.RotationFreeShell(points, tris, 0.05, rf.Material(1.0, 0.3, 1.2e-9))
    contact = SurfaceSelfContact(points, shell.tri, dhat=0.02, stiffness=1.0)
    dyn = rf.Dynamics(shell, 0.01, 2e4, fixed=(3 * np.flatnonzero(bottom)[:, None] + np.arange(3)).ravel(),
                      max_iterations=60)
    if with_contact:
        dyn.set_contact(contact)
    dyn.force = shell.pressure_load(1e-4, (0.0, 0.0, -1.0))
    dyn.reset(np.zeros(shell.n_dofs))
    intersecting = []
    for _ in range(15):
        dyn.step()
        intersecting.append(contact.intersecting(points + dyn.u.reshape(-1, 3)))
    if with_contact:
        assert not any(intersecting)
        assert 0.0 < contact.min_distance(points + dyn.u.reshape(-1, 3)) < 0.02  # in contact
        assert dyn.counts["pattern_growths"] >= 1 and dyn.counts["step_limits"] >= 1
    else:
        assert any(intersecting)  # the same load passes through without the barrier


class _Floor:
    """The plane z = −0.02 (gap z + 0.02, normal +z) acting everywhere."""

    def gap_normal(self, x):
        return x[:, 2] + 0.02, np.tile([0.0, 0.0, 1.0], (len(x), 1)), np.ones(len(x), bool)


def test_rigid_obstacle_penalty_derivatives_and_balance():
    # a flat sheet on the floor z = −0.02 pressed by 1e-3 N/mm²; penalty 1 N/mm per vertex,
    # smoothing 2 µm. Gradient = ∇ energy and the blocks = ∇ gradient (a plane's normal is
    # constant, so the quasi-Newton tangent is exact): central differences (step 1e-7 on
    # O(0.02) gaps: 1e-6 relative, measured 5e-11 and 6e-12); at rest the floor carries the load:
    # Σ reactions = q A to 1e-6 (measured 2.4e-13)
    from eyemech.problems.lens.surface_contact import NodalObstacles

    points, tris = rf.rectangle_mesh(1.0, 1.0, 6, 6)
    shell = rf.RotationFreeShell(points, tris, 0.05, rf.Material(1.0, 0.3, 1e-6))
    floor = NodalObstacles({"floor": _Floor()}, stiffness=1.0)
    x = points + np.random.default_rng(1).uniform(-0.03, -0.0215, points.shape) * [0, 0, 1]  # all pressed
    grad = floor.gradient(x)
    nodes, blocks = floor.blocks(x)
    eps = 1e-7
    for v in range(0, len(points), 5):
        up, down = x.copy(), x.copy()
        up[v, 2] += eps
        down[v, 2] -= eps
        slope = (floor.energy(up) - floor.energy(down)) / (2 * eps)
        assert abs(slope - grad[3 * v + 2]) < 1e-6 * np.abs(grad).max()
        fd = (floor.gradient(up)[3 * v + 2] - floor.gradient(down)[3 * v + 2]) / (2 * eps)
        assert abs(fd - blocks[list(nodes).index(v), 2, 2]) < 1e-6 * floor.stiffness
    dyn = rf.Dynamics(shell, 1.0, 0.0, max_iterations=40)
    dyn.set_obstacles(floor)
    dyn.force = shell.pressure_load(1e-3, (0.0, 0.0, -1.0))
    dyn.reset(np.zeros(shell.n_dofs))
    for _ in range(20):
        dyn.step()
    reaction = floor.gradient(points + dyn.u.reshape(-1, 3)).reshape(-1, 3).sum(axis=0)
    assert abs(-reaction[2] / 1e-3 - 1.0) < 1e-6
    # each vertex carries ≈ q A / 49 = 2e-5 N: with k = 1 N/mm it rests inside the ±2 µm smoothing
    # band about the floor (measured gaps 1.5–1.8 µm)
    gap = (points + dyn.u.reshape(-1, 3))[:, 2] + 0.02
    assert np.all(np.abs(gap) < floor.smoothing)


@pytest.mark.slow
def test_lens_release_agrees_with_p2():
    from mpi4py import MPI

    from eyemech.problems import iol_speed
    from eyemech.problems.run.context import RunOptions

    options = RunOptions(fields=False, pictures=False)
    runs = {model: iol_speed.run(iol_speed.Parameters(model=model, steps=20), comm=MPI.COMM_SELF,
                                 options=options).quantities for model in ("p2-c0ip", "p1-rotation-free")}
    for key in ("tip_history", "optic_history"):
        p2, p1 = (np.asarray(runs[m][key]) for m in ("p2-c0ip", "p1-rotation-free"))
        assert np.linalg.norm(p1 - p2, axis=1).max() < 0.05


class _Ground:
    """The plane z = 0 (gap z, normal +z) acting everywhere."""

    def gap_normal(self, x):
        return x[:, 2], np.tile([0.0, 0.0, 1.0], (len(x), 1)), np.ones(len(x), bool)


def test_sheet_sliding_on_a_wall_stops_where_coulomb_says():
    """A stiff square sheet (1 × 1, h 0.1, ρ 1) pressed on the ground by q = 0.01 and launched
    at v0 = 0.1 along x, μ = 0.5, no damping: Coulomb decelerates it by a = μ q/(ρ h) = 0.05, and
    backward Euler (v_{n+1} = v_n − a Δt, u_{n+1} = u_n + Δt v_{n+1}) stops it after
    N = v0/(a Δt) = 100 steps of Δt = 0.02, having slid v0²/(2a) − v0 Δt/2 = 0.099 (the
    continuous 0.1 less the scheme's half step). The lagged smoothed Coulomb law (ε = 1e-5
    mm per step ≪ the slips of 2e-3) gives it to 1e-4 (measured 7.9e-6: the lagged normal
    force is the settled penalty force to 1.5e-6). The friction's force is the gradient of its
    potential and its Hessian the force's derivative (central differences, step 1e-8 on slips
    of 1e-3: truncation ~1e-10)."""
    from eyemech.problems.lens.surface_contact import NodalObstacles

    mu, q, rho, h, v0, dt = 0.5, 1e-2, 1.0, 0.1, 0.1, 0.02
    points, tris = rf.rectangle_mesh(1.0, 1.0, 2, 2)
    shell = rf.RotationFreeShell(points, tris, h, rf.Material(1.0, 0.3, rho))
    ground = NodalObstacles({"ground": _Ground()}, 10.0, friction={"ground": mu}, slip=1e-5)
    dyn = rf.Dynamics(shell, dt, 60.0, max_iterations=40)  # damped (≈ critically) while it settles
    dyn.set_obstacles(ground)
    dyn.force = shell.pressure_load(q, (0.0, 0.0, -1.0))
    dyn.reset(np.zeros(shell.n_dofs))

    def step():
        ground.begin_step(shell.X + dyn.u.reshape(-1, 3))
        return dyn.step()

    for _ in range(100):
        step()
    # the derivatives of the lagged friction at a slipped state
    ground.begin_step(shell.X + dyn.u.reshape(-1, 3))
    jitter = np.random.default_rng(2).uniform(-1e-3, 1e-3, points.shape) * [1, 1, 0]
    x = shell.X + dyn.u.reshape(-1, 3) + jitter
    grad = ground.gradient(x)
    nodes, blocks = ground.blocks(x)
    step_size = 1e-8
    for v in (0, 4, 8):
        for c in (0, 1):
            up, down = x.copy(), x.copy()
            up[v, c] += step_size
            down[v, c] -= step_size
            assert abs((ground.energy(up) - ground.energy(down)) / (2 * step_size) - grad[3 * v + c]) \
                < 1e-6 * np.abs(grad).max()
            fd = (ground.gradient(up) - ground.gradient(down)).reshape(-1, 3)[v] / (2 * step_size)
            hessian = sum(b[:, c] for n, b in zip(nodes, blocks) if n == v)
            assert np.allclose(fd, hessian, atol=1e-5 * np.abs(blocks).max())
    # the slide
    dyn.c = 0.0
    start = dyn.u.reshape(-1, 3)[:, 0].mean()
    dyn.v = np.tile([v0, 0.0, 0.0], len(points))
    dyn.v_previous = None
    for _ in range(200):
        step()
    slid = dyn.u.reshape(-1, 3)[:, 0].mean() - start
    a = mu * q / (rho * h)
    assert slid == pytest.approx(v0 ** 2 / (2 * a) - 0.5 * v0 * dt, rel=1e-4)
    assert np.abs(dyn.v).max() < 1e-5  # stopped (the ε-viscous law leaves a creep of < ε/Δt)


def test_extrapolated_start_is_exact_for_a_quartic_motion_with_unequal_steps():
    """``Dynamics._extrapolation`` is the Lagrange polynomial through the past positions (rebuilt
    from the backward-Euler velocities and their step lengths): a motion u(t) of degree 4 is
    extrapolated exactly by degree 4 (round-off: 1e-12 relative asserted), and degree 2 is
    exact for a quadratic one, whatever the step lengths (a cut step, then doubled ones)."""
    params, lens = _coarse_lens_release()
    dyn = rf.Dynamics(lens.shell, 0.01, params.damping)
    rng = np.random.default_rng(1)
    coefficients = rng.standard_normal((5, lens.shell.n_dofs))
    for degree in (2, 4):
        motion = lambda t: sum(c * t ** k for k, c in enumerate(coefficients[:degree + 1]))  # noqa: E731
        times = [0.0, 0.01, 0.015, 0.02, 0.04]  # steps 0.01, 0.005, 0.005, 0.02
        steps = np.diff(times)
        velocities = [(motion(times[k + 1]) - motion(times[k])) / steps[k] for k in range(len(steps))]
        dyn.v_step = steps[-1]
        dyn.past = tuple((steps[k], velocities[k]) for k in range(len(steps) - 2, -1, -1))
        dyn.dt = 0.02
        predicted = dyn._extrapolation(motion(times[-1]), velocities[-1], degree)
        exact = motion(times[-1] + dyn.dt)
        assert np.abs(predicted - exact).max() < 1e-12 * np.abs(exact).max()


def test_release_newton_iterations_from_the_least_potential_start():
    """The paper-resolution release, 30 steps, fresh factors: Newton from the start of least
    incremental potential (u_n, degree-2 and degree-4 extrapolations) takes 69 iterations and
    71 factorisations (the first Hessian shifted once), one iteration a step from the 18th
    (docs/iol.md §4b; the start by least residual among u_n, degree 1 and 2 took 91). Bounds:
    the counts + 3 (round-off may move a step across the tolerance). Gradient and Hessian
    passes: 158 (the degree-4 start, chosen from the 11th step on, is evaluated first with
    its Jacobian; every candidate evaluated each step: 196)."""
    from eyemech.problems import iol_speed

    params = iol_speed.Parameters(model="p1-rotation-free")
    run = rf.release(params, 30, rf.FastLens.build(params))
    iterations = run["history"]["iterations"]
    assert sum(iterations) <= 69 + 3 and run["counts"]["factorisations"] <= 71 + 3
    assert run["counts"]["iterations"] == sum(iterations)
    assert max(iterations[20:]) == 1
    assert run["counts"]["residuals"] <= 158 + 6


def test_self_contact_skips_its_narrow_phase_only_where_no_pair_can_be_within_dhat():
    # the U-folded strip's top layer lowered onto the bottom one in 0.005 mm moves (layers
    # 0.2 mm apart down to 0.005): at every state the pairs within d̂ (their number and the
    # smallest distance) are ipctk's own full build's; the narrow phase is skipped while the
    # kept candidates' clearance less twice the drift since their build exceeds d̂ (measured:
    # skipped at the first states, built once the layers come near)
    ipctk = pytest.importorskip("ipctk")
    from eyemech.problems.lens.surface_contact import SurfaceSelfContact

    points, tris, _ = _folded_strip()
    contact = SurfaceSelfContact(points, tris, dhat=0.02, stiffness=1.0)
    top = points[:, 2] > 0.2 - 1e-9
    for drop in np.arange(0.0, 0.196, 0.005):
        x = points.copy()
        x[top, 2] -= drop
        kept = contact.collisions(x)
        full = ipctk.NormalCollisions()
        full.build(contact.mesh, np.asfortranarray(x), contact.dhat, broad_phase=ipctk.SweepAndPrune())
        assert len(kept) == len(full)
        if len(full):
            assert kept.compute_minimum_distance(contact.mesh, x) == pytest.approx(
                full.compute_minimum_distance(contact.mesh, x), rel=1e-12)
    assert contact.narrow_phases_skipped >= 1 and len(full) > 0
