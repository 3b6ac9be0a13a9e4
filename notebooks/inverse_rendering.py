# ---
# jupyter:
#   jupytext:
#     notebook_metadata_filter: -jupytext.text_representation
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # A material from a photo: inverse rendering
#
# Beam-profile measurements (`measure_and_fit.py`) need a laser and a dark room. Often what
# you have is a photo of an object -- a marble sphere, a bar of soap -- under a light you know.
# If the scene's geometry, camera and lights are known, the material can be fitted to the photo
# through the renderer: jsss's texture-space renderer is a smooth function of sigma_a and
# sigma_s', and its costly part (the blur of the irradiance) does not depend on them once the
# Gaussian variances are fixed, so a Levenberg-Marquardt fit takes seconds, not the hours of a
# differentiable path tracer.
#
# What a photo can and cannot tell:
#
# * its **brightness** per channel gives gain x R_d, the exposure gain times the total diffuse
#   reflectance. Photos have no absolute scale, so `fit_render` asks where the gain comes from:
#   a white target of known reflectance (`gain_from_reference`), the camera's word (`gain=G`),
#   or `gain="fit"`, which is a result only where something in the photo pins the gain (here:
#   the specular highlight, whose Fresnel reflectance is known physics) and is otherwise
#   reported unresolved, with infinite errors for R_d, sigma_a and the gain;
# * the **blur** of light into the shadow gives the diffusion length 1/sigma_tr,
#   sigma_tr = sqrt(3 sigma_a sigma_t');
# * the **mean free path** 1/sigma_t' shows only where the profile is resolved: a pixel much
#   larger than it, or a method without spread (Lambert), cannot see it -- and the fit says so.
#
# This notebook makes a photo with jsss itself (so the truth is known), fits it from a wrong
# start, looks at the residual, and then shows a fit that cannot work.

# %%
import os
from dataclasses import replace

import jax

jax.config.update("jax_enable_x64", True)  # fits need float64
import matplotlib.pyplot as plt
import numpy as np

from fitting import fit_render
from jsss.medium import Medium
from jsss.render import load_scene, plan_scene, render
from jsss.render.shading import tone_map

FAST = os.environ.get("JSSS_FULL") != "1"   # JSSS_FULL=1: a 160 x 120 photo (see notebooks/README.md)
size = (64, 48) if FAST else (160, 120)
examples = os.path.join(os.getcwd(), "..", "examples")
scene = load_scene(os.path.join(examples, "marble_sphere.toml"))
scene = replace(scene, camera=replace(scene.camera, width=size[0], height=size[1]),
                texture_size=128 if FAST else 256)
truth = scene.material.medium
print("true sigma_a", np.asarray(truth.sigma_a), "sigma_s'", np.asarray(truth.sigma_s_prime))

# %% [markdown]
# ## The photo
#
# An accurate render (profile within 0.1 % of the dipole) times an unknown exposure of 2.5,
# with 1 % noise per pixel.

# %%
clean = render(scene, plan_scene(scene, accuracy=0.001, method="texture-space"), dtype=np.float64).radiance
rng = np.random.default_rng(0)
photo = 2.5 * clean * (1 + 0.01 * rng.standard_normal(clean.shape))
plt.imshow(tone_map(photo)[0]); plt.axis("off"); plt.title("the photo");

# %% [markdown]
# ## The fit, from 3x the absorption and half the scattering
#
# `fit_render` plans the fit's renders for the start, fits, re-plans for the estimate and fits
# again until the plan no longer changes (the variances must be the estimate's own, or the
# fit is biased toward the medium they were planned for). It reports standard errors from the
# Jacobian, widened if the fit is worse than the noise model.

# %%
start = Medium(3 * np.asarray(truth.sigma_a), np.asarray(truth.sigma_s_prime) / 2, truth.eta)
fit = fit_render(scene, photo, init=start, gain="fit")
print(f"{fit.method}, {fit.steps} solver steps, chi2/dof {fit.chi2_reduced:.2f}, converged {fit.converged}")
for line in fit.history:
    print("  ", line)
for name, value, error, true in [("sigma_a", fit.medium.sigma_a, fit.sigma_a_err, truth.sigma_a),
                                 ("sigma_s'", fit.medium.sigma_s_prime, fit.sigma_s_prime_err, truth.sigma_s_prime)]:
    z = (np.asarray(value) - np.asarray(true)) / error
    print(f"{name:9s}", np.round(np.asarray(value), 5), "+-", np.round(error, 5), " (fit - truth) / error:", np.round(z, 2))
print("gain", round(fit.gain, 4), "+-", round(fit.gain_err, 4))
print("R_d", np.round(fit.reflectance, 4), "mean free path [mm]", np.round(fit.mean_free_path, 4))

# %%
noise = 0.01 * photo.mean(-1)
residual = np.full(noise.shape, np.nan)  # pixels the fit used only: the background has no noise to divide by
residual[fit.mask] = (fit.image - photo).mean(-1)[fit.mask] / noise[fit.mask]
fig, axes = plt.subplots(1, 3, figsize=(12, 3.4), constrained_layout=True)
shown, exposure = tone_map(photo)
axes[0].imshow(shown); axes[0].set_title("photo")
axes[1].imshow(tone_map(fit.image, exposure=exposure)[0]); axes[1].set_title("fit")
im = axes[2].imshow(residual, cmap="RdBu_r", vmin=-4, vmax=4); axes[2].set_title("(fit - photo) / noise")
fig.colorbar(im, ax=axes[2], shrink=0.8, label="standard deviations")
for ax in axes:
    ax.axis("off")

# %% [markdown]
# The residual is noise: no structure at the terminator or the rim. Silhouette and grazing
# pixels are left out of the fit (a silhouette pixel is partly background).
#
# ## A fit that cannot work: Lambert has no spread
#
# Lambert shading makes a pixel's colour from the albedo alone, so it cannot see how far light
# travels. Fitted with it, the photo still gives R_d, but sigma_a and sigma_s' can be scaled
# together freely: the fit reports infinite errors and a warning instead of a confident number.

# %%
lambert = fit_render(scene, photo, method="lambert", init=start, gain="fit")
print("converged:", lambert.converged)
print("R_d", np.round(lambert.reflectance, 4), "+-", np.round(lambert.reflectance_err, 4))
print("mean free path error:", lambert.mean_free_path_err)
for warning in lambert.warnings:
    print("warning:", warning)

# %% [markdown]
# ## From the command line
#
# `jsss-render fit scene.toml photo.exr` does the same with a photo from disk and writes the
# parameters (JSON), a scene with the fitted material that `jsss-render` renders directly, and
# the figure above.
#
# ## Against photos the renderer did not make
#
# A photo here came from the same renderer that fits it, so the fit can only be as wrong as its
# noise. `benchmarks/inverse_rendering.py` fits photos made by a volumetric path tracer
# (Mitsuba 3) instead, where nothing shares jsss's assumptions. There, with the exposure known,
# the transport profile recovers R_d within 2 % and the mean free path within 15 % on the marble
# sphere and the ketchup plane (2026-12-02, docs/guides/inverse_rendering.md), after two effects
# the profiles leave out were added to the renderer: light arriving at a slant returns more (Chandrasekhar's H
# function, `jsss.diffusion.incidence`), and a nearby lamp's rays keep spreading below the surface. Two
# things a photo cannot give you: R_d when the exposure is unknown (brightness is gain x R_d,
# and only the profile's shape separates them), and the mean free path of a channel whose light
# leaves within a pixel of where it entered (ketchup's blue).
# Under the test suite this notebook fits a 64 x 48 photo (about a minute); the full settings
# (160 x 120) take about two.
