"""The README and the docs guides cannot drift from the code: every Python snippet runs on its own,
as a user would paste it (a fresh interpreter in the repository root, nothing defined by an
earlier snippet), every scene TOML block loads, and the commands on the demo's files use the
demo's own eta."""

import re
import shlex
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# The README and the pages a reader copies from; the benchmark pages are measurements, and the
# tutorials are executed by tests/test_notebooks.py.
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md")) + sorted((ROOT / "docs" / "guides").glob("*.md"))


def _blocks(language):
    """{snippet text: the first page holding it}: a snippet repeated on two pages runs once."""
    found = {}
    for page in PAGES:
        for text in re.findall(rf"^```{language}\n(.*?)^```", page.read_text(), flags=re.S | re.M):
            found.setdefault(text, page.relative_to(ROOT).as_posix())
    return found


SNIPPETS = _blocks("python")
SCENES = _blocks("toml")


def test_the_docs_have_snippets():
    """The README has its examples, and the guides theirs (a renamed page must not pass silently)."""
    readme = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    assert len(readme) >= 4
    assert len(SNIPPETS) >= 8 and any(page.startswith("docs/guides/") for page in SNIPPETS.values())
    assert any(page == "docs/guides/scene_format.md" for page in SCENES.values())


def test_the_readme_keeps_the_two_commands():
    text = (ROOT / "README.md").read_text()
    assert "pip install -e . && fit-params --demo" in text
    assert "pip install -e '.[test]' && pytest -q" in text
    assert len(text.splitlines()) <= 200


@pytest.mark.parametrize("snippet", list(SNIPPETS), ids=[f"{page}-{i}" for i, page in enumerate(SNIPPETS.values())])
def test_snippet_runs_on_its_own(snippet):
    out = subprocess.run([sys.executable, "-c", snippet], cwd=ROOT, capture_output=True, text=True,
                         stdin=subprocess.DEVNULL, timeout=900)
    assert out.returncode == 0, f"{SNIPPETS[snippet]}:\n{snippet}\n{out.stderr[-2000:]}"


def _files_named(value):
    """Every string in a parsed scene that names an image or a mesh."""
    if isinstance(value, dict):
        for item in value.values():
            yield from _files_named(item)
    elif isinstance(value, list):
        for item in value:
            yield from _files_named(item)
    elif isinstance(value, str) and re.search(r"\.(png|jpe?g|tiff?|exr|obj|gltf|glb)$", value):
        yield value


def _scene_from_block(text, folder):
    """The block as a scene file in ``folder``: a whole scene as it is; a fragment (a page showing
    one table) laid over examples/marble_sphere.toml, its tables replacing the example's. The
    files it names are the examples' where they exist there, else stand-ins a user would have."""
    import shutil

    import imageio.v3 as iio
    import numpy as np
    import tomlkit

    data = tomllib.loads(text)
    if not {"geometry", "camera"} <= data.keys():
        base = tomllib.loads((ROOT / "examples" / "marble_sphere.toml").read_text())
        data = {**base, **data}
    for name in set(_files_named(data)):
        target = folder / name
        target.parent.mkdir(parents=True, exist_ok=True)
        if (ROOT / "examples" / name).is_file():
            shutil.copy(ROOT / "examples" / name, target)
        elif name.endswith(".exr"):
            shutil.copy(ROOT / "examples" / "maps" / "studio.exr", target)
        else:
            iio.imwrite(target, np.full((8, 8, 3), 200, np.uint8))
    path = folder / "documented.toml"
    path.write_text(tomlkit.dumps(data))
    return path


@pytest.mark.parametrize("block", list(SCENES), ids=[f"{page}-{i}" for i, page in enumerate(SCENES.values())])
def test_documented_scene_loads(block, tmp_path):
    """Each scene block of the docs is valid: jsss refuses misspelt keys, so a renamed key in the
    code fails here until the page follows."""
    from jsss.render import load_scene

    scene = load_scene(_scene_from_block(block, tmp_path))
    assert scene.lights


def test_the_scene_format_page_shows_every_part():
    """The full scene of docs/guides/scene_format.md: a Jensen material with maps, one light."""
    from jsss.render import load_scene

    block = next(text for text, page in SCENES.items() if page == "docs/guides/scene_format.md")
    with pytest.MonkeyPatch.context():
        import tempfile

        with tempfile.TemporaryDirectory() as folder:
            scene = load_scene(_scene_from_block(block, Path(folder)))
    assert scene.material.profile_model == "dipole" and len(scene.lights) == 1
    assert scene.material.maps is not None and scene.material.maps.texturing == "pre-post"


def test_commands_on_the_demo_files_use_the_demo_eta():
    """fit-params --demo writes marble (eta 1.5) to demo/; a command on those files with another
    --eta fits the wrong medium (--eta 1.3 gave chi2/dof 1.7e3 and sigma_a +56 %)."""
    from jsss.materials import jensen2001

    eta = float(jensen2001("marble").eta.ravel()[0])
    lines = [line for page in PAGES
             for block in re.findall(r"^```bash\n(.*?)^```", page.read_text(), flags=re.S | re.M)
             for line in block.splitlines() if line.startswith("fit-params") and "demo/" in line]
    assert len(lines) >= 3
    for line in lines:
        words = shlex.split(line.split("#")[0])
        if "--eta" in words:
            assert float(words[words.index("--eta") + 1]) == eta, line


def _command_lines():
    """Every command of the README's and the guides' bash blocks, comments dropped, ``&&`` split."""
    for page in PAGES:
        for block in re.findall(r"^```bash\n(.*?)^```", page.read_text(), flags=re.S | re.M):
            for line in block.splitlines():
                for command in line.split("#")[0].split("&&"):
                    if command.strip():
                        yield page.relative_to(ROOT).as_posix(), shlex.split(command)


def test_every_documented_command_parses():
    """Each fit-params, jsss-render and jsss line of the docs is accepted by that command's own
    argument parser (a renamed or removed flag fails here, without running a fit)."""
    from measure.commands import fit_params, info, render

    parsers = {"fit-params": fit_params.parser, "jsss-render": render.parser, "jsss": info.parser}
    checked = 0
    for page, words in _command_lines():
        if words[0] in parsers:
            try:
                parsers[words[0]]().parse_args(words[1:])
            except SystemExit as exit:
                pytest.fail(f"{page}: {' '.join(words)} (exit {exit.code})")
            checked += 1
    assert checked >= 15
