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
# # How accurate is diffusion?
#
# The dipole and the multipole are diffusion approximations. A Monte Carlo random walk
# (`jsss.transport.montecarlo.random_walk`) solves the transport problem they approximate, so it
# shows where they depart: close to the source, at low albedo, and with index mismatch.
# By default it runs with few photons (4 000 per walk) and a 2 x 4 error map, in about 20 s;
# `JSSS_FULL=1` runs 100 000 photons per walk and a 5 x 9 map (times in notebooks/README.md).

# %%
import os

import jax

jax.config.update("jax_enable_x64", True)
import matplotlib.pyplot as plt
import numpy as np

from jsss import Medium, dipole
from jsss.diffusion.multipole import slab_profiles
from jsss.materials import jensen2001
from jsss.transport.montecarlo import random_walk

fast = os.environ.get("JSSS_FULL") != "1"  # JSSS_FULL=1: 100 000 photons, a 5 x 9 map
photons = 4000 if fast else 100_000

# %% [markdown]
# ## What diffusion assumes
#
# Light in a turbid medium is described by the radiative transfer equation: radiance
# L(x, w) changes along a ray by absorption (sigma_a), by scattering away (sigma_s) and by
# light scattered into it through the phase function. Diffusion theory keeps only the first
# two angular moments of L, the fluence phi and the flux vector E, and closes the system with
# Fick's law E = -D grad phi, D = 1 / (3 sigma_t'). That is exact only when the radiance is
# nearly isotropic, which needs many scattering events: far from sources and boundaries, at
# high albedo sigma_s' / sigma_t'.
#
# The dipole (Jensen et al. 2001) turns a beam entering a half space into one isotropic point
# source at depth z_r = 1 / sigma_t' (one transport mean free path, where the beam's first
# collisions happen on average) and a negative image source above the surface, at the
# extrapolated boundary where the fluence would vanish (its height depends on eta through the
# internal Fresnel reflection). The profile R(r) is the flux leaving at distance r. Three
# consequences to look for in the plots below:
#
# * **near the source** (r below a few mean free paths), light has scattered only a few times;
#   diffusion misplaces it (the dipole's core is a property of its point source, not of the
#   beam);
# * **at low albedo**, most light leaves after one or two collisions, with an angular law
#   diffusion does not have; the total reflectance is wrong by tens of percent;
# * **with an index mismatch**, the boundary condition is an approximation to the Fresnel
#   reflection of an anisotropic radiance.
#
# The random walk makes none of these assumptions: photons fly exponential distances,
# scatter isotropically (or Henyey-Greenstein), and meet the boundary with the exact Fresnel
# probability for their angle.

# %% [markdown]
# ## Three Jensen materials (one channel each): semi-infinite and a 2 mm slab
#
# Markers: Monte Carlo with its standard errors; dashed: dipole (semi-infinite); dotted:
# multipole (a 2 mm slab, with image sources mirrored at both boundaries, Donner & Jensen
# 2005). Marble (high albedo) follows diffusion except in its first tenth of a millimetre;
# ketchup's red (albedo' 0.75) departs everywhere. The slab loses the light that the half
# space would have sent back from below 2 mm, which shows at radii beyond the thickness.

# %%
choices = [("marble", 1), ("skin1", 0), ("ketchup", 0)]
fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), sharey=True)
for ax, (name, channel) in zip(axes, choices):
    m = jensen2001(name)
    medium = Medium(m.sigma_a[channel], m.sigma_s_prime[channel], m.eta[channel])
    mfp = float(medium.mean_free_path)
    edges = np.concatenate([[0.0], np.geomspace(0.05 * mfp, 30 * mfp, 25), [np.inf]])
    semi = random_walk(medium, n_photons=photons, bin_edges=edges, max_steps=5000, seed=0, progress=False)
    slab = random_walk(medium, thickness=2.0, n_photons=photons, bin_edges=edges, max_steps=5000, seed=1, progress=False)
    r = semi.r[1:-1]
    ax.errorbar(r, semi.R_profile[1:-1], yerr=semi.R_profile_err[1:-1], fmt="o", ms=3, color="k", label="MC, semi-infinite")
    ax.errorbar(r, slab.R_profile[1:-1], yerr=slab.R_profile_err[1:-1], fmt="s", ms=3, color="tab:orange", label="MC, 2 mm slab")
    rr = np.geomspace(edges[1], edges[-2], 200)
    ax.plot(rr, dipole.profile(medium, rr), "k--", label="dipole")
    ax.plot(rr, slab_profiles(medium, 2.0, rr)[0], ":", color="tab:orange", label="multipole")
    ax.set(xscale="log", yscale="log", xlabel="r [mm]", title=f"{name} ({'RGB'[channel]})")
axes[0].set_ylabel("R(r) [1/mm^2]")
axes[0].legend(fontsize=7);

# %% [markdown]
# ## Error map: the dipole's total reflectance against Monte Carlo over albedo and index
#
# Each cell is one walk against `dipole.total_reflectance` (the integral of R(r)). Read it as
# a rule of thumb for when diffusion is good enough: above albedo' 0.95 the total is within a
# few percent at every index; below 0.8 it is not. Where it is not, use
# `profile_model = "transport"` (tables exact to transport, `jsss.transport`), or fit
# measurements with the transport model (`fit-params --model transport`, the default).

# %%
albedos = [0.5, 0.8, 0.95, 0.99] if fast else [0.3, 0.5, 0.7, 0.8, 0.9, 0.95, 0.98, 0.99, 0.995]
etas = [1.0, 1.5] if fast else [1.0, 1.2, 1.3, 1.4, 1.5]
errors = np.zeros((len(etas), len(albedos)))
for i, eta in enumerate(etas):
    for j, a in enumerate(albedos):
        medium = Medium(1 - a, a, eta)
        mc = random_walk(medium, n_photons=photons // 2, max_steps=5000, seed=i * 100 + j, progress=False)
        errors[i, j] = float(dipole.total_reflectance(medium)) / mc.R - 1
fig, ax = plt.subplots(figsize=(6, 3))
limit = 10 * np.ceil(np.abs(100 * errors).max() / 10)  # symmetric, and wide enough for every value
image = ax.imshow(100 * errors, cmap="RdBu", vmin=-limit, vmax=limit, aspect="auto")
ax.set(xticks=range(len(albedos)), xticklabels=albedos, yticks=range(len(etas)), yticklabels=etas,
       xlabel="reduced albedo", ylabel="eta", title="dipole total reflectance error vs MC [%]")
fig.colorbar(image, label="dipole / Monte Carlo - 1 [%]")
print(np.round(100 * errors, 1))

# %% [markdown]
# ## Light that arrives at a slant
#
# Every profile here is for a beam along the normal. Light arriving at an angle theta is
# deposited nearer the surface, so more of it comes back. For isotropic scattering in an
# index-matched half space the total reflectance is known exactly (Chandrasekhar 1960):
# A(mu0) = 1 - H(mu0) sqrt(1 - albedo), mu0 = cos theta, with Chandrasekhar's H function
# (`jsss.diffusion.incidence`). The renderer scales each light's irradiance by A(mu0) / A(1), its
# "oblique incidence" pass. The walk below starts photons at the given angle and checks it.

# %%
from jsss.diffusion.incidence import plane_albedo

cosines = np.linspace(0.1, 1.0, 50)
fig, ax = plt.subplots(figsize=(6, 3.4))
for albedo, colour in [(0.75, "tab:red"), (0.95, "tab:green")] + ([] if fast else [(0.999, "tab:blue")]):
    ax.plot(cosines, np.asarray(plane_albedo(albedo, cosines)) / float(plane_albedo(albedo, 1.0)), color=colour,
            label=f"H function, albedo {albedo}")
    for mu in (1.0, 0.5) if fast else (1.0, 0.6, 0.3):
        walk = random_walk(Medium(1 - albedo, albedo, 1.0), cos_incident=mu, n_photons=photons, max_steps=5000,
                           seed=int(100 * mu), progress=False)
        ax.errorbar(mu, walk.R / float(plane_albedo(albedo, 1.0)), yerr=walk.R_err / float(plane_albedo(albedo, 1.0)),
                    fmt="o", ms=4, color=colour)
ax.set(xlabel="cosine of the incoming light", ylabel="reflectance / at normal incidence",
       title="oblique incidence (markers: random walks, eta = 1)")
ax.legend(fontsize=7);
