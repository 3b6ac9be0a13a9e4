"""Colour maps against a truth that shares no code with the renderer.

tests/truth/colour_layer_walk.py walks photons (NumPy, no jsss) through a half-space under a
Fresnel interface; each carries sqrt(c) of a step colour map where it enters and where it
leaves (d'Eon 2007 sec. 5.3's layer). The scene as a user writes it -- a plane lit straight
down, the step map as an EXR, profile = "transport" (exact to transport, so the comparison
tests the texturing, not diffusion's known bias) -- renders its texel exitance in texture
space, which must agree bin by bin with the walk's, across the colour edge and at the plane's
rim (the walk's strip beam ends where the plane does). The other two rules must not: the
comparison can tell pre-post from pre and post.
"""

import jax.numpy as jnp
import numpy as np
import pytest

from jsss.render import Method, parse_scene, plan_scene, render_params
from measure.exr import write_exr
from tests.truth.colour_layer_walk import step_exitance

SIGMA_A, SIGMA_S, ETA = [0.02, 0.05, 0.1], [1.0, 1.2, 1.5], 1.3
LEFT, RIGHT = [0.9, 0.6, 0.25], [0.2, 0.8, 1.0]
WIDTH, BIN = 30.0, 1.0


@pytest.fixture(scope="module")
def walk():
    return step_exitance(SIGMA_A, SIGMA_S, ETA, LEFT, RIGHT, photons=800_000, half_width=WIDTH / 2, bin_width=BIN,
                         seed=11)


def _texture_space_bins(tmp_path, texturing, centres):
    size = 256
    u = (np.arange(size) + 0.5) / size
    colour = np.empty((size, size, 3))
    colour[:, u < 0.5], colour[:, u >= 0.5] = LEFT, RIGHT
    write_exr(tmp_path / "step.exr", colour[::-1])
    scene = parse_scene({
        "geometry": {"shape": "plane", "width": WIDTH, "depth": 60.0},
        "material": {"sigma_a": SIGMA_A, "sigma_s_prime": SIGMA_S, "eta": ETA, "profile": "transport",
                     "texturing": texturing, "maps": {"albedo": "step.exr"}},
        "lights": [{"type": "directional", "direction": [0.0, 0.0, -1.0]}],
        "camera": {"position": [0.0, 0.0, 200.0], "up": [0.0, 1.0, 0.0], "fov": 12, "resolution": [128, 128]},
        "render": {"texture_size": 256, "accuracy": 0.02}}, source="step.toml", base_dir=tmp_path)
    plan = plan_scene(scene, method=Method.TEXTURE_SPACE)
    params = render_params(scene, plan, dtype=jnp.float64)
    prepared = plan.method_config.prepare(scene, plan, params)
    exitance = np.asarray(plan.method_config.exitance(params, prepared))  # per unit irradiance (intensity 1)
    x, y = prepared.texels.position[..., 0], prepared.texels.position[..., 1]
    middle = prepared.texels.mask & (np.abs(y) < 5.0)  # 60 mm deep: the middle is as if infinite in y
    return np.array([exitance[middle & (np.abs(x - c) < BIN / 2)].mean(0) for c in centres])


def test_texture_space_agrees_with_the_colour_layer_walk_across_the_edge(tmp_path, walk):
    centres, truth, stderr = walk
    assert np.median(stderr / truth) < 0.01  # the walk resolves 3 % per 1 mm bin (the dim rim bins less)
    near = np.abs(centres) < 1.0
    far = np.abs(centres + 10) < 1.0
    assert np.all(np.abs(truth[near].mean(0) - truth[far].mean(0)) > 0.05 * truth[far].mean(0))  # the edge shows
    model = _texture_space_bins(tmp_path, "pre-post", centres)
    ratio = model / truth
    np.testing.assert_array_less(np.abs(ratio - 1), 0.03 + 3 * stderr / truth)
    sums = model.sum(0) / truth.sum(0)
    np.testing.assert_allclose(sums, 1.0, atol=0.01)


@pytest.mark.parametrize("rule", ["pre", "post"])
def test_the_other_rules_are_not_the_layer_the_walk_crosses_twice(tmp_path, walk, rule):
    centres, truth, stderr = walk
    model = _texture_space_bins(tmp_path, rule, centres)
    edge = np.abs(centres) < 2.0
    assert np.max(np.abs(model[edge] / truth[edge] - 1)) > 0.05 + 3 * np.max(stderr[edge] / truth[edge])
