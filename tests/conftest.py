"""Shared test helpers: run the command line (serially or under mpiexec) and read
the JSON it prints as its last stdout line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent


def run_cli(*args: str, ranks: int = 1, timeout: float = 900) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of ``eyemech args...``."""
    command = [str(BIN / "eyemech"), *args]
    if ranks > 1:
        command = [str(BIN / "mpiexec"), "-n", str(ranks), *command]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.run(command, capture_output=True, text=True, timeout=timeout, env=env)
    return proc.returncode, proc.stdout, proc.stderr


def last_json(stdout: str) -> dict:
    lines = [line for line in stdout.strip().splitlines() if line.startswith("{")]
    assert lines, f"no JSON line in output:\n{stdout}"
    return json.loads(lines[-1])


@pytest.fixture
def cli():
    return run_cli
