"""``eyemech study all --quick`` (issue 9): every registered study runs on coarse
settings and writes at least one CSV and one PNG, each stamped with the machine,
versions and date (CSV: a ``# `` comment line; PNG: the ``Comment`` text chunk that
:func:`_common.save_chart` writes beside the visible footer)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from PIL import Image

from eyemech.problems.studies import studies
from eyemech.problems.studies._common import stamp


def test_study_all_quick_writes_stamped_csv_and_png(tmp_path):
    eyemech = Path(sys.executable).parent / "eyemech"
    done = subprocess.run([str(eyemech), "study", "all", "--quick", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, done.stderr[-3000:]
    lines = done.stdout.splitlines()
    expected_stamp = stamp().split(" · ", 1)[1]  # machine and versions (the date may roll over)
    for name in studies():
        line = next((x for x in lines if x.startswith(f"{name}: wrote ")), None)
        assert line is not None, f"{name} did not report its files:\n{done.stdout}"
        files = [Path(f.strip()) for f in line.split(": wrote ", 1)[1].rsplit(" (", 1)[0].split(",")]
        csvs = [f for f in files if f.suffix == ".csv"]
        pngs = [f for f in files if f.suffix == ".png"]
        assert csvs and pngs, f"{name} wrote {files}"
        for table in csvs:
            assert expected_stamp in table.read_text(), f"{table} has no stamp"
        for chart in pngs:
            assert expected_stamp in Image.open(chart).text.get("Comment", ""), f"{chart} has no stamp"
