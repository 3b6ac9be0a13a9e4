"""Sphinx configuration of the jsss docs: ``sphinx-build -W docs docs/_build/html``.

Why Sphinx with myst-nb and the pydata theme: the anchors this project follows build their
docs that way. JAX (and equinox's neighbours in the JAX world) write Sphinx pages in Markdown
with myst-nb, which renders notebooks with their outputs; numpy, scipy and scikit-image use
Sphinx with pydata-sphinx-theme and numpy-style docstrings, which Sphinx's own napoleon reads.
jsss's docstrings are numpy-style and its pages were Markdown (README sections, docs/*.md),
so they move over unchanged. mkdocs with mkdocstrings was the other choice the issue named;
it reads numpy docstrings through a plugin and notebooks through another, and none of the
anchors use it.

What the build reads:

- Markdown pages under docs/ (MyST), the CHANGELOG through docs/changelog.md;
- the API reference, one page per module of jsss, fitting and measure, written by
  :func:`_write_api_pages` from the package tree on every build (``docs/api/`` is generated,
  git-ignored), each an ``automodule`` with its members (napoleon, numpy style);
- the tutorials: notebooks/*.py (jupytext percent scripts) converted to
  ``docs/tutorials/NAME.ipynb`` on every build (git-ignored). The docs build never executes
  them: tests/test_notebooks.py already does, and writes each executed notebook to
  ``docs/_build/executed/``; a tutorial page shows those outputs where that copy's cells equal
  the script's (so no stale output is ever shown), and the bare script otherwise. Executing
  them a second time in the docs build would have cost the CI suite another 3 minutes on two
  cores (the notebooks' own test time); this way the docs test costs the build alone.
  ``pytest -n 0 tests/test_notebooks.py && sphinx-build -W docs docs/_build/html`` gives the
  site with every tutorial executed.
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

project = "jsss"
author = "the jsss authors"
copyright = "2026, the jsss authors"

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
]

exclude_patterns = ["_build", "**.ipynb_checkpoints", "README.md"]
source_suffix = {".md": "myst-nb", ".ipynb": "myst-nb", ".rst": "restructuredtext"}
nb_execution_mode = "off"     # executed once, by tests/test_notebooks.py (above)
myst_enable_extensions = ["dollarmath"]
myst_heading_anchors = 3
suppress_warnings = [
    # Pages moved from the README keep links to repository files (examples/, benchmarks/):
    # those are not documents of the site, and MyST may not turn every one into a link.
    "myst.xref_missing",
    # A docstring's type text such as "shape" or "path" matches attributes of several classes;
    # Sphinx warns that the guess is ambiguous (and links none). Unresolved ones never warn.
    "ref.python",
]

autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
autodoc_member_order = "bysource"
autodoc_typehints = "none"    # jaxtyping annotations read badly inline; the docstrings say shapes and units
autodoc_inherit_docstrings = False
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = True      # an Attributes section is a field list: autodoc documents the fields themselves
napoleon_use_param = False    # parameter types as text: "shape" or "path" in a type is not a cross-reference

# Docstring markup that docutils reads as something else, in files other people were editing
# when the docs were set up (jsss/render/*, measure/commands/fit_params.py): mended here, as the
# page is built, instead of in the files. Each entry is a no-op once the docstring is fixed.
# {object's full name: [(text, replacement), ...]}
DOCSTRING_MENDS = {
    "jsss.render.methods.base.RenderMethod.describe": [("``knobs: ``", "``knobs:``")],
}
# |x| is an absolute value in these docstrings, not a docutils substitution.
ESCAPE_PIPES = {"jsss.render.comparison.relative_rms", "jsss.render.methods.texture_space.TextureSpace.diffusion",
                "jsss.render.texture_space.face_stretch"}
# A section header that is not one of numpy's: {object: (header line, its note)}.
SECTION_MENDS = {"jsss.render.lighting.LightGeometry": (
    "Attributes (arrays of the points' shape ``P``)", "The attributes are arrays of the points' shape ``P``.")}
# A module docstring that opens with an indented usage block (a literal block wants "::").
LITERAL_USAGE = {"measure.commands.fit_params"}


def _mend_docstring(app, what, name, obj, options, lines):
    for old, new in DOCSTRING_MENDS.get(name, ()):
        for i, line in enumerate(lines):
            lines[i] = line.replace(old, new)
    if name in ESCAPE_PIPES:
        lines[:] = [line.replace("|", "\\|") for line in lines]
    _close_sections(lines)
    if name in SECTION_MENDS:
        header, note = SECTION_MENDS[name]
        for i, line in enumerate(lines):
            if line.strip() == header:
                lines[i:i + 1] = [note, "", line.replace(header, "Attributes")]
                break
    if name in LITERAL_USAGE and len(lines) > 2 and not lines[1].strip() and lines[2].startswith(" "):
        lines[1:2] = ["", "::", ""]


_ENTRY = re.compile(r"^\*{0,2}\w+(, \*{0,2}\w+)*\s*(:.*)?$")


def _close_sections(lines):
    """numpy style ends a section only at the next header, so a paragraph written after an
    Attributes or Parameters section would be read as entries of it: such a paragraph (a line
    after a blank one that is not ``name : type``) gets a Notes header."""
    section = None
    for i in range(len(lines)):
        line = lines[i]
        if i + 1 < len(lines) and set(lines[i + 1].strip()) == {"-"} and line.strip():
            section = line.strip()
            continue
        if section in ("Attributes", "Parameters", "Other Parameters") and i > 0 and not lines[i - 1].strip() \
                and line.strip() and not line[0].isspace() and not set(line.strip()) == {"-"} \
                and not _ENTRY.match(line):
            lines[i:i] = ["Notes", "-----"]
            section = "Notes"


def _end_field_lists(app, what, name, obj, options, lines):
    """Napoleon turns an Attributes section into ``:ivar:`` fields and leaves the paragraph
    after it glued to the field list; docutils wants a blank line between them."""
    for i in range(len(lines) - 1, 0, -1):
        here, before = lines[i], lines[i - 1]
        if here and not here[0].isspace() and not here.startswith(":") and \
                (before.startswith(":") or (before[:1].isspace() and before.strip())):
            j = i - 1
            while j > 0 and lines[j][:1].isspace() and lines[j].strip():
                j -= 1
            if lines[j].startswith((":ivar", ":vartype", ":param", ":type")):
                lines.insert(i, "")


def _benchmark_page_title(app, docname, source):
    """The benchmark scripts write their pages as they print them: a dated first line (or a
    title) and ``###`` tables. The site wants one title per page and no skipped heading level:
    a first line that is not a heading becomes the title, and the other headings move up so
    that the highest is level 2."""
    if not docname.startswith("benchmarks/"):
        return
    lines = source[0].split("\n")
    if not lines:
        return
    first = lines[0] if lines[0].startswith("# ") else "# " + lines[0]
    rest = lines[1:]
    in_code = False
    heading = []
    for i, line in enumerate(rest):
        if line.startswith("```"):
            in_code = not in_code
        elif not in_code and re.match(r"#+ ", line):
            heading.append(i)
    levels = [len(rest[i]) - len(rest[i].lstrip("#")) for i in heading]
    shift = min(levels) - 2 if levels and min(levels) > 2 else 0
    for i in heading:
        rest[i] = rest[i][shift:]
    source[0] = "\n".join([first] + rest)


def setup(app):
    app.connect("source-read", _benchmark_page_title)
    # Napoleon (priority 500) has already turned sections into fields when these run.
    app.connect("autodoc-process-docstring", _mend_docstring, priority=400)
    app.connect("autodoc-process-docstring", _end_field_lists, priority=600)


html_theme = "pydata_sphinx_theme"
html_title = "jsss"
html_theme_options = {"navigation_depth": 2, "show_toc_level": 2}
html_static_path = []

# ---------------------------------------------------------------------------------------------
# Generated sources: the API reference and the tutorials

PACKAGES = ("jsss", "fitting", "measure")


def _modules(package: str) -> list[tuple[str, bool]]:
    """(dotted name, is a package) of every module under ``package``, sorted; private modules
    (a leading underscore) and data folders without code are left out."""
    found = []
    for path in sorted((ROOT / package).rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if any(part.startswith("_") and part != "__init__" for part in parts):
            continue
        is_package = parts[-1] == "__init__"
        found.append((".".join(parts[:-1] if is_package else parts), is_package))
    return found


def _write_if_changed(path: Path, text: str) -> None:
    """Sphinx rebuilds what changed: an unchanged page keeps its time stamp."""
    if not path.exists() or path.read_text() != text:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def _write_api_pages() -> None:
    """docs/api/PACKAGE.rst lists its modules; docs/api/MODULE.rst documents one module's own
    members (a package's page shows its docstring only: its names are documented where they
    are defined, once)."""
    api = HERE / "api"
    wanted = set()
    for package in PACKAGES:
        modules = _modules(package)
        lines = [package, "=" * len(package), "", f".. automodule:: {package}", "   :no-members:", "",
                 ".. toctree::", "   :maxdepth: 1", ""]
        lines += [f"   {name}" for name, _ in modules if name != package]
        _write_if_changed(api / f"{package}.rst", "\n".join(lines) + "\n")
        wanted.add(f"{package}.rst")
        for name, is_package in modules:
            if name == package:
                continue
            title = f"``{name}``"
            body = [title, "=" * len(title), "", f".. automodule:: {name}"]
            body += ["   :no-members:"] if is_package else []
            _write_if_changed(api / f"{name}.rst", "\n".join(body) + "\n")
            wanted.add(f"{name}.rst")
    for stale in api.glob("*.rst"):  # a module that was removed or renamed
        if stale.name not in wanted:
            stale.unlink()


def executed_copy(script: Path, executed_folder: Path):
    """The notebook to show for the tutorial ``script``: the executed copy that
    tests/test_notebooks.py wrote, if its cells are the script's cells, else the script's own
    cells without outputs. Returns (notebook, whether it carries outputs)."""
    import jupytext
    import nbformat

    source = jupytext.read(script)
    executed = executed_folder / f"{script.stem}.ipynb"
    if executed.exists():
        try:
            ran = nbformat.read(executed, as_version=4)
        except Exception:  # a half-written or foreign file: show the script
            ran = None
        if ran is not None and [(c.cell_type, c.source) for c in ran.cells] == \
                [(c.cell_type, c.source) for c in source.cells]:
            return ran, True
    return source, False


def _write_tutorials() -> None:
    import nbformat

    folder = HERE / "tutorials"
    executed_folder = HERE / "_build" / "executed"
    scripts = sorted(p for p in (ROOT / "notebooks").glob("*.py") if not p.name.startswith("_"))
    for script in scripts:
        notebook, _ = executed_copy(script, executed_folder)
        _write_if_changed(folder / f"{script.stem}.ipynb", nbformat.writes(notebook) + "\n")
    for stale in folder.glob("*.ipynb"):
        if not (ROOT / "notebooks" / f"{stale.stem}.py").exists():
            stale.unlink()


if not os.environ.get("JSSS_DOCS_NO_GENERATE"):
    _write_api_pages()
    _write_tutorials()
