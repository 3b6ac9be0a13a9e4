"""The render methods as immutable configurations: checked when built, returned by the planner, run by render."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from jsss.render import (ImageSpace, Lambert, Method, NormalFiltering, Pass, RenderMethod, TextureSpace,
                         method_config, parse_scene, plan_scene, render)
from jsss.render.methods import CONFIGURATIONS
from tests.jsss.render.scenes import scene_dict


@pytest.mark.parametrize("build, message", [
    (lambda: ImageSpace(samples=0), r"ImageSpace\(samples=0\): samples per pixel must be a whole number >= 1"),
    (lambda: ImageSpace(samples=8.5), r"ImageSpace\(samples=8\.5\)"),
    (lambda: ImageSpace(samples=True), r"ImageSpace\(samples=True\)"),
    (lambda: ImageSpace(samples=32, uniform_fraction=1.0), r"ImageSpace\(uniform_fraction=1\.0\) must lie in \[0, 1\)"),
    (lambda: ImageSpace(seed=-1), r"ImageSpace\(seed=-1\)"),
    (lambda: NormalFiltering(kind="gaussian"),
     r"NormalFiltering\(kind='gaussian'\): the filter must be one of 'spectral', 'naive'"),
    (lambda: NormalFiltering(eigenpairs=0), r"NormalFiltering\(eigenpairs=0\) must be a whole number >= 1"),
    (lambda: TextureSpace(size=0), r"TextureSpace\(size=0\): the texture needs a whole number >= 2 of texels"),
    (lambda: TextureSpace(size=256.0), r"TextureSpace\(size=256\.0\)"),
    (lambda: TextureSpace(size=256, taps=4), r"TextureSpace\(taps=4\): a blur pass needs an odd number >= 3"),
    (lambda: TextureSpace(size=256, max_ratio=1.0), r"TextureSpace\(max_ratio=1\.0\): each blur step must grow"),
    (lambda: TextureSpace(size=256, max_ratio=float("inf")), r"TextureSpace\(max_ratio=inf\)"),
])
def test_a_bad_knob_is_refused_when_built_naming_it_and_the_fix(build, message):
    with pytest.raises(ValueError, match=message) as error:
        build()
    assert "e.g." in str(error.value) or "must" in str(error.value)


def test_configurations_are_immutable_hashable_values():
    """Equal knobs, equal (and equally hashed) configurations: what a compiled program can be kept by;
    a field cannot be changed after construction."""
    assert TextureSpace(256) == TextureSpace(256, taps=7, max_ratio=4.0)
    assert hash(ImageSpace(16)) == hash(ImageSpace(samples=16)) and ImageSpace(16) != ImageSpace(32)
    assert len({Lambert(), Lambert(), NormalFiltering("naive"), NormalFiltering("spectral")}) == 3
    with pytest.raises(dataclasses.FrozenInstanceError):
        TextureSpace(256).size = 512
    with pytest.raises(TypeError, match="abstract"):
        RenderMethod()
    assert {m: c.method for m, c in CONFIGURATIONS.items()} == {m: m for m in Method}


@pytest.fixture(scope="module")
def scene():
    return parse_scene(scene_dict(camera={"position": [0.0, -110.0, 30.0], "fov": 28, "resolution": [24, 18]},
                                  render={"texture_size": 64, "accuracy": 0.1}))


@pytest.mark.parametrize("method, knobs, expected", [
    ("lambert", {}, Lambert()),
    ("normal filtering", {"normal_filter": "naive"}, NormalFiltering(kind="naive")),
    ("normal-filtering", {}, NormalFiltering(kind="spectral")),
    ("image-space", {"samples": 16}, ImageSpace(samples=16)),
    ("texture-space", {}, TextureSpace(size=64, taps=7, max_ratio=2.0)),
])
def test_the_planner_returns_the_methods_configuration(scene, method, knobs, expected):
    """plan.method_config is the configuration of the method asked for, with the planner's knobs
    (texture space: the scene's 64^2 texture, 7 taps, steps of 2x below a 15 % target), and the
    plan's knob attributes read it."""
    plan = plan_scene(scene, method=method, **knobs)
    assert type(plan.method_config) is type(expected) and plan.method_config == expected
    assert plan.method == expected.method == Method(method)
    assert plan.samples == (16 if isinstance(expected, ImageSpace) else None)
    assert plan.texture_size == (64 if isinstance(expected, TextureSpace) else None)
    assert plan.normal_filter == (expected.kind if isinstance(expected, NormalFiltering) else None)
    assert f"knobs: {expected.describe(plan)}" in plan.describe()


def test_a_planned_method_is_a_configuration_of_its_kind(scene):
    """Without method=, the calibration's choice comes back as its configuration too."""
    plan = plan_scene(scene)
    assert isinstance(plan.method_config, CONFIGURATIONS[plan.method])


def test_render_runs_the_plans_configuration(scene):
    """render dispatches on plan.method_config: a texture-space plan whose configuration is
    swapped for Lambert's renders Lambert's frame, and a different texture size is another frame."""
    lambert = render(scene, plan_scene(scene, method="lambert"), dtype=jnp.float64).radiance
    texture = plan_scene(scene, method="texture-space")
    swapped = dataclasses.replace(texture, method_config=Lambert()).replace(Pass.DIFFUSION, False, "test")
    np.testing.assert_array_equal(render(scene, swapped, dtype=jnp.float64).radiance, lambert)
    small = dataclasses.replace(texture, method_config=TextureSpace(32, 7, 2.0))
    assert render(scene, small).prepared.texels.size == 32
    assert method_config("image-space", samples=4) == ImageSpace(4)
    with pytest.raises(ValueError, match="samples"):
        method_config("image-space", samples=0)


@pytest.mark.parametrize("spelling, member", [
    ("normal filtering", "NORMAL_FILTERING"), ("normal-filtering", "NORMAL_FILTERING"),
    ("Normal Filtering", "NORMAL_FILTERING"), ("texture_space", "TEXTURE_SPACE"), ("texture space", "TEXTURE_SPACE"),
    ("IMAGE-SPACE", "IMAGE_SPACE"), (" lambert ", "LAMBERT")])
def test_a_method_is_read_from_any_spelling_a_user_types(spelling, member):
    """The scene file's, the command line's (no spaces) and a person's (any case) spellings name one member."""
    assert Method(spelling) is Method[member]


@pytest.mark.parametrize("spelling", ["normal", "texturespace", "image space sampling", ""])
def test_an_unknown_method_is_refused(spelling):
    with pytest.raises(ValueError):
        Method(spelling)
