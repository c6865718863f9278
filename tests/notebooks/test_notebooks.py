"""Every notebook under notebooks/ executes without a cell error.

The notebooks are jupytext percent-format scripts (``# %%`` cells). Each one is converted with
jupytext to an nbformat notebook and executed by nbclient in a fresh ``python3`` kernel, in a
temporary working directory. The notebooks assert what they show, so executing them is a test.

The kernel must find the package: the repository root is put on PYTHONPATH before the kernel
starts. The ``python3`` kernelspec comes with ipykernel; if it is missing, register it with
``python -m ipykernel install --user``.
"""
from __future__ import annotations

import os
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow      # the fast lane (pytest -m 'not slow') leaves these out

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.py"))
KERNEL = "python3"
TIMEOUT_S = 300

jupytext = pytest.importorskip("jupytext")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("nbformat")
pytest.importorskip("ipykernel")


def _require_kernel() -> None:
    from jupyter_client.kernelspec import KernelSpecManager, NoSuchKernel

    try:
        KernelSpecManager().get_kernel_spec(KERNEL)
    except NoSuchKernel:
        pytest.fail(f"no Jupyter kernel named {KERNEL!r}: run `python -m ipykernel install --user`")


def test_notebooks_found():
    assert NOTEBOOKS, "expected at least one notebooks/*.py"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_executes(path, tmp_path, monkeypatch):
    _require_kernel()
    # the kernel inherits this process's environment: make the package importable there
    paths = [str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(dict.fromkeys(paths)))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = jupytext.read(path)
    assert any(c.cell_type == "code" for c in nb.cells), f"{path.name} has no code cells"
    client = nbclient.NotebookClient(nb, timeout=TIMEOUT_S, kernel_name=KERNEL, allow_errors=False,
                                     resources={"metadata": {"path": str(tmp_path)}})
    client.execute()  # raises CellExecutionError (cell source + traceback) on the first failing cell
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors, errors
    assert list(tmp_path.iterdir()) == [], "notebooks must write nothing outside their own temp dirs"
