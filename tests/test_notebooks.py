"""Every notebook executes against a small run, so they never rot; what it displays is
the run's: each notebook lists the numbers it shows in ``shown`` as (file, key path,
value), and each must equal that file's value (a notebook that shows the unloaded first
step of a ``.pvd`` series fails). Its pictures are shown inline (PNG outputs), and the
results.json files it reads fit the schema."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from test_results_schema import check_results

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("*.py"))
# pictures each notebook shows inline, at least (charts and pyvista views)
PICTURES = {"scleral_buckling": 3, "sphere_inflation": 2, "sweep_comparison": 2, "keratotomy": 2,
            "tonometry": 2, "lens": 1}
REPORT = 'import json as _json\nprint("SHOWN " + _json.dumps(shown))'


def lookup(data, path: str):
    for part in path.split("."):
        data = data[int(part)] if isinstance(data, list) else data[part]
    return data


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes_and_shows_the_runs_numbers(path, tmp_path, monkeypatch):
    import jupytext
    import nbformat
    from nbclient import NotebookClient

    notebook = jupytext.read(path)
    notebook.cells.append(nbformat.v4.new_code_cell(REPORT))
    monkeypatch.setenv("EYEMECH_RUN_DIR", str(tmp_path / "run"))
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    client = NotebookClient(notebook, timeout=900, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    outputs = [o for cell in notebook.cells for o in cell.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    pictures = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(pictures) >= PICTURES[path.stem], f"{len(pictures)} pictures shown inline"
    report = "".join(o.get("text", "") for o in notebook.cells[-1].outputs)
    shown = json.loads(report.split("SHOWN ", 1)[1])
    assert shown, "the notebook shows no number from its run"
    checked = set()
    for file, key, value in shown:
        if file.endswith("results.json") and file not in checked:
            check_results(Path(file))
            checked.add(file)
        expected = lookup(json.loads(Path(file).read_text()), key)
        assert math.isclose(value, expected, rel_tol=1e-9, abs_tol=1e-12), \
            f"{Path(file).parent.name}/{Path(file).name} {key}: shown {value}, the run's {expected}"


def test_sweep_comparison_reads_another_scenes_sweep(tmp_path, monkeypatch):
    """The sweep notebook takes its grid keys and quantities from the sweep's files: a
    retina-reattachment sweep (no sphere key anywhere) is charted and checked alike."""
    import subprocess
    import sys

    import jupytext
    import nbformat
    from nbclient import NotebookClient

    sweep = tmp_path / "sweep"
    subprocess.run([str(Path(sys.executable).parent / "eyemech"), "sweep", "retina-reattachment",
                    "--grid", "pressure=1e-5,2e-5", "--out", str(sweep), "--quiet", "--fields"],
                   check=True, capture_output=True, timeout=900)
    notebook = jupytext.read(Path(__file__).parents[1] / "notebooks" / "sweep_comparison.py")
    notebook.cells.append(nbformat.v4.new_code_cell(REPORT))
    monkeypatch.setenv("EYEMECH_SWEEP_DIR", str(sweep))
    NotebookClient(notebook, timeout=900, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    report = "".join(o.get("text", "") for o in notebook.cells[-1].outputs)
    shown = json.loads(report.split("SHOWN ", 1)[1])
    assert {Path(f).parent.name for f, _, _ in shown} == {"case_0000", "case_0001"}
    for file, key, value in shown:
        assert math.isclose(value, lookup(json.loads(Path(file).read_text()), key), rel_tol=1e-9)
