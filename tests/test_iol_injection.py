"""``iol-injection`` to the end on the coarse lens (issue 8, "Done when" 1).

The run starts from ``tests/data/iol_folded_coarse.npz``, the folded state of
``eyemech run iol-fold --set resolution=coarse`` (250 triangles; the fold itself takes
≈ 2.5 min here, so it is not repeated in the test). What is checked:

- the run reaches the end of the scene (plunger past the nozzle tip, then the settle time);
- the lens has left the injector (every node beyond the nozzle tip) into the capsule;
- no self-intersection in any step, and the smallest self distance is > 0: guaranteed by
  the barrier with CCD-limited Newton updates (Li et al. 2020, IPC: "intersection-free
  for every iterate"), measured here with ipctk's exact intersection test every step;
- the rigid-contact penetration stays below 0.02 mm in every step: the nodal penalty
  k = 1 N/mm under nodal forces ≲ 1e-2 N (the fluid's drag on the whole lens,
  c m v ≈ 2e4 /s × 1e-8 t × 60 mm/s) gives f/k ≲ 0.01 mm — the definition of the penalty.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eyemech.problems import iol_injection
from eyemech.problems.context import RunOptions

FOLDED = Path(__file__).parent / "data" / "iol_folded_coarse.npz"
PENETRATION_TOLERANCE_MM = 0.02


@pytest.fixture(scope="module")
def injection():
    pytest.importorskip("ipctk")
    params = iol_injection.Parameters(resolution="coarse", folded_state=str(FOLDED))
    return params, iol_injection.run(params, options=RunOptions(fields=False, pictures=False)).quantities


def test_coarse_injection_runs_to_the_end_and_the_lens_unfolds_in_the_capsule(injection):
    params, q = injection
    layout = iol_injection.InjectorLayout()
    assert q["time"][-1] == pytest.approx(q["end_time_s"], abs=1e-9)
    assert q["lens_exited"]
    centre = np.asarray(q["final_optic_center"])
    assert centre[0] > layout.tip  # in the capsule
    assert q["final_decentration_mm"] < layout.capsule_semi_axes[0]
    assert q["optic_unrolled"]  # the optic's rims are no longer rolled about the axis


def test_coarse_injection_never_passes_through_itself_nor_the_walls(injection):
    _, q = injection
    assert not q["self_intersecting"]
    assert q["min_self_distance_mm"] > 0.0
    assert all(d > 0.0 for d in q["self_distance_mm"] if np.isfinite(d))
    assert max(q["penetration_mm"]) < PENETRATION_TOLERANCE_MM
