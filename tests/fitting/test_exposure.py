"""The photo's exposure (issue 36, part 1): from a white target of known reflectance, from the
user's word, or fitted only when asked, and then reported as unresolved where the photo cannot
tell the gain from R_d.

The reference's truth is a closed form that shares nothing with the renderer's shading: a
Lambertian plane of reflectance rho under a point light of intensity I at P shows radiance
rho I cos(theta) / (pi d^2) at every point x, with d = |P - x| and cos(theta) = P_z / d.
"""

import json
import tomllib

import jax.numpy as jnp
import numpy as np
import pytest

from fitting.render import GAIN_PINNED, RenderFitError, fit_render, gain_from_reference
from jsss import dipole
from jsss.render import parse_scene, plan_scene, render

from .test_render import SCENE

CARD = """
[geometry]
shape = "plane"
width = 60.0

[material]
name = "marble"

[[lights]]
type = "point"
position = [15.0, -10.0, 35.0]
intensity = 1500.0

[camera]
position = [0.0, -70.0, 55.0]
look_at = [0.0, 0.0, 0.0]
fov = 40
resolution = [80, 60]
"""


def _card_photo(scene, reflectance, gain, noise, seed=0):
    """The closed form at each pixel centre's ray hit on z = 0 (the camera's own pinhole model,
    PerspectiveView.directions), times the gain, with relative Gaussian noise; 0 off the card."""
    camera = scene.camera
    rays = camera.directions()
    origin = np.asarray(camera.position, float)
    t = -origin[2] / rays[..., 2]
    hit = origin + t[..., None] * rays
    on_card = (t > 0) & (np.abs(hit[..., 0]) < 30) & (np.abs(hit[..., 1]) < 30)
    light = np.asarray([15.0, -10.0, 35.0])
    d = np.linalg.norm(light - hit, axis=-1)
    radiance = reflectance * 1500.0 * (light[2] / d) / (np.pi * d**2)
    rng = np.random.default_rng(seed)
    photo = gain * radiance * (1 + noise * rng.standard_normal(radiance.shape))
    return np.repeat(np.where(on_card, photo, 0.0)[..., None], 3, axis=-1)


@pytest.fixture(scope="module")
def card():
    return parse_scene(tomllib.loads(CARD), source="card.toml")


def test_the_gain_of_a_photographed_grey_card_is_its_closed_form(card):
    """A grey card (rho 0.18) photographed at gain 3.7 with 2 % noise: the gain within 3 stated
    errors, and the stated error near the noise over sqrt(pixels) (median efficiency 1.25)."""
    photo = _card_photo(card, 0.18, 3.7, 0.02)
    gain, error = gain_from_reference(card, photo, 0.18)
    assert abs(gain / 3.7 - 1) < 3 * error, (gain, error)
    n = int(np.count_nonzero(photo[..., 0]))
    assert 0.5 < error / (1.25 * 0.02 / np.sqrt(n)) < 2


def test_hot_pixels_do_not_move_the_reference(card):
    """Fireflies: 2 % of the card's pixels 50x too bright move the median by about 2.5 % of the
    spread, not the mean's 100 %."""
    photo = _card_photo(card, 0.99, 1.0, 0.02, seed=1)
    rng = np.random.default_rng(2)
    on = np.flatnonzero(photo[..., 0].reshape(-1) > 0)
    hot = rng.choice(on, size=on.size // 50, replace=False)
    flat = photo.reshape(-1, 3)
    flat[hot] *= 50
    gain, _ = gain_from_reference(card, flat.reshape(photo.shape), 0.99)
    assert abs(gain - 1) < 0.005


def test_bad_reference_input_is_one_clear_error(card):
    photo = _card_photo(card, 0.99, 1.0, 0.0)
    with pytest.raises(RenderFitError, match="reflectance must lie in"):
        gain_from_reference(card, photo, 1.5)
    with pytest.raises(RenderFitError, match="lit pixels of the reference target"):
        gain_from_reference(card, photo, 0.99, mask=np.zeros(photo.shape[:2], bool))


SPHERE = SCENE  # the marble sphere of test_render: eta 1.5, a directional light, 64 x 48


@pytest.fixture(scope="module")
def sphere():
    return parse_scene(tomllib.loads(SPHERE), source="sphere.toml")


def _subsurface_photo(scene, noise):
    """A subsurface-only photo (no highlight) at gain 2.5 with relative Gaussian noise."""
    plan = plan_scene(scene, accuracy=0.001, method="texture-space")
    plan = plan.replace("specular", False, "subsurface light only")
    clean = np.asarray(render(scene, plan, dtype=jnp.float64).radiance)
    return 2.5 * clean * (1 + noise * np.random.default_rng(0).standard_normal(clean.shape))


@pytest.fixture(scope="module")
def subsurface_photo(sphere):
    return _subsurface_photo(sphere, 0.01)


def test_no_exposure_is_an_error_naming_the_ways_to_give_one(sphere, subsurface_photo):
    with pytest.raises(RenderFitError, match="exposure is unknown.*reference.*--gain.*--fit-gain"):
        fit_render(sphere, subsurface_photo, specular=False)


def test_a_fitted_gain_the_photo_cannot_pin_is_reported_unresolved(sphere):
    """gain='fit' on a noisy (10 % per pixel) photo of subsurface light only: not converged, no
    finite error for the gain, R_d or sigma_a, and a warning that says how to add a reference.
    sigma_s' (the spread) keeps its error."""
    fit = fit_render(sphere, _subsurface_photo(sphere, 0.10), specular=False, gain="fit", noise=0.10)
    assert not fit.converged and fit.gain_unresolved
    assert not np.isfinite(fit.gain_err) and not np.any(np.isfinite(fit.reflectance_err))
    assert not np.any(np.isfinite(fit.sigma_a_err)) and np.all(np.isfinite(fit.sigma_s_prime_err))
    assert any(w.startswith("exposure unresolved") and "white target" in w for w in fit.warnings)


def test_a_gain_the_profiles_shape_pins_is_a_result(sphere, subsurface_photo):
    """At 1 % noise the shape of the sphere's glow (its terminator and the light wrapping past it
    depend on the albedo, not on the gain) pins the gain: 2.8 % measured, below GAIN_PINNED; the
    fit converges with the gain and R_d within 3 stated errors."""
    fit = fit_render(sphere, subsurface_photo, specular=False, gain="fit")
    assert fit.converged and not fit.gain_unresolved and fit.gain_err / fit.gain < GAIN_PINNED
    assert abs(fit.gain - 2.5) < 3 * fit.gain_err
    truth = np.asarray(dipole.total_reflectance(sphere.material.medium))  # the scene's profile model
    assert np.all(np.abs(fit.reflectance - truth) < 3 * fit.reflectance_err)


def test_a_reference_gain_with_its_error_recovers_the_material(sphere, subsurface_photo):
    """The gain given with a 1 % error (as a reference gives it) is fitted with that prior: the
    truth within 3 stated errors, and the gain's error reaches R_d (at least 0.5 % of it)."""
    fit = fit_render(sphere, subsurface_photo, specular=False, gain=2.5 * 1.004, gain_err=0.01)
    truth = sphere.material.medium
    assert fit.converged
    z_a = (np.asarray(fit.medium.sigma_a) - np.asarray(truth.sigma_a)) / fit.sigma_a_err
    z_s = (np.asarray(fit.medium.sigma_s_prime) - np.asarray(truth.sigma_s_prime)) / fit.sigma_s_prime_err
    assert np.all(np.abs(z_a) < 3) and np.all(np.abs(z_s) < 3), (z_a, z_s)
    assert np.all(fit.reflectance_err / fit.reflectance > 0.005)
    assert fit.gain_err > 0


def test_the_pinned_threshold_is_a_relative_error():
    assert 0 < GAIN_PINNED < 0.2


def _command(*args, cwd):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "measure.commands.render", "fit", *map(str, args)],
                          capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=900, cwd=cwd)


def test_the_command_takes_the_exposure_from_a_grey_card_or_refuses(tmp_path, card, sphere):
    """jsss-render fit as a user runs it: without an exposure source, one line and exit 2; with
    a grey card's photo (the closed form at gain 2.5), the card's gain is used, the fit is a
    result (exit 0) and the JSON says where the exposure came from; --fit-gain on a 10 %-noise
    subsurface photo is unresolved: null errors, converged false, exit 1 with one closing line."""
    from measure.exr import write_exr

    (tmp_path / "sphere.toml").write_text(SPHERE)
    (tmp_path / "card.toml").write_text(CARD)
    write_exr(tmp_path / "photo.exr", _subsurface_photo(sphere, 0.01))
    write_exr(tmp_path / "card.exr", _card_photo(card, 0.18, 2.5, 0.01))
    bare = _command("sphere.toml", "photo.exr", "--no-specular", "-q", cwd=tmp_path)
    assert bare.returncode == 2 and bare.stderr.count("\n") == 1 and "--reference-scene" in bare.stderr, bare.stderr
    out = _command("sphere.toml", "photo.exr", "--no-specular", "-q", "--json", "--reference-scene", "card.toml",
                   "--reference-photo", "card.exr", "--reference-reflectance", "0.18", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result["exposure"].startswith("reference: card.toml") and result["converged"]
    assert abs(result["gain"] / 2.5 - 1) < 3 * result["gain_err"] / result["gain"] + 1e-3
    write_exr(tmp_path / "noisy.exr", _subsurface_photo(sphere, 0.10))
    fitted = _command("sphere.toml", "noisy.exr", "--no-specular", "-q", "--json", "--fit-gain", "--noise", "0.1",
                      cwd=tmp_path)
    assert fitted.returncode == 1, fitted.stderr
    result = json.loads(fitted.stdout)
    assert not result["converged"] and result["gain_err"] is None and result["reflectance_err"] == [None] * 3
    assert fitted.stderr.strip().splitlines()[-1].startswith("jsss-render fit: error: the exposure is unresolved")
