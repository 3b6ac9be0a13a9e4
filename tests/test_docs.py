"""The docs site builds with warnings as errors, its links stay inside the repository, and a
tutorial page never shows outputs of an older version of its notebook.

The build is Sphinx with myst-nb (docs/conf.py): the API reference of every module, the guides,
the benchmark pages and the tutorials (shown with the outputs of tests/test_notebooks.py's run
where that run is current; the build itself executes nothing)."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def test_docs_build_with_warnings_as_errors(tmp_path):
    """``sphinx-build -W``: a docstring whose markup breaks, a page outside every toctree, a
    broken heading level or a missing include fails the suite."""
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_nb")
    pytest.importorskip("pydata_sphinx_theme")
    out = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                          "-d", str(tmp_path / "doctrees"), str(DOCS), str(tmp_path / "html")],
                         cwd=ROOT, capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=600)
    assert out.returncode == 0, out.stderr[-4000:]
    html = tmp_path / "html"
    for page in ("index", "api/jsss.diffusion.dipole", "api/fitting.medium", "api/measure.pipeline",
                 "api/jsss.render.scene", "guides/conventions", "papers", "tutorials/render", "changelog"):
        assert (html / f"{page}.html").is_file(), page
    # autodoc really documented the functions (an import failure leaves an empty page and a warning)
    assert "total_reflectance" in (html / "api" / "jsss.diffusion.dipole.html").read_text()


def _links(page):
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.S | re.M)  # not inside code
    text = re.sub(r"`[^`\n]*`", "", text)
    return re.findall(r"\]\(([^)\s#]+)(?:#[^)]*)?\)", text)


PAGES = [ROOT / "README.md", ROOT / "CHANGELOG.md"] + sorted(DOCS.rglob("*.md"))


@pytest.mark.parametrize("page", PAGES, ids=[p.relative_to(ROOT).as_posix() for p in PAGES])
def test_links_stay_in_the_repository(page):
    """Every relative link of the README and the docs names a file or folder of this repository
    (the README once linked ../shared/DESIGN.md, outside it)."""
    if "_build" in page.parts:
        pytest.skip("build output")
    broken = []
    for target in _links(page):
        if re.match(r"[a-z]+:", target):  # https:, mailto:
            continue
        resolved = (page.parent / target).resolve()
        if not resolved.is_relative_to(ROOT) or not resolved.exists():
            broken.append(target)
    assert not broken, broken


def test_a_tutorial_shows_only_current_outputs(tmp_path):
    """docs/conf.py takes the executed copy only where its cells are the script's: a notebook
    executed before its script changed is not shown."""
    nbformat = pytest.importorskip("nbformat")
    jupytext = pytest.importorskip("jupytext")
    sys.path.insert(0, str(DOCS))
    try:
        import os

        os.environ["JSSS_DOCS_NO_GENERATE"] = "1"  # import the helper without writing pages
        import conf
    finally:
        sys.path.remove(str(DOCS))
        os.environ.pop("JSSS_DOCS_NO_GENERATE", None)
    script = tmp_path / "tiny.py"
    script.write_text(jupytext.writes(nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_markdown_cell("# Tiny"), nbformat.v4.new_code_cell("print(1)")],
        metadata={"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}}),
        fmt="py:percent"))
    executed = tmp_path / "executed"
    executed.mkdir()
    ran = jupytext.read(script)
    ran.cells[1].outputs = [nbformat.v4.new_output("stream", name="stdout", text="1\n")]
    nbformat.write(ran, executed / "tiny.ipynb")

    shown, has_outputs = conf.executed_copy(script, executed)
    assert has_outputs and shown.cells[1].outputs[0].text == "1\n"

    script.write_text(script.read_text().replace("print(1)", "print(2)"))  # the script moved on
    shown, has_outputs = conf.executed_copy(script, executed)
    assert not has_outputs and shown.cells[1].source == "print(2)" and not shown.cells[1].get("outputs")
