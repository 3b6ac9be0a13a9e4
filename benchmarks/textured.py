"""What textured materials cost: frame time with maps, and the error of blending basis profiles.

    python benchmarks/textured.py [--quick] [--write]

1. **Frame time.** The marble sphere example at 512 x 512 pixels, texture space at 512^2
   texels, float32: the compiled frame's median time without maps, and with a colour map the
   texture's size (read as it is), twice its size (averaged 2 x 2, then read), and an odd size
   (bilinear gathers); and with parameter maps (a two-material checker: 4 basis profiles, and
   a smooth gradient). Ratios are to the plain frame measured in the same run (the machine is
   shared and noisy).
2. **Blending error.** A sigma_a gradient over a 100x range: the basis the planner's target
   chooses (nodes, its own error estimate) and the error measured independently at 64 random
   media of the range, against each one's exact dipole profile (truth: the closed form, not the
   blend), over the radii every Gaussian is resolved on.

3. **Colour map against an independent walk.** tests/truth/colour_layer_walk.py (NumPy, no
   jsss code) carries sqrt(c) of a step map in and out of a Fresnel half-space; texture space
   renders the same step as a scene (profile = "transport"). Per channel: the largest
   |jsss / walk - 1| over the 1 mm bins across the edge, that bin's walk noise, and the sums;
   for each texturing rule (only pre-post is the walk's layer).

``--write`` writes the tables, dated, to docs/benchmarks/textured.md; ``--image PNG`` renders
the picture of the textured examples in docs/guides/rendering.md (the veined marble under each texturing rule,
and the checker plane).
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys
import tempfile
import tomllib

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

from _timing import median_seconds  # noqa: E402
from jsss.diffusion import dipole  # noqa: E402
from jsss.medium import Medium  # noqa: E402
from jsss.render import Method, choose_basis, parse_scene, plan_scene, render_params  # noqa: E402
from jsss.render.surface_maps import blend_coefficients  # noqa: E402
from measure.exr import write_exr  # noqa: E402

ROOT = os.path.join(os.path.dirname(__file__), "..")
DOCS = os.path.join(ROOT, "docs", "benchmarks", "textured.md")


def _stripes(left, right, shape):
    u = (np.arange(shape[1]) + 0.5) / shape[1]
    values = np.empty(shape + (3,))
    values[:, u < 0.5], values[:, u >= 0.5] = left, right
    return values


def _frame_times(folder: str, pixels: int, texels: int, repeats: int):
    with open(os.path.join(ROOT, "examples", "marble_sphere.toml"), "rb") as f:
        data = tomllib.load(f)
    data["camera"]["resolution"] = [pixels, pixels]
    data["render"]["texture_size"] = texels
    rng = np.random.default_rng(0)
    maps = {
        "none": None,
        f"colour map {texels}^2": {"albedo": (rng.uniform(0.2, 1.0, (texels, texels, 3)), "c_same.exr")},
        f"colour map {2 * texels}^2": {"albedo": (rng.uniform(0.2, 1.0, (2 * texels, 2 * texels, 3)), "c_double.exr")},
        "colour map 300 x 200": {"albedo": (rng.uniform(0.2, 1.0, (200, 300, 3)), "c_odd.exr")},
        "sigma_a checker (2 media)": {"sigma_a": (_stripes([0.0021, 0.0041, 0.0071], [0.05, 0.1, 0.2], (256, 256)),
                                                  "sa_checker.exr")},
        "sigma_a gradient (10x)": {"sigma_a": (0.0021 * 10 ** np.linspace(0, 1, 256)[None, :, None]
                                               * np.ones((256, 1, 3)), "sa_gradient.exr")},
    }
    rows, plain = [], None
    for label, entry in maps.items():
        scene_data = dict(data, material=dict(data["material"]))
        if entry is not None:
            key, (values, name) = next(iter(entry.items()))
            write_exr(os.path.join(folder, name), values[::-1])
            scene_data["material"]["maps"] = {key: name}
        scene = parse_scene(scene_data, source=label, base_dir=folder)
        plan = plan_scene(scene, method=Method.TEXTURE_SPACE)
        params = render_params(scene, plan, dtype=jnp.float32)
        prepared = plan.method_config.prepare(scene, plan, params)
        frame = jax.jit(lambda p, prepared=prepared, plan=plan: plan.method_config.radiance(p, prepared))
        seconds = median_seconds(lambda frame=frame, params=params: jax.block_until_ready(frame(params)), repeats=repeats)
        plain = seconds if plain is None else plain
        basis = "" if plan.basis is None else f"{len(plan.basis.scale_nodes)} x {len(plan.basis.shape_nodes)}"
        rows.append((label, basis, plan.texture_size, 1000 * seconds, seconds / plain))
    return rows


def _blending(targets, points: int):
    t = np.linspace(0, 1, 128)[None, :, None] * np.ones((4, 1, 3))
    sigma_a = 0.002 * 100**t
    sigma_s = np.full_like(sigma_a, 1.5)
    material = parse_scene({"geometry": {"shape": "sphere"}, "material": {"name": "marble"},
                            "lights": [{"type": "directional", "direction": [0, 0, -1]}],
                            "camera": {"position": [0, -100, 0]}}, source="gradient").material
    eta = np.asarray(material.eta)
    rng = np.random.default_rng(5)
    test = Medium(0.002 * 100 ** rng.uniform(0, 1, (points, 3)), np.full((points, 3), 1.5), eta)
    rows = []
    for target in targets:
        basis = choose_basis(material, sigma_a, sigma_s, target)
        coefficients = blend_coefficients(basis.scale_nodes, basis.shape_nodes, test.sigma_a, test.sigma_s_prime,
                                          xp=np)
        weights = np.einsum("pkc,knc->pnc", coefficients, basis.weights)
        r = np.geomspace(np.sqrt(basis.variances.min()) / 30, np.sqrt(basis.variances.max()) * 8, 2000)
        gaussians = np.exp(-r[:, None] ** 2 / (2 * basis.variances)) / (2 * np.pi * basis.variances)
        errors = []
        for p in range(points):
            exact = np.asarray(dipole.profile(Medium(test.sigma_a[p], test.sigma_s_prime[p], eta), r))
            residual = exact - gaussians @ weights[p]
            errors.append(np.sqrt(np.trapezoid(r[:, None] * residual**2, r, axis=0)
                                  / np.trapezoid(r[:, None] * exact**2, r, axis=0)))
        errors = np.asarray(errors)
        rows.append((target, f"{len(basis.scale_nodes)} x {len(basis.shape_nodes)}", len(basis.variances),
                     100 * basis.error, 100 * basis.fit_error, 100 * np.median(errors), 100 * errors.max()))
    return rows


def _walk_table(folder: str, photons: int):
    """The colour-map walk table: the scene, map and bins are the truth test's own
    (tests/jsss/render/test_colour_map_truth.py), here for every rule and more photons."""
    sys.path.insert(0, ROOT)
    from pathlib import Path

    from tests.jsss.render.test_colour_map_truth import BIN, ETA, LEFT, RIGHT, SIGMA_A, SIGMA_S, WIDTH, \
        _texture_space_bins
    from tests.truth.colour_layer_walk import step_exitance

    centres, truth, stderr = step_exitance(SIGMA_A, SIGMA_S, ETA, LEFT, RIGHT, photons=photons,
                                           half_width=WIDTH / 2, bin_width=BIN, seed=11)
    rows = []
    for rule in ("pre-post", "pre", "post"):
        model = _texture_space_bins(Path(folder), rule, centres)
        error = model / truth - 1
        worst = np.abs(error).argmax(0)
        rows.append((rule, [(100 * error[w, c], 100 * stderr[w, c] / truth[w, c], centres[w]) for c, w in
                            enumerate(worst)], 100 * (model.sum(0) / truth.sum(0) - 1)))
    return rows


def _image(path: str):
    """The textured examples side by side, through the public API with their own plans."""
    import dataclasses

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jsss.render import load_scene, render
    from jsss.render.shading import tone_map

    veins = load_scene(os.path.join(ROOT, "examples", "marble_veins.toml"))
    panels = []
    exposure = None
    for rule in ("pre-post", "pre", "post"):
        maps = dataclasses.replace(veins.material.maps, texturing=rule)
        scene = dataclasses.replace(veins, material=dataclasses.replace(veins.material, maps=maps))
        result = render(scene)
        image, exposure = tone_map(result.radiance, exposure=exposure)
        panels.append((image, f"marble_veins, texturing = \"{rule}\"\n{result.plan.method}"))
    checker = render(load_scene(os.path.join(ROOT, "examples", "checker_plane.toml")))
    panels.append((tone_map(checker.radiance)[0], f"checker_plane: sigma_a maps\n{checker.plan.method}, "
                                                  f"{checker.plan.basis.size} basis profiles"))
    figure, axes = plt.subplots(1, len(panels), figsize=(4 * len(panels), 3.6))
    for axis, (image, title) in zip(axes, panels):
        axis.imshow(image)
        axis.set_title(title, fontsize=9)
        axis.axis("off")
    figure.suptitle(f"jsss textured materials ({datetime.date.today()}, jsss-render's own plans; "
                    "truth: docs/benchmarks/textured_truth.md)", fontsize=9)
    figure.tight_layout(rect=(0, 0, 1, 0.92))
    figure.savefig(path, dpi=100)
    print(f"wrote {path}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="256^2 pixels and texels, 3 repeats")
    parser.add_argument("--write", action="store_true", help=f"write the tables to {os.path.relpath(DOCS, ROOT)}")
    parser.add_argument("--image", metavar="PNG", help="render the picture of the textured examples in docs/guides/rendering.md")
    args = parser.parse_args(argv)
    if args.image:
        _image(args.image)
        return
    pixels = texels = 256 if args.quick else 512
    with tempfile.TemporaryDirectory() as folder:
        times = _frame_times(folder, pixels, texels, 3 if args.quick else 9)
        walk = _walk_table(folder, 200_000 if args.quick else 2_000_000)
    blending = _blending((0.2, 0.05, 0.02, 0.01), 16 if args.quick else 64)
    load = os.getloadavg()[0]
    lines = [f"## Frame time with maps (`benchmarks/textured.py{' --quick' if args.quick else ''}`, "
             f"{datetime.date.today()}, {os.cpu_count()}-core CPU, float32, load {load:.1f})", "",
             f"The marble sphere example at {pixels} x {pixels} pixels, texture space; median of the compiled frame; "
             "ratio to the frame without maps in the same run.", "",
             "| maps | basis | texture | ms | ratio |", "|---|---|---:|---:|---:|"]
    lines += [f"| {label} | {basis or '-'} | {size}^2 | {ms:.1f} | {ratio:.2f} |" for label, basis, size, ms, ratio in times]
    lines += ["", f"## Blending basis profiles (`benchmarks/textured.py`, {datetime.date.today()})", "",
              "A sigma_a map from 0.002 to 0.2 1/mm (sigma_s' = 1.5 1/mm, marble's eta): the basis each target "
              "chooses, its own estimate (at the map's texels farthest from the nodes, against each one's fit), "
              f"and the error of the blended profile at {16 if args.quick else 64} "
              "random media of the range against their exact dipole profile (truth: the closed form; relative RMS, "
              "d'Eon's eq. 10, worst channel), which includes the Gaussians' own fit error.", "",
              "| target | nodes | Gaussians | blend estimate % | worst node fit % | measured median % | measured max % |",
              "|---:|---|---:|---:|---:|---:|---:|"]
    lines += [f"| {t:g} | {nodes} | {n} | {est:.2f} | {fit:.2f} | {med:.2f} | {mx:.2f} |"
              for t, nodes, n, est, fit, med, mx in blending]
    lines += ["", f"## Colour map against an independent walk (`benchmarks/textured.py`, {datetime.date.today()})", "",
              "Truth: tests/truth/colour_layer_walk.py (NumPy, shares no code with jsss), "
              f"{'2e5' if args.quick else '2e6'} photons per channel: a half-space (sigma_a 0.02/0.05/0.1, "
              "sigma_s 1.0/1.2/1.5 1/mm, g = 0, eta 1.3) under a strip beam 30 mm wide at normal incidence, "
              "a step colour map (0.9/0.6/0.25 | 0.2/0.8/1.0) at x = 0, sqrt(c) where a photon enters and where "
              "it leaves. jsss: the same scene, texture space, profile = \"transport\", its texel exitance in 1 mm "
              "bins along the middle of a plane 60 mm deep. Worst bin per channel (its walk noise, its x), and "
              "the sums.", "",
              "| texturing | R worst % (noise, x mm) | G | B | sums R / G / B % |", "|---|---|---|---|---|"]
    for rule, worst, sums in walk:
        cells = " | ".join(f"{e:+.1f} ({n:.1f}, {x:+.1f})" for e, n, x in worst)
        lines.append(f"| {rule} | {cells} | {' / '.join(f'{v:+.2f}' for v in sums)} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.write:
        os.makedirs(os.path.dirname(DOCS), exist_ok=True)
        with open(DOCS, "w") as f:
            f.write("# Textured materials: cost and blending error\n\nWritten by `python benchmarks/textured.py "
                    "--write`.\n\n" + text)


if __name__ == "__main__":
    main()
