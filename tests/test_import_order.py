"""``import dolfinx`` with nothing imported before it, in the environment's Python and in a
fresh Jupyter kernel (scripts/import_order.py: the PyPI wheel needs MPICH's libmpi loaded
first, which ``eyemech-import-order.pth`` arranges at the first import of DOLFINx)."""

from __future__ import annotations

import subprocess
import sys

import pytest

CHECK = "import dolfinx, petsc4py.PETSc; print('dolfinx', dolfinx.__version__)"


@pytest.mark.parametrize("first", ["dolfinx", "petsc4py.PETSc"])
def test_bare_import_in_a_fresh_interpreter(first, tmp_path):
    # -c from an empty folder: nothing of the repository on sys.path, no conftest imports
    done = subprocess.run([sys.executable, "-c", f"import {first}; {CHECK}"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "dolfinx 0." in done.stdout


def test_bare_import_in_a_fresh_jupyter_kernel(tmp_path):
    import nbformat
    from nbclient import NotebookClient

    notebook = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(CHECK)])
    NotebookClient(notebook, timeout=120, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = notebook.cells[0].outputs
    assert not [o for o in outputs if o.get("output_type") == "error"], outputs
    assert "dolfinx 0." in "".join(o.get("text", "") for o in outputs)


def test_the_finder_leaves_python_without_dolfinx_alone(tmp_path):
    """Start-up imports nothing of MPI: a Python that never imports DOLFINx stays light."""
    done = subprocess.run([sys.executable, "-c", "import sys; print('mpi4py' in sys.modules, "
                           "any(type(f).__name__ == 'MPIFirst' for f in sys.meta_path))"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert done.stdout.split() == ["False", "True"], done.stdout + done.stderr
