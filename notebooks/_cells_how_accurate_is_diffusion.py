CELLS = [
    ("md", """
# How accurate is diffusion?

The dipole and the multipole are diffusion approximations. A Monte Carlo random walk
(`jsss.montecarlo.random_walk`) solves the transport problem they approximate, so it
shows where they depart: close to the source, at low albedo, and with index mismatch.
By default it runs with few photons (4 000 per walk) and a 2 x 4 error map, in about 20 s;
`JSSS_FULL=1` runs 100 000 photons per walk and a 5 x 9 map (times in notebooks/README.md).
"""),
    ("code", """
import os
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import matplotlib.pyplot as plt
from jsss import Medium, dipole
from jsss.materials import jensen2001
from jsss.multipole import slab_profiles
from jsss.montecarlo import random_walk
fast = os.environ.get("JSSS_FULL") != "1"  # JSSS_FULL=1: 100 000 photons, a 5 x 9 map
photons = 4000 if fast else 100_000
"""),
    ("md", """
## Three Jensen materials (one channel each): semi-infinite and a 2 mm slab

Solid: Monte Carlo; dashed: dipole (semi-infinite); dotted: multipole (2 mm slab).
"""),
    ("code", """
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
"""),
    ("md", "## Error map: the dipole's total reflectance against Monte Carlo over albedo and index"),
    ("code", """
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
"""),
]
