"""Photos taken through the real surface, highlight included (issue 36, part 3): fit_render's
``highlight`` -- the roughness fitted, the highlight's pixels masked, or (as before) modelled at
the scene's roughness -- and what the result says was done.

The photos are jsss's own renders with noise at a Beckmann roughness of 0.15, fitted with a
scene that says 0.4, so the truth (the medium and the roughness the photo was rendered with) is
known outside the fit; these tests check the fit's handling of the highlight, not the
renderer's physics (benchmarks/inverse_rendering.py fits path-traced photos).
"""

import dataclasses
import json
import tomllib

import jax.numpy as jnp
import numpy as np
import pytest

from fitting.render import RenderFitError, fit_pixels, fit_render
from jsss.render import parse_scene, plan_scene, render
from measure.commands import render as render_command
from measure.exr import write_exr

# The light comes from behind the camera's left shoulder: the highlight sits on the sphere's
# face, inside the fitted pixels.
SPHERE = """
[geometry]
shape = "sphere"
radius = 20.0

[material]
sigma_a = [0.0021, 0.0041, 0.0071]
sigma_s_prime = [2.19, 2.62, 3.00]
eta = 1.5
roughness = 0.15
profile = "dipole"

[[lights]]
type = "directional"
direction = [0.35, 0.9, -0.45]
intensity = 1.0

[camera]
position = [0.0, -110.0, 30.0]
look_at = [0.0, 0.0, 0.0]
fov = 28
resolution = [64, 48]

[render]
texture_size = 128
"""

# A plane seen from above and lit at a grazing angle from the camera's side: the mirror
# direction points away from the camera, so the photo has no highlight (the half vector is
# more than 50 degrees from every visible normal, where even a lobe of m = 0.3 is exp(-15)).
PLANE = """
[geometry]
shape = "plane"
width = 60.0

[material]
sigma_a = [0.0021, 0.0041, 0.0071]
sigma_s_prime = [2.19, 2.62, 3.00]
eta = 1.5
roughness = 0.15
profile = "dipole"

[[lights]]
type = "point"
position = [0.0, -90.0, 20.0]
intensity = 3000.0

[camera]
position = [0.0, -70.0, 55.0]
look_at = [0.0, 0.0, 0.0]
fov = 40
resolution = [64, 48]

[render]
texture_size = 128
"""

WRONG = 0.4  # the roughness the photographer's scene states; the photo's is 0.15


def _scene(text, roughness=None):
    scene = parse_scene(tomllib.loads(text), source="scene.toml")
    if roughness is None:
        return scene
    return dataclasses.replace(scene, material=dataclasses.replace(scene.material, roughness=roughness))


def _photo(scene, noise=0.01, seed=0):
    """The scene's texture-space render (highlight included) with 1 % relative Gaussian noise."""
    plan = plan_scene(scene, accuracy=0.001, method="texture-space")
    clean = np.asarray(render(scene, plan, dtype=jnp.float64).radiance)
    rng = np.random.default_rng(seed)
    return clean * (1 + noise * rng.standard_normal(clean.shape))


@pytest.fixture(scope="module")
def shot():
    """(truth's scene, photo at m = 0.15, the scene stating m = 0.4)."""
    truth = _scene(SPHERE)
    return truth, _photo(truth), _scene(SPHERE, WRONG)


def _fit(scene, photo, **options):
    return fit_render(scene, photo, gain=1.0, noise=0.01, method="texture-space", **options)


def _pulls(fit, truth):
    """(sigma_a, sigma_s') of the fit minus the truth, in the fit's stated errors, per channel."""
    m = truth.material.medium
    return ((np.asarray(fit.medium.sigma_a) - np.asarray(m.sigma_a)) / fit.sigma_a_err,
            (np.asarray(fit.medium.sigma_s_prime) - np.asarray(m.sigma_s_prime)) / fit.sigma_s_prime_err)


def test_a_highlight_held_at_a_wrong_roughness_biases_the_medium(shot):
    """The behaviour before: the lobe at m = 0.4 where the photo's is 0.15. The highlight's pixels
    pull sigma_a and sigma_s' off by more than the 3 errors a fit may miss by (measured: chi2/dof
    4.3, sigma_s' R 3.8 errors low; 6.9 until 2026-12-08, when the second round, worse on its own
    plan, was kept), even under Huber's loss. The start is the truth, so the bias is the
    highlight's alone."""
    truth, photo, wrong = shot
    fit = _fit(wrong, photo, highlight="model")
    assert fit.highlight == "model" and fit.roughness == WRONG and fit.highlight_pixels == 0
    pull_a, pull_s = _pulls(fit, truth)
    assert fit.chi2_reduced > 2, fit.chi2_reduced
    assert max(np.abs(pull_a).max(), np.abs(pull_s).max()) > 3, (pull_a, pull_s)


def test_the_default_fits_the_roughness_and_recovers_the_medium(shot):
    """Default ("auto"): the highlight is in the photo and the light is directional, so the
    roughness is fitted: it comes back within 3 errors of 0.15 (measured 0.1491 +- 0.0004), the
    medium within 3 errors, chi2/dof near 1, and the result says so."""
    truth, photo, wrong = shot
    fit = _fit(wrong, photo)
    assert fit.highlight == "fit" and fit.converged
    assert fit.parameter_names[-1] == "ln roughness"
    assert abs(fit.roughness - 0.15) < 3 * fit.roughness_err, (fit.roughness, fit.roughness_err)
    assert fit.roughness_err < 0.01  # the photo pins it: not a wide error that passes anything
    pull_a, pull_s = _pulls(fit, truth)
    assert np.all(np.abs(pull_a) < 3) and np.all(np.abs(pull_s) < 3), (pull_a, pull_s)
    assert fit.chi2_reduced < 1.5, fit.chi2_reduced
    assert any("roughness is fitted" in line for line in fit.history)
    assert fit.as_dict()["highlight"] == "fit" and fit.as_dict()["roughness"] == fit.roughness


def test_masking_leaves_out_the_highlight_and_recovers_the_medium(shot):
    """highlight="mask": the pixels where the lobe may be wrong by 2 % of the light for m in
    [0.2, 0.8] are left out (measured 617 of 748: a smooth sphere lit from near the camera is
    mostly highlight at some roughness within 2x), the photo's brightest pixel (the highlight's
    peak)
    among them; the medium within 3 errors of the truth; the count reported."""
    truth, photo, wrong = shot
    fit = _fit(wrong, photo, highlight="mask")
    everything = fit_pixels(wrong, photo)
    assert fit.highlight == "mask" and fit.highlight_pixels > 0
    assert fit.n_pixels + fit.highlight_pixels == int(everything.sum())
    peak = np.unravel_index(np.argmax(np.where(everything, photo.sum(-1), -np.inf)), everything.shape)
    assert everything[peak] and not fit.mask[peak]
    pull_a, pull_s = _pulls(fit, truth)
    assert np.all(np.abs(pull_a) < 3) and np.all(np.abs(pull_s) < 3), (pull_a, pull_s)
    assert any(f"highlight masked: {fit.highlight_pixels} pixels" in line for line in fit.history)


def test_a_photo_without_a_highlight_masks_nothing_through_the_command(tmp_path, capsys):
    """A plane lit from the camera's side has no highlight in view: the default masks nothing and
    fits no roughness (nothing in the photo constrains it), and ``jsss-render fit --json`` says
    so."""
    scene = _scene(PLANE)
    write_exr(tmp_path / "photo.exr", _photo(scene))
    (tmp_path / "plane.toml").write_text(PLANE)
    assert render_command.main(["fit", str(tmp_path / "plane.toml"), str(tmp_path / "photo.exr"), "-o",
                                str(tmp_path), "--no-gain", "--noise", "0.01", "--method", "texture-space",
                                "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["highlight"] == "mask" and summary["highlight_pixels"] == 0
    assert summary["roughness"] == 0.15 and "ln roughness" not in summary["parameters"]
    assert any("no highlight in the fitted pixels" in line for line in summary["history"])


def test_a_bad_highlight_is_one_line_and_exit_2(tmp_path, capsys):
    """The flag's bad value: argparse's one line naming it, exit 2, before any file is read; the
    library refuses it too, naming the choices."""
    with pytest.raises(SystemExit) as exit_:
        render_command.main(["fit", str(tmp_path / "scene.toml"), str(tmp_path / "photo.exr"), "--highlight", "shiny"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--highlight" in err and "shiny" in err, err
    with pytest.raises(RenderFitError, match="highlight must be 'auto', 'mask', 'fit' or 'model'"):
        fit_render(_scene(SPHERE), np.ones((48, 64, 3)), gain=1.0, highlight="shiny")
