"""A parameter study compiles each form once: material numbers, loads and mesh-dependent
numbers enter the forms as ``dolfinx.fem.Constant``s, so that a sweep over moduli and mesh
sizes reuses the compiled kernels (FFCx compiles on a cache miss only; a literal baked into
the form would make every new value a miss). Counted, not timed; the last test checks
that the per-case compile time ``eyemech sweep`` writes to ``sweep.csv`` shows it."""

from __future__ import annotations

import csv
import os
import random
import subprocess

import pytest
from mpi4py import MPI

from eyemech.problems import keratotomy, liquid_sphere, scleral_buckling, sphere_inflation
from eyemech.problems.run.context import RunOptions

QUIET = RunOptions(fields=False, pictures=False)


# values never used before in this cache: a form with them baked in would have to compile
MODULI = [0.05 * (1.0 + random.random()) for _ in range(3)]


@pytest.mark.parametrize("scene, sizes", [(sphere_inflation, (4.0, 3.5, 3.0)),
                                          (liquid_sphere, (4.0, 3.5, 3.0))],
                         ids=["sphere-inflation", "liquid-sphere"])
def test_a_sweep_over_modulus_and_mesh_size_compiles_nothing_after_its_first_case(scene, sizes,
                                                                                   compilations):
    scene.run(scene.Parameters(c10=MODULI[0], mesh_size=sizes[0]), comm=MPI.COMM_SELF, options=QUIET)
    first = len(compilations)
    for c10, size in zip(MODULI[1:], sizes[1:]):
        scene.run(scene.Parameters(c10=c10, mesh_size=size), comm=MPI.COMM_SELF, options=QUIET)
    assert compilations[first:] == []


def test_keratotomy_with_new_moduli_and_mesh_size_compiles_nothing_after_its_first_case(compilations):
    """Both corneas (intact and 8 incisions, a quarter) in two short creep runs (2 fixed
    steps): the second case's moduli, relaxation time, IOP and mesh size are new to this
    process and the cache. ≈ 5 s a case."""
    short = dict(symmetry="quarter", azimuthal_divisions=8, t_end=600.0, first_dt=300.0,
                 time_stepping="fixed")

    def case(mesh_size: float) -> keratotomy.Parameters:
        return keratotomy.Parameters(mu_inf=0.03 + 0.02 * random.random(),
                                     mu_v=0.02 + 0.02 * random.random(),
                                     tau=3000.0 + 1000.0 * random.random(),
                                     iop_mmHg=14.0 + 2.0 * random.random(),
                                     mesh_size=mesh_size, **short)

    keratotomy.run(case(2.0), comm=MPI.COMM_SELF, options=QUIET)
    first = len(compilations)
    keratotomy.run(case(1.7), comm=MPI.COMM_SELF, options=QUIET)
    assert compilations[first:] == []


def test_eye_with_new_moduli_penalty_and_mesh_compiles_nothing_after_its_first_case(compilations):
    """The eye without the settling step (three stages): the coarse resolution (8 cube
    edges), then mesh_size = 2.2 mm (10 edges) with new c_sclera, penalty factor (the
    buckle's penalty follows both and the element size), detachment height (the cavity
    wall's area and volume), bulk modulus and IOP. 46 s for both under a load of 2 (the
    defaults' 2 mm of travel). The lead's finding, 5 Jacobian blocks compiled again in a
    process's second run, came from UFL's operand order (forms/ordering.py, tested below
    on its own)."""

    def case(**overrides) -> scleral_buckling.Parameters:
        return scleral_buckling.Parameters(settle=False, c_sclera=0.08 + 0.01 * random.random(),
                                           penalty_factor=20.0 + 10.0 * random.random(), **overrides)

    scleral_buckling.run(case(resolution="coarse"), comm=MPI.COMM_SELF, options=QUIET)
    first = len(compilations)
    scleral_buckling.run(case(mesh_size=2.2, detachment_height=0.4 + 0.2 * random.random(),
                              bulk_modulus=2000.0 + 100.0 * random.random(),
                              iop_mmHg=14.0 + 2.0 * random.random()),
                         comm=MPI.COMM_SELF, options=QUIET)
    assert compilations[first:] == []


def test_eye_with_a_new_buckle_and_sutures_compiles_nothing_after_its_first_case(compilations):
    """The planning map's factors (``eyemech study buckling-planning``): the coarse eye
    twice, settle = false, the band shortened (the default), the second case with a new buckle
    position, band and tire widths, tire height, corner radius, tire arc, suture width,
    bite radius and penalty smoothing ε (> 0 in both: ε = 0 is another form). The
    buckle's sizes and position, the bites' centres and radius and ε are Constants
    (forms/buckle.py, forms/sutures.py); a literal among them would compile the eye's
    residual and Jacobian blocks again. ≈ 10 s a case."""

    def case() -> scleral_buckling.Parameters:
        return scleral_buckling.Parameters(
            resolution="coarse", settle=False,
            buckle_position=12.0 + random.random(), band_width=2.0 + random.random(),
            tire_width=6.5 + random.random(), tire_height=0.8 + 0.4 * random.random(),
            buckle_corner_radius=0.2 + 0.2 * random.random(), tire_arc_deg=80.0 + 20.0 * random.random(),
            suture_width=9.0 + random.random(), suture_bite_radius=1.0 + 0.4 * random.random(),
            contact_smoothing=0.002 + 0.002 * random.random())

    scleral_buckling.run(case(), comm=MPI.COMM_SELF, options=QUIET)
    first = len(compilations)
    scleral_buckling.run(case(), comm=MPI.COMM_SELF, options=QUIET)
    assert compilations[first:] == []


@pytest.mark.parametrize("later", [(109, 117), (209, 217), (1009, 1017)])
def test_a_forms_signature_does_not_depend_on_its_constants_creation_counts(later):
    """The same form over two Constants created 9th and 17th in a process, or later
    (a later run of a scene): UFL orders a product's operands by ``repr``, whose
    count '17' sorts before '9' but '117' after '109', so without forms/ordering.py the
    form is ``b·a`` in the first run and ``a·b`` in the second: a new signature and a
    new compilation (measured on the coarse eye: 10 of 66 forms)."""
    import basix.ufl
    import ufl
    from ufl.constant import Constant

    import eyemech.forms  # noqa: F401  (installs the order)

    def signature(first: int, second: int) -> str:
        cell = "tetrahedron"
        domain = ufl.Mesh(basix.ufl.element("Lagrange", cell, 1, shape=(3,)))
        u = ufl.Coefficient(ufl.FunctionSpace(domain, basix.ufl.element("Lagrange", cell, 1)))
        a, b = Constant(domain, count=first), Constant(domain, count=second)
        return ((a * b + a / b) * u * ufl.dx).signature()

    assert signature(9, 17) == signature(*later)


def test_sweep_csv_records_each_cases_form_compilation_near_zero_after_the_first(tmp_path):
    """``sweep.csv``'s ``form_compilation_s`` (the run contract's timing of building the
    residual and Jacobian forms): in a fresh FFCx cache the first case compiles them; the
    cases after it change only the Constant c10 and find the kernels compiled, leaving the
    UFL processing. Measured (mesh_size 4, 2 shared cores under load): 10.9 s for the
    first case, 0.098 and 0.086 s (0.9 %) for the others; the bound 10 % leaves room for
    the load, a recompilation would be ≈ 100 %."""
    from conftest import BIN

    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))  # a cold JIT cache
    moduli = ",".join(f"{0.05 * (1.0 + random.random()):.6f}" for _ in range(3))
    proc = subprocess.run([str(BIN / "eyemech"), "sweep", "sphere-inflation", "--grid",
                           f"c10={moduli}", "--set", "mesh_size=4", "--out", str(tmp_path / "out"),
                           "--no-fields", "--no-pictures", "--quiet"],
                          capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stderr
    rows = list(csv.DictReader((tmp_path / "out" / "sweep.csv").open()))
    assert [r["status"] for r in rows] == ["ok"] * 3
    first, *later = (float(r["form_compilation_s"]) for r in rows)
    assert first > 1.0  # FFCx and the C compiler ran
    assert all(t < 0.1 * first for t in later), (first, later)


def test_interpolated_stress_has_one_signature_in_every_run():
    """An interpolated expression built on ``deformation_gradient`` (a ``ufl.variable``,
    whose label is numbered per process) hashes the same for two meshes once passed
    through ``without_variables``; without it FFCx would compile it again in each run and
    each sweep case (its label is hashed as numbered)."""
    import dolfinx
    import ffcx.naming
    from mpi4py import MPI

    from eyemech.forms import Yeoh, cauchy_stress, deformation_gradient, von_mises, without_variables

    def signature(strip: bool) -> str:
        mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1, dolfinx.mesh.CellType.hexahedron)
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
        Q = dolfinx.fem.functionspace(mesh, ("DG", 0))
        u, c10, c20 = dolfinx.fem.Function(V), dolfinx.fem.Function(Q), dolfinx.fem.Function(Q)
        stress = von_mises(cauchy_stress(Yeoh(c10, c20), deformation_gradient(u)))
        expression = without_variables(stress) if strip else stress
        return ffcx.naming.compute_signature([(expression, Q.element.interpolation_points)], "")

    assert signature(True) == signature(True)
    assert signature(False) != signature(False)  # the labels are what differs


def test_a_cached_form_is_found_without_listing_the_cache_folder(tmp_path, compilations, monkeypatch):
    """problems/run/jit_cache.py: the second build of a form finds the compiled module by
    its file name (FFCx 0.11 lists the whole cache folder for every form, 35 ms with
    13,000 files), compiles nothing and assembles the same number; a folder listing
    raises here, so FFCx's own lookup would fail the test."""
    import importlib.machinery

    import dolfinx
    import ufl

    from eyemech.problems.run import jit_cache

    jit_cache.install()
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
    c = dolfinx.fem.Constant(mesh, 3.0)
    options = {"cache_dir": str(tmp_path / "jit")}

    def area_times_c() -> float:
        form = dolfinx.fem.form(c * ufl.dx(domain=mesh), jit_options=options)
        return dolfinx.fem.assemble_scalar(form)

    assert area_times_c() == pytest.approx(3.0)
    assert len(compilations) == 1

    def listing(*_args, **_kwargs):
        raise AssertionError("the JIT cache folder was listed")

    monkeypatch.setattr(importlib.machinery.FileFinder, "_fill_cache", listing)
    c.value = 5.0
    assert area_times_c() == pytest.approx(5.0)
    assert len(compilations) == 1


def test_a_compilation_left_by_a_killed_process_is_taken_over(tmp_path, compilations):
    """problems/run/jit_cache.py: a process killed while compiling a form leaves its C file
    without the ready marker; FFCx then makes every later process wait and time out. With
    the owner record naming a process that has ended, the next process moves the C file
    aside and compiles the form itself; a live owner, or no record, is waited for."""
    import socket

    import dolfinx
    import ufl

    from eyemech.problems.run import jit_cache

    jit_cache.install()
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
    cache = tmp_path / "jit"
    options = {"cache_dir": str(cache), "timeout": 2}
    integrand = dolfinx.fem.Constant(mesh, 7.0) * ufl.dx(domain=mesh)
    assert dolfinx.fem.assemble_scalar(dolfinx.fem.form(integrand, jit_options=options)) == pytest.approx(7.0)
    (c_file,) = cache.glob("*.c")
    for path in cache.iterdir():  # the cache as a killed compilation leaves it
        path.unlink()
    c_file.write_text("")
    ended = subprocess.Popen(["true"])
    ended.wait()
    c_file.with_suffix(".c.owner").write_text(f"{socket.gethostname()} {ended.pid}\n")

    assert dolfinx.fem.assemble_scalar(dolfinx.fem.form(integrand, jit_options=options)) == pytest.approx(7.0)
    assert len(compilations) == 2
    assert c_file.with_suffix(".c.abandoned").exists() and c_file.with_suffix(".c.cached").exists()
    assert c_file.with_suffix(".c.owner").read_text().split() == [socket.gethostname(), str(os.getpid())]

    # an owner that still runs (this process), or a C file without a record: FFCx's wait
    module = c_file.stem
    for owner in (f"{socket.gethostname()} {os.getpid()}", None):
        for path in cache.iterdir():
            path.unlink()
        c_file.write_text("")
        if owner:
            c_file.with_suffix(".c.owner").write_text(owner)
        with pytest.raises(TimeoutError, match="timed out"):
            jit_cache.cached_module(module, [], cache, timeout=1)
        assert c_file.exists() and not c_file.with_suffix(".c.abandoned").exists()
