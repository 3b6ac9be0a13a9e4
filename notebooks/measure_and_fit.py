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
# them as OpenEXR, extracts the calibrated radial profile and fits the dipole, as
# `fit-params` does.

# %%
import tempfile

import jax

jax.config.update("jax_enable_x64", True)
import matplotlib.pyplot as plt
import numpy as np

from jsss import dipole, hankel
from jsss.materials import jensen2001
from measure.exr import read_exr
from measure.pipeline import fit_measurement
from measure.synth import synthesize, write_measurement

grid = hankel.hankel_grid()
marble = jensen2001("marble")
synthetic = synthesize(marble, size=256, pixel_mm=0.05, beam_sigma_mm=0.05, photons_per_unit=1e5, seed=0, grid=grid)
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
# What the camera records is **radiance toward itself**, not the exitance R(r) of the dipole:
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

# %%
result = fit_measurement(measurement, reference, 0.05, 1.5, dark=dark, grid=grid)
table = result.table()
print(f"beam centre {np.round(result.center, 3)} px, beam sigma {result.beam_sigma_mm:.4f} mm")
print(f"{'ch':<3} {'sigma_a':>10} {'true':>8} {'sigma_s_prime':>14} {'true':>6}")
for i, ch in enumerate(table["channels"]):
    print(f"{ch:<3} {table['sigma_a'][i]:>10.5f} {float(marble.sigma_a[i]):>8.4f} {table['sigma_s_prime'][i]:>14.4f} {float(marble.sigma_s_prime[i]):>6.2f}")

# %%
prof = result.profile
r = np.geomspace(0.03, prof.r_mm[-1], 200)
model = np.asarray(dipole.profile(result.fit.medium, r))
fig, ax = plt.subplots(figsize=(6, 4))
for c, colour in enumerate(("tab:red", "tab:green", "tab:blue")):
    ax.errorbar(prof.r_mm, prof.mean[:, c], yerr=prof.stderr[:, c], fmt=".", ms=3, color=colour)
    ax.plot(r, model[:, c], color=colour, lw=1)
ax.set(xscale="log", yscale="log", xlabel="r [mm]", ylabel="R_d(r) [1/mm^2]", title="measured bins and the fitted dipole");
