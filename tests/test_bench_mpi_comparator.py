"""scripts/bench_mpi.py's comparison of a parallel run with the serial one, without any
solve: spreads and errors (round-off when the solve is exact) are measured against the
scale of the quantity they come from, everything else relatively."""

from __future__ import annotations

from eyemech.scripts import bench_mpi

# contact-patch's quantities on 1 and 2 ranks (measured: the spreads are round-off)
SERIAL = {"pressure_mean": 0.01006030431469909, "pressure_spread": 1.0658141036401503e-11,
          "stress_spread_lower": 3.87068849194705e-12, "penalty_stiffness": 120.0,
          "newton_iterations": 8, "dofs": 930}
PARALLEL = dict(SERIAL, pressure_spread=4.4e-12, stress_spread_lower=3.0e-13)


def test_round_off_spreads_are_not_reported_as_differences():
    worst, where = bench_mpi.largest_difference(SERIAL, PARALLEL)
    # 6.3e-12 against the pressure's 0.01; 3.6e-12 against the run's largest float, 120
    assert worst < 1e-8, (worst, where)


def test_a_real_difference_is_still_caught():
    worst, where = bench_mpi.largest_difference(SERIAL, dict(PARALLEL, pressure_mean=0.0102))
    assert where == "pressure_mean" and abs(worst - 0.0137) < 1e-3
    worst, where = bench_mpi.largest_difference(SERIAL, dict(PARALLEL, pressure_spread=1e-4))
    assert where == "pressure_spread" and abs(worst - 1e-4 / 0.01006) < 1e-6


def test_a_list_of_another_length_is_a_difference():
    worst, where = bench_mpi.largest_difference({"x": [1.0, 2.0]}, {"x": [1.0]})
    assert worst == float("inf") and where.startswith("x")


def test_the_solvers_effort_is_compared_apart_from_the_results():
    worst, where = bench_mpi.largest_difference(SERIAL, dict(PARALLEL, newton_iterations=9))
    assert worst < 1e-8, (worst, where)
    worst, where = bench_mpi.largest_difference(SERIAL, dict(PARALLEL, newton_iterations=9),
                                                effort=True)
    assert where == "newton_iterations" and abs(worst - 1 / 9) < 1e-12


def test_a_count_of_the_partition_is_not_a_result():
    """retina-reattachment reports its contact pairs across ranks: 0 serially, some on 2."""
    worst, where = bench_mpi.largest_difference({"contact_pairs_across_ranks": 0, "gap": 1.0},
                                                {"contact_pairs_across_ranks": 12, "gap": 1.0})
    assert worst == 0.0 and where == ""


def test_a_merge_replaces_the_rows_measured_again_and_keeps_the_others(tmp_path):
    def row(scene, ranks, wall, date="2026-11-29"):
        return {**dict.fromkeys(bench_mpi.COLUMNS, ""), "scene": scene, "ranks": ranks,
                "exit_code": 0, "wall_s": wall, "load": 1.0, "date": date}

    earlier = [row("hertz", 1, 16.4), row("hertz", 2, 8.2), row("iol-fold", 1, 753.2),
               row("iol-fold", 2, 508.0)]
    now = [row("iol-fold", 1, 700.0, "2026-12-06"), row("iol-fold", 3, 600.0, "2026-12-06"),
           row("keratotomy", 1, 50.0, "2026-12-06")]
    table = bench_mpi.merged(earlier, now)
    assert [(r["scene"], r["ranks"], r["wall_s"]) for r in table] == [
        ("hertz", 1, 16.4), ("hertz", 2, 8.2), ("iol-fold", 1, 700.0), ("iol-fold", 2, 508.0),
        ("iol-fold", 3, 600.0), ("keratotomy", 1, 50.0)]
    # a CSV written before the date column reads back with an empty date
    path = tmp_path / "mpi-scenes.csv"
    path.write_text("scene,ranks,exit_code,wall_s\nhertz,1,0,16.4\n")
    assert bench_mpi.read_rows(path) == [{"scene": "hertz", "ranks": 1, "exit_code": 0,
                                          "wall_s": "16.4", "date": ""}]
    text = bench_mpi.markdown(table, [1, 2, 3])
    assert "2026-11-29 to 2026-12-06" in text and "| `keratotomy` | 50.0 (1.0) |  |  |" in text


def test_a_volume_swept_by_the_wall_is_compared_against_the_cavity():
    # the default eye after its IOP step on 1 and 2 ranks: the swept volume is round-off
    serial = {"after_iop": {"wall_inward_volume_uL": -1.18e-11, "cavity_volume_mm3": 4663.198}}
    parallel = {"after_iop": {"wall_inward_volume_uL": -0.54e-11, "cavity_volume_mm3": 4663.198}}
    worst, where = bench_mpi.largest_difference(serial, parallel)
    assert worst < 1e-14, (worst, where)
    parallel["after_iop"]["wall_inward_volume_uL"] = 1.0  # a microlitre is a difference
    assert bench_mpi.largest_difference(serial, parallel)[0] > 1e-4


def test_a_count_of_ccd_limited_updates_is_effort():
    # iol-fold on 1 and 3 ranks: the collision-free fraction is 0.9999... on one partition
    # and 1.0 on another, so the count of "limited" updates differs while the fold agrees
    serial = {"ccd_limited_updates": 7, "min_self_distance_mm": 0.1499551}
    parallel = {"ccd_limited_updates": 1, "min_self_distance_mm": 0.1499551}
    assert bench_mpi.largest_difference(serial, parallel) == (0.0, "")
    worst, where = bench_mpi.largest_difference(serial, parallel, effort=True)
    assert where == "ccd_limited_updates" and worst > 0.8


def test_a_path_sensitive_scene_is_compared_by_its_end_state():
    """The lens scenes take another number of adaptive steps on another partition: their
    histories are compared by the last entry, anything else as always."""
    serial = {"time": [0.0, 0.5, 0.68], "haptic_strain": 0.14013}
    parallel = {"time": [0.0, 0.3, 0.5, 0.68], "haptic_strain": 0.14055}
    assert bench_mpi.largest_difference(serial, parallel)[0] == float("inf")
    worst, where = bench_mpi.largest_difference(serial, parallel, end_state=True)
    assert where == "haptic_strain" and abs(worst - 0.00042 / 0.14055) < 1e-9
    parallel["time"][-1] = 0.60  # an end at another time is still a difference
    assert bench_mpi.largest_difference(serial, parallel, end_state=True)[1] == "time"


def test_the_table_shows_the_serial_paths_own_reach():
    row = {**dict.fromkeys(bench_mpi.COLUMNS, ""), "scene": "iol-fold", "ranks": 1,
           "exit_code": 0, "wall_s": 249.4, "load": 3.3, "date": "2026-12-07",
           "perturbed_rel_diff": "1.2e-03", "perturbed_quantity": "min_self_distance_mm"}
    text = bench_mpi.markdown([row], [1, 2, 3])
    assert "E × (1 + 1e-12)" in text
    assert "| `iol-fold` | 249.4 (3.3) |  |  |  |  | 1.2e-03 (min_self_distance_mm) |" in text
    assert set(bench_mpi.PATH_SENSITIVE) == {"iol-fold", "iol-injection"}


def test_an_adaptive_runs_step_count_is_effort():
    """iol-fold on 3 ranks: 79 time steps against 77 (Newton's stopping test fell otherwise
    at two steps), the end within 1.2e-3: the count is the solver's effort, not a result."""
    serial = {"steps": 77, "min_self_distance_mm": 0.045851, "intersecting_steps": 0}
    parallel = {"steps": 79, "min_self_distance_mm": 0.045794, "intersecting_steps": 0}
    worst, where = bench_mpi.largest_difference(serial, parallel, end_state=True)
    assert where == "min_self_distance_mm" and worst < 2e-3
    assert bench_mpi.largest_difference(serial, parallel, effort=True)[1] == "steps"
    assert not bench_mpi.is_effort("intersecting_steps")
