"""The planning map's table (``eyemech study buckling-planning``) is made by the study, not
by hand: docs/atlas/buckling-planning.md and docs/studies/buckling_planning_table.md hold
exactly what :func:`markdown_table` makes of the committed CSV, so a map made again brings
its page's table along. No solve: the rows are read back from the CSV."""

from __future__ import annotations

from pathlib import Path

from eyemech.problems.studies._common import read_csv
from eyemech.problems.studies.buckling_planning import markdown_table

DOCS = Path(__file__).resolve().parents[1] / "docs"
CSV = DOCS / "studies" / "buckling_planning.csv"


def _table_in(page: Path, header: str) -> list[str]:
    lines = page.read_text().splitlines()
    start = lines.index(header)
    end = next((k for k in range(start, len(lines)) if not lines[k].startswith("|")), len(lines))
    return lines[start:end]


def test_the_atlas_page_shows_the_table_the_study_makes_of_its_csv():
    table = markdown_table(read_csv(CSV)).splitlines()
    assert len(table) == 2 + len(read_csv(CSV))
    assert _table_in(DOCS / "atlas" / "buckling-planning.md", table[0]) == table
    assert (DOCS / "studies" / "buckling_planning_table.md").read_text().splitlines() == table


def test_the_table_names_each_case_and_its_verdicts():
    rows = {row["setting"]: row for row in read_csv(CSV)}
    table = markdown_table(list(rows.values()))
    defaults = next(line for line in table.splitlines() if line.startswith("| **defaults**"))
    gap = float(rows["defaults"]["settled_tear_rim_gap_max_mm"])
    band = float(rows["defaults"]["settled_tear_rim_gap_band_mm"])
    assert f"{gap:.3f} ± {band:.3f}".replace("-", "−") in defaults
    assert rows["defaults"]["settled_tear_verdict"] == "closed" and "**closed**" in defaults
    # the tire alone has no band: its tension is a dash, not a zero
    tire_alone = next(line for line in table.splitlines() if line.startswith("| tire alone"))
    assert tire_alone.endswith("| — |")


def test_a_failed_case_is_a_row_that_says_so():
    row = dict(read_csv(CSV)[3], status="failed", error="Newton stalled in step 4")
    line = markdown_table([row]).splitlines()[-1]
    assert line.startswith("| band shortened 10 % | failed: Newton stalled in step 4 |")
    assert line.count("|") == 9  # the header's 8 columns
