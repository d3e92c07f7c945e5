"""The suture bites deliver the asked pull on every mesh (forms/sutures.py,
problems/solid/sutures.py): each bite's weight is normalised by its integral on the
mesh, so the half model carries exactly its share of every suture (½ on the symmetry
plane x = 0, 1 off it), whether or not the mesh resolves the bite."""

from __future__ import annotations

import math

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

from eyemech.forms.sutures import half_space_share
from eyemech.problems import scleral_buckling as sb
from eyemech.problems.run.context import RunContext, RunOptions
from eyemech.problems.run.parameters import build

QUIET = RunOptions(fields=False, pictures=False)
FORCE = 0.2  # N, the scene's default suture_force


def test_half_space_share_is_the_exact_integral_of_the_bump_on_a_half_plane():
    """½ on the line, 1 and 0 a bite radius in and out, and the quadrature of the
    flat bump in between (midpoint rule on a 2000² grid: agrees to 1e-5)."""
    assert half_space_share(0.0, 1.0) == pytest.approx(0.5, abs=1e-15)
    assert half_space_share(1.0, 1.0) == pytest.approx(1.0, abs=1e-15)
    assert half_space_share(-2.0, 1.0) == pytest.approx(0.0, abs=1e-15)
    n = 2000
    x = (np.arange(n) + 0.5) / n * 2 - 1
    X, Y = np.meshgrid(x, x)
    w = np.maximum(1 - X**2 - Y**2, 0) / (0.5 * math.pi) * (2 / n) ** 2
    for offset in (0.3, -0.6):
        assert half_space_share(offset, 1.0) == pytest.approx(w[X >= -offset].sum(), abs=1e-5)


def _delivered(params: sb.Parameters) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bite loads' resultant on the half model (−R_sutures tested with each unit
    translation), the resultant asked for (Σ share_s F_s), and the raw ∫ w_s dA."""
    with RunContext(sb.SCENE.name, params, MPI.COMM_SELF, None, QUIET) as ctx:
        model = sb.BucklingModel(params, ctx)
        sutures = model.sutures.forces
        rng = np.random.default_rng(7)
        directions = rng.normal(size=(len(sutures.points), 3))
        sutures.directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
        sutures.set_magnitude(FORCE)
        V = model.u.function_space
        ds = model.eye.ds({"quadrature_degree": model.body.family.quadrature_degree})
        delivered = np.zeros(3)
        for i in range(3):
            translation = dolfinx.fem.Function(V)
            translation.interpolate(lambda x, i=i: np.eye(3)[i][:, None] * np.ones(x.shape[1]))
            form = dolfinx.fem.form(sutures.residual(translation, ds(model.eye.tag("sclera_outer"))))
            delivered[i] = -dolfinx.fem.assemble_scalar(form)
        asked = (sutures.shares[:, None] * FORCE * sutures.directions).sum(axis=0)
        return delivered, asked, sutures.mesh_integrals / sutures.shares


@pytest.mark.parametrize("overrides", [
    {"resolution": "coarse"},
    {"mesh_size": "2.2"},
    {"resolution": "coarse", "buckle": "segmental", "tire_orientation": "radial",
     "suture_azimuths": "0"},
], ids=["coarse", "mesh_size_2.2", "radial_coarse"])
def test_the_bites_deliver_the_asked_pull_on_every_mesh(overrides):
    """Each case builds the eye (no solve). Without the normalisation the coarse bites
    carry 1.16–1.18 (coarse), 1.08–1.28 (mesh_size 2.2) and 0.96–1.59 (radial, coarse)
    of their share (raw ∫ w_s dA / share, printed with -s)."""
    delivered, asked, raw = _delivered(build(sb.Parameters, overrides))
    print("raw bite integral / share:", np.round(raw, 4))
    assert np.linalg.norm(delivered - asked) <= 1e-6 * np.linalg.norm(asked)
    # the mesh does not resolve the bite: the normalisation is not idle
    assert np.max(np.abs(raw - 1.0)) > 1e-3


def test_a_bite_narrower_than_the_cells_is_bad_input(tmp_path):
    """A 0.5 mm bite on the coarse eye's sclera (cells of ~2 mm) has no quadrature point
    inside it: its pull would vanish (or divide by zero when normalised). The run stops with
    exit 2 naming suture_bite_radius, where the bites are and what to change, and leaves no
    folder behind (the run made it; nothing was solved)."""
    from conftest import run_cli

    out = tmp_path / "run"
    code, _out, err = run_cli("run", "scleral-buckling", "--set", "resolution=coarse",
                              "--set", "suture_bite_radius=0.5", "--out", str(out), "--quiet")
    assert code == 2, err
    last = err.strip().splitlines()[-1]
    assert "suture_bite_radius" in last and "finer resolution" in last
    assert "Traceback" not in err and not out.exists()
