"""What a run says while it runs (problems/run/progress.py): a line per load step off a
terminal, Newton iterations under -v, "case i/N" in a sweep, the bar naming the stage."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

from eyemech.problems.run.progress import PathProgress
from eyemech.problems.solve.driver import Stepping, StepRecord

EYEMECH = Path(sys.executable).parent / "eyemech"
SPHERE = ["sphere-inflation", "--set", "mesh_size=2", "--set", "load_steps=3", "--no-pictures",
          "--no-fields"]
LINE = re.compile(r"^sphere-inflation: step (\d+), load ([0-9.e-]+), (\d+) Newton iterations, "
                  r"residual ([0-9.e+-]+), ([0-9.]+) s$")


def test_a_line_per_load_step_when_stderr_is_not_a_terminal(tmp_path):
    done = subprocess.run([str(EYEMECH), "run", *SPHERE, "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    lines = [LINE.match(x) for x in done.stderr.splitlines() if x.startswith("sphere-inflation:")]
    steps = json.loads((tmp_path / "results.json").read_text())["steps"]
    assert all(lines) and len(lines) == len(steps) >= 3
    for match, step in zip(lines, steps):
        assert float(match[2]) == float(f"{step['pressure'] / 0.01:.6g}")
        assert int(match[3]) == step["newton_iterations"]


def test_quiet_silences_the_lines(tmp_path):
    done = subprocess.run([str(EYEMECH), "run", *SPHERE, "--quiet", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0 and "step 1" not in done.stderr


def test_verbose_logs_each_newton_iteration(tmp_path):
    done = subprocess.run([str(EYEMECH), "-v", "run", *SPHERE, "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0
    iterations = re.findall(r"INFO +Newton iteration (\d+): residual", done.stderr)
    steps = json.loads((tmp_path / "results.json").read_text())["steps"]
    # SNES reports iteration 0 (the start) and each iteration after it
    assert len(iterations) >= sum(s["newton_iterations"] + 1 for s in steps)


def test_a_sweep_says_which_case_runs(tmp_path):
    done = subprocess.run([str(EYEMECH), "sweep", "sphere-inflation", "--set", "mesh_size=2",
                           "--grid", "c10=0.05,0.1", "--no-pictures", "--no-fields",
                           "--out", str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "case 1/2: c10=0.05" in done.stderr and "case 2/2: c10=0.1" in done.stderr
    assert re.search(r"case 2/2: ok in [0-9.]+ s", done.stderr)


def _record(step: int, load: float) -> StepRecord:
    return StepRecord(step, load, 0.25, 4, 0, [1.0, 1e-3, 1e-9])


def test_the_bar_and_the_lines_name_the_stage():
    stepping = Stepping(0.0, 3.0, stops=(1.0, 2.0), stage_names=("IOP", "buckling", "suturing"))
    records: list[StepRecord] = []
    progress = PathProgress("eye", stepping, records, show=True, terminal=True)
    try:
        for step, load in enumerate((0.5, 1.0, 1.5, 2.0, 3.0), start=1):
            records.append(_record(step, load))
            progress.update(load / 3.0 - progress.n)
            stage = "IOP" if load <= 1.0 else "buckling" if load <= 2.0 else "suturing"
            assert progress.bar.desc.rstrip(": ") == f"eye · {stage}"
    finally:
        progress.close()
    line = PathProgress("eye", stepping, records, show=True, terminal=False).line(_record(3, 1.5))
    assert line.startswith("eye · buckling: step 3, load 1.5 (stage 2/3), 4 Newton iterations, "
                           "residual 1.00e-09")


def test_the_main_job_names_its_stages():
    from eyemech.problems import scleral_buckling as sb
    from eyemech.problems.scleral_buckling.stages import operation

    assert tuple(stage.name for stage in operation(sb.Parameters())) == \
        ("iop", "buckling", "suturing", "settling")
