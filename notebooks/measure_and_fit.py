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
# # From beam-profile images to sigma_a and sigma_s'
#
# A measurement (Jensen et al. 2001 sec. 3) is an HDR image of a flat sample lit at one
# point by a narrow beam, plus a reference image of the same beam on a white diffuser.
# This tutorial makes a synthetic pair for marble with `measure.synth`, writes and reads
# them as OpenEXR, extracts the calibrated radial profile and fits it with the transport
# model (scaled Monte Carlo tables, exact to radiative transfer), as `fit-params` does: both
# default to it. The images are framed as the demo's: 256 pixels of 0.14 mm reach 2.1
# diffusion lengths of marble's red.

# %%
import tempfile

import jax

jax.config.update("jax_enable_x64", True)
import matplotlib.pyplot as plt
import numpy as np

from jsss import hankel
from jsss.materials import jensen2001
from measure.exr import read_exr
from measure.pipeline import fit_measurement
from measure.synth import synthesize, write_measurement

grid = hankel.hankel_grid()
marble = jensen2001("marble")
synthetic = synthesize(marble, size=256, pixel_mm=0.14, beam_sigma_mm=0.14, photons_per_unit=1e5, seed=0, grid=grid)
folder = tempfile.mkdtemp()
paths = write_measurement(folder, synthetic, name="marble")
sorted(p.name for p in paths.values())

# %% [markdown]
# ## The images (log scale): five decades of light around the beam, and the beam itself on the reference

# %%
measurement = read_exr(paths["measurement"]).pixels
reference = read_exr(paths["reference"]).pixels
dark = read_exr(paths["dark"]).pixels
fig, axes = plt.subplots(1, 2, figsize=(8, 4))
for ax, image, title in zip(axes, (measurement, reference), ("marble", "white reference")):
    shown = ax.imshow(np.log10(np.clip(image[..., 1] - dark[..., 1], 1e-6, None)), cmap="magma")
    ax.set_title(title + " (green)"); ax.axis("off")
    fig.colorbar(shown, ax=ax, shrink=0.8, label="log10 pixel value, dark frame subtracted")

# %% [markdown]
# ## Calibrate, bin, fit
#
# What the camera records is **radiance toward itself**, not the exitance R(r):
# pixel value = K L(r, theta). The white reference removes K: the same beam on a diffuser of
# known reflectance rho returns radiance rho E / pi, so dividing by the reference's sum over
# the image turns pixel values into radiance per unit incident flux. `fit_measurement` then
#
# * finds the beam's centre and width on the reference (a Gaussian);
# * bins the calibrated pixels in rings around the centre (log-spaced, from just outside the
#   beam to where the signal meets the noise), with each ring's standard error from the
#   photon and read noise of its pixels;
# * fits sigma_a and sigma_s' by Levenberg-Marquardt: the model is the profile convolved
#   with the measured beam, in the Hankel domain, averaged over each ring's pixels.
#
# sigma_s' mostly sets the profile's shape near the beam, sigma_a its decay far out: the
# decay length is the diffusion length 1 / sqrt(3 sigma_a sigma_t'). A field of view shorter
# than about two diffusion lengths leaves sigma_a poorly determined, and `fit-params` warns.
#
# Two things no residual can show, and the table states beside every fit: the **scale** (every
# coefficient goes as 1/pixel size: measure it with `fit-params pixel-size` on a checkerboard),
# and the **calibration** (a 1 % error in the reference's reflectance moves marble's sigma_a by
# about 10 %, outside the stated errors).

# %%
result = fit_measurement(measurement, reference, 0.14, 1.5, dark=dark, grid=grid)
table = result.table()
print(f"beam centre {np.round(result.center, 3)} px, beam sigma {result.beam_sigma_mm:.4f} mm")
print(f"{'ch':<3} {'sigma_a':>10} {'true':>8} {'sigma_s_prime':>14} {'true':>6}")
for i, ch in enumerate(table["channels"]):
    print(f"{ch:<3} {table['sigma_a'][i]:>10.5f} {float(marble.sigma_a[i]):>8.4f} {table['sigma_s_prime'][i]:>14.4f} {float(marble.sigma_s_prime[i]):>6.2f}")
print("field in diffusion lengths:", np.round(table["field_diffusion_lengths"], 2))
print("sigma_a moves by this many % per 1 % calibration error:", np.round(table["sigma_a_per_calibration"], 1))

# %% [markdown]
# ## What was fitted, and how well
#
# The plot shows what the fit compared: the calibrated bins (the camera's radiance factor
# pi (1 - F0) L toward it) and the fitted model in the same bins, beam-convolved and averaged
# over the same pixels (`result.fitted_bins`); below, the residuals in units of each bin's
# error (`result.normalized_residuals`). A good fit scatters within +-2; the dipole on the same
# image runs in arcs far outside.

# %%
dipole_fit = fit_measurement(measurement, reference, 0.14, 1.5, dark=dark, grid=grid, model="dipole")
prof = result.profile
fitted = prof.r_mm >= result.r_min_mm
fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.4, 5.6), sharex=True, height_ratios=(3, 1.4))
for c, colour in enumerate(("tab:red", "tab:green", "tab:blue")):
    top.errorbar(prof.r_mm[fitted], prof.mean[fitted, c], yerr=prof.stderr[fitted, c], fmt=".", ms=3, color=colour)
    top.plot(prof.r_mm[fitted], result.fitted_bins[fitted, c], color=colour, lw=1)
    bottom.plot(prof.r_mm, result.normalized_residuals[:, c], ".-", ms=3, lw=0.5, color=colour)
    bottom.plot(prof.r_mm, dipole_fit.normalized_residuals[:, c], ":", lw=1, color=colour)
top.set(xscale="log", yscale="log", ylabel="pi (1-F0) L [1/mm^2]", title="bins and the fitted transport model")
bottom.set(xlabel="r [mm]", ylabel="(data - fit) / error", yscale="symlog", title="dotted: the dipole")
print("chi2/dof transport:", np.round(np.asarray(result.fit.chi2_reduced), 2),
      " dipole:", np.round(np.asarray(dipole_fit.fit.chi2_reduced), 0))
