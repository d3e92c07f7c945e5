"""Mattress sutures tied to a length (``suture_model = mattress``): a tied leg's tension
is its stiffness times its stretch; on the coarse eye the buckle rises with the suture's
width, as surgeons use it; the tire's row balances the legs' push against the sclera's
contact force; the default operation with tied sutures settles.
docs/scleral_buckling.md, "Mattress sutures"."""

from __future__ import annotations

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from eyemech.forms.sutures import bite_weight, tied_leg_energy, tied_leg_stretch
from eyemech.problems import scleral_buckling as sb
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.parameters import ParameterError, build

QUIET = RunOptions(fields=False, pictures=False)


def test_a_tied_leg_pulls_with_its_stiffness_times_its_stretch():
    """A flat bite (radius 0.3 mm) on the top of a plate, its leg to an anchor 1 m above:
    tied 0.2 mm shorter, then the plate moved 0.05 mm towards the anchor. Every point's
    leg is then 0.15 mm too long (to 1e-7: the legs are parallel to 1e-4 rad), so the
    tension is k · 0.15 and the bite's load along the leg is the same; moved 0.25 mm the
    stretch is −0.05 mm: the form is signed and smooth (the term drops a slack leg as a
    whole: MattressSutures.converged)."""
    mesh = dolfinx.mesh.create_box(MPI.COMM_WORLD, [[0, 0, 0], [1, 1, 0.1]], [8, 8, 1])
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    u, u_tied = dolfinx.fem.Function(V), dolfinx.fem.Function(V)
    X = ufl.SpatialCoordinate(mesh)
    top = dolfinx.mesh.locate_entities_boundary(mesh, 2, lambda x: np.isclose(x[2], 0.1))
    tags = dolfinx.mesh.meshtags(mesh, 2, top, np.full(len(top), 1, dtype=np.int32))
    # one quadrature for the normalisation and the forms, as the eye's measures have
    ds = ufl.Measure("ds", mesh, subdomain_data=tags, subdomain_id=1,
                     metadata={"quadrature_degree": 4})
    centre, anchor = ufl.as_vector([0.5, 0.5, 0.1]), ufl.as_vector([0.5, 0.5, 1000.1])
    area = mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(
        bite_weight(X, centre, 0.3) * ds)), op=MPI.SUM)
    weight = bite_weight(X, centre, 0.3) / area
    stiffness, shortening = 20.0, 0.2
    stretch = tied_leg_stretch(X + u, X + u_tied, anchor, anchor, shortening)
    tension_form = dolfinx.fem.form(stiffness * stretch * weight * ds)
    energy = tied_leg_energy(stretch, stiffness, weight) * ds
    # the load on the plate along +z: −∂Π/∂u · e_z (a rigid translation's virtual work)
    lift = dolfinx.fem.Function(V)
    lift.interpolate(lambda x: np.vstack([0 * x[0], 0 * x[0], 1 + 0 * x[0]]))
    load_form = dolfinx.fem.form(-ufl.derivative(energy, u, lift))

    def assembled(form):
        return mesh.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM)

    for moved, expected in ((0.05, 0.15), (0.25, -0.05)):
        u.interpolate(lambda x, m=moved: np.vstack([0 * x[0], 0 * x[0], m + 0 * x[0]]))
        assert assembled(tension_form) == pytest.approx(stiffness * expected, abs=1e-6)
        assert assembled(load_form) == pytest.approx(stiffness * expected, abs=1e-6)


# a tire alone (the default 90° tire, sutured at 0 and 36°), tied over suturing; the
# acute state the surgeon judges the buckle's height in: ≈ 25 s each
TIRE = dict(resolution="coarse", buckle="segmental", suture_model="mattress", settle="false")


@pytest.fixture(scope="module")
def tied():
    return {width: sb.run(build(sb.Parameters, {**TIRE, "suture_width": str(width)}), options=QUIET)
            for width in (8.0, 10.0)}


def test_the_buckle_rises_with_the_suture_width(tied):
    """Each leg is shortened by half the sclera between its bite and the tire's edge,
    0.25 mm at 8 mm bites over the 7 mm tire and 0.75 mm at 10 mm: the wider sutures
    imbricate more sclera under the tire and hold it deeper. Measured: the tire's travel
    after suturing 0.97 → 1.28 mm (the instrument held it at 2.0 mm until suturing, then
    let go); both tires press the sclera (contact force > 0). The legs stay in tension."""
    travel = {w: r.quantities["after_suturing"]["tire_travel_mm"] for w, r in tied.items()}
    assert travel[10.0] > travel[8.0] + 0.2, travel
    for result in tied.values():
        after = result.quantities["after_suturing"]
        assert after["suture_tie"] == pytest.approx(1.0)
        assert after["tire_contact_force_N"] > 0.5
        assert after["suture_force_min_N"] > 0.1
        # every rim node paired with the choroid: at 10 mm a load step once carried the
        # rim through it (unpaired, no contact, the rim gap null); such a step is cut now
        assert after["tear_rim_gap_max_mm"] is not None
        assert after["retina_choroid_gap_min_mm"] > -0.05
    # measured: 0.136 mm open at 8 mm bites, 0.032 mm closed at 10 mm
    rim = {w: r.quantities["after_suturing"]["tear_rim_gap_max_mm"] for w, r in tied.items()}
    assert rim[8.0] > 0.05 > rim[10.0], rim


def test_the_tires_row_balances_the_legs_push(tied):
    """Free under tied sutures, the tire's row is ∂Π_c/∂δ + ∂Π_s/∂δ = 0 once the instrument
    has let go: the sclera's contact force on it equals the legs' push (−∂Π_s/∂δ), to
    Newton's tolerance, at the end of suturing."""
    for result in tied.values():
        after = result.quantities["after_suturing"]
        assert after["tire_free"]
        assert after["tire_contact_force_N"] == pytest.approx(after["tire_suture_pull_N"], rel=1e-5)


def test_the_default_operation_settles_with_tied_sutures():
    """The default operation (the band shortened by 25 %, the tire under it, vented) with
    mattress sutures, settling on: it finishes; the sutures push band and tire deeper than
    the 0.2 N loop (coarse eye, measured: travel after suturing 1.63 mm against 1.09, the
    tightest leg 2.3 N) and stay tied as the IOP returns to 15 mmHg."""
    result = sb.run(build(sb.Parameters, {"resolution": "coarse", "suture_model": "mattress"}),
                    options=QUIET)
    sutured, settled = (result.quantities[k] for k in ("after_suturing", "after_settling"))
    assert result.status == "ok"
    assert 1.3 < sutured["band_travel_mm"] < 2.0
    assert settled["iop_mmHg"] == pytest.approx(15.0)
    assert settled["suture_force_min_N"] > 0.0


@pytest.mark.parametrize("settings, key", [
    ({"suture_model": "mattress", "suture_tie_fraction": "0"}, "suture_tie_fraction"),
    ({"suture_model": "mattress", "suture_tie_fraction": "1.5"}, "suture_tie_fraction"),
    ({"suture_model": "mattress", "suture_stiffness": "-1"}, "suture_stiffness"),
    ({"suture_model": "mattress", "suture_force": "0.3"}, "suture_force"),
    ({"suture_tie_fraction": "0.8"}, "suture_tie_fraction"),
    ({"suture_model": "bites", "suture_stiffness": "10"}, "suture_stiffness"),
])
def test_bad_tied_sutures_are_refused_before_any_solve(settings, key):
    """A knot that takes nothing or more than the sclera between bite and element, a thread
    without stiffness, a prescribed pull on tied sutures, or the knot's settings without
    tied sutures: one error naming the key."""
    with pytest.raises(ParameterError) as error:
        build(sb.Parameters, {"resolution": "coarse", **settings})
    assert error.value.key == key
