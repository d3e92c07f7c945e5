"""Checkpoint and restart (issue 11, docs/restart.md): a run killed (SIGKILL) in the middle
of a step or in the middle of a checkpoint write, or stopped by SIGTERM, continues with
``--resume`` to the numbers of the uninterrupted run -- serially, on 2 ranks, and on a
different number of ranks than it was written on.

The kills are deterministic: ``EYEMECH_TEST_KILL=step:N`` kills the process inside Newton
(after its first update) of the N-th converged step of the run, ``checkpoint:N`` inside the
N-th checkpoint write after the files are written but before the commit (rename),
``sigterm:N:R`` sends SIGTERM to rank R only inside step N.

Tolerances: a resume on the same number of ranks repeats the same floating-point
operations from a bitwise copy of the state, so it is compared to 1e-12; across rank
counts the partition changes the round-off (1e-8 for the cornea, as in
tests/test_keratotomy.py; 1e-6 and CONTACT_RANKS_RTOL for the eye with node-to-surface
contact, as in tests/test_scleral_buckling.py).
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest
from conftest import BIN, CONTACT_RANKS_RTOL, run_cli

from eyemech.problems import keratotomy, scleral_buckling
from eyemech.problems.run.checkpoint import latest
from eyemech.problems.run.context import RunOptions
from eyemech.problems.run.results import to_jsonable

# 6 converged steps: intact IOP (1), intact creep (2, 3), incised IOP (4), incised creep (5, 6)
CORNEA = dict(mesh_size=1.5, azimuthal_divisions=8, t_end=1800.0, first_dt=900.0,
              dt_growth=1.0, incisions=4, time_stepping="fixed")
# adaptive steps between the outputs at 900 and 1800 s
ADAPTIVE_CORNEA = dict(mesh_size=1.5, azimuthal_divisions=8, t_end=1800.0, first_dt=900.0,
                       dt_growth=1.0, incisions=4, symmetry="quarter")
EYE = dict(resolution="coarse")  # the defaults: 40 converged load steps over the four stages
QUIET = ("--no-fields", "--no-pictures", "--quiet")
NTS = ("max_penetration_mm", "retina_choroid_gap_nts_min_mm", "retina_contact_force_N",
       "retina_penalty_contact_area_mm2")


def sets(settings: dict) -> list[str]:
    return [a for k, v in settings.items() for a in ("--set", f"{k}={v}")]


def eyemech(*args: str, ranks: int = 1, kill: str = "") -> subprocess.CompletedProcess:
    command = [str(BIN / "eyemech"), *args]
    if ranks > 1:
        command = [str(BIN / "mpiexec"), "-n", str(ranks), *command]
    env = {k: v for k, v in os.environ.items() if k != "EYEMECH_TEST_KILL"}
    if kill:
        env["EYEMECH_TEST_KILL"] = kill
    return subprocess.run(command, capture_output=True, text=True, timeout=600, env=env)


def resume(folder: Path, ranks: int = 1) -> dict:
    scene = json.loads((latest(folder) / "meta.json").read_text())["scene"]
    proc = eyemech("run", scene, "--resume", str(folder), *QUIET, ranks=ranks)
    assert proc.returncode == 0, proc.stderr
    saved = json.loads((folder / "results.json").read_text())
    assert saved["status"] == "ok" and saved["mpi_size"] == ranks
    assert saved["checkpoints"]["resumed_from"]
    return saved


def killed(scene: str, settings: dict, folder: Path, kill: str, ranks: int = 1) -> Path:
    """Run until the kill; returns the checkpoint a resume will start from."""
    proc = eyemech("run", scene, *sets(settings), "--out", str(folder), *QUIET,
                   "--checkpoint-every", "1", ranks=ranks, kill=kill)
    assert proc.returncode != 0, "the run was meant to be killed"
    assert not (folder / "results.json").exists()  # it never got to the end
    found = latest(folder)
    assert found is not None
    return found


def assert_close(expected, actual, rtol: float, path: str = "") -> None:
    """Every number of ``expected`` (nested dicts and lists) in ``actual``."""
    if isinstance(expected, dict):
        for key, value in expected.items():
            tol = CONTACT_RANKS_RTOL if key in NTS and rtol > 1e-12 else rtol
            assert_close(value, actual[key], tol, f"{path}{key}.")
    elif isinstance(expected, list):
        assert len(actual) == len(expected), path
        for a, b in zip(expected, actual):
            assert_close(a, b, rtol, path)
    elif isinstance(expected, (bool, str)) or expected is None:
        assert actual == expected, path
    else:
        # a volume change (µL) is a difference of the eye's volumes (~6,000 µL): one that is
        # zero comes out as round-off of those, measured up to 5e-12 µL between 1 and 2 ranks
        zero = 1e-9 if path.rstrip(".").endswith("_uL") else 1e-12
        assert actual == pytest.approx(expected, rel=rtol, abs=zero), path


@pytest.fixture(scope="module")
def cornea():
    result = keratotomy.run(keratotomy.Parameters(**CORNEA),
                            options=RunOptions(fields=False, pictures=False))
    return to_jsonable(result.quantities)


@pytest.fixture(scope="module")
def eye():
    result = scleral_buckling.run(scleral_buckling.Parameters(**EYE),
                                  options=RunOptions(fields=False, pictures=False))
    return to_jsonable(result.quantities), to_jsonable(result.steps)


def test_eye_killed_mid_step_resumes_to_the_same_numbers(eye, tmp_path):
    # killed in Newton of step 6 (stage 2, contact active): resumes from step 5
    checkpoint = killed("scleral-buckling", EYE, tmp_path, "step:6")
    assert checkpoint.name == "ckpt_000005"
    saved = resume(tmp_path)
    quantities, steps = eye
    assert_close(quantities, saved["quantities"], 1e-12)
    assert [s["newton_iterations"] for s in saved["steps"]] == \
        [s["newton_iterations"] for s in steps]


def test_augmented_lagrangian_eye_killed_mid_step_resumes_to_the_same_numbers(tmp_path):
    """The contact multipliers are in the checkpoint (the buckle's at its Gauss points, the
    retina's per slave node): killed in the second step of stage 3, after stage 2's
    augmentations moved them, the resumed run ends at the uninterrupted run's numbers with
    the same Newton iterations and augmentations, step by step."""
    settings = dict(resolution="coarse", settle=False, contact_method="augmented-lagrangian")
    uninterrupted = scleral_buckling.run(scleral_buckling.Parameters(**settings),
                                         options=RunOptions(fields=False, pictures=False))
    expected, steps = to_jsonable(uninterrupted.quantities), to_jsonable(uninterrupted.steps)
    first_of_stage_3 = next(s["step"] for s in steps if s["stage"] == 3)
    assert sum(s["augmentations"] for s in steps if s["stage"] == 2) > 0
    checkpoint = killed("scleral-buckling", settings, tmp_path, f"step:{first_of_stage_3 + 1}")
    assert checkpoint.name == f"ckpt_{first_of_stage_3:06d}"
    saved = resume(tmp_path)
    assert_close(expected, saved["quantities"], 1e-12)
    for key in ("newton_iterations", "augmentations"):
        assert [s[key] for s in saved["steps"]] == [s[key] for s in steps], key


@pytest.mark.mpi
def test_eye_killed_mid_checkpoint_on_two_ranks_resumes_on_one_and_two(eye, tmp_path):
    first = tmp_path / "two"
    checkpoint = killed("scleral-buckling", EYE, first, "checkpoint:7", ranks=2)
    # the write of checkpoint 7 was not committed: the last good one is untouched
    assert checkpoint.name == "ckpt_000006"
    assert list((first / "checkpoints").glob(".tmp_ckpt_000007"))
    second = tmp_path / "one"
    shutil.copytree(first, second)
    quantities, _ = eye
    assert_close(quantities, resume(first, ranks=2)["quantities"], 1e-6)
    assert_close(quantities, resume(second, ranks=1)["quantities"], 1e-6)


@pytest.mark.mpi
def test_eye_checkpointed_on_three_ranks_resumes_on_three_and_one(eye, tmp_path):
    """On 3 ranks one rank of the coarse eye holds none of the retina's contact nodes, so
    it never searches and has no sticky memory; writing that memory into a checkpoint must
    still join the other ranks' gathers (without that, the run failed at its first
    checkpoint with the ranks' collectives crossed). Killed inside the third checkpoint's
    write, it resumes on 3 ranks and on 1 to the serial run's numbers."""
    first = tmp_path / "three"
    assert killed("scleral-buckling", EYE, first, "checkpoint:3", ranks=3).name == "ckpt_000002"
    second = tmp_path / "one"
    shutil.copytree(first, second)
    quantities, _ = eye
    assert_close(quantities, resume(first, ranks=3)["quantities"], 1e-6)
    assert_close(quantities, resume(second, ranks=1)["quantities"], 1e-6)


def test_cornea_sweep_killed_mid_step_resumes_the_case(cornea, tmp_path):
    """A sweep case killed in the middle of a time step (step 3: intact creep) is continued
    by ``sweep --resume`` from its checkpoint, and gives the uninterrupted numbers."""
    args = ("sweep", "keratotomy", *sets({k: v for k, v in CORNEA.items() if k != "incisions"}),
            "--grid", f"incisions={CORNEA['incisions']}", "--out", str(tmp_path), *QUIET,
            "--checkpoint-every", "1")
    assert eyemech(*args, kill="step:3").returncode != 0
    assert latest(tmp_path / "case_0000").name == "ckpt_000002"
    proc = eyemech(*args, "--resume")
    assert proc.returncode == 0, proc.stderr
    saved = json.loads((tmp_path / "case_0000" / "results.json").read_text())
    assert saved["checkpoints"]["resumed_from"].endswith("ckpt_000002")
    assert_close(cornea, saved["quantities"], 1e-12)
    rows = list(csv.DictReader((tmp_path / "sweep.csv").open()))
    assert [r["status"] for r in rows] == ["ok"]


def test_adaptive_cornea_killed_mid_step_resumes_to_the_same_numbers(tmp_path):
    """Adaptive time steps (problems/solid/viscous_bar.py::march_adaptive) resume from the
    checkpoint's time and step size, with the accumulated error estimate and the step
    counts: killed inside one of the incised cornea's last creep steps (the intact cornea's
    creep is a finished path), the resumed run repeats the uninterrupted one."""
    uninterrupted = keratotomy.run(keratotomy.Parameters(**ADAPTIVE_CORNEA),
                                   options=RunOptions(fields=False, pictures=False))
    expected, steps = to_jsonable(uninterrupted.quantities), len(uninterrupted.steps)
    assert expected["time_steps"] > 2 and expected["intact_time_steps"] > 2
    assert killed("keratotomy", ADAPTIVE_CORNEA, tmp_path, f"step:{steps}").name == \
        f"ckpt_{steps - 1:06d}"
    saved = resume(tmp_path)
    assert_close(expected, saved["quantities"], 1e-12)
    assert len(saved["steps"]) == steps


@pytest.mark.mpi
def test_cornea_killed_mid_checkpoint_on_two_ranks_resumes_on_one_and_two(cornea, tmp_path):
    first = tmp_path / "two"
    # checkpoint 5 (in the incised creep) is cut; 4 is the end of the incised IOP path
    assert killed("keratotomy", CORNEA, first, "checkpoint:5", ranks=2).name == "ckpt_000004"
    second = tmp_path / "one"
    shutil.copytree(first, second)
    assert_close(cornea, resume(first, ranks=2)["quantities"], 1e-8)
    assert_close(cornea, resume(second, ranks=1)["quantities"], 1e-8)


@pytest.mark.mpi
def test_sigterm_on_one_rank_checkpoints_and_stops_every_rank(cornea, tmp_path):
    proc = eyemech("run", "keratotomy", *sets(CORNEA), "--out", str(tmp_path), *QUIET,
                   "--checkpoint-every", "0", ranks=2, kill="sigterm:3:0")
    assert proc.returncode == 128 + 15, proc.stderr
    assert "stopped by SIGTERM after step 3" in proc.stderr
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["status"] == "interrupted"
    assert latest(tmp_path).name == "ckpt_000003"  # written on the signal, not by schedule
    assert_close(cornea, resume(tmp_path, ranks=1)["quantities"], 1e-8)


def test_resume_refuses_other_parameters(tmp_path):
    killed("keratotomy", CORNEA, tmp_path, "step:2")
    code, _, stderr = run_cli("run", "keratotomy", "--resume", str(tmp_path), "--set",
                              "tau=100", *QUIET)
    assert code == 2 and "tau" in stderr and "Traceback" not in stderr


def test_sweep_resume_skips_finished_cases_and_reruns_failed_ones(tmp_path):
    """(That a failing case is recorded and the others finish is tests/test_cli.py's
    test_sweep_records_a_failing_case_and_finishes_the_others.)"""
    base = ("sweep", "sphere-inflation", "--grid", "pressure=0.005,0.01,0.015", "--set",
            "mesh_size=2", "--out", str(tmp_path), "--no-pictures", "--no-fields")
    code, _, err = run_cli(*base)
    assert code == 0, err
    # case 1 failed in an earlier attempt, case 2 was killed before it wrote anything
    failed = tmp_path / "case_0001" / "results.json"
    failed.write_text(json.dumps({**json.loads(failed.read_text()), "status": "failed"}))
    (tmp_path / "case_0002" / "results.json").unlink()
    finished = (tmp_path / "case_0000" / "results.json").stat().st_mtime_ns
    code, _, err = run_cli(*base, "--resume")
    assert code == 0, err
    rows = list(csv.DictReader((tmp_path / "sweep.csv").open()))
    assert [r["status"] for r in rows] == ["ok", "ok", "ok"]
    assert (tmp_path / "case_0000" / "results.json").stat().st_mtime_ns == finished
    assert json.loads(failed.read_text())["status"] == "ok"
    radii = [float(r["inner_radius_deformed"]) for r in rows]
    assert radii[0] < radii[1] < radii[2]


@pytest.mark.parametrize("text, every", [("5", (5, 0.0)), ("0", (0, 0.0)), ("10m", (0, 10.0)),
                                         ("0.5min", (0, 0.5))])
def test_checkpoint_every_reads_steps_or_minutes(text, every):
    from eyemech.problems.run.checkpoint import CheckpointOptions

    assert CheckpointOptions.parse_every(text) == every


def test_latest_skips_uncommitted_and_incomplete_checkpoints(tmp_path):
    folder = tmp_path / "checkpoints"
    for name, meta in (("ckpt_000002", True), ("ckpt_000010", True), ("ckpt_000011", False),
                       (".tmp_ckpt_000012", True)):
        (folder / name).mkdir(parents=True)
        if meta:
            (folder / name / "meta.json").write_text("{}")
    assert latest(tmp_path) == folder / "ckpt_000010"
    assert latest(folder) == folder / "ckpt_000010"
    assert latest(tmp_path / "nothing") is None


def test_time_based_checkpoints_are_due_after_the_interval(monkeypatch):
    from mpi4py import MPI

    from eyemech.problems.run import checkpoint
    from eyemech.problems.run.results import Result

    clock = [100.0]
    monkeypatch.setattr(checkpoint.time, "monotonic", lambda: clock[0])
    points = checkpoint.Checkpoints("x", {}, Result("x", {}), MPI.COMM_SELF, None,
                                    checkpoint.CheckpointOptions(every_minutes=2.0))
    clock[0] += 119.0
    assert not points._due()
    clock[0] += 1.0
    assert points._due()
