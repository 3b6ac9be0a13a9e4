"""Accuracy vs time of the four rendering methods on the example scenes; the planner's calibration.

For each example scene (examples/*.toml), seen from its own camera, from half as far and from
4x and 12x as far (same field of view: the profile spans more or fewer pixels), every method
and knob renders a diffuse frame that is compared with a brute-force reference (the exact
profile integrated over the whole surface, ``jsss.render.reference``): relative RMS error
over the object's pixels, milliseconds per frame (median of 3 after compiling), one-time
preparation, and the speed-up over the reference computed in the same run.

    python benchmarks/methods.py [--quick] [--calibrate] [--figure docs/methods.png]
    python benchmarks/methods.py --validate-only

``--calibrate`` writes the rows to jsss/data/calibration.json, the table the planner
reads; ``--figure`` saves the near frames side by side with their error maps. Every run
ends with the leave-one-scene-out check of the table in use (each scene's frames predicted
from the other scenes' rows: the predicted and measured error of what the planner would
choose); ``--validate-only`` prints just that, without rendering.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

from jsss.render import Method, load_scene, plan_scene  # noqa: E402
from jsss.render.calibration import leave_one_scene_out, load_calibration, save_calibration  # noqa: E402
from jsss.render.comparison import compare_methods, scene_at_distance  # noqa: E402
from jsss.render.reference import reference_radiance  # noqa: E402
from jsss.render.shading import tone_map  # noqa: E402

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SCENES = ("marble_sphere", "ketchup_plane", "skin_backlit")
DISTANCES = (0.5, 1.0, 4.0, 12.0)
SHOWN = ((Method.LAMBERT, ""), (Method.NORMAL_FILTERING, "spectral"), (Method.IMAGE_SPACE, "32 spp"),
         (Method.TEXTURE_SPACE, "profile 5 %"))


def figure(near, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2 * len(near), 1 + len(SHOWN), figsize=(2.4 * (1 + len(SHOWN)), 3.6 * len(near)))
    for i, (name, reference, frames) in enumerate(near):
        image, exposure = tone_map(reference.radiance)
        scale = np.abs(reference.radiance).max()
        axes[2 * i, 0].imshow(image)
        axes[2 * i, 0].set_title(f"{name}\nreference", fontsize=8)
        axes[2 * i + 1, 0].axis("off")
        for j, (method, knob) in enumerate(SHOWN, start=1):
            frame = next(f for f in frames if (f.row.method, f.row.knob) == (method, knob))
            axes[2 * i, j].imshow(tone_map(frame.radiance, exposure=exposure)[0])
            axes[2 * i, j].set_title(f"{method} {knob}\n{100 * frame.row.error:.1f} %, {frame.row.ms:.3g} ms", fontsize=8)
            error = np.abs(frame.radiance - reference.radiance).max(-1) / scale
            axes[2 * i + 1, j].imshow(error, cmap="magma", vmin=0, vmax=0.2)
            axes[2 * i + 1, j].set_title("|error| / max (0-20 %)", fontsize=7)
        for ax in axes[2 * i:2 * i + 2].ravel():
            ax.set_xticks([])
            ax.set_yticks([])
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"figure: {path}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="64 x 48 frames, 100k reference points "
                        "(default 96 x 72, 300k)")
    parser.add_argument("--calibrate", action="store_true", help="write jsss/data/calibration.json")
    parser.add_argument("--figure", type=Path, default=None, help="save the near frames and error maps")
    parser.add_argument("--validate-only", action="store_true", help="only the leave-one-scene-out check of the table")
    args = parser.parse_args()
    if args.validate_only:
        validate()
        return 0
    width, height, points = (64, 48, 100_000) if args.quick else (96, 72, 300_000)
    stamp = f"{time.strftime('%Y-%m-%d')}, {platform.machine()} CPU x{jax.local_device_count()} " \
            f"({jax.devices()[0].platform}), {width}x{height}, {points} reference points"
    print(f"# benchmarks/methods.py, {stamp}")
    print("| scene | distance | blur px | method | knob | error | ms/frame | own prep ms | all prep ms | "
          "x faster than reference |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    rows, near = [], []
    for name in SCENES:
        base = load_scene(EXAMPLES / f"{name}.toml")
        for factor in DISTANCES:
            scene = scene_at_distance(base, factor, width=width, height=height)
            t0 = time.perf_counter()
            reference = reference_radiance(scene, samples=points)
            reference_ms = 1000 * (time.perf_counter() - t0)
            _, frames = compare_methods(scene, name, reference=reference)
            for f in frames:
                r = f.row
                knob = r.knob + (f" ({f.gaussians} Gaussians)" if f.gaussians else "")
                print(f"| {name} | {factor:g}x | {r.blur_pixels:.3g} | {r.method} | {knob} | {100 * r.error:.2f} % | "
                      f"{r.ms:.3g} | {r.prep_ms:.0f} | {f.prep_ms:.0f} | {reference_ms / max(r.ms, 1e-3):.0f} |", flush=True)
                rows.append(r)
            print(f"| {name} | {factor:g}x | | reference | {points} points | noise {100 * reference.noise:.2f} % | "
                  f"{reference_ms:.0f} | | | 1 |", flush=True)
            if factor == 1.0 and args.figure:
                near.append((name, reference, frames))
    if args.calibrate:
        print(f"calibration: {save_calibration(rows, measured=stamp)}")
    if args.figure:
        figure(near, args.figure)
    print("\nplanner's choice for the example scenes (their own size), from the table in use:")
    print("| scene | target | method | knob | predicted error | predicted ms |")
    print("|---|---|---|---|---|---|")
    for name in SCENES:
        scene = load_scene(EXAMPLES / f"{name}.toml")
        for target in (0.2, 0.05, 0.02):
            plan = plan_scene(scene, accuracy=target)
            chosen = next(e for e in plan.estimates if (e.method, e.knob) == (plan.method, plan.knob))
            print(f"| {name} | {100 * target:g} % | {plan.method} | {chosen.knob} | {100 * chosen.error:.2f} % | "
                  f"{chosen.ms:.3g} |")
    validate()
    return 0


def validate(targets=(0.2, 0.05, 0.02)):
    """Leave one scene out: predict each scene's calibration frames from the other scenes."""
    rows = load_calibration()
    print("\nleave one scene out (each scene's frames predicted from the other scenes' rows; "
          "error of the method chosen, predicted beside measured):")
    print("| held-out scene | reach in frame | features | target | chosen | predicted | measured | meets |")
    print("|---|---|---|---|---|---|---|---|")
    misses, total, gaps = 0, 0, []
    for target in targets:
        for frame in leave_one_scene_out(rows, target):
            f = frame["features"]
            method, knob = frame["chosen"]
            total += 1
            misses += not frame["meets"]
            gaps.extend(abs(p - m) for p, m in frame["errors"].values())
            print(f"| {frame['scene']} | {f.blur_frame:.3g} | {f.describe().rsplit(', reach', 1)[0]} | "
                  f"{100 * target:g} % | {method} {knob} | {100 * frame['predicted']:.2f} % | "
                  f"{100 * frame['measured']:.2f} % | {'yes' if frame['meets'] else 'NO'} |")
    print(f"\n{total - misses} of {total} held-out choices met their target; median |predicted - measured| "
          f"over every method and knob: {100 * np.median(gaps):.2f} points")


if __name__ == "__main__":
    sys.exit(main())
