"""A colour (albedo) map and the mean free path from a photo (fitting.albedo_map).

The photos are jsss's own renders of a plane with a known checker colour map (pre-post
texturing) plus Gaussian noise of a known level: these tests check the fit -- recovery within
its stated errors, the errors themselves against the exact (J^T J)^-1, bad input -- not the
renderer's physics (benchmarks/ compare it with a path tracer).
"""

import dataclasses
import tomllib

import jax.numpy as jnp
import numpy as np
import pytest

from fitting.albedo_map import AlbedoMapError, fit_albedo_map
from jsss.render import parse_scene, plan_scene, render
from jsss.render.surface_maps import SurfaceMaps

SCENE = """
[geometry]
shape = "plane"
width = 20.0

[material]
sigma_a = [0.05, 0.1, 0.2]
sigma_s_prime = [1.5, 1.8, 2.0]
eta = 1.4
roughness = 0.3

[[lights]]
type = "directional"
direction = [-1.0, 0.2, -0.8]
intensity = 2.0

[camera]
position = [0.0, -20.0, 28.0]
look_at = [0.0, 0.0, 0.0]
fov = 40
resolution = [64, 48]

[render]
texture_size = 64
"""
MAP = 16  # texels per side of the fitted map: about two fitted pixels per texel
GAIN = 2.0
NOISE = 0.01


def _checker(size):
    rows, cols = np.indices((size, size))
    check = ((rows * 4 // size + cols * 4 // size) % 2)[..., None]
    return np.where(check, [0.9, 0.6, 0.3], [0.4, 0.7, 0.8])


@pytest.fixture(scope="module")
def problem():
    """The scene (material without its map), the true map, a photo, its noise and the true mfp."""
    scene = parse_scene(tomllib.loads(SCENE), source="plane.toml")
    truth = _checker(MAP)
    textured = dataclasses.replace(scene, material=dataclasses.replace(scene.material,
                                                                       maps=SurfaceMaps(albedo=truth)))
    plan = plan_scene(textured, accuracy=0.001, method="texture-space")
    clean = np.asarray(render(textured, plan, dtype=jnp.float64).radiance)
    sigma = NOISE * np.maximum(clean, 0.01 * clean.max())
    photo = GAIN * (clean + sigma * np.random.default_rng(1).standard_normal(clean.shape))
    medium = scene.material.medium
    mfp = 1.0 / (np.asarray(medium.sigma_a) + np.asarray(medium.sigma_s_prime))
    return scene, truth, photo, GAIN * sigma, mfp


@pytest.fixture(scope="module")
def fits(problem):
    """One fit with the probed error map and one with the exact one. The mean free path starts at
    the truth, which keeps each fit to one compilation (a start far off re-plans the Gaussians):
    the map starts from the photo's own ratio to a white render, and the fit moves the mean
    free path within its errors."""
    scene, _, photo, sigma, mfp = problem
    common = dict(gain=GAIN, sigma=sigma, map_size=MAP, init_mean_free_path=mfp)
    return (fit_albedo_map(scene, photo, errors="probe", **common),
            fit_albedo_map(scene, photo, errors="exact", **common))


def test_map_recovered_within_its_errors(problem, fits):
    """Every well-seen texel within 4 stated errors of the truth (about 750 values: 4 sigma is
    exceeded by chance with probability 0.05), and the errors neither too wide nor too narrow."""
    _, truth, _, _, _ = problem
    fit = fits[0]
    assert fit.converged
    assert fit.seen.sum() >= 200  # most of the plane is in view
    z = ((fit.albedo - truth) / fit.albedo_err)[fit.seen]
    assert np.all(np.abs(z) < 4), np.abs(z).max()
    assert 0.7 <= np.sqrt(np.mean(z**2)) <= 1.4
    assert 0.7 <= fit.chi2_reduced <= 1.4


def test_unseen_texels_are_flagged_not_invented(fits):
    """Texels the camera does not look up keep the start and get an infinite error; no NaN anywhere."""
    fit = fits[0]
    assert (~fit.seen).any()
    assert np.all(np.isinf(fit.albedo_err[~fit.seen]))
    assert np.all(np.isfinite(fit.albedo)) and np.all(np.isfinite(fit.albedo_err[fit.seen]))


def test_probed_errors_match_the_exact_inverse(fits):
    """The probing estimate of diag (J^T J)^-1 against the inverse of J^T J formed from the full
    Jacobian, on the same problem: within 15 % per texel on the median, 40 % at worst (one
    random-sign probe per colour: its scatter is the inverse's entries between texels four apart)."""
    probe, exact = fits
    seen = probe.seen
    ratio = probe.albedo_err[seen] / exact.albedo_err[seen]
    assert np.median(np.abs(ratio - 1)) < 0.15
    assert np.all(np.abs(ratio - 1) < 0.4), ratio
    assert np.allclose(probe.mean_free_path_err, exact.mean_free_path_err, rtol=0.05)


def test_mean_free_path_within_its_errors(problem, fits):
    _, _, _, _, mfp = problem
    fit = fits[1]
    assert np.all(np.isfinite(fit.mean_free_path_err)) and np.all(fit.mean_free_path_err > 0)
    assert np.all(np.abs(fit.mean_free_path - mfp) < 3 * fit.mean_free_path_err), (fit.mean_free_path, mfp)


def test_bad_input_names_the_value_and_the_fix(problem):
    scene, _, photo, sigma, _ = problem
    with pytest.raises(AlbedoMapError, match="gain: the photo's exposure is required"):
        fit_albedo_map(scene, photo)
    with pytest.raises(AlbedoMapError, match="one direction with the map's scale"):
        fit_albedo_map(scene, photo, gain="fit")
    with pytest.raises(ValueError, match="set \\[camera\\] resolution"):
        fit_albedo_map(scene, photo[:-1], gain=GAIN)
    with pytest.raises(AlbedoMapError, match="map_size must be an integer from 2"):
        fit_albedo_map(scene, photo, gain=GAIN, sigma=sigma, map_size=1)
    with pytest.raises(AlbedoMapError, match="errors must be"):
        fit_albedo_map(scene, photo, gain=GAIN, errors="hutchinson")
