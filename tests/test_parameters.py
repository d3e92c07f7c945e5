"""Parameter handling: typed overrides, TOML configs and errors that name the key.
No solves here — these are the checks that run before anything is built."""

from __future__ import annotations

import dataclasses

import pytest

from eyemech.problems import sphere_inflation as si
from eyemech.problems.run.parameters import (
    GEOMETRY,
    SOLVER,
    ParameterError,
    build,
    check,
    describe,
    groups,
    load_toml,
)


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


def test_unknown_key_suggests_the_close_ones():
    with pytest.raises(ParameterError) as info:
        build(si.Parameters, {"presure": "0.02"})
    assert "did you mean 'pressure'" in str(info.value)


def test_many_keys_are_not_dumped_but_pointed_to():
    from eyemech.problems import keratotomy

    with pytest.raises(ParameterError) as info:
        build(keratotomy.Parameters, {"incision_dept": "0.5"})
    message = str(info.value)
    assert "did you mean 'incision_depth'" in message and "--help" in message
    assert "azimuthal_divisions" not in message  # 30 keys: pointed to, not listed


# each value written as a TOML literal and as --set text: the same value or the same error
SAME_READING = [
    ("load_steps", "2", "2"), ("load_steps", "2.0", "2.0"), ("load_steps", "0.1", "0.1"),
    ("load_steps", '"0.1"', "0.1"), ("load_steps", '"3"', "3"), ("load_steps", "true", "true"),
    ("pressure", "1e-3", "1e-3"), ("pressure", '"0.02"', "0.02"), ("pressure", "true", "true"),
    ("element", '"Q1P0"', "Q1P0"), ("element", '"Q9"', "Q9"), ("mesh_size", "2", "2"),
    ("pressure", "nan", "nan"), ("load_steps", "1_0", "10"),  # TOML's own spelling of 10
]


@pytest.mark.parametrize("key, toml_value, text", SAME_READING)
def test_toml_and_set_read_a_value_alike(key, toml_value, text, tmp_path):
    config = tmp_path / "case.toml"
    config.write_text(f"{key} = {toml_value}\n")

    def outcome(overrides):
        try:
            return getattr(build(si.Parameters, overrides), key)
        except ParameterError as err:
            return ("error", err.key)

    from_toml, from_set = outcome(load_toml(config)), outcome({key: text})
    assert from_toml == from_set
    assert type(from_toml) is type(from_set)


@pytest.mark.parametrize("text", ["1_0", "0.1", "2.5", "", "1,2", "true"])
def test_an_integer_is_an_integer(text):
    with pytest.raises(ParameterError, match="load_steps.*integer"):
        build(si.Parameters, {"load_steps": text})


@pytest.mark.parametrize("scene, overrides, key", [
    ("sphere_inflation", {"cells_across_wall": "1e-9"}, "cells_across_wall"),
    ("liquid_sphere", {"cells_across_wall": "1e-9"}, "cells_across_wall"),
    ("sphere_inflation", {"mesh_size": "50"}, "mesh_size"),
    ("retina_reattachment", {"slave": "fixed"}, "slave"),
    ("retina_reattachment", {"master": "soft_rim"}, "master"),
])
def test_the_message_names_the_key_that_was_set(scene, overrides, key):
    import importlib

    module = importlib.import_module(f"eyemech.problems.{scene}")
    with pytest.raises(ParameterError) as info:
        build(module.Parameters, overrides)
    assert info.value.key == key, str(info.value)


def test_toml_config(tmp_path):
    config = tmp_path / "case.toml"
    config.write_text('[parameters]\npressure = 0.015\nmesh_size = 2.0\n')
    params = build(si.Parameters, load_toml(config))
    assert params.pressure == 0.015 and params.mesh_size == 2.0


def test_every_parameter_is_documented():
    for name, _kind, _default, _unit, text in describe(si.Parameters):
        assert text, f"{name} has no help text"


# words in a key that say what it is: a solver knob or a mesh size is never "physics"
NOT_PHYSICS = {"load_steps": SOLVER, "mesh_size": GEOMETRY, "resolution": GEOMETRY,
               "max_cells": GEOMETRY, "divisions": GEOMETRY, "element": GEOMETRY,
               "degree": GEOMETRY, "time_stepping": SOLVER, "time_tolerance": SOLVER,
               "max_steps": SOLVER, "dt": SOLVER, "first_dt": SOLVER, "rtol": SOLVER,
               "atol": SOLVER, "solver": SOLVER, "predictor": SOLVER, "penalty": SOLVER}


def _scene_cases():
    from eyemech.problems import scenes

    return [pytest.param(scene, id=name) for name, scene in scenes().items()]


@pytest.mark.parametrize("scene", _scene_cases())
def test_every_scene_groups_its_parameters(scene):
    """Every scene tags its fields: physics, geometry and mesh, solver and stepping (what
    `eyemech run NAME --help` and docs/parameters.md list them under)."""
    grouped = groups(scene.parameters)
    found = {row[0]: group for group, rows in grouped.items() for row in rows}
    assert set(found) == {f.name for f in dataclasses.fields(scene.parameters)}
    wrong = {key: found[key] for key in found
             if key in NOT_PHYSICS and found[key] != NOT_PHYSICS[key]}
    assert not wrong, f"misfiled: {wrong}"
    assert len(grouped) >= 2 or len(found) < 4, f"{scene.name}: everything in {list(grouped)}"


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
