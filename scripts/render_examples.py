"""Render the three example scenes as the README shows them (docs/examples.png).

    python scripts/render_examples.py [--out docs/examples.png] [--size 320 240]

Each scene is rendered with the planner's own plan (what ``jsss-render scene.toml`` does) and
shown at a physical exposure where one exists: 1 is the brightest radiance a white Lambertian
object of the same shape would have under the same lights (``white_lambertian_radiance``), so
a diffuse frame brighter than that white would clip (a sign of light created). A backlit scene
has almost no white radiance toward the camera; its exposure is then the frame's own 99th
percentile, and the title says so.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)  # the planner fits profiles in float64; frames render in float32

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from jsss.render import load_scene, plan_scene, render  # noqa: E402
from jsss.render.reference import white_lambertian_radiance  # noqa: E402
from jsss.render.shading import tone_map  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENES = ("marble_sphere", "skin_backlit", "ketchup_plane")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "examples.png")
    parser.add_argument("--size", type=int, nargs=2, default=(320, 240))
    args = parser.parse_args(argv)
    fig, axes = plt.subplots(1, len(SCENES), figsize=(3.2 * len(SCENES), 2.7))
    for ax, name in zip(axes, SCENES):
        scene = load_scene(ROOT / "examples" / f"{name}.toml")
        scene = dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, width=args.size[0],
                                                                       height=args.size[1]))
        t0 = time.perf_counter()
        plan = plan_scene(scene)
        radiance = np.asarray(render(scene, plan).radiance)
        white = white_lambertian_radiance(scene).max()
        own = np.percentile(radiance.max(-1)[radiance.max(-1) > 0], 99)
        physical = own <= white
        ax.imshow(tone_map(radiance, exposure=1.0 / (white if physical else own))[0])
        ax.set_title(f"{name}: {plan.method}\n" + ("white Lambertian = 1" if physical else "own 99th percentile = 1"),
                     fontsize=8)
        ax.axis("off")
        print(f"{name}: {plan.method} ({plan.knob}), {time.perf_counter() - t0:.1f} s, brightest pixel "
              f"{radiance.max() / white:.3f} of the white Lambertian's", flush=True)
    fig.suptitle(f"the planner's choice at each scene's accuracy target ({time.strftime('%Y-%m-%d')})", fontsize=8)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=100)
    print(f"written: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
