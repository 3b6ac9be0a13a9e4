"""The path-traced truth of a pre-post colour map (benchmarks/albedo_map_truth.py): Mitsuba's
``mask`` BSDF of opacity 1 - sqrt(c) over an index-matched medium must scale a homogeneous
plane's frame by c, and its opacity bitmap must lie on the plane in jsss's UV layout."""

import tempfile

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")

from benchmarks import albedo_map_truth as amt
from benchmarks import transport_truth as tt
from jsss.render import parse_scene
from jsss.render.image_space import camera_buffers

# A low-albedo medium: short walks, so the frames are cheap (the construction does not depend on it)
FAST = {"sigma_a": [0.3, 0.3, 0.3], "sigma_s_prime": [1.0, 1.0, 1.0]}


def _scene(width, height):
    data = amt.scene_data(width, height)
    data["material"].update(FAST)
    return parse_scene(data)


@pytest.fixture(scope="module")
def mitsuba():
    mi.set_variant("scalar_rgb")
    return mi


def test_a_uniform_mask_scales_the_frame_by_c(mitsuba):
    """sqrt(c) on the way in (next-event transmittance) times sqrt(c) on the way out (the camera
    path kept with probability 1 - opacity): c, within 4 standard errors of the chunks."""
    c = (0.6, 0.4, 0.2)
    with tempfile.TemporaryDirectory() as folder:
        ratio, stderr, _ = amt.uniform_check(mitsuba, _scene(12, 9), amt.surface_files(folder), c, 128, 6)
    assert np.all(stderr < 0.02), stderr  # the comparison below can fail
    assert np.all(np.abs(ratio - np.asarray(c)) < 4 * stderr + 0.002), (ratio, stderr)
    assert np.all(np.abs(ratio - np.sqrt(c)) > 8 * stderr)  # sqrt(c) once (a one-sided mask) is excluded


@pytest.mark.parametrize("axis", ["u", "v"])
def test_the_opacity_bitmap_lies_in_jsss_uv_layout(mitsuba, axis):
    """Opaque where u < 1/2 (jsss: x < 0) or v < 1/2 (jsss: y > 0): exactly black there, lit on the
    other side (a flipped u or v, or a transposed bitmap, lights the wrong half)."""
    scene = _scene(16, 12)
    albedo = np.ones((8, 8, 3))
    if axis == "u":
        albedo[:, :4] = 0.0
    else:
        albedo[:4] = 0.0
    with tempfile.TemporaryDirectory() as folder:
        frame = amt.frames(mitsuba, scene, amt.surface_files(folder), albedo, 4, 1, progress=False)[0]
    buffers = camera_buffers(scene.mesh, scene.camera)
    inner = tt._interior(buffers.mask)
    position = np.asarray(buffers.position)
    # Pixels well inside either half (the bilinear ramp spans a map texel, 7.5 mm, about the middle)
    coordinate = position[..., 0] if axis == "u" else -position[..., 1]
    dark, lit = inner & (coordinate < -6), inner & (coordinate > 6)
    assert dark.sum() > 5 and lit.sum() > 5
    assert np.all(frame[dark] == 0.0)
    assert np.all(frame[lit].sum(-1) > 0)
