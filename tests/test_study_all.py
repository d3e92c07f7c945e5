"""``eyemech study all --quick``: every registered study runs on coarse settings, every
case of it runs (exit 0: a failed case exits 4), and it writes at least one CSV and one
PNG, each stamped with the machine, versions and date (CSV: its ``<stem>.meta.json``
sidecar, the CSV itself a plain table; PNG: the ``Comment`` text chunk that
:func:`_common.save_chart` writes beside the visible footer)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from PIL import Image

from eyemech.problems.studies import studies
from eyemech.problems.studies._common import sidecar, stamp


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
            assert not table.read_text().startswith("#"), f"{table} starts with a comment line"
            meta = json.loads(sidecar(table).read_text())
            assert expected_stamp in meta["made"], f"{table} has no stamp"
            assert meta["study"] == name and meta["quick"] is True and meta["settings_hash"]
        for chart in pngs:
            assert expected_stamp in Image.open(chart).text.get("Comment", ""), f"{chart} has no stamp"
