"""The photo's noise, estimated from the photo (issue 36, part 2), and a loss that heavy-tailed
pixels do not steer. Truth: noise drawn from a known model, and a known material."""

import tomllib

import jax.numpy as jnp
import numpy as np
import pytest

from fitting.render import HUBER_K, RenderFitError, estimate_noise, fit_render, provisional_noise
from jsss.render import parse_scene, plan_scene, render

from .test_exposure import SPHERE


def _smooth_image(shape=(120, 160), seed=0):
    y, x = np.mgrid[0:shape[0], 0:shape[1]]
    base = 0.2 + np.exp(-((x - 70) ** 2 + (y - 50) ** 2) / 2000.0)
    return np.repeat(base[..., None], 3, axis=-1) * np.array([1.0, 0.7, 0.4])


@pytest.mark.parametrize("model", ["read+shot", "relative"])
def test_a_known_noise_model_is_recovered_within_10_percent(model):
    """Read + shot noise (a + b mu) or a relative error (c mu^2): each pixel's estimated standard
    error within 10 % of the one drawn with, RMS over the image."""
    mu = _smooth_image()
    truth = np.sqrt(1e-5 + 2e-4 * mu) if model == "read+shot" else 0.02 * mu
    rng = np.random.default_rng(1)
    photo = mu + truth * rng.standard_normal(mu.shape)
    use = np.ones(mu.shape[:2], bool)
    sigma = estimate_noise(photo - mu, mu, use)
    assert np.sqrt(np.mean((sigma / truth - 1) ** 2)) < 0.10


def test_a_smooth_misfit_is_not_taken_for_noise():
    """A model 5 % off in a smooth pattern leaves the estimate where the noise alone puts it (the
    differences of adjacent residuals cancel it), so chi^2 can still show the misfit."""
    mu = _smooth_image()
    truth = 0.01 * mu
    rng = np.random.default_rng(2)
    photo = mu + truth * rng.standard_normal(mu.shape)
    _, x = np.mgrid[0:mu.shape[0], 0:mu.shape[1]]
    biased = mu * (1 + 0.05 * np.sin(x / 25.0))[..., None]
    sigma = estimate_noise(photo - biased, biased, np.ones(mu.shape[:2], bool))
    assert np.sqrt(np.mean((sigma / truth - 1) ** 2)) < 0.15
    assert np.mean(((photo - biased) / sigma) ** 2) > 3  # the misfit shows


def _best_scale(model, photo, sigma, robust):
    """The scale k of the model that the fit's loss prefers (whitened, Huber's with ``robust``)."""
    scales = np.linspace(0.8, 1.2, 801)

    def loss(k):
        r = np.abs((k * model - photo) / sigma)
        return np.sum(np.where(r <= HUBER_K, r**2, 2 * HUBER_K * r - HUBER_K**2) if robust else r**2)
    return scales[np.argmin([loss(k) for k in scales])]


@pytest.mark.parametrize("robust", [True, False], ids=["huber", "squares"])
def test_the_first_fits_noise_does_not_pull_the_fit_dark(robust):
    """A path-traced photo's 20 % noise per pixel, Gaussian about the truth: weighted by the
    provisional noise the loss prefers the truth's brightness within 1 % (measured: exactly, on
    a grid of 0.05 %, with either loss), and the noise is read within 10 % of the drawn one
    (measured 19.9 %). Weighting each pixel by 5 % of its own noisy value, as the fit did before
    2026-12-07, prefers it 4.5 % (Huber's) and 9.4 % (squares) dark: a pixel pulled dark by its
    noise weighs more, and Huber at a quarter of the noise is nearly a median fit."""
    mu = _smooth_image()
    rng = np.random.default_rng(4)
    photo = mu * (1 + 0.2 * rng.standard_normal(mu.shape))
    use = np.ones(mu.shape[:2], bool)
    sigma = provisional_noise(photo, use)
    assert abs(np.median(sigma / mu) / 0.2 - 1) < 0.10
    assert abs(_best_scale(mu, photo, sigma, robust) - 1) < 0.01
    assert _best_scale(mu, photo, 0.05 * np.abs(photo), robust) < 0.97  # the check bites
    given = provisional_noise(photo, use, 0.2)  # a noise the user gives: times the local level, too
    assert abs(_best_scale(mu, photo, given, robust) - 1) < 0.01


def test_too_few_pixels_ask_for_the_noise():
    mu = _smooth_image((10, 10))
    with pytest.raises(RenderFitError, match="give it"):
        estimate_noise(mu * 0, mu, np.ones((10, 10), bool))


def test_fireflies_do_not_steer_the_fit():
    """A 1 %-noise photo of the marble sphere with 1 % of its pixels 30x too bright (a path
    tracer's fireflies): with the defaults (noise estimated, Huber's loss) sigma_a and sigma_s'
    stay within 3 stated errors of the truth, the exposure given, and the errors are not widened
    by the fireflies (chi^2 from the median square: 1.13 measured; from the Huber loss it was 65).
    Plain least squares with the estimated noise ran sigma_a to -100 %."""
    scene = parse_scene(tomllib.loads(SPHERE), source="sphere.toml")
    plan = plan_scene(scene, accuracy=0.001, method="texture-space").replace("specular", False, "subsurface only")
    clean = np.asarray(render(scene, plan, dtype=jnp.float64).radiance)
    rng = np.random.default_rng(3)
    photo = clean * (1 + 0.01 * rng.standard_normal(clean.shape))
    on = np.flatnonzero(clean[..., 1].reshape(-1) > 0)
    hot = rng.choice(on, size=max(on.size // 100, 1), replace=False)
    flat = photo.reshape(-1, 3)
    flat[hot] *= 30
    fit = fit_render(scene, flat.reshape(photo.shape), specular=False, gain=1.0)
    truth = scene.material.medium
    z_a = (np.asarray(fit.medium.sigma_a) - np.asarray(truth.sigma_a)) / fit.sigma_a_err
    z_s = (np.asarray(fit.medium.sigma_s_prime) - np.asarray(truth.sigma_s_prime)) / fit.sigma_s_prime_err
    assert np.all(np.abs(z_a) < 3) and np.all(np.abs(z_s) < 3), (z_a, z_s)
    assert np.all(fit.sigma_a_err / np.asarray(truth.sigma_a) < 0.3)  # and the photo still constrains it
    assert fit.chi2_reduced < 2 and any("beyond 5 standard errors" in w for w in fit.warnings)
