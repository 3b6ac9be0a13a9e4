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
# # Sums of Gaussians
#
# Renderers blur irradiance with separable Gaussians, so a diffusion profile R(r) is
# replaced by a sum of a few Gaussians (d'Eon et al. 2007). This tutorial fits 4 and 8
# Gaussians to a dipole with Levenberg-Marquardt (`fitting.fit_gaussians`), compares them with
# the closed-form 8-Gaussian fit (`jsss.gaussians.empirical_dipole_fit`), and tabulates the
# error for every Jensen 2001 channel.

# %%
import jax

jax.config.update("jax_enable_x64", True)  # fits need float64
import matplotlib.pyplot as plt
import numpy as np

from fitting import fit_gaussians, jensen2001_profiles, radial_grid
from jsss import dipole
from jsss.gaussians import empirical_dipole_fit, evaluate, relative_rms_error
from jsss.materials import jensen2001, jensen2001_names

# %% [markdown]
# ## Why Gaussians, and how their error is measured
#
# A 2D Gaussian G_v(r) = exp(-r^2 / 2v) / (2 pi v) is the only radially symmetric kernel that
# is also separable (a horizontal blur followed by a vertical one), and blurring by v1 then by
# v2 is blurring by v1 + v2. So a renderer can diffuse a texture with a chain of cheap 1D
# blurs and take every Gaussian of the sum from one step of the chain (d'Eon 2007 sec. 5).
# The price is that the profile becomes sum_i w_i G_{v_i}(r), and a profile with a sharp core
# and a long tail needs several terms spread over decades of variance.
#
# d'Eon's error measures the profile as light is applied: the power error
# int r (R - sum w G)^2 dr relative to int r R^2 dr. The factor r weights each radius by the
# ring of surface it covers. In the plots, 2 pi r R(r) is the light leaving per unit radius:
# its integral over r is the total reflectance.

# %% [markdown]
# ## Marble, green channel: the profile, its fits and their residuals (scaled by 2 pi r, as light is applied radially)

# %%
marble = jensen2001("marble")
r = radial_grid(marble)
profile = dipole.profile(marble, r)[:, 1]
fits = {n: fit_gaussians(r, profile, n) for n in (4, 8)}
empirical = empirical_dipole_fit(marble)
fig, (top, bottom) = plt.subplots(2, 1, figsize=(6, 6), sharex=True)
top.loglog(r, 2 * np.pi * r * profile, "k", lw=2, label="dipole")
for n, fit in fits.items():
    model = evaluate(fit.gaussian_sum(), r)
    top.loglog(r, 2 * np.pi * r * model, "--", label=f"{n} Gaussians (LM): {100 * float(fit.rel_rms):.3f} %")
    bottom.semilogx(r, 2 * np.pi * r * (model - profile), label=f"{n} Gaussians")
model = evaluate(empirical, r)[:, 1]
err = float(relative_rms_error(empirical, r, dipole.profile(marble, r))[1])
top.loglog(r, 2 * np.pi * r * model, ":", label=f"empirical 8: {100 * err:.3f} %")
bottom.semilogx(r, 2 * np.pi * r * (model - profile), ":", label="empirical 8")
top.set(ylim=(1e-5, 2), ylabel="2 pi r R(r) [1/mm]")
bottom.set(xlabel="r [mm]", ylabel="residual x 2 pi r")
top.legend(fontsize=8); bottom.legend(fontsize=8);

# %% [markdown]
# ## The error table: four Gaussians for each of the 36 channels (d'Eon reports 0.0793 % to 1.52 %)
#
# One fit with four shared variances for all 36 channels (12 materials x RGB), as a renderer
# needs (every channel is blurred with the same Gaussians; only the weights differ per
# channel). The channels whose profiles span the most decades (low absorption, long tails)
# carry the largest errors.

# %%
names = jensen2001_names()
radii, profiles, labels = jensen2001_profiles()
fit = fit_gaussians(radii, profiles, 4)
errors = 100 * np.asarray(fit.rel_rms).reshape(len(names), 3)
print(f"{'material':<11} {'R %':>7} {'G %':>7} {'B %':>7}")
for name, row in zip(names, errors):
    print(f"{name:<11} {row[0]:>7.3f} {row[1]:>7.3f} {row[2]:>7.3f}")
print(f"max {errors.max():.3f} %, min {errors.min():.4f} %")
