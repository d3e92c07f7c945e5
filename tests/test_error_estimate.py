"""Richardson's error estimate (``--set error_estimate=true``, problems/run/error_estimate.py):
the formula, how a scene's parameters are coarsened, what lands in results.json, and that
the estimate brackets the true error where the answer is exact.

References for the bracketing cases: the thick incompressible sphere's exact inner radius
(problems/reference/analytic.py); Timoshenko & Woinowsky-Krieger's plate coefficients
0.00126532 (clamped) and 0.00406235 (simply supported) q L⁴/D, exact for the Kirchhoff
plate. Each asks |q − q_exact| ≤ estimate (the estimate holds the error) and estimate ≤ 4
|q − q_exact| (it is not an empty bound); measured ratios in docs/cli.md, "Error estimates".
"""

from __future__ import annotations

import dataclasses
import json

import pytest
from conftest import run_cli
from mpi4py import MPI

from eyemech.problems import hertz, plate_clamped, plate_simply_supported, sphere_inflation
from eyemech.problems.reference import analytic
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.error_estimate import Refinement, estimate_errors, extrapolate, richardson
from eyemech.problems.run.newton import SolveFailure
from eyemech.problems.run.results import Result, Timings

QUIET = RunOptions(fields=False, pictures=False)


def test_richardson_removes_the_leading_error_term():
    # q(h) = 1 + 0.3 h²: at h = 1 and 2 the extrapolation is exact
    value, estimate = richardson(1.3, 2.2, 2.0, 2.0)
    assert value == pytest.approx(1.0) and estimate == pytest.approx(0.3)
    # three solutions give the observed order
    value, order = extrapolate([1 + 0.5 * h**3 for h in (0.4, 0.2, 0.1)], [0.4, 0.2, 0.1])
    assert order == pytest.approx(3.0) and value == pytest.approx(1.0)
    with pytest.raises(ValueError):
        extrapolate([1.0], [0.1])


def test_coarse_parameters_follow_the_resolution_keys():
    refinement = hertz.ESTIMATE
    coarse = refinement.coarse(hertz.Parameters(error_estimate=True))
    assert (coarse.resolution, coarse.far_resolution) == (1.3, 1.5) and coarse.error_estimate is False
    # an absolute size set by the user is coarsened instead of its resolution
    absolute = refinement.coarse(hertz.Parameters(mesh_size=0.02, error_estimate=True))
    assert (absolute.mesh_size, absolute.resolution, absolute.far_resolution) == (0.04, 2.6, 1.5)
    # divisions are counts: halved and rounded; the actual ratio from the sizes
    plate = plate_clamped.Parameters(divisions=9, error_estimate=True)
    coarse_plate = plate_estimate().coarse(plate)
    assert coarse_plate.divisions == 4
    assert plate_estimate().actual_ratio(plate, coarse_plate) == pytest.approx(9 / 4)


def plate_estimate() -> Refinement:
    from eyemech.problems.shell.model import PLATE_ESTIMATE

    return PLATE_ESTIMATE


@dataclasses.dataclass(frozen=True)
class _Params:
    cells: float = 2.0
    error_estimate: bool = True


class _Context:
    def __init__(self, quantities: dict):
        self.comm = MPI.COMM_SELF
        self.options = RunOptions()
        self.timings = Timings()
        self.result = Result(scene="fake", parameters={}, quantities=dict(quantities))


def test_estimates_are_flat_quantities_and_a_failed_coarse_solve_leaves_them_null():
    refinement = Refinement(keys=("cells",), order=2.0, quantities=("x", "y"))
    seen = []

    def coarse_run(params, comm, out, options):
        seen.append((params, out, options.fields, options.pictures))
        return Result(scene="fake", parameters={}, quantities={"x": 2.2, "y": 5.0})

    ctx = _Context({"x": 1.3, "y": 5.0})
    added = estimate_errors(ctx, coarse_run, _Params(), refinement)
    assert seen == [(_Params(cells=1.0, error_estimate=False), None, False, False)]
    assert added["x_error_estimate"] == pytest.approx(0.3) and added["x_extrapolated"] == pytest.approx(1.0)
    assert added["y_error_estimate"] == 0.0
    assert (added["error_estimate_ratio"], added["error_estimate_order"]) == (2.0, 2.0)
    assert ctx.result.quantities["x_error_estimate"] == added["x_error_estimate"]
    assert "error_estimate" in ctx.timings.as_dict()

    def failing_run(params, comm, out, options):
        raise SolveFailure(step=1, load=0.5, last_converged=0.25, residuals=[1.0], reason="DIVERGED_MAX_IT")

    ctx = _Context({"x": 1.3, "y": 5.0})
    added = estimate_errors(ctx, failing_run, _Params(), refinement)
    assert added["x_error_estimate"] is None and added["x_extrapolated"] is None
    assert "the coarse solve failed" in added["error_estimate_note"]
    assert ctx.result.quantities["x"] == 1.3  # the run's own numbers stand


def _bracket(error: float, estimate: float) -> None:
    assert abs(error) <= estimate <= 4.0 * abs(error), (error, estimate)


def test_sphere_inflation_estimate_brackets_the_exact_error():
    """Default sphere (P2P1, 2 cells across the wall; the coarse solve at 1): measured
    error 2.0e-5 mm, estimate 3.8e-5 mm."""
    params = sphere_inflation.Parameters(error_estimate=True)
    q = sphere_inflation.run(params, options=QUIET).quantities
    exact = analytic.sphere_inner_radius(params.pressure, params.inner_radius, params.outer_radius,
                                         params.c10)
    _bracket(q["inner_radius_deformed"] - exact, q["inner_radius_deformed_error_estimate"])
    assert abs(q["inner_radius_deformed_extrapolated"] - exact) < abs(q["inner_radius_deformed"] - exact)


@pytest.mark.parametrize("module, coefficient", [(plate_clamped, 0.00126532),
                                                 (plate_simply_supported, 0.00406235)])
def test_plate_estimate_brackets_the_exact_error(module, coefficient):
    """Default plates (32 divisions, the coarse solve on 16): clamped error 3.5e-4, estimate
    3.9e-4; simply supported 2.3e-4, estimate 2.8e-4."""
    params = module.Parameters(error_estimate=True)
    q = module.run(params, options=QUIET).quantities
    D = params.youngs_modulus * params.thickness**3 / (12 * (1 - params.poisson_ratio**2))
    exact = coefficient * params.q * params.length**4 / D
    _bracket(q["center_deflection"] - exact, q["center_deflection_error_estimate"])


def test_the_command_line_reports_the_estimate(tmp_path):
    code, out, err = run_cli("run", "plate-clamped", "--set", "divisions=8", "--set", "error_estimate=true",
                             "--json", "--no-pictures", "--no-fields", "--out", str(tmp_path))
    assert code == 0, err
    data = json.loads(out.strip().splitlines()[-1])
    q = data["quantities"]
    assert q["center_deflection_error_estimate"] > 0 and q["error_estimate_ratio"] == 2.0
    assert data["timings"]["error_estimate"] > 0
    # the coarse solve is counted: two linear solves
    assert data["solver_counts"]["newton_solves"] == 2
    assert json.loads((tmp_path / "results.json").read_text())["quantities"] == q
