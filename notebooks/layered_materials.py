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
# # Layered materials: thin slabs, stacks and skin
#
# This tutorial computes reflectance profiles R(r) of a thin slab, a two-layer stack and a
# three-layer skin model with `jsss.diffusion.multipole` and `jsss.layers`, and compares them with the
# semi-infinite dipole. Lengths are in mm, profiles in 1/mm^2.

# %%
import jax

jax.config.update("jax_enable_x64", True)  # reference profiles need float64
import matplotlib.pyplot as plt
import numpy as np

from jsss import Medium, dipole, hankel
from jsss.diffusion.multipole import slab_profiles, slab_totals
from jsss.layers import Layer, skin_three_layer, stack

grid = hankel.hankel_grid()  # build once (about a second), reuse for every stack
r = np.asarray(grid.r)

# %% [markdown]
# ## A thin slab against the dipole
#
# A slab much thinner than the diffusion length reflects less than a semi-infinite block of
# the same medium and transmits the rest. As the slab thickens, R(r) approaches the dipole.
#
# The multipole (Donner & Jensen 2005) satisfies the boundary condition at *both* faces: the
# dipole's pair of sources is mirrored again and again about the two extrapolated boundaries,
# an infinite series whose terms fall off fast (a dozen pairs suffice for these slabs).

# %%
medium = Medium(0.01, 1.0, 1.4)
fig, ax = plt.subplots(figsize=(6, 4))
for d in [0.2, 1.0, 5.0]:
    R, T = slab_profiles(medium, d, r)
    Rt, Tt = slab_totals(medium, d)
    ax.loglog(r, R, label=f"slab d={d} mm: R={float(Rt):.3f}, T={float(Tt):.3f}")
ax.loglog(r, dipole.profile(medium, r), "k--", label=f"dipole: R={float(dipole.total_reflectance(medium)):.3f}")
ax.set(xlim=(1e-2, 30), ylim=(1e-6, 10), xlabel="r [mm]", ylabel="R(r) [1/mm^2]")
ax.legend(fontsize=8);

# %% [markdown]
# ## A two-layer stack
#
# A strongly absorbing thin layer over a clear one: Kubelka-Munk in frequency space adds
# up all inter-layer bounces.
#
# Light crossing from one layer into the next and back is a convolution of profiles; in
# frequency space (the Hankel transform of a radial profile) convolutions become products, and
# the infinite series of bounces between two layers, R1 + T1 R2 T1 + T1 R2 R1 R2 T1 + ...,
# sums to R1 + T1^2 R2 / (1 - R1 R2) at each frequency (d'Eon 2007 after Donner & Jensen
# 2005). One inverse transform gives R(r) of the stack.

# %%
top = Layer(Medium(0.3, 2.0, 1.4), 0.2)
bottom = Layer(Medium(0.005, 1.5, 1.4), 3.0)
two = stack([top, bottom], grid=grid)
only_top = stack([top], grid=grid)
fig, ax = plt.subplots(figsize=(6, 4))
ax.loglog(r, two.R, label=f"stack: R={float(two.R_total):.3f}, T={float(two.T_total):.3f}")
ax.loglog(r, only_top.R, label=f"top layer alone: R={float(only_top.R_total):.3f}")
ax.loglog(r, dipole.profile(top.medium, r), "k--", label="dipole of the top medium")
ax.set(xlim=(1e-2, 30), ylim=(1e-6, 10), xlabel="r [mm]", ylabel="R(r) [1/mm^2]")
ax.legend(fontsize=8);

# %% [markdown]
# ## Three-layer skin
#
# `skin_three_layer()` returns an oil film and an epidermis over a semi-infinite dermis.
# Red light travels furthest: the blood in the dermis absorbs green and blue.

# %%
layers, dermis = skin_three_layer()
skin = stack(layers, dermis, grid=grid)
fig, ax = plt.subplots(figsize=(6, 4))
for c, colour in enumerate("rgb"):
    ax.loglog(r, np.clip(np.asarray(skin.R[:, c]), 1e-12, None), colour, label=f"skin {colour.upper()}: R={float(skin.R_total[c]):.3f}")
    ax.loglog(r, dipole.profile(dermis, r)[:, c], colour + "--", lw=0.8)
ax.set(xlim=(1e-2, 30), ylim=(1e-6, 30), xlabel="r [mm]", ylabel="R(r) [1/mm^2]", title="skin (solid) vs dermis dipole (dashed)")
ax.legend(fontsize=8)
print("total diffuse reflectance R, G, B:", np.round(np.asarray(skin.R_total), 4))
