"""Silhouette pixels: their coverage against the exact area of a disc, and frames weighted by it."""

import jax.numpy as jnp
import numpy as np
import pytest

from jsss.render import parse_scene, plan_scene, render
from jsss.render.image_space import camera_buffers
from jsss.render.mesh import uv_sphere
from jsss.render.raster import PerspectiveView, antialiased_raster, rasterize
from tests.jsss.render.scenes import scene_dict

RADIUS, DISTANCE = 10.0, 60.0
CAMERA = PerspectiveView((0.0, -DISTANCE, 0.0), (0.0, 0.0, 0.0), 30.0, 64, 48)


def _disc_coverage(shape, centre, radius, fine=33):
    """Exact-to-1e-3 share of each pixel inside a disc, by fine sub-sampling (independent of the rasterizer)."""
    H, W = shape
    offsets = (np.arange(fine) + 0.5) / fine
    x = np.arange(W)[:, None] + offsets[None, :]  # (W, fine)
    y = np.arange(H)[:, None] + offsets[None, :]
    inside = ((x[None, :, None, :] - centre[0]) ** 2 + (y[:, None, :, None] - centre[1]) ** 2) <= radius**2
    return inside.mean(axis=(2, 3))


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("JSSS_CACHE_DIR", str(tmp_path))


def test_silhouette_coverage_matches_the_exact_area_of_the_spheres_disc():
    """A sphere seen along the axis outlines a disc of radius f R / sqrt(D^2 - R^2) pixels (its
    tangent cone). Each silhouette pixel's coverage must follow the disc's area in that pixel;
    a mask sampled at pixel centres alone is 0 or 1 there (issue 20: aliased silhouettes)."""
    mesh = uv_sphere(RADIUS, segments=256, rings=128)
    xy, z = CAMERA.project(mesh.vertices)
    shape = (CAMERA.height, CAMERA.width)
    raster = antialiased_raster(xy, z, mesh.faces, shape)
    exact = _disc_coverage(shape, (CAMERA.width / 2, CAMERA.height / 2),
                           CAMERA.focal * RADIUS / np.sqrt(DISTANCE**2 - RADIUS**2))
    edge = (exact > 0) & (exact < 1)
    assert edge.sum() > 100
    binary = rasterize(xy, z, mesh.faces, shape).mask.astype(float)
    centre_error = np.abs(binary - exact)[edge].mean()
    error = np.abs(raster.coverage - exact)[edge].mean()
    assert centre_error > 0.1  # what centre sampling alone gets: the stair-steps
    assert error < 0.07, (error, centre_error)  # 3 x 3 samples: about a ninth of a pixel at worst
    assert np.abs(raster.coverage - exact)[~edge].max() < 1e-12  # interior and background untouched
    assert raster.coverage.sum() == pytest.approx(exact.sum(), rel=2e-3)
    # A pixel whose area the surface covers has a triangle to shade it, and fully covered pixels keep theirs.
    assert np.all(raster.mask == (raster.coverage > 0))
    centre, full = rasterize(xy, z, mesh.faces, shape), raster.coverage == 1
    assert np.array_equal(raster.face[full], centre.face[full])
    assert np.array_equal(raster.bary[full], centre.bary[full])


@pytest.mark.parametrize("method", ["lambert", "texture-space"])
def test_silhouette_pixels_follow_a_supersampled_render(method):
    """The truth for a pixel is the mean radiance over its area: the same scene rendered at 3x
    the resolution and averaged over 3 x 3 blocks. At silhouette pixels the coverage-weighted
    frame must be much closer to it than centre sampling (the frame without coverage)."""
    def frame(factor):
        data = scene_dict(camera={"position": [0.0, -110.0, 30.0], "fov": 28, "resolution": [48 * factor, 36 * factor]})
        scene = parse_scene(data)
        result = render(scene, plan_scene(scene, method=method), dtype=jnp.float64)
        xy, z = scene.camera.project(scene.mesh.vertices)
        centre = rasterize(xy, z, scene.mesh.faces, (scene.camera.height, scene.camera.width)).mask
        return result.radiance, camera_buffers(scene.mesh, scene.camera), centre

    radiance, buffers, centre = frame(1)
    fine, _, _ = frame(3)
    truth = fine.reshape(36, 3, 48, 3, 3).mean(axis=(1, 3))
    coverage = buffers.coverage
    partial = (coverage > 0) & (coverage < 1)
    assert partial.sum() > 50
    assert np.all(radiance[coverage == 0] == 0)
    # Centre sampling: a pixel is the surface's radiance (at this frame's shading points) where
    # its centre is covered, else 0.
    centre_sampled = np.where(centre[..., None], radiance / np.where(coverage > 0, coverage, 1.0)[..., None], 0.0)
    scale = truth[coverage == 1].mean()
    error = np.abs(radiance - truth)[partial].mean() / scale
    stepped = np.abs(centre_sampled - truth)[partial].mean() / scale
    assert error < 0.5 * stepped, (error, stepped)


def test_face_chunks_hold_at_most_the_candidate_budget_and_cover_every_face_once():
    """raster._chunks (bisection on the running total) against the rule it replaced, a loop that
    closes a run before the face that would overflow it (a face over budget goes alone)."""
    from jsss.render import raster

    def by_loop(counts):
        start, total, out = 0, 0, []
        for i, c in enumerate(counts):
            if total + c > raster._MAX_CANDIDATES and i > start:
                out.append((start, i))
                start, total = i, 0
            total += c
        return out + ([(start, len(counts))] if start < len(counts) else [])

    rng = np.random.default_rng(3)
    budget = raster._MAX_CANDIDATES
    for counts in (rng.integers(0, budget // 50, 2000), rng.integers(0, 3 * budget, 40), np.zeros(5, int),
                   np.array([budget, budget, 0, 1]), np.array([], int)):
        assert list(raster._chunks(counts)) == by_loop(counts)


@pytest.mark.parametrize("perspective", [True, False])
def test_a_large_face_tested_alone_gives_the_chunked_raster_bit_for_bit(perspective, monkeypatch):
    """Faces with many candidate pixels are tested on their own box, without per-pixel gathers
    (raster._ALONE). On a mesh of large and small faces, with shared edges through pixel centres
    (ties in depth that the later face wins) and a second layer behind, the raster equals the
    one every face in chunks gives, bit for bit, with and without perspective and a pixel mask."""
    from jsss.render import raster

    rng = np.random.default_rng(0)
    big = np.array([[0.0, 0.0], [64.0, 0.0], [64.0, 48.0], [0.0, 48.0]])  # two triangles, diagonal through centres
    small = rng.uniform(5, 60, (40, 2)) * [1.0, 0.75]
    xy = np.concatenate([big, big * 0.5 + 8, small])
    depth = np.concatenate([np.full(4, 2.0), np.full(4, 1.0), rng.uniform(0.5, 3.0, 40)])
    faces = np.concatenate([[[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]],
                            8 + np.arange(36).reshape(12, 3)])
    where = rng.uniform(size=(48, 64)) < 0.8
    for mask in (None, where):
        monkeypatch.setattr(raster, "_ALONE", 64)  # these faces' boxes: 3072, 768 and 1-1500 pixels
        alone = rasterize(xy, depth, faces, (48, 64), perspective=perspective, where=mask)
        monkeypatch.setattr(raster, "_ALONE", 1 << 62)
        chunked = rasterize(xy, depth, faces, (48, 64), perspective=perspective, where=mask)
        assert np.array_equal(alone.face, chunked.face) and np.array_equal(alone.bary, chunked.bary)
        assert np.array_equal(alone.depth, chunked.depth)
    assert (np.unique(alone.face) >= 0).sum() > 6  # large and small faces both won pixels
