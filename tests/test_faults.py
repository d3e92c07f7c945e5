"""The run contract under bad input, faults and shared folders: a table of rows, each
run through the real command line.

- Bad input: exit 2, one line on stderr naming the key, no traceback, nothing written
  (the output folder is not created, or an existing one is left as it was): unusable
  paths (names and paths too long), nested TOML, contact pairs that are no pair,
  ``--petsc`` files outside the run's folder, ``--resume`` without a run.
- Damaged checkpoints: a resume falls back to the older intact checkpoint; with none
  readable it stops with exit 2 and leaves the folder's results.json as it was.
- Faults under MPI (``EYEMECH_TEST_RAISE_ON_RANK`` on each rank, fields on, 2 ranks): a
  scene, a sweep and a resume each end within 30 s with the failing rank's traceback.
- Ranks out of step (``EYEMECH_TEST_DIVERGE``): a collective call on one rank only, or a
  decision one rank takes alone, ends the job with the lock-step check's error, not a
  hang; a job stuck in C ends on SIGTERM in seconds; SIGTERM to a scene without
  checkpoints gives 143, serially and under mpiexec.
- A run owns its folder: a new run does not take over an unfinished run's checkpoints,
  prunes only its own, clears the previous run's extra outputs; ``--resume`` continues
  the folder's own run or returns a finished run's record unchanged; sweeps are keyed by
  their cases' parameters.
- Shared folders: a folder in use by another run is refused (exit 2); files follow the
  umask; a sweep with failed cases exits 4.
- Full disks (a small tmpfs in a private mount namespace): fields and checkpoints that
  do not fit end with exit 2 and one message naming the file.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent
SPHERE = ("sphere-inflation", "--set", "mesh_size=3")
# keratotomy in 6 steps: intact IOP (1), intact creep (2, 3), incised IOP (4), creep (5, 6)
CORNEA = ("keratotomy", "--set", "mesh_size=1.5", "--set", "azimuthal_divisions=8",
          "--set", "t_end=1800", "--set", "first_dt=900", "--set", "dt_growth=1",
          "--set", "incisions=4", "--set", "time_stepping=fixed")
QUIET = ("--quiet", "--no-pictures")
FAULT_TIMEOUT = 30.0  # seconds an MPI job with a fault on one rank may take to end


def eyemech(*args: str, ranks: int = 1, env: dict | None = None, timeout: float = 60,
            cwd: Path | None = None, umask: int | None = None) -> subprocess.CompletedProcess:
    command = [str(BIN / "eyemech"), *args]
    if ranks > 1:
        command = [str(BIN / "mpiexec"), "-n", str(ranks), *command]
    full = {k: v for k, v in os.environ.items()
            if k not in ("EYEMECH_TEST_RAISE_ON_RANK", "EYEMECH_TEST_KILL")}
    full.update(PYTHONUNBUFFERED="1", **(env or {}))
    preexec = (lambda: os.umask(umask)) if umask is not None else None
    return subprocess.run(command, capture_output=True, text=True, timeout=timeout, env=full,
                          cwd=cwd, preexec_fn=preexec)


def listing(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` with its content (what 'left as it was' compares)."""
    if not folder.exists():
        return {}
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


# -- bad input: exit 2, one message naming the key, nothing written -----------------------
def _toml(text: bytes):
    def make(tmp: Path) -> list[str]:
        path = tmp / "case.toml"
        path.write_bytes(text)
        return ["--config", str(path)]
    return make


def _file(tmp: Path) -> Path:
    path = tmp / "a_file"
    path.write_text("not a folder\n")
    return path


def _lock_held(tmp: Path) -> list[str]:
    """The output folder is held by a live process on this host."""
    folder = tmp / "out"
    folder.mkdir()
    holder = subprocess.Popen(["sleep", "60"])
    _lock_held.holders.append(holder)
    (folder / ".eyemech.lock").write_text(f"{holder.pid} {os.uname().nodename} now\n")
    return []


_lock_held.holders = []

# (id, scene and arguments, words the one-line message must contain, set-up returning extra
# arguments; "out" is where the run is pointed unless the set-up gives --out itself)
BAD_INPUT = [
    # earlier issues: unknown keys, types, non-physical values
    ("unknown-key", [*SPHERE, "--set", "presure=0.01"], ["presure", "unknown key"], None),
    ("not-a-number", [*SPHERE, "--set", "pressure=abc"], ["pressure", "cannot read"], None),
    ("negative-modulus", [*SPHERE, "--set", "c10=-1"], ["c10"], None),
    ("radius-order", [*SPHERE, "--set", "outer_radius=5"], ["outer_radius"], None),
    ("negative-mesh-size", [*SPHERE, "--set", "mesh_size=-1"], ["mesh_size"], None),
    ("unknown-scene", ["no-such-scene"], ["sphere-inflation"], None),
    ("bad-literal", [*SPHERE, "--set", "element=P7"], ["element"], None),
    ("missing-config", [*SPHERE, "--config", "/nonexistent/case.toml"], ["--config"], None),
    ("bad-toml", [*SPHERE], ["--config", "not valid TOML"], _toml(b"mesh_size = = 3\n")),
    ("checkpoint-every", [*SPHERE, "--checkpoint-every", "soon"], ["--checkpoint-every"], None),
    # item 3: infinite and NaN values
    ("inf-c10", [*SPHERE, "--set", "c10=inf"], ["c10", "finite"], None),
    ("inf-bulk-modulus", [*SPHERE, "--set", "bulk_modulus=inf"], ["bulk_modulus", "finite"], None),
    ("nan-bulk-modulus", [*SPHERE, "--set", "bulk_modulus=nan"], ["bulk_modulus", "finite"], None),
    ("inf-outer-radius", [*SPHERE, "--set", "outer_radius=inf"], ["outer_radius", "finite"], None),
    ("inf-pressure", [*SPHERE, "--set", "pressure=-inf"], ["pressure", "finite"], None),
    ("inf-youngs-modulus", ["plate-clamped", "--set", "youngs_modulus=inf"],
     ["youngs_modulus", "finite"], None),
    ("inf-penalty", ["hertz", "--set", "penalty=inf"], ["penalty", "finite"], None),
    ("inf-mu-inf", ["keratotomy", "--set", "mu_inf=inf"], ["mu_inf", "finite"], None),
    ("inf-in-toml", [*SPHERE], ["c10", "finite"], _toml(b"[parameters]\nc10 = inf\n")),
    # item 4: time-stepped scenes have a step-count cap
    ("inf-t-end", ["keratotomy", "--set", "t_end=inf"], ["t_end", "finite"], None),
    ("t-end-steps", ["keratotomy", "--set", "t_end=1e9", "--set", "dt_growth=1", "--set",
                     "time_stepping=fixed"], ["t_end", "time steps", "max_steps"], None),
    # its own cap; adaptive runs are not counted before the solve (TooManySteps stops them)
    ("t-end-steps-sls", ["sls-creep", "--set", "t_end=1e9", "--set", "time_stepping=fixed"],
     ["steps"], None),
    # item 5: --petsc names and values
    ("petsc-typo", [*SPHERE, "--petsc", "snes_linesearch_typ=bt"],
     ["--petsc", "snes_linesearch_typ"], None),
    ("petsc-bad-type", [*SPHERE, "--petsc", "snes_linesearch_type=bogus"],
     ["--petsc", "snes_linesearch_type=bogus"], None),
    ("petsc-bad-number", [*SPHERE, "--petsc", "snes_max_it=many"], ["--petsc", "snes_max_it"],
     None),
    ("petsc-bad-pc", [*SPHERE, "--petsc", "pc_type=nonsense"], ["--petsc", "pc_type"], None),
    # item 6: unusable paths and configs
    ("out-is-file", [*SPHERE], ["--out", "is a file"], lambda tmp: ["--out", str(_file(tmp))]),
    ("out-under-file", [*SPHERE], ["--out", "under the file"],
     lambda tmp: ["--out", str(_file(tmp) / "sub")]),
    ("out-unwritable", [*SPHERE], ["--out", "cannot"],
     lambda tmp: ["--out", "/proc/eyemech-cannot-write-here"]),
    ("resume-a-file", [*SPHERE], ["--resume", "not a folder"],
     lambda tmp: ["--resume", str(_file(tmp))]),
    ("config-folder", [*SPHERE], ["--config", "folder"], lambda tmp: ["--config", str(tmp)]),
    ("config-not-utf8", [*SPHERE], ["--config", "UTF-8"], _toml(b"mesh_size = 3\n# \xff\xfe\n")),
    ("parameters-not-table", [*SPHERE], ["parameters", "table"], _toml(b"parameters = 3\n")),
    ("top-level-beside-table", [*SPHERE], ["pressure", "[parameters]"],
     _toml(b"pressure = 0.02\n[parameters]\nmesh_size = 3.0\n")),
    # item 9: a folder held by another run
    ("out-locked", [*SPHERE], ["--out", "in use by another eyemech run"], _lock_held),
    # item 11: a mesh too fine to build
    ("mesh-too-fine", ["sphere-inflation", "--set", "mesh_size=0.01"],
     ["mesh_size", "cells", "EYEMECH_MAX_CELLS"], None),
    ("mesh-too-fine-liquid", ["liquid-sphere", "--set", "mesh_size=0.02"],
     ["mesh_size", "cells"], None),
    # found only after meshing: still no results.json, no folder
    ("hertz-negative-gap", ["hertz", "--set", "initial_gap=-0.1"], ["initial_gap"], None),
    # a contact pair that is no pair: a surface with itself, two faces of one body
    ("retina-slave-is-master", ["retina-reattachment", "--set", "slave=master"],
     ["'slave'", "itself"], None),
    ("retina-pair-on-one-body", ["retina-reattachment", "--set", "slave=fixed"],
     ["'slave'", "fixed"], None),
    # the key that sets the element size is the one named
    ("cells-across-wall", ["sphere-inflation", "--set", "cells_across_wall=1e-9"],
     ["'cells_across_wall'", "larger than the sphere"], None),
    # paths the file system cannot take, a TOML file nested too deeply
    ("out-name-too-long", [*SPHERE], ["--out", "allows"],
     lambda tmp: ["--out", str(tmp / ("a" * 300))]),
    ("out-path-too-long", [*SPHERE], ["--out", "allows"],
     lambda tmp: ["--out", str(tmp.joinpath(*["b" * 200] * 25))]),
    ("resume-name-too-long", [*SPHERE], ["--resume", "allows"],
     lambda tmp: ["--resume", str(tmp / ("a" * 300))]),
    ("config-nested", [*SPHERE], ["--config", "deeply"],
     _toml(b"x = " + b"[" * 5000 + b"]" * 5000 + b"\n")),
    # --resume needs a run to resume
    ("resume-missing-folder", [*SPHERE], ["--resume", "no such folder"],
     lambda tmp: ["--resume", str(tmp / "never-run")]),
    ("resume-empty-folder", [*SPHERE], ["--resume", "no run to resume"],
     lambda tmp: (tmp / "empty").mkdir() or ["--resume", str(tmp / "empty")]),
    # --petsc files stay in the run's folder (the file outside is left as it was)
    ("petsc-view-outside", [*SPHERE], ["--petsc", "snes_view", "inside the run's folder"],
     lambda tmp: ["--petsc", f"snes_view=ascii:{_file(tmp)}"]),
    ("petsc-matrix-outside", [*SPHERE], ["--petsc", "ksp_view_mat", "inside the run's folder"],
     lambda tmp: ["--petsc", f"ksp_view_mat=binary:{tmp / 'A.bin'}"]),
    ("petsc-monitor-outside", [*SPHERE], ["--petsc", "snes_monitor", "inside the run's folder"],
     lambda tmp: ["--petsc", f"snes_monitor=ascii:{tmp / 'monitor.txt'}"]),
    ("petsc-view-parent", [*SPHERE, "--petsc", "snes_view=ascii:../up.txt"],
     ["--petsc", "'..'"], None),
    ("petsc-draw", [*SPHERE, "--petsc", "ksp_view=draw"], ["--petsc", "window"], None),
    # a viewer's file the run's folder cannot take is named as given (not PETSc's trial's
    # "a value of the wrong kind" with the trial's scratch path)
    ("petsc-view-subfolder", [*SPHERE, "--petsc", "snes_view=ascii:sub/snes.txt"],
     ["--petsc", "snes_view=ascii:sub/snes.txt", "without a folder"], None),
    ("petsc-view-name-too-long", [*SPHERE, "--petsc", f"snes_view=ascii:{'a' * 300}.txt"],
     ["--petsc", f"snes_view=ascii:{'a' * 300}.txt", "File name too long"], None),
]


@pytest.mark.parametrize("row", BAD_INPUT, ids=[r[0] for r in BAD_INPUT])
def test_bad_input_exits_2_with_one_message_and_writes_nothing(tmp_path, row):
    _, args, words, setup = row
    out = tmp_path / "out"
    extra = setup(tmp_path) if setup else []
    if "--out" not in extra:
        extra += ["--out", str(out)]
    before = listing(tmp_path)
    try:
        done = eyemech("run", *args, *extra, *QUIET)
    finally:
        for holder in _lock_held.holders:
            holder.kill()
            holder.wait()
        _lock_held.holders.clear()
    assert done.returncode == 2, done.stderr[-3000:]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr[-3000:]
    assert all(word in lines[0] for word in words), lines[0]
    assert listing(tmp_path) == before  # nothing written, nothing removed
    assert not out.exists() or out.is_dir() and {p.name for p in out.iterdir()} <= {".eyemech.lock"}


# same for a sweep: every value is checked before the first case
SWEEP_BAD = [
    ("grid-repeated-key", ["--grid", "c10=0.05", "--grid", "c10=0.1"], ["c10", "twice"]),
    ("grid-repeated-value", ["--grid", "c10=0.1,0.10"], ["c10", "repeats the value"]),
    ("grid-inf", ["--grid", "c10=0.1,inf"], ["c10", "finite"]),
    ("grid-petsc-typo", ["--grid", "pressure=0.01", "--petsc", "ksp_typ=cg"], ["ksp_typ"]),
    ("grid-mesh-too-fine", ["--grid", "mesh_size=3,0.01"], ["mesh_size", "cells"]),
]


@pytest.mark.parametrize("row", SWEEP_BAD, ids=[r[0] for r in SWEEP_BAD])
def test_bad_sweep_input_exits_2_before_any_case(tmp_path, row):
    _, args, words = row
    out = tmp_path / "sweep"
    done = eyemech("sweep", *SPHERE, *args, "--out", str(out), *QUIET)
    assert done.returncode == 2, done.stderr[-3000:]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and all(w in lines[0] for w in words), done.stderr[-3000:]
    assert not out.exists()


def test_sweep_out_is_a_file_exits_2(tmp_path):
    done = eyemech("sweep", *SPHERE, "--grid", "pressure=0.01", "--out", str(_file(tmp_path)),
                   *QUIET)
    assert done.returncode == 2 and "is a file" in done.stderr, done.stderr[-3000:]


# -- item 12: the failure message names the quantity and its unit --------------------------
def test_solve_failure_names_the_quantity_and_unit():
    from eyemech.problems.solve.driver import SolveFailure, Stepping

    text = str(SolveFailure(3, 14.06, 12.0, [1.0], "DIVERGED_LINE_SEARCH", *Stepping(
        start=0.0, end=3600.0, quantity="time", unit="s").describe()))
    assert "trying time 14.06 s" in text and "Last converged time 12 s" in text
    assert "trying load factor 0.4505 " in str(SolveFailure(1, 0.4505, 0.4, [], "x",
                                                            *Stepping().describe()))
    assert "path value" in str(SolveFailure(1, 2.5, 2.0, [], "x",
                                            *Stepping(0.0, 3.0).describe()))


# -- items 9 and 10: the folder lock and file modes -----------------------------------------
def test_stale_lock_is_taken_over_and_files_follow_the_umask(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    dead = subprocess.Popen(["true"])
    dead.wait()  # its process id is free: the lock is stale
    (out / ".eyemech.lock").write_text(f"{dead.pid} {os.uname().nodename} then\n")
    done = eyemech("run", *SPHERE, "--out", str(out), *QUIET, umask=0o022)
    assert done.returncode == 0, done.stderr[-3000:]
    assert not (out / ".eyemech.lock").exists()  # released at the end
    for name in ("results.json", "state.pvd", "state_0000.vtu"):
        assert stat.S_IMODE((out / name).stat().st_mode) == 0o644, name
    sweep = tmp_path / "sweep"
    done = eyemech("sweep", *SPHERE, "--grid", "pressure=0.01", "--out", str(sweep), *QUIET,
                   "--no-fields", umask=0o002)
    assert done.returncode == 0, done.stderr[-3000:]
    assert stat.S_IMODE((sweep / "sweep.csv").stat().st_mode) == 0o664
    assert stat.S_IMODE((sweep / "case_0000" / "results.json").stat().st_mode) == 0o664


def test_second_run_on_a_busy_folder_is_refused_and_the_first_finishes(tmp_path):
    """Two real runs: the second starts while the first holds the folder."""
    out = tmp_path / "out"
    first = subprocess.Popen([str(BIN / "eyemech"), "run", *CORNEA, "--out", str(out), *QUIET,
                              "--no-fields"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
    try:
        deadline = time.monotonic() + 60
        while not (out / ".eyemech.lock").exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert (out / ".eyemech.lock").exists()
        second = eyemech("run", *SPHERE, "--out", str(out), *QUIET)
        assert second.returncode == 2, second.stderr[-3000:]
        assert "in use by another eyemech run" in second.stderr
        assert str(first.pid) in second.stderr
        _, err = first.communicate(timeout=120)
    finally:
        first.kill()
    assert first.returncode == 0, err[-3000:]
    saved = json.loads((out / "results.json").read_text())
    assert saved["scene"] == "keratotomy" and saved["status"] == "ok"
    # only the first run's files (it writes no fields): none of the refused run's frames
    assert not list(out.glob("state*")) and not list(out.glob("fields_*"))


# -- item 8: sweep exit code and unreadable case results -----------------------------------
def test_sweep_with_failed_cases_exits_4_and_resume_reruns_unreadable_cases(tmp_path):
    out = tmp_path / "sweep"
    grid = ("--grid", "pressure=0.01,0.012")
    done = eyemech("sweep", *SPHERE, *grid, "--out", str(out), *QUIET, "--no-fields",
                   env={"EYEMECH_TEST_RAISE_ON_RANK": "0"})  # every case raises (1 rank)
    assert done.returncode == 4, done.stderr[-3000:]
    assert "2 of 2 cases failed" in done.stderr
    rows = list(csv.DictReader((out / "sweep.csv").open()))
    assert [r["status"] for r in rows] == ["error", "error"]
    done = eyemech("sweep", *SPHERE, *grid, "--out", str(out), *QUIET, "--no-fields",
                   "--resume")
    assert done.returncode == 0, done.stderr[-3000:]
    (out / "case_0001" / "results.json").write_bytes(b'{"status": "o')  # truncated
    done = eyemech("sweep", *SPHERE, *grid, "--out", str(out), *QUIET, "--no-fields",
                   "--resume")
    assert done.returncode == 0, done.stderr[-3000:]
    assert "case_0001/results.json is unreadable" in done.stderr
    rows = list(csv.DictReader((out / "sweep.csv").open()))
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert json.loads((out / "case_0001" / "results.json").read_text())["status"] == "ok"


# -- item 7: damaged checkpoints --------------------------------------------------------------
@pytest.fixture(scope="module")
def interrupted(tmp_path_factory) -> Path:
    """A keratotomy run stopped by SIGTERM in step 4: checkpoints after steps 3 and 4, and
    results.json with status "interrupted"."""
    folder = tmp_path_factory.mktemp("interrupted") / "run"
    done = eyemech("run", *CORNEA, "--out", str(folder), *QUIET, "--no-fields",
                   "--checkpoint-every", "1", env={"EYEMECH_TEST_KILL": "sigterm:4"}, timeout=300)
    assert done.returncode == 128 + signal.SIGTERM, done.stderr[-3000:]
    assert sorted(p.name for p in (folder / "checkpoints").iterdir()) == \
        ["ckpt_000003", "ckpt_000004"]
    return folder


def _damage(folder: Path, how: str) -> None:
    newest, older = folder / "checkpoints" / "ckpt_000004", folder / "checkpoints" / "ckpt_000003"
    if how == "truncated-rank-file":
        data = (newest / "rank_0000.npz").read_bytes()
        (newest / "rank_0000.npz").write_bytes(data[: len(data) // 3])
    elif how == "empty-rank-file":
        (newest / "rank_0000.npz").write_bytes(b"")
    elif how == "truncated-meta":
        (newest / "meta.json").write_bytes((newest / "meta.json").read_bytes()[:100])
    elif how == "missing-rank-file":
        (newest / "rank_0000.npz").unlink()
    elif how == "both-damaged":
        (newest / "rank_0000.npz").write_bytes(b"")
        (older / "meta.json").write_bytes(b"{")


@pytest.mark.parametrize("how", ["truncated-rank-file", "empty-rank-file", "truncated-meta",
                                 "missing-rank-file"])
def test_damaged_checkpoint_falls_back_to_the_older_one(interrupted, tmp_path, how):
    folder = tmp_path / "run"
    shutil.copytree(interrupted, folder)
    _damage(folder, how)
    done = eyemech("run", "keratotomy", "--resume", str(folder), *QUIET, "--no-fields")
    assert done.returncode == 0, done.stderr[-3000:]
    assert "ckpt_000004 is unreadable" in done.stderr
    saved = json.loads((folder / "results.json").read_text())
    assert saved["status"] == "ok"
    assert saved["checkpoints"]["resumed_from"].endswith("ckpt_000003")


def test_no_readable_checkpoint_exits_2_and_keeps_the_record(interrupted, tmp_path):
    folder = tmp_path / "run"
    shutil.copytree(interrupted, folder)
    _damage(folder, "both-damaged")
    before = listing(folder)
    done = eyemech("run", "keratotomy", "--resume", str(folder), *QUIET, "--no-fields")
    assert done.returncode == 2, done.stderr[-3000:]
    last = done.stderr.strip().splitlines()[-1]
    assert "no readable checkpoint" in last and "ckpt_000004" in last and "ckpt_000003" in last
    assert "Traceback" not in done.stderr
    assert listing(folder) == before
    assert json.loads((folder / "results.json").read_text())["status"] == "interrupted"


# -- items 1 and 2: a fault on one rank, fields on, 2 ranks: the job ends ------------------
def _fault(rank: int, *args: str, cwd: Path | None = None) -> tuple[subprocess.CompletedProcess, float]:
    start = time.monotonic()
    try:
        done = eyemech(*args, ranks=2, env={"EYEMECH_TEST_RAISE_ON_RANK": str(rank)},
                       timeout=FAULT_TIMEOUT, cwd=cwd)
    except subprocess.TimeoutExpired:
        pytest.fail(f"hang: {' '.join(args)} with the fault on rank {rank} did not end within "
                    f"{FAULT_TIMEOUT:.0f} s")
    seconds = time.monotonic() - start
    print(f"fault on rank {rank}: {' '.join(args[:2])} ended after {seconds:.1f} s")
    assert done.returncode != 0
    assert f"EYEMECH_TEST_RAISE_ON_RANK: test error on rank {rank} inside the residual" \
        in done.stderr
    assert f"eyemech: rank {rank} of 2 failed" in done.stderr
    return done, seconds


@pytest.mark.mpi
@pytest.mark.parametrize("rank", [0, 1])
@pytest.mark.parametrize("kind", ["sphere-inflation", "plate-clamped", "sweep", "resume"])
def test_a_fault_on_one_rank_ends_the_job(kind, rank, tmp_path, interrupted):
    out = tmp_path / "out"
    if kind == "sphere-inflation":
        _fault(rank, "run", *SPHERE, "--out", str(out), "--quiet")
    elif kind == "plate-clamped":
        _fault(rank, "run", "plate-clamped", "--set", "divisions=4", "--out", str(out), "--quiet")
    elif kind == "sweep":
        args = ("sweep", *SPHERE, "--grid", "pressure=0.01,0.012", "--ranks-per-case", "2",
                "--out", str(out), "--quiet")
        _fault(rank, *args)
        if rank == 1:  # the aborted sweep's stale locks are taken over; --resume finishes it
            done = eyemech(*args, "--resume", "--no-pictures", ranks=2, timeout=120)
            assert done.returncode == 0, done.stderr[-3000:]
            rows = list(csv.DictReader((out / "sweep.csv").open()))
            assert [r["status"] for r in rows] == ["ok", "ok"]
            assert not (out / ".eyemech.lock").exists()
    else:
        shutil.copytree(interrupted, out)
        _fault(rank, "run", "keratotomy", "--resume", str(out), "--quiet")
        # the resume never reached a new step: the record of the run is kept
        assert json.loads((out / "results.json").read_text())["status"] == "interrupted"


@pytest.mark.parametrize("scene, setting, key", [
    ("hertz", "initial_gap=-0.1", "initial_gap"),  # the obstacle inside the ball
    # a fold saved for the coarse lens given to the default lens; its path in the row's
    # folder name made nested folders
    ("iol-injection", "folded_state=tests/data/iol_folded_coarse.npz", "folded_state")])
def test_bench_refused_after_meshing_leaves_no_folder(tmp_path, scene, setting, key):
    """Bad input found after meshing removes every folder the run made, the bench's --out
    included, and names the key."""
    out = tmp_path / "new" / "bench"
    done = eyemech("bench", scene, "--set", setting, "--out", str(out),
                   cwd=Path(__file__).parents[1])
    assert done.returncode == 2, done.stderr[-3000:]
    assert f"'{key}'" in done.stderr.strip().splitlines()[-1]
    assert not (tmp_path / "new").exists()


def test_petsc_viewer_file_is_written_in_the_run_folder(tmp_path):
    """A relative file name of a viewer lands in the run's folder, not in the working
    directory (and the option check's trial solve writes nothing there either)."""
    out, cwd = tmp_path / "out", tmp_path / "cwd"
    cwd.mkdir()
    done = eyemech("run", *SPHERE, "--petsc", "snes_view=ascii:snes.txt", "--out", str(out),
                   *QUIET, "--no-fields", cwd=cwd)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "SNES Object" in (out / "snes.txt").read_text()
    assert not list(cwd.iterdir())


# -- a run owns its folder ---------------------------------------------------------------------
def _stepped_run(folder: Path, *extra: str, kill: str = "", every: str = "1",
                 timeout: float = 300) -> subprocess.CompletedProcess:
    return eyemech("run", *CORNEA, *extra, "--out", str(folder), *QUIET, "--no-fields",
                   "--checkpoint-every", every, env={"EYEMECH_TEST_KILL": kill} if kill else None,
                   timeout=timeout)


def test_new_run_refuses_a_folder_with_an_interrupted_runs_checkpoints(interrupted, tmp_path):
    folder = tmp_path / "run"
    shutil.copytree(interrupted, folder)
    before = listing(folder)
    done = _stepped_run(folder, "--set", "optical_zone=4.0")
    assert done.returncode == 2, done.stderr[-3000:]
    message = done.stderr.strip().splitlines()[-1]
    assert "ckpt_000003" in message and "ckpt_000004" in message and "--resume" in message
    assert listing(folder) == before


def test_resume_of_checkpoints_without_a_parameter_names_it_and_changes_nothing(interrupted,
                                                                               tmp_path):
    """Checkpoints written before the scene had a parameter (no run.json, no run id, no
    value of optical_zone in their meta.json): --resume fills it with its default, which
    makes another run, and is refused with exit 2 naming the parameter and the remedy that
    the folder's own check accepts; the folder is left as it was (no run.json)."""
    folder = tmp_path / "run"
    shutil.copytree(interrupted, folder)
    for name in ("run.json", "results.json"):
        (folder / name).unlink(missing_ok=True)
    for meta_file in (folder / "checkpoints").glob("ckpt_*/meta.json"):
        meta = json.loads(meta_file.read_text())
        meta.pop("run_id", None)
        meta["parameters"].pop("optical_zone")
        meta_file.write_text(json.dumps(meta))
    before = listing(folder)
    done = eyemech("run", "keratotomy", "--resume", str(folder), *QUIET, "--no-fields")
    assert done.returncode == 2, done.stderr[-3000:]
    message = done.stderr.strip().splitlines()[-1]
    assert "'--resume'" in message and "no value of optical_zone" in message, message
    assert f"remove {folder / 'checkpoints'}" in message and "Traceback" not in done.stderr
    assert listing(folder) == before


def test_a_new_run_keeps_its_own_checkpoints_and_resumes_itself(interrupted, tmp_path):
    """An ended run's checkpoints numbered above the new run's (ckpt_000025/26) neither
    outlive the new run's nor get resumed: pruning keeps the running run's newest, the
    checkpoint a SIGTERM names exists, and --resume continues the new run with its own
    parameters."""
    folder = tmp_path / "run"
    shutil.copytree(interrupted, folder)
    done = eyemech("run", "keratotomy", "--resume", str(folder), *QUIET, "--no-fields")
    assert done.returncode == 0, done.stderr[-3000:]  # the old run ends: ok
    old = folder / "checkpoints"
    for step, name in ((3, "ckpt_000025"), (4, "ckpt_000026")):
        (old / f"ckpt_{step:06d}").rename(old / name)
    done = _stepped_run(folder, "--set", "optical_zone=4.0", kill="sigterm:3")
    assert done.returncode == 143, done.stderr[-3000:]
    named = done.stderr.strip().splitlines()[-1].split("checkpoint ")[-1]
    assert Path(named).is_dir(), done.stderr[-3000:]
    assert sorted(p.name for p in old.iterdir()) == ["ckpt_000002", "ckpt_000003"]
    done = eyemech("run", "keratotomy", "--resume", str(folder), *QUIET, "--no-fields")
    assert done.returncode == 0, done.stderr[-3000:]
    saved = json.loads((folder / "results.json").read_text())
    assert saved["parameters"]["optical_zone"] == 4.0
    assert saved["checkpoints"]["resumed_from"].endswith("ckpt_000003")
    run = json.loads((folder / "run.json").read_text())
    meta = json.loads((old / "ckpt_000003" / "meta.json").read_text())
    assert saved["run_id"] == run["run_id"] == meta["run_id"]


def test_resume_without_a_checkpoint_restarts_the_runs_own_parameters(tmp_path):
    """Killed before its first checkpoint, a 4-incision quarter cornea resumes as itself
    (from the beginning), not as the scene's defaults."""
    folder = tmp_path / "run"
    quarter = ("--set", "symmetry=quarter")
    done = _stepped_run(folder, *quarter, kill="step:1", every="0")
    assert done.returncode != 0 and not (folder / "checkpoints").exists()
    done = eyemech("run", "keratotomy", "--resume", str(folder), *QUIET, "--no-fields",
                   timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "starts again from the beginning" in done.stderr
    parameters = json.loads((folder / "results.json").read_text())["parameters"]
    assert parameters["incisions"] == 4 and parameters["symmetry"] == "quarter"
    done = eyemech("run", "keratotomy", "--resume", str(folder), "--set", "incisions=8",
                   *QUIET, "--no-fields")
    assert done.returncode == 2 and "incisions" in done.stderr, done.stderr[-3000:]


def test_resume_of_a_finished_run_returns_its_record_unchanged(tmp_path):
    folder = tmp_path / "run"
    done = eyemech("run", *SPHERE, "--set", "c10=0.1", "--out", str(folder), *QUIET)
    assert done.returncode == 0, done.stderr[-3000:]
    before = listing(folder)
    done = eyemech("run", "sphere-inflation", "--resume", str(folder), "--json", *QUIET)
    assert done.returncode == 0, done.stderr[-3000:]
    assert listing(folder) == before
    assert json.loads(done.stdout.strip().splitlines()[-1]) == \
        json.loads((folder / "results.json").read_text())


def test_a_rerun_clears_the_previous_runs_extra_outputs(tmp_path):
    folder = tmp_path / "run"
    assert eyemech("run", *SPHERE, "--set", "load_steps=3", "--out", str(folder),
                   *QUIET).returncode == 0
    assert (folder / "state_0003.vtu").exists()
    done = eyemech("run", *SPHERE, "--out", str(folder), *QUIET)
    assert done.returncode == 0, done.stderr[-3000:]
    frames = sorted(p.name for p in folder.glob("state_*.vtu"))
    assert frames == ["state_0000.vtu", "state_0001.vtu"]


# -- sweeps keyed by their cases' parameters ----------------------------------------------
def _sweep(out: Path, *args: str, resume: bool = True) -> tuple[subprocess.CompletedProcess,
                                                               list[dict]]:
    done = eyemech("sweep", *SPHERE, *args, "--out", str(out), *QUIET, "--no-fields",
                   *(["--resume"] if resume else []), timeout=300)
    rows = list(csv.DictReader((out / "sweep.csv").open())) if (out / "sweep.csv").exists() \
        else []
    return done, rows


def test_sweep_resume_follows_the_cases_parameters(tmp_path):
    out = tmp_path / "sweep"
    done, first = _sweep(out, "--grid", "c10=0.05,0.1", resume=False)
    assert done.returncode == 0, done.stderr[-3000:]
    kept = (out / "case_0000" / "results.json").read_bytes()
    radius = {r["c10"]: float(r["inner_radius_deformed"]) for r in first}
    done, rows = _sweep(out, "--grid", "c10=0.2,0.05")
    assert done.returncode == 0, done.stderr[-3000:]
    got = {r["c10"]: float(r["inner_radius_deformed"]) for r in rows}
    assert got["0.05"] == radius["0.05"]  # the finished case, not run again ...
    assert (out / "case_0001" / "results.json").read_bytes() == kept  # ... moved to its place
    assert got["0.2"] < radius["0.1"] < radius["0.05"]  # the new case's own number
    assert json.loads((out / "case_0000" / "results.json").read_text())["parameters"]["c10"] == 0.2
    done, rows = _sweep(out, "--grid", "c10=0.2,0.05", "--set", "pressure=0.02")
    assert done.returncode == 0, done.stderr[-3000:]
    stiffer = {r["c10"]: float(r["inner_radius_deformed"]) for r in rows}
    assert stiffer["0.05"] > got["0.05"] and stiffer["0.2"] > got["0.2"]  # run again


def test_sweep_refuses_another_scenes_folder(tmp_path):
    out = tmp_path / "sweep"
    done, _ = _sweep(out, "--grid", "pressure=0.01", resume=False)
    assert done.returncode == 0, done.stderr[-3000:]
    before = listing(out)
    done = eyemech("sweep", "cook-membrane", "--set", "elements_per_side=2", "--grid",
                   "load=1,2", "--out", str(out), "--resume", *QUIET)
    assert done.returncode == 2, done.stderr[-3000:]
    assert "sweep of 'sphere-inflation'" in done.stderr.strip().splitlines()[-1]
    assert listing(out) == before


# -- ranks out of step, signals under MPI -------------------------------------------------
LOCKSTEP_TEST_SECONDS = "5"  # the lock-step deadline in these tests (default 120 s)


@pytest.mark.mpi
def test_a_collective_on_one_rank_ends_with_the_lockstep_error(tmp_path):
    """Rank 1 makes one collective call more than rank 0 at the end of step 2 (as the
    buckle's outline in rank 0's pictures did): rank 0 reaches the lock-step check, waits
    its deadline, names rank 1 and ends the job (instead of both ranks spinning)."""
    start = time.monotonic()
    done = eyemech("run", *CORNEA, "--out", str(tmp_path / "out"), *QUIET, "--no-fields",
                   ranks=2, timeout=120, env={"EYEMECH_TEST_DIVERGE": "collective:2:1",
                                              "EYEMECH_LOCKSTEP_SECONDS": LOCKSTEP_TEST_SECONDS})
    seconds = time.monotonic() - start
    print(f"ended after {seconds:.1f} s")
    assert done.returncode == 1, done.stderr[-3000:]
    assert "rank(s) 1 of 2 did not arrive at the end of step 2" in done.stderr, \
        done.stderr[-3000:]


@pytest.mark.mpi
def test_a_decision_on_one_rank_ends_with_the_lockstep_error(tmp_path):
    out = tmp_path / "out"
    done = eyemech("run", *CORNEA, "--out", str(out), *QUIET, "--no-fields", ranks=2,
                   timeout=120, env={"EYEMECH_TEST_DIVERGE": "decision:2:1"})
    assert done.returncode == 1, done.stderr[-3000:]
    message = done.stderr.strip().splitlines()[-1]
    assert "ranks diverged at the end of step 2" in message and "rank 1: value 901" in message
    assert json.loads((out / "results.json").read_text())["status"] == "error"


@pytest.mark.mpi
def test_a_petsc_error_on_one_rank_ends_the_job(tmp_path):
    """Rank 1's residual raises a PETSc error inside Newton of step 2, so SNES fails on
    rank 1 only while rank 0 waits in the solve's collective calls: rank 1 would cut the
    step and go on alone. It waits for rank 0 to leave the solve with an error too, names
    it when it does not, and ends the job (exit 1) instead of hanging."""
    start = time.monotonic()
    done = eyemech("run", *CORNEA, "--out", str(tmp_path / "out"), *QUIET, "--no-fields",
                   ranks=2, timeout=120, env={"EYEMECH_TEST_DIVERGE": "petsc:2:1",
                                              "EYEMECH_LOCKSTEP_SECONDS": LOCKSTEP_TEST_SECONDS})
    print(f"ended after {time.monotonic() - start:.1f} s")
    assert done.returncode == 1, done.stderr[-3000:]
    assert "rank 1 of 2 left a Newton solve with a PETSc error and rank(s) 0 did not" \
        in done.stderr, done.stderr[-3000:]


COOK = ("cook-membrane", "--set", "elements_per_side=2", "--set", "load_steps=3")


@pytest.mark.mpi
@pytest.mark.parametrize("kind, message", [
    ("decision", "ranks diverged at the end of step 2 (path 'cook-membrane')"),
    ("collective", "rank(s) 1 of 2 did not arrive at the end of step 2 (path 'cook-membrane')")])
def test_a_walk_without_checkpoints_is_checked_in_step(kind, message, tmp_path):
    """cook-membrane's path follower runs without checkpoints; its walk checks the ranks
    at each step's end all the same, so a branch on one rank's data ends the job."""
    done = eyemech("run", *COOK, "--out", str(tmp_path / "out"), *QUIET, "--no-fields",
                   ranks=2, timeout=120, env={"EYEMECH_TEST_DIVERGE": f"{kind}:2:1",
                                              "EYEMECH_LOCKSTEP_SECONDS": LOCKSTEP_TEST_SECONDS})
    assert done.returncode == 1, done.stderr[-3000:]
    assert message in done.stderr, done.stderr[-3000:]


def _wait_for(predicate, seconds: float, what: str) -> None:
    deadline = time.monotonic() + seconds
    while not predicate():
        if time.monotonic() > deadline:
            pytest.fail(f"{what} did not happen within {seconds:.0f} s")
        time.sleep(0.1)


def _rank_pids(mpiexec: int) -> list[int]:
    """The processes two generations below ``mpiexec`` (its proxy's children: the ranks)."""
    parents = {}
    for status in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = status.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parents[int(status.parent.name)] = int(fields[1])
    proxies = [p for p, parent in parents.items() if parent == mpiexec]
    return sorted(p for p, parent in parents.items() if parent in proxies)


@pytest.mark.mpi
def test_sigterm_ends_a_job_stuck_in_a_collective_call(tmp_path):
    """Rank 1 waits in a collective call no other rank makes (inside Newton of step 2) and
    rank 0 waits for it inside SNES: both main threads are in C, where Python's handler
    never runs. SIGTERM to mpiexec ends the job with 143 within the watchdog's grace."""
    stderr = tmp_path / "stderr"
    env = dict(os.environ, PYTHONUNBUFFERED="1", EYEMECH_TEST_DIVERGE="hang:2:1",
               EYEMECH_SIGNAL_GRACE_SECONDS="3")
    with stderr.open("w") as err:
        job = subprocess.Popen([str(BIN / "mpiexec"), "-n", "2", str(BIN / "eyemech"), "run",
                                *CORNEA, "--out", str(tmp_path / "out"), *QUIET, "--no-fields"],
                               stdout=subprocess.DEVNULL, stderr=err, env=env)
    try:
        _wait_for(lambda: "hangs in step 2" in stderr.read_text(), 120, "the planted hang")
        time.sleep(1.0)
        start = time.monotonic()
        job.send_signal(signal.SIGTERM)
        code = job.wait(timeout=60)
    finally:
        job.kill()
    seconds = time.monotonic() - start
    print(f"ended {seconds:.1f} s after SIGTERM")
    assert code == 143, stderr.read_text()[-3000:]
    assert seconds < 20
    assert "stuck in a call to C" in stderr.read_text()


# a scene without checkpoints, long enough that the signal comes while it runs
SPHERE_LONG = ("sphere-inflation", "--set", "mesh_size=1.0", "--set", "load_steps=4")


@pytest.mark.mpi
@pytest.mark.parametrize("target", ["mpiexec", "one rank"])
def test_sigterm_to_a_scene_without_checkpoints_exits_143(tmp_path, target):
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    job = subprocess.Popen([str(BIN / "mpiexec"), "-n", "2", str(BIN / "eyemech"), "run",
                            *SPHERE_LONG, "--out", str(out), *QUIET],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        _wait_for(lambda: (out / "run.json").exists(), 120, "the run's start")
        if target == "mpiexec":
            job.send_signal(signal.SIGTERM)
        else:
            os.kill(_rank_pids(job.pid)[-1], signal.SIGTERM)
        _, err = job.communicate(timeout=60)
    finally:
        job.kill()
    assert job.returncode == 143, err[-3000:]
    assert "Caught signal" not in err and "BAD TERMINATION" not in err


def test_sigterm_to_a_serial_scene_without_checkpoints_exits_143(tmp_path):
    out = tmp_path / "out"
    job = subprocess.Popen([str(BIN / "eyemech"), "run", *SPHERE_LONG, "--out", str(out),
                            *QUIET], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: (out / "run.json").exists(), 120, "the run's start")
        job.send_signal(signal.SIGTERM)
        _, err = job.communicate(timeout=60)
    finally:
        job.kill()
    assert job.returncode == 143, err[-3000:]  # an exit code, not death by the signal (-15)
    assert "stopped by SIGTERM" in err


# -- full disks -----------------------------------------------------------------------------
def _private_tmpfs() -> bool:
    """Whether this user may mount a tmpfs in a private user and mount namespace."""
    try:
        return subprocess.run(["unshare", "-rm", "sh", "-c", "mount -t tmpfs tmpfs /mnt"],
                              capture_output=True, timeout=20).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


SMALL_DISK = pytest.mark.skipif(not _private_tmpfs(), reason="no user namespace in which to "
                                "mount a small tmpfs (unshare -rm)")


def on_small_disk(tmp_path: Path, size: str, *args: str, ranks: int = 1):
    """``eyemech args`` with ``--out`` on a tmpfs of ``size`` (a real ENOSPC from the
    kernel) mounted in a private namespace; the folder is copied out before the mount
    goes. Returns the run and the copy."""
    import shlex

    disk, copy = tmp_path / "disk", tmp_path / "copy"
    disk.mkdir()
    command = [str(BIN / "eyemech"), *args, "--out", str(disk / "out")]
    if ranks > 1:
        command = [str(BIN / "mpiexec"), "-n", str(ranks), *command]
    script = (f"mount -t tmpfs -o size={size} tmpfs {shlex.quote(str(disk))} || exit 99; "
              f"{shlex.join(command)}; code=$?; cp -a {shlex.quote(str(disk / 'out'))} "
              f"{shlex.quote(str(copy))} 2>/dev/null; exit $code")
    env = {k: v for k, v in os.environ.items() if not k.startswith("EYEMECH_TEST_")}
    done = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True,
                          text=True, timeout=300, env=dict(env, PYTHONUNBUFFERED="1"))
    assert done.returncode != 99, done.stderr
    return done, copy


@SMALL_DISK
@pytest.mark.parametrize("ranks", [1, pytest.param(2, marks=pytest.mark.mpi)])
@pytest.mark.parametrize("size, vtx", [("100k", False), ("150k", False), ("100k", True),
                                       ("120k", True), ("200k", True)])
def test_fields_on_a_full_disk_exit_2_naming_the_file(tmp_path, ranks, size, vtx):
    """The disk fills while the .vtu frames or the VTX (ADIOS2, ``--vtx``) files are
    written, at sizes that fill it at different writes (a frame, a VTX write, a VTX close,
    a writer the scene never got to close). ADIOS2's writer that failed is retired (its
    destructor would repeat the write and abort with SIGABRT), and the run context closes
    the writers a scene left open; the .vtu frames are made in memory (VTK's XML writer
    corrupts the heap when its file write fails: "double free", SIGSEGV)."""
    done, copy = on_small_disk(tmp_path, size, "run", *SPHERE, "--quiet",
                               *(["--vtx"] if vtx else []), ranks=ranks)
    assert done.returncode == 2, done.stderr[-3000:]
    assert "Aborted" not in done.stderr and "Traceback" not in done.stderr
    assert "double free" not in done.stderr and "SEGV" not in done.stderr
    said = [line for line in done.stderr.splitlines() if line.startswith("eyemech:")]
    # (under mpiexec the abort's line can come twice: hydra forwards it as MPI_Abort ends)
    assert len(set(said)) == 1 and f"cannot write {tmp_path}" in said[0], done.stderr[-3000:]
    assert not list(copy.glob("*.tmp*")) and not list(copy.glob(".*.tmp"))


@SMALL_DISK
def test_pictures_on_a_full_disk_leave_no_partial_file(tmp_path):
    done, copy = on_small_disk(tmp_path, "200k", "run", *SPHERE, "--quiet")
    assert done.returncode == 2, done.stderr[-3000:]
    assert "deformed.png: No space left on device" in done.stderr.strip().splitlines()[-1]
    assert not list(copy.glob("*.png"))


@SMALL_DISK
def test_a_checkpoint_on_a_full_disk_exits_2_naming_the_file(tmp_path):
    """The first checkpoint (0.7 MB) fits, the second does not: exit 2, and the first is
    intact beside the uncommitted .tmp_ folder."""
    done, copy = on_small_disk(tmp_path, "1200k", "run", *CORNEA, *QUIET, "--no-fields",
                               "--checkpoint-every", "1")
    assert done.returncode == 2, done.stderr[-3000:]
    last = done.stderr.strip().splitlines()[-1]
    assert "No space left on device" in last and ".tmp_ckpt_000002" in last
    assert "Traceback" not in done.stderr
    assert sorted(p.name for p in (copy / "checkpoints").iterdir()) == \
        [".tmp_ckpt_000002", "ckpt_000001"]
