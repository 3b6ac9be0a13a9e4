"""Every tutorial in notebooks/ is a jupytext percent script that runs top to bottom on a fresh kernel.

Each executed notebook is also written to docs/_build/executed/ (git-ignored): the docs show
the tutorials with these outputs (docs/conf.py), so the docs build never executes them again.
"""

import os
from pathlib import Path

import pytest

jupytext = pytest.importorskip("jupytext")
nbclient = pytest.importorskip("nbclient")

FOLDER = Path(__file__).parent.parent / "notebooks"
EXECUTED = Path(__file__).parent.parent / "docs" / "_build" / "executed"
NOTEBOOKS = sorted(p for p in FOLDER.glob("*.py") if not p.name.startswith("_"))


def test_there_are_notebooks():
    """The tutorials exist (a missing directory must not pass silently)."""
    assert NOTEBOOKS


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_is_a_percent_script(path):
    """Plain Python (it compiles, so it lints and runs as a script) in jupytext's percent format,
    exactly as jupytext writes it back: a markdown title, code cells, the kernel in the header
    and not jupytext's version (its filter is in the header too), so saving from Jupyter
    changes nothing that was reviewed."""
    text = path.read_text()
    compile(text, str(path), "exec")
    nb = jupytext.reads(text, fmt="py:percent")
    assert nb.cells[0].cell_type == "markdown" and nb.cells[0].source.startswith("# ")
    assert any(cell.cell_type == "code" for cell in nb.cells)
    assert nb.metadata["kernelspec"]["name"] == "python3"
    assert jupytext.writes(nb, fmt="py:percent") == text


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path, monkeypatch):
    """Build the notebook from its script with jupytext and execute it in notebooks/ with a
    non-interactive matplotlib backend (Jupyter's inline one, which keeps the figures as
    outputs) and the default (fast) settings."""
    # Jupyter's inline backend: non-interactive like Agg, and the figures become the outputs the docs show
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    monkeypatch.delenv("JSSS_FULL", raising=False)  # the notebooks' default (fast) settings
    nb = jupytext.read(path)
    client = nbclient.NotebookClient(nb, timeout=300, kernel_name="python3",
                                     resources={"metadata": {"path": str(path.parent)}})
    client.execute()
    errors = [o for cell in nb.cells if cell.cell_type == "code" for o in cell.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors, errors
    _keep_for_the_docs(nb, path.stem)


def _keep_for_the_docs(nb, name):
    """Write the executed notebook where docs/conf.py reads it, atomically (a docs build may
    read it at the same time); a read-only checkout just goes without."""
    import nbformat

    try:
        EXECUTED.mkdir(parents=True, exist_ok=True)
        partial = EXECUTED / f".{name}.{os.getpid()}.ipynb"
        nbformat.write(nb, partial)
        os.replace(partial, EXECUTED / f"{name}.ipynb")
    except OSError:
        pass
