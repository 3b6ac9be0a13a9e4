"""A command's argument parser, its ``--help`` and ``import jsss`` load no JAX: the parsers list
the render methods from :mod:`jsss.render.passes`, and ``jsss`` and ``jsss.render`` import
their names on first use (PEP 562). JAX, equinox and SciPy were 1.5-2.3 s of every start.
Each check runs in a fresh interpreter, whose ``sys.modules`` is the truth; no timing."""

import json
import subprocess
import sys

import pytest

HEAVY = ("jax", "equinox", "scipy", "matplotlib", "trimesh")


def _loaded_after(code: str) -> list[str]:
    """The heavy packages a fresh interpreter holds after running ``code``."""
    probe = f"import sys, json\n{code}\nprint(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))"
    out = subprocess.run([sys.executable, "-c", probe], check=False, capture_output=True, text=True, timeout=120,
                         stdin=subprocess.DEVNULL)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.splitlines()[-1])


@pytest.mark.parametrize("command", ["render", "fit_params"])
def test_building_a_commands_parser_imports_no_jax(command):
    code = f"from measure.commands import {command}\nparser = {command}.parser()"
    assert _loaded_after(code) == []


@pytest.mark.parametrize("argv", [["--help"], ["fit", "--help"], ["--version"]])
def test_render_help_imports_no_jax(argv):
    code = ("from measure.commands import render\n"
            "try:\n"
            f"    render.main({argv!r})\n"
            "except SystemExit as stop:\n"
            "    assert stop.code == 0, stop.code")
    assert _loaded_after(code) == []


def test_the_probe_sees_an_import():
    """The check can fail: importing a module that needs JAX shows up."""
    assert "jax" in _loaded_after("import jsss.render.planner")


def test_lazy_packages_keep_every_public_name():
    """Everything in ``__all__`` of ``jsss`` and ``jsss.render`` resolves to what the submodule
    defines; ``jsss.render.linear_frame`` stays the function after its module is imported."""
    import importlib

    import jsss
    import jsss.render

    importlib.import_module("jsss.render.linear_frame")  # the submodule first, then the package's name
    from jsss.render import linear_frame, render
    from jsss.render.renderer import render as defined

    for package in (jsss, jsss.render):
        for name in package.__all__:
            assert getattr(package, name) is not None, name
        assert set(package.__all__) <= set(dir(package))
    assert callable(linear_frame) and render is defined
    assert jsss.dipole is sys.modules["jsss.diffusion.dipole"] and jsss.Medium.__module__ == "jsss.medium"
    with pytest.raises(AttributeError):
        jsss.render.no_such_name  # noqa: B018


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_png_has_the_pixels_matplotlib_wrote(tmp_path, dtype):
    """jsss-render writes its PNG with Pillow (matplotlib's import was 0.4 s of each start): the
    decoded pixels equal ``matplotlib.image.imsave``'s, NaN pixels and values at 0 and 1 included."""
    import matplotlib.image
    import numpy as np
    from PIL import Image

    from measure.commands._console import write_png

    rng = np.random.default_rng(3)
    image = rng.random((17, 23, 3)).astype(dtype)
    image[0, 0], image[1, 1], image[2, 2, 1] = 0.0, 1.0, np.nan
    matplotlib.image.imsave(tmp_path / "matplotlib.png", image, format="png")
    write_png(tmp_path / "jsss.png", image, software="test")
    ours, theirs = (np.asarray(Image.open(tmp_path / name)) for name in ("jsss.png", "matplotlib.png"))
    assert ours.shape == (17, 23, 4) and np.array_equal(ours, theirs)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        write_png(tmp_path / "bad.png", image * 2, software="test")
    assert not (tmp_path / "bad.png").exists()
