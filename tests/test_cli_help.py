"""`eyemech run NAME --help`: the scene's parameters by group, with defaults and units;
an unknown key is answered with the close ones."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

EYEMECH = Path(sys.executable).parent / "eyemech"


def test_run_name_help_lists_the_parameters_by_group():
    done = subprocess.run([str(EYEMECH), "run", "sphere-inflation", "--help"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    text = done.stdout
    assert "--set KEY=VALUE" in text  # the command's own options come first
    heads = [text.index(f"  {group}:") for group in ("physics", "geometry and mesh",
                                                    "solver and stepping")]
    assert heads == sorted(heads)
    physics, geometry, solver = (text[a:b] for a, b in zip(heads, heads[1:] + [len(text)]))
    assert "pressure = 0.01 MPa" in physics and "c10 = 0.05 MPa" in physics
    assert "inner_radius = 10.0 mm" in geometry and "element = P2P1" in geometry
    assert "load_steps = 1" in solver


def test_sweep_name_help_too():
    done = subprocess.run([str(EYEMECH), "sweep", "hertz", "-h"], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0 and "--grid" in done.stdout and "indentation = " in done.stdout


def test_an_unknown_key_gets_a_did_you_mean(tmp_path):
    done = subprocess.run([str(EYEMECH), "run", "sphere-inflation", "--set", "presure=0.02",
                           "--out", str(tmp_path / "out")], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2
    assert "did you mean 'pressure'" in done.stderr
    assert not (tmp_path / "out").exists()


def test_a_reader_that_stops_early_ends_the_help_quietly():
    """`eyemech run NAME --help | head`: the reader is gone before the help is written (its
    end of the pipe closed at once). The scenes' imports start PETSc, whose SIGPIPE handler
    aborted with exit 15 and "Caught signal number 13 Broken Pipe"."""
    proc = subprocess.Popen([str(EYEMECH), "run", "scleral-buckling", "--help"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0, err[-2000:]
    assert "PETSC ERROR" not in err and "Broken Pipe" not in err
