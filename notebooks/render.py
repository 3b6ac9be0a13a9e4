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
# # Rendering translucent objects in texture space
#
# `jsss.render` renders a scene with d'Eon et al.'s (2007) texture-space diffusion: irradiance is
# gathered into the object's texture, blurred once per Gaussian of the material's profile
# (each blur building on the previous one), weighted per colour and looked up by the camera.
# A planner reads the scene and decides which passes are needed and why. This notebook renders
# the three example scenes at a small size, then shows what the planner changes when the
# camera moves far away, and how the profile's Gaussians compare with the exact profile.

# %%
import os
from dataclasses import replace

import jax

jax.config.update("jax_enable_x64", True)  # the planner fits profiles in float64; frames render in float32
import matplotlib.pyplot as plt
import numpy as np

from jsss.render import load_scene, plan_scene, render
from jsss.render.shading import tone_map

FAST = os.environ.get("JSSS_FULL") != "1"   # JSSS_FULL=1: the full size (see notebooks/README.md)
size = (96, 72) if FAST else (320, 240)
texture = 128 if FAST else 512
examples = os.path.join(os.getcwd(), "..", "examples")

# %% [markdown]
# ## The example scenes and their plans
#
# What a frame is made of, pass by pass (each plan below says which it runs and why):
#
# * **irradiance**: the light each texel receives, after the Fresnel loss at entry, with shadow
#   maps for visibility. Two corrections to the profiles' beam along the normal:
#   *oblique incidence* (light arriving at a slant is deposited shallower and more of it
#   returns: Chandrasekhar's H function) and *deposit depth* (a nearby point light's rays keep
#   spreading below the surface, so it is read half a reduced mean free path deep);
# * **diffusion**: the irradiance texture blurred by each Gaussian of the profile; the profile's
#   light at a point is the weighted sum (the blurs use true surface distances through the
#   texture's stretch where it varies);
# * **translucent shadow maps**: light that crosses a thin part from a lit face to a shadowed
#   one (the skin's silhouette);
# * **single scattering**: the first bounce with its own angular law, which replaces its share of
#   the diffusion light (low-albedo materials such as ketchup);
# * **exit angle**: the angle at which the multiply scattered light leaves. Diffusion spreads it
#   evenly behind the Fresnel boundary; a half space does not (Chandrasekhar's H(mu0) H(mu)
#   kernel: ketchup's red leaves more at grazing angles, marble more along the normal), so the
#   exitance is spread by that kernel of the light arriving at each point;
# * **camera**: exitance spread over outgoing directions by the exit lobe (the Fresnel lobe, or
#   the exit-angle pass's), looked up per pixel, plus a microfacet specular lobe.

# %%
images = {}
for name in ("marble_sphere", "skin_backlit", "ketchup_plane"):
    scene = load_scene(os.path.join(examples, f"{name}.toml"))
    camera = replace(scene.camera, width=size[0], height=size[1])
    scene = replace(scene, camera=camera, texture_size=min(scene.texture_size, texture))
    result = render(scene, plan_scene(scene, method="texture-space"))
    images[name] = tone_map(result.radiance)[0]
    print(name)
    print(result.plan.describe())
    print()
fig, axes = plt.subplots(1, 3, figsize=(12, 3.2))
for ax, (name, image) in zip(axes, images.items()):
    ax.imshow(image)
    ax.set_title(name)
    ax.axis("off")

# %% [markdown]
# ## Seen from far away, diffusion is below a pixel
#
# The same marble sphere from 200 m: the profile's RMS radius (about 5 mm) is smaller than a
# pixel's footprint, so the planner picks Lambert shading with the profile's total albedo
# (its calibration table, see `methods.py`, predicts the smallest cost at the target).

# %%
scene = load_scene(os.path.join(examples, "marble_sphere.toml"))
far = replace(scene, camera=replace(scene.camera, position=(0.0, -2.0e5, 5.0e4), width=32, height=24))
print(plan_scene(far).describe())

# %% [markdown]
# ## The profile the blurs apply, against the exact one
#
# A scene's homogeneous medium keeps the dipole where its total reflectance is within a
# quarter of the accuracy target of the transport truth's, and takes the transport tables
# otherwise (`profile = "auto"`, the default; `plan.profile` says why): marble at 5 % keeps
# the dipole (-1 %). The planner measures the Gaussians' error from half a pixel's footprint
# out (dotted line): inside one pixel the camera sees only the profile's flux, which the fit
# keeps exactly.

# %%
from jsss import dipole, transport
from jsss.gaussians import evaluate
from jsss.render.profiles import render_profile

plan = plan_scene(scene, method="texture-space")
print(plan.profile.describe())
gs = render_profile(scene.material, plan.variances)
r = np.geomspace(0.01, 60, 400)
medium = scene.material.medium
exact = np.asarray(transport.profile(medium, r) if plan.profile.model == "transport" else dipole.profile(medium, r))
fig, ax = plt.subplots(figsize=(6, 4))
for c, colour in enumerate("rgb"):
    ax.loglog(r, r * exact[:, c], colour, lw=2, alpha=0.5)
    ax.loglog(r, r * np.asarray(evaluate(gs, r))[:, c], colour + "--")
ax.axvline(plan.pixel_size / 2, color="k", ls=":", lw=1)
ax.set(xlabel="r [mm]", ylabel="r R(r)", ylim=(1e-5, 1),
       title=f"marble, {plan.profile.model}: {len(plan.variances)} Gaussians, error {100 * plan.profile_error:.2f} % (dashed)")
assert plan.profile_error < scene.accuracy
