"""problems/solve/scalars.py: the global value of a scalar form, from a UFL form (compiled
on the spot) or a compiled one (assembled as it is, nothing compiled again). The sum over
ranks is checked under mpiexec by the scenes' quantities (tests/test_parallel.py); here the
values are exact integrals on a unit cube."""

from __future__ import annotations

import dolfinx
import pytest
import ufl
from mpi4py import MPI

from eyemech.problems.solve.scalars import assemble_scalar


@pytest.fixture(scope="module")
def cube():
    return dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 2, 2, 2)


def test_a_ufl_form_is_integrated_over_the_whole_mesh(cube):
    x = ufl.SpatialCoordinate(cube)
    assert assemble_scalar(x[0] * x[1] * ufl.dx(domain=cube)) == pytest.approx(0.25, rel=1e-13)
    assert assemble_scalar(1.0 * ufl.ds(domain=cube), cube.comm) == pytest.approx(6.0, rel=1e-13)


def test_a_compiled_form_is_assembled_without_compiling_again(cube, monkeypatch):
    c = dolfinx.fem.Constant(cube, 2.0)
    compiled = dolfinx.fem.form(c * ufl.dx(domain=cube))

    def refuse(*_args, **_kwargs):
        raise AssertionError("a compiled form was compiled again")

    monkeypatch.setattr(dolfinx.fem, "form", refuse)
    assert assemble_scalar(compiled) == pytest.approx(2.0, rel=1e-13)
    c.value = 3.0  # a Constant changes the value, not the form
    assert assemble_scalar(compiled, cube.comm) == pytest.approx(3.0, rel=1e-13)
