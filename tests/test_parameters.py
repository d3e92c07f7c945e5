"""Parameter handling: typed overrides, TOML configs and errors that name the key.
No solves here — these are the checks that run before anything is built."""

from __future__ import annotations

import pytest

from eyemech.problems import sphere_inflation as si
from eyemech.problems.run.parameters import ParameterError, build, check, describe, load_toml


def test_defaults_are_valid():
    params = build(si.Parameters)
    assert params.inner_radius == 10.0 and params.outer_radius == 12.0


def test_overrides_are_typed_from_the_dataclass():
    params = build(si.Parameters, {"pressure": "0.02", "load_steps": "3", "element": "P2P1"})
    assert params.pressure == pytest.approx(0.02) and isinstance(params.load_steps, int)


@pytest.mark.parametrize("overrides, key, words", [
    ({"presure": "1"}, "presure", "valid keys are"),
    ({"pressure": "high"}, "pressure", "cannot read"),
    ({"load_steps": "2.5"}, "load_steps", "integer"),
    ({"c10": "0"}, "c10", "> 0"),
    ({"c10": "-1"}, "c10", "> 0"),
    ({"outer_radius": "9"}, "outer_radius", "inner_radius"),
    ({"mesh_size": "-0.5"}, "mesh_size", ">= 0"),  # 0 = derived from cells_across_wall
    ({"element": "Q9"}, "element", "one of"),
])
def test_bad_input_names_the_key(overrides, key, words):
    with pytest.raises(ParameterError) as info:
        build(si.Parameters, overrides)
    assert info.value.key == key
    assert key in str(info.value) and words in str(info.value)


def test_unknown_key_lists_the_valid_ones():
    with pytest.raises(ParameterError) as info:
        build(si.Parameters, {"radius": "1"})
    assert "inner_radius" in str(info.value) and "mesh_size" in str(info.value)


def test_toml_config(tmp_path):
    config = tmp_path / "case.toml"
    config.write_text('[parameters]\npressure = 0.015\nmesh_size = 2.0\n')
    params = build(si.Parameters, load_toml(config))
    assert params.pressure == 0.015 and params.mesh_size == 2.0


def test_every_parameter_is_documented():
    for name, _kind, _default, _unit, text in describe(si.Parameters):
        assert text, f"{name} has no help text"


def test_a_bug_in_a_solver_hook_is_raised_not_taken_for_divergence():
    import dolfinx
    import ufl
    from mpi4py import MPI

    from eyemech.problems.solve.driver import NonlinearSolver

    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    u, v = dolfinx.fem.Function(V), ufl.TestFunction(V)
    residual = (ufl.inner(ufl.grad(u), ufl.grad(v)) + (u - 1) * v) * ufl.dx

    def broken_hook(_x, _b):
        raise ValueError("hook bug")

    solver = NonlinearSolver(residual, u, [], residual_hooks=[broken_hook])
    with pytest.raises(ValueError, match="hook bug"):
        solver.solve()


@pytest.mark.parametrize("key, value", [("settle", "false"), ("settle", 0), ("c_sclera", "1.5")])
def test_a_python_caller_gets_one_error_for_a_value_of_the_wrong_type(key, value):
    """The command line converts "false" to False; a Python caller's value is taken as
    given, and the string "false" would be a true flag."""
    from eyemech.problems import scleral_buckling

    with pytest.raises(ParameterError, match=key):
        check(scleral_buckling.Parameters(**{key: value}))
