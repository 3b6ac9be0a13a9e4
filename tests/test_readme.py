"""Every Python snippet of the README runs on its own, as a user would paste it (a fresh
interpreter in the repository root, nothing defined by an earlier snippet)."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SNIPPETS = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)


def test_the_readme_has_snippets():
    assert len(SNIPPETS) >= 5


@pytest.mark.parametrize("index", range(len(SNIPPETS)))
def test_readme_snippet_runs_on_its_own(index):
    out = subprocess.run([sys.executable, "-c", SNIPPETS[index]], cwd=ROOT, capture_output=True, text=True,
                         stdin=subprocess.DEVNULL, timeout=900)
    assert out.returncode == 0, f"snippet {index}:\n{SNIPPETS[index]}\n{out.stderr[-2000:]}"


def test_the_readme_scene_format_is_a_valid_scene(tmp_path):
    """The documented scene (the README's TOML block) loads, so the documentation cannot drift."""
    from jsss.render import load_scene

    blocks = re.findall(r"```toml\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    assert blocks
    path = tmp_path / "documented.toml"
    path.write_text(blocks[0])
    import imageio.v3 as iio
    import numpy as np

    for name in re.findall(r'^\w+ = "(\w+\.png)"', blocks[0], flags=re.M):  # the maps it names, as a user has them
        iio.imwrite(tmp_path / name, np.full((8, 8, 3), 200, np.uint8))
    scene = load_scene(path)
    assert scene.material.profile_model == "dipole" and len(scene.lights) == 1
    assert scene.material.maps is not None and scene.material.maps.texturing == "pre-post"
