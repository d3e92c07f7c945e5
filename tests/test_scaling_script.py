"""scripts/scaling.py (issue 10 part 3): the table and chart side, without any solve
(the runs themselves are minutes long and belong in docs/scaling, not in tests)."""

from __future__ import annotations

import csv

from eyemech.scripts import scaling


def _row(case: str, solver: str, ranks: int, level: int, dofs: int, krylov: float) -> dict:
    row = {key: "" for key in scaling.COLUMNS}
    row.update(case=case, scene="scleral-buckling", level=level, solver=solver, ranks=ranks,
               dofs=dofs, status="ok", krylov_per_solve=krylov, s_per_newton=0.5)
    return row


def test_append_and_report_write_table_and_chart(tmp_path, capsys):
    scaling.append(tmp_path, _row("sb-coarse", "direct", 1, 0, 4248, 1.0))
    scaling.append(tmp_path, _row("sb-coarse", "iterative", 2, 0, 4248, 349.1))
    scaling.append(tmp_path, _row("sb-default", "iterative", 1, 1, 8984, 343.2))
    rows = list(csv.DictReader((tmp_path / "scaling.csv").open()))
    assert [r["case"] for r in rows] == ["sb-coarse", "sb-coarse", "sb-default"]
    assert scaling.main(["report", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "scaling.png").stat().st_size > 0
    table = capsys.readouterr().out.splitlines()
    assert len(table) == 2 + 3 and table[-1].startswith("| sb-default | iterative | 1 | 8984")


def test_probe_rows_go_to_their_own_table(tmp_path):
    row = {key: i for i, key in enumerate(scaling.PROBE_COLUMNS)}
    scaling.append(tmp_path, row, "refinement.csv", scaling.PROBE_COLUMNS)
    scaling.append(tmp_path, row, "refinement.csv", scaling.PROBE_COLUMNS)
    rows = list(csv.DictReader((tmp_path / "refinement.csv").open()))
    assert len(rows) == 2 and tuple(rows[0]) == scaling.PROBE_COLUMNS
    assert not (tmp_path / "scaling.csv").exists()
