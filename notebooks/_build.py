"""Writes the tutorial notebooks from plain cell lists (run: python notebooks/_build.py NAME).

The .ipynb files are committed without outputs; the test suite executes them.
"""

from __future__ import annotations

import sys
from pathlib import Path

import nbformat

HERE = Path(__file__).parent


def write(name: str, cells: list[tuple[str, str]]) -> None:
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    for kind, source in cells:
        source = source.strip("\n")
        nb.cells.append(nbformat.v4.new_markdown_cell(source) if kind == "md" else nbformat.v4.new_code_cell(source))
    nbformat.write(nb, HERE / f"{name}.ipynb")


if __name__ == "__main__":
    import importlib

    for name in sys.argv[1:]:
        module = importlib.import_module(f"_cells_{name}")
        write(name, module.CELLS)
