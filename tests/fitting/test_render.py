"""Inverse rendering: a material from a photo of a known scene (fitting.render, jsss-render fit).

The photos here are jsss's own renders with noise, so these tests check the fit (recovery
within the stated errors, identifiability, bad input), not the renderer's physics: that the
renders agree with a path tracer is benchmarks/transport_truth.py's job, and
benchmarks/inverse_rendering.py fits path-traced photos.
"""

import dataclasses
import json
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

from fitting.render import MODEL_ERROR, RenderFitError, fit_render, fit_pixels
from jsss import dipole
from measure.exr import write_exr
from jsss.medium import Medium
from jsss.render import linear_frame, parse_scene, plan_scene, render
from jsss.render.profiles import render_profile

SCENE = """
[geometry]
shape = "sphere"
radius = 20.0

[material]
sigma_a = [0.0021, 0.0041, 0.0071]
sigma_s_prime = [2.19, 2.62, 3.00]
eta = 1.5
roughness = 0.25

[[lights]]
type = "directional"
direction = [0.6, 0.8, -0.5]
intensity = 1.0

[camera]
position = [0.0, -110.0, 30.0]
look_at = [0.0, 0.0, 0.0]
fov = 28
resolution = [64, 48]

[render]
texture_size = 128
"""


@pytest.fixture(scope="module")
def scene():
    import tomllib

    return parse_scene(tomllib.loads(SCENE), source="sphere.toml")


def _photo(scene, method="texture-space", gain=2.5, noise=0.01, seed=0):
    plan = plan_scene(scene, accuracy=0.001, method=method)
    clean = render(scene, plan, dtype=jnp.float64).radiance
    rng = np.random.default_rng(seed)
    return gain * clean * (1 + noise * rng.standard_normal(clean.shape))


def _start(scene):
    m = scene.material.medium
    return Medium(2 * np.asarray(m.sigma_a), np.asarray(m.sigma_s_prime) / 1.5, m.eta)


def test_the_fits_fixed_pass_model_is_the_renderers_frame(scene):
    """Consistency, not truth: the frame the fit solves with (the renderer's linear frame, its
    blur in float32 as the fit takes it) reproduces the renderer's own float64 frame: 5e-5 is
    the float32 blur's rounding (relative 1e-7 per texel, through about 20 blur steps and the
    diffusion-minus-single-scattering difference)."""
    plan = plan_scene(scene, accuracy=0.001, method="texture-space")
    frame = render(scene, plan, dtype=jnp.float64).radiance
    medium = scene.material.medium
    weights = render_profile(scene.material, plan.variances).weights
    albedo = medium.sigma_s_prime / (medium.sigma_a + medium.sigma_s_prime)
    model = np.asarray(linear_frame(scene, plan, blur_dtype=jnp.float32).radiance(weights, albedo))
    use = fit_pixels(scene, frame)
    assert np.max(np.abs(model[use] / frame[use] - 1)) < 5e-5


def test_recovers_the_material_and_gain_within_the_stated_errors(scene):
    """A 1 %-noise render, fitted from 2x the absorption and 2/3 of the scattering: the truth
    within 3 stated standard errors, chi^2 per degree of freedom about 1."""
    photo = _photo(scene)
    fit = fit_render(scene, photo, init=_start(scene), gain="fit")
    truth = scene.material.medium
    z_a = (np.asarray(fit.medium.sigma_a) - np.asarray(truth.sigma_a)) / fit.sigma_a_err
    z_s = (np.asarray(fit.medium.sigma_s_prime) - np.asarray(truth.sigma_s_prime)) / fit.sigma_s_prime_err
    assert fit.converged and fit.method == "texture-space"
    assert np.all(np.abs(z_a) < 3) and np.all(np.abs(z_s) < 3), (z_a, z_s)
    assert abs(fit.gain - 2.5) < 3 * fit.gain_err
    assert 0.8 < fit.chi2_reduced < 1.25
    assert np.all(fit.sigma_a_err / np.asarray(truth.sigma_a) < 0.2)  # the image does constrain it
    assert not fit.warnings


def test_the_renderers_own_error_is_in_the_stated_errors(scene):
    """A renderer whose channels are 2 model errors off (here the photo is scaled instead: the
    same residuals), exposure held: with the default ``model_error`` R_d stays within 3 stated
    errors, with the photo's noise alone (``model_error=0``) it misses by more. And the term is
    the fit's own response, linearised: refitted on the photo scaled once more by exp(delta) per
    channel, each R_d moves by what the added variance says, within 10 %."""
    plan = plan_scene(scene, accuracy=0.001, method="texture-space").replace("specular", False, "subsurface only")
    clean = 2.5 * np.asarray(render(scene, plan, dtype=jnp.float64).radiance)
    off = np.exp(np.array([2.0, -2.0, 1.0]) * MODEL_ERROR)
    photo = clean * off * (1 + 0.01 * np.random.default_rng(1).standard_normal(clean.shape))
    truth = np.asarray(dipole.total_reflectance(scene.material.medium))
    common = {"specular": False, "gain": 2.5, "noise": 0.01}
    fit = fit_render(scene, photo, **common)
    alone = fit_render(scene, photo, model_error=0, **common)
    z, z_alone = (fit.reflectance / truth - 1) / (fit.reflectance_err / fit.reflectance), \
        (alone.reflectance / truth - 1) / (alone.reflectance_err / alone.reflectance)
    assert fit.model_error == MODEL_ERROR and alone.model_error == 0
    assert np.all(np.abs(z) < 3) and abs(z_alone[0]) > 3 and abs(z_alone[1]) > 3, (z, z_alone)
    assert np.allclose(fit.reflectance, alone.reflectance, rtol=1e-9)  # the estimate is the same
    delta = np.array([0.01, -0.02, 0.015])
    moved = fit_render(scene, photo * np.exp(delta), model_error=0, **common)
    response = np.log(moved.reflectance / alone.reflectance) / delta  # d ln R_d / d ln (light), per channel
    added = np.sqrt(fit.reflectance_err**2 - alone.reflectance_err**2) / fit.reflectance
    assert np.allclose(added, MODEL_ERROR * np.abs(response), rtol=0.1), (added, response)


@pytest.mark.parametrize("method", ["lambert", pytest.param("normal filtering", marks=pytest.mark.xfail(strict=True, reason=(
    "known defect, measured 2026-12-05: with the exit-angle pass the shading's angular shape shows the albedo, and "
    "the filter, fixed at the start's profile, biases R_d by -0.8 to -1.1 points, 3-4.6 stated errors: a model error "
    "the errors leave out (started at the truth: 0.3-0.5 errors; with the flat lobe: 0.3-1.0; the filter made again "
    "each round: +1.3 to +1.7 points, the unconstrained mean free path drifting 21 % short)")))])
def test_methods_without_spread_report_the_mean_free_path_unconstrained(scene, method):
    """Lambert, and normal filtering with its filter fixed during the fit, make an image that
    depends on the albedo alone (R_d and single scattering), not on the scale of sigma_t: the
    fit must say so (infinite errors, a warning, not converged) instead of printing a
    confident value, while the albedo it does see is recovered."""
    photo = _photo(scene, method=method, noise=0.003)
    # model_error=0: the photo is this renderer's own, and the filter's bias is what is measured
    fit = fit_render(scene, photo, method=method, init=_start(scene), gain="fit", model_error=0)
    assert any("not constrained" in w for w in fit.warnings) and not fit.converged
    assert np.all(fit.mean_free_path_err / fit.mean_free_path > 0.5)
    truth_rd = np.asarray(dipole.total_reflectance(scene.material.medium))
    assert np.all(np.isfinite(fit.reflectance_err))
    assert np.all(np.abs(fit.reflectance - truth_rd) < 3 * fit.reflectance_err + 1e-3)


@pytest.mark.parametrize("case, message", [
    ("size", "32 x 24 pixels, but the scene's camera renders 64 x 48"),
    ("nan", "pixels on the object are NaN or infinite"),
    ("lights", "the scene has no lights"),
    ("channels", "expected an RGB image"),
    ("model_error", r"model_error must be a relative error in \[0, 1\)"),
    ("model_error_one", r"model_error must be a relative error in \[0, 1\) .*; got 1.0"),
])
def test_bad_input_is_one_clear_error(scene, case, message):
    photo = np.ones((48, 64, 3))
    if case == "size":
        photo = np.ones((24, 32, 3))
    elif case == "nan":
        photo[24, 32, 1] = np.nan
    elif case == "lights":
        scene = dataclasses.replace(scene, lights=())
    elif case == "channels":
        photo = np.ones((48, 64))
    with pytest.raises(RenderFitError, match=message):
        model_error = {"model_error": float("nan"), "model_error_one": 1.0}
        fit_render(scene, photo, gain="fit", **({"model_error": model_error[case]} if case in model_error else {}))


def test_fit_command_writes_parameters_a_renderable_scene_and_a_figure(scene, tmp_path):
    from jsss.render import load_scene

    (tmp_path / "sphere.toml").write_text(SCENE.replace("sigma_a = [0.0021, 0.0041, 0.0071]",
                                                        "sigma_a = [0.005, 0.005, 0.005]"))
    write_exr(tmp_path / "photo.exr", _photo(scene))
    run = lambda *extra: subprocess.run(  # noqa: E731
        [sys.executable, "-m", "measure.commands.render", "fit", str(tmp_path / "sphere.toml"), *extra],
        capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=900, cwd=tmp_path)
    out = run(str(tmp_path / "photo.exr"), "--json", "-o", str(tmp_path / "fit"), "--fit-gain")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result["model_error"] == MODEL_ERROR
    for key in ("sigma_a", "sigma_s_prime", "sigma_a_err", "sigma_s_prime_err"):
        assert len(result[key]) == 3 and all(np.isfinite(result[key]))
    truth = scene.material.medium
    assert np.all(np.abs(np.array(result["sigma_s_prime"]) - np.asarray(truth.sigma_s_prime))
                  < 3 * np.array(result["sigma_s_prime_err"]))
    fitted = load_scene(tmp_path / "fit" / "photo.fit.toml")
    assert np.allclose(np.asarray(fitted.material.medium.sigma_a), result["sigma_a"], rtol=1e-6)
    assert (tmp_path / "fit" / "photo.fit.png").stat().st_size > 10_000
    write_exr(tmp_path / "small.exr", np.ones((24, 32, 3)))
    bad = run(str(tmp_path / "small.exr"), "--fit-gain")
    assert bad.returncode == 2
    assert bad.stderr.strip().count("\n") == 0 and "32 x 24 pixels" in bad.stderr
    bad = run(str(tmp_path / "photo.exr"), "--fit-gain", "--model-error", "-0.1")
    assert bad.returncode == 2 and bad.stderr.strip().count("\n") == 0 and "--model-error" in bad.stderr, bad.stderr


def test_rim_mm_leaves_out_the_pixels_near_an_open_surfaces_rim():
    """A 40 mm plane: with rim_mm = 5 every fitted pixel's point is at least 5 mm inside the
    square (closed form: 20 mm minus its larger |coordinate|), and some were left out; a
    negative distance is a one-line error; a closed sphere has no rim to leave out."""
    from jsss.render.image_space import camera_buffers

    plane = parse_scene({"geometry": {"shape": "plane", "width": 40.0},
                         "material": {"name": "ketchup"},
                         "lights": [{"type": "point", "position": [5.0, -5.0, 30.0], "intensity": 1000.0}],
                         "camera": {"position": [0.0, -50.0, 40.0], "look_at": [0.0, 0.0, 0.0], "fov": 50,
                                    "resolution": [48, 36]}})
    photo = np.ones((36, 48, 3))
    everything, inner = fit_pixels(plane, photo), fit_pixels(plane, photo, rim_mm=5.0)
    position = camera_buffers(plane.mesh, plane.camera).position
    to_rim = 20.0 - np.abs(position[..., :2]).max(-1)
    assert np.all(to_rim[inner] >= 5.0 - 1e-9)
    assert (everything & (to_rim < 5.0)).sum() > 50 and inner.sum() < everything.sum()
    with pytest.raises(RenderFitError, match="rim_mm"):
        fit_pixels(plane, photo, rim_mm=-1.0)


def test_a_sphere_has_no_rim(scene):
    photo = np.ones((48, 64, 3))
    assert np.array_equal(fit_pixels(scene, photo, rim_mm=50.0), fit_pixels(scene, photo))


def test_the_fits_medium_is_held_in_its_range_and_flat_beyond_it():
    """A photo that does not constrain a channel let Levenberg-Marquardt run sigma_a / sigma_s'
    to 1e36 (a path-traced ketchup photo's blue, 2026-12-07): the next plan raised "transport
    tables cover ... <= 1e3" and the render overflowed. The fit's medium is held in
    SCATTERING_RANGE and ABSORPTION_RATIO_RANGE: inside, the coefficients are exp(theta) with
    unit slope; beyond, the edge, finite, with zero slope (so the residuals stop moving and that
    parameter gets an infinite error), and the transport profile's R_d stays finite there."""
    import jax

    from fitting.render import (
        ABSORPTION_RATIO_RANGE,
        SCATTERING_RANGE,
        _artist,
        _medium,
    )

    eta = jnp.full(3, 1.3)
    inside = jnp.log(jnp.asarray([0.01, 0.1, 1.0, 1.0, 2.0, 3.0]))
    medium = _medium(inside, eta)
    np.testing.assert_allclose(np.concatenate([medium.sigma_a, medium.sigma_s_prime]), np.exp(inside), rtol=1e-12)
    slope = jax.jacfwd(lambda t: jnp.log(jnp.concatenate([_medium(t, eta).sigma_a, _medium(t, eta).sigma_s_prime])))
    np.testing.assert_allclose(slope(inside), np.eye(6), atol=1e-12)

    # blue ran to sigma_a / sigma_s' = 1e36, green's sigma_s' to 1e-209 /mm
    beyond = inside.at[2].set(inside[5] + np.log(1e36)).at[4].set(-480.0)
    held = _medium(beyond, eta)
    a, s = np.asarray(held.sigma_a), np.asarray(held.sigma_s_prime)
    np.testing.assert_allclose(a[2] / s[2], ABSORPTION_RATIO_RANGE[1], rtol=1e-12)
    np.testing.assert_allclose(s[1], SCATTERING_RANGE[0], rtol=1e-12)
    J = np.asarray(slope(beyond))
    assert np.all(J[:, 2] == 0) and np.all(J[:, 4] == 0)  # flat beyond the edge
    assert J[0, 0] == pytest.approx(1.0) and J[5, 5] == pytest.approx(1.0)  # the others still move
    artist = np.asarray(_artist(beyond, "transport", 0.0, eta))
    assert np.all(np.isfinite(artist)) and np.all(np.isfinite(np.asarray(jax.jacfwd(_artist)(beyond, "transport", 0.0, eta))))


def test_the_plans_own_error_propagates_as_the_renderers_does():
    """The plan's error term (a re-plan's change to the estimate's frame, propagated through the
    fit's linearised solution) and the renderer's (a channel's light scaled by 1 + epsilon) are
    one formula: a re-plan that scaled channel c by exp(epsilon) gives the covariance the model
    error epsilon in channel c gives, to (e^epsilon - 1)^2 / epsilon^2 (plain squares: the
    whitened residuals are linear in the frame). Closed form; random Jacobian and frame."""
    from fitting.render import _model_error_covariance, _model_error_slopes, _plan_error_covariance

    rng = np.random.default_rng(5)
    image = jnp.asarray(rng.uniform(0.5, 1.5, (6, 8, 3)))
    photo = image * (1 + 0.01 * rng.standard_normal(image.shape))
    args = (None, photo, jnp.ones((6, 8, 1)), 1 / (0.01 * photo), None, (2.0, 0.0, 0.0))
    theta = jnp.zeros(6)
    J = rng.standard_normal((6 * 8 * 3, 6))
    slopes = _model_error_slopes(theta, args, image, jnp.zeros_like(image), False, 1, False, False)
    epsilon = 1e-3
    for c in range(3):
        scaled = np.zeros(3)
        scaled[c] = epsilon
        difference = np.asarray(image) * (np.exp(scaled) - 1)
        plan = _plan_error_covariance(J, theta, args, image, difference, False, 1, False, False)
        model = _model_error_covariance(J, slopes[:, c:c + 1], epsilon)
        np.testing.assert_allclose(plan, model * ((np.exp(epsilon) - 1) / epsilon) ** 2, rtol=1e-9,
                                   atol=1e-12 * np.abs(model).max())
        assert np.abs(model).max() > 0


def test_a_round_whose_estimate_fits_worse_on_its_own_plan_is_not_kept(scene, monkeypatch):
    """The fit's objective is each estimate's misfit on the plan made for it. Here every plan
    for a medium other than the start's is made at 30 % accuracy (a profile of few Gaussians),
    so round 1's estimate, near the truth, fits a 1 %-noise photo worse on its own plan than the
    start (2 % off in sigma_a) does on the start's: the start is the estimate, unmoved, on its
    own plan, and the history says why. Without that plan (no patch) the round is kept."""
    import fitting.render as fr

    truth = scene.material.medium
    start = Medium(1.02 * np.asarray(truth.sigma_a), np.asarray(truth.sigma_s_prime), truth.eta)
    photo = _photo(scene, gain=1.0)
    real = fr.plan_scene

    def coarse_away_from_the_start(fit_scene, **kw):
        at_start = np.allclose(np.asarray(fit_scene.material.medium.sigma_a), start.sigma_a, rtol=1e-12)
        return real(fit_scene, **(kw if at_start else kw | {"accuracy": 0.3}))

    common = {"init": start, "gain": 1.0, "specular": False, "noise": 0.01, "method": "texture-space"}
    monkeypatch.setattr(fr, "plan_scene", coarse_away_from_the_start)
    fit = fit_render(scene, photo, **common)
    # (to exp(ln x)'s rounding: the fit's parameters are logarithms)
    np.testing.assert_allclose(fit.medium.sigma_a, start.sigma_a, rtol=1e-13)
    np.testing.assert_allclose(fit.medium.sigma_s_prime, start.sigma_s_prime, rtol=1e-13)
    assert any("round 1's estimate not kept" in line for line in fit.history), fit.history
    assert fit.converged  # the start is on its own plan
    monkeypatch.setattr(fr, "plan_scene", real)
    kept = fit_render(scene, photo, **common)
    assert not any("not kept" in line for line in kept.history), kept.history
    z = (np.asarray(kept.medium.sigma_a) - np.asarray(truth.sigma_a)) / kept.sigma_a_err
    assert np.all(np.abs(z) < 3), z
