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
# # Four ways to render subsurface light, and what each costs
#
# `jsss.render` can produce the light that scatters under a surface in four ways:
#
# | method | idea | cost |
# | --- | --- | --- |
# | `lambert` | the profile's total albedo, no spread | one multiply per pixel |
# | `normal filtering` | blur the *normals* with the profile (Patro 2007), shade with them | Lambert's, after a one-time filter per mesh |
# | `image-space` | integrate the profile around each pixel from the camera's irradiance image, samples drawn exactly from the dipole (Mertens 2003) | samples x pixels |
# | `texture-space` | blur the irradiance in the object's texture with a sum of Gaussians (d'Eon 2007) | one blur chain per frame |
#
# This notebook renders the example scenes with all of them at a small size, measures each
# against a brute-force reference (the exact profile integrated over the whole surface), and
# shows how the planner uses such measurements to choose.

# %%
import os

import jax

jax.config.update("jax_enable_x64", True)  # references and planning in float64; frames in float32
import matplotlib.pyplot as plt
import numpy as np

from jsss.render import Method, load_scene, plan_scene
from jsss.render.comparison import VARIANTS, compare_methods, scene_at_distance
from jsss.render.shading import tone_map

FAST = os.environ.get("JSSS_FULL") != "1"   # JSSS_FULL=1: the full size (see notebooks/README.md)
size = (40, 30) if FAST else (96, 72)
points = 40_000 if FAST else 300_000
# fast: one knob each for normal filtering and texture space (each frame is a compile); the
# three image-space sample counts stay, for the 1/sqrt(N) plot below
variants = [v for v in VARIANTS if not FAST or v[0] in (Method.LAMBERT, Method.IMAGE_SPACE)
            or v[1] in ({"normal_filter": "spectral"}, {"accuracy": 0.05})]
examples = os.path.join(os.getcwd(), "..", "examples")

# %% [markdown]
# ## Every method on the marble sphere and the ketchup plane

# %%
results = {}
for name in ("marble_sphere", "ketchup_plane"):
    scene = scene_at_distance(load_scene(os.path.join(examples, f"{name}.toml")), 1.0,
                              width=size[0], height=size[1], texture_size=128 if FAST else 256)
    results[name] = compare_methods(scene, name, reference_samples=points, variants=variants,
                                    repeats=1 if FAST else 3)
    reference, frames = results[name]
    print(f"{name}: profile spans {frames[0].row.blur_pixels:.3g} pixels; reference noise {100 * reference.noise:.2f} %")
    print(f"  {'method':<18} {'knob':<13} {'error':>8} {'ms/frame':>9}")
    for f in frames:
        print(f"  {f.row.method:<18} {f.row.knob:<13} {100 * f.row.error:7.2f}% {f.row.ms:9.3g}")

# %%
shown = [(Method.LAMBERT, ""), (Method.NORMAL_FILTERING, "spectral"), (Method.IMAGE_SPACE, "32 spp"),
         (Method.TEXTURE_SPACE, "profile 5 %")]
fig, axes = plt.subplots(4, 5, figsize=(13, 8))
for i, (name, (reference, frames)) in enumerate(results.items()):
    image, exposure = tone_map(reference.radiance)
    axes[2 * i, 0].imshow(image)
    axes[2 * i, 0].set_title(f"{name}: reference", fontsize=8)
    scale = np.abs(reference.radiance).max()
    for j, key in enumerate(shown, start=1):
        f = next(f for f in frames if (f.row.method, f.row.knob) == key)
        axes[2 * i, j].imshow(tone_map(f.radiance, exposure=exposure)[0])
        axes[2 * i, j].set_title(f"{key[0]} {key[1]}: {100 * f.row.error:.1f} %", fontsize=8)
        error_map = axes[2 * i + 1, j].imshow(np.abs(f.radiance - reference.radiance).max(-1) / scale, cmap="magma",
                                              vmin=0, vmax=0.2)
    axes[2 * i + 1, 0].text(0.5, 0.5, "error maps:\n|method - reference|", ha="center", va="center", fontsize=8,
                            transform=axes[2 * i + 1, 0].transAxes)
for ax in axes.ravel():
    ax.axis("off")
plt.tight_layout()
fig.colorbar(error_map, ax=axes[1::2, 1:].ravel().tolist(), shrink=0.8,
             label="|error| / brightest reference pixel (clipped at 0.2)")

# %% [markdown]
# What the error maps show: on the sphere Lambert misses the soft terminator, image-space
# integration is noisy (a dither from interleaved sampling) and texture space is closest. On
# the plane the light that reaches its edges leaves through them in the reference; image-space
# integration loses it too (samples off the object count zero), while Lambert, normal
# filtering and the mask-normalised texture blur keep it and are too bright along the edges.
#
# ## Image-space noise falls like one over the square root of the samples

# %%
reference, frames = results["marble_sphere"]
image = [f.row for f in frames if f.row.method == Method.IMAGE_SPACE]
spp = np.array([int(r.knob.split()[0]) for r in image])
error = np.array([r.error for r in image])
slope = np.polyfit(np.log(spp), np.log(error), 1)[0]
fig, ax = plt.subplots(figsize=(5, 3.5))
ax.loglog(spp, 100 * error, "o-", label=f"image-space (slope {slope:.2f})")
ax.loglog(spp, 100 * error[0] * np.sqrt(spp[0] / spp), "k--", label="1/sqrt(N)")
ax.set(xlabel="samples per pixel", ylabel="relative RMS error [%]")
ax.legend()
print(f"slope {slope:.2f} (the error also holds a bias: light from surfaces the camera does not see is missing)")

# %% [markdown]
# ## The planner chooses from a measured table
#
# `benchmarks/methods.py --calibrate` renders the example scenes from four distances with every
# method and stores error and time in `jsss/data/calibration.json`. For a new scene the planner
# looks up frames whose profile spans a similar number of pixels, predicts each method's error and
# time, and takes the cheapest that meets the accuracy target. A looser target or a camera far
# away makes it pick something cheaper:

# %%
scene = load_scene(os.path.join(examples, "ketchup_plane.toml"))
for label, s, target in (("ketchup plane, 5 %", scene, 0.05), ("ketchup plane, 30 %", scene, 0.3),
                         ("ketchup plane 12x as far, 5 %", scene_at_distance(scene, 12.0, width=320, height=240), 0.05)):
    plan = plan_scene(s, accuracy=target)
    print(f"{label:<32} -> {plan.method} {plan.knob}  ({plan.method_why})")

# %%
print(plan_scene(scene, accuracy=0.05).describe())
