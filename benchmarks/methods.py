"""Accuracy vs time of the four rendering methods on the calibration scenes; the planner's calibration.

For each calibration scene, seen from its own camera and from 4x and 12x as far (and, for the
three original scenes, half as far; same field of view: the profile spans more or fewer
pixels), every method and knob renders a diffuse frame that is compared with a brute-force
reference (``jsss.render.reference``): relative RMS error over the object's pixels,
milliseconds per frame (median of 9 after compiling), one-time preparation, and the speed-up
over the reference computed in the same run.

**The truth.** The reference integrates over the whole surface the transport profile
(:mod:`jsss.transport`, exact to radiative transfer within the tables' noise) wherever the
tables cover the medium (``reference_radiance(profile_model="transport")``), and a layered
stack's own profile. The methods render with the profile the scene's ``profile = "auto"``
picks (:mod:`jsss.render.profile_choice`: the transport tables for ketchup, the dipole for
marble at 5 %), so a row's error includes the Gaussian fit of the transport profile (its
1/r core, which a few Gaussians follow poorly) or, where auto keeps the dipole, the
dipole's distance from transport. The reference applies the oblique-incidence and
deposit-depth passes where the planner would; it lacks the single-scattering pass's angular
law (every order leaves as diffuse light, and the frames render with that pass off too)
and any correction of the planar profile for curvature or thickness.
Its distance from a path tracer (index-matched Mitsuba frames) is in
docs/benchmarks/methods.md.

**The scenes** (examples/ and benchmarks/calibration_scenes/, each TOML says its kind): every
kind of frame the planner's features tell apart has at least two scenes, so that a
held-out scene (``leave_one_scene_out``) can find alike frames among the others:

===================  ======  =========  ======  ===========  ==============
scene                surface lighting   shape   albedo       profile (auto)
===================  ======  =========  ======  ===========  ==============
marble_sphere        closed  front      curved  high         dipole
ketchup_plane        open    front      flat    low          transport
skin_backlit         closed  back       curved  layered      stack
marble_plane         open    front      flat    high         dipole
ketchup_sphere       closed  front      curved  low          transport
marble_backlit       closed  back       curved  high         dipole
skin_studio          closed  front*     curved  layered      stack
ketchup_grazing      open    back       flat    low          transport
===================  ======  =========  ======  ===========  ==============

(* environment light, 40 % of it from behind.) The radius of ketchup_sphere (32 mm) puts its
curvature at marble_sphere's, and marble_backlit shares skin_backlit's lighting and framing:
pairs that differ in the material only. ketchup_grazing is the one open back-lit scene (a
plane lit at a grazing slant from behind): held out, its frames fall back to the worst of
every frame, but a new frame of that kind finds it. The five added scenes are rendered at
1x, 4x and 12x (not 0.5x, the costliest reference), and the reference takes 150k points (300k
until 2026-12-04; its own noise measured 0.4-1.3 %): ``--calibrate`` took 11-19 minutes on a
2-core machine shared with other jobs.

    python benchmarks/methods.py [--quick] [--calibrate] [--figure docs/methods.png]
    python benchmarks/methods.py --validate-only

``--calibrate`` writes the rows to jsss/data/calibration.json, the table the planner
reads; ``--figure`` saves the near frames side by side with their error maps. Every run
ends with the leave-one-scene-out check of the table in use (each scene's frames predicted
from the other scenes' rows: the predicted and measured error of what the planner would
choose, and whether the prediction found alike frames or fell back to the worst of its
kind); ``--validate-only`` prints just that, without rendering.
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

ROOT = Path(__file__).resolve().parents[1]
DISTANCES = (0.5, 1.0, 4.0, 12.0)
NEW_DISTANCES = (1.0, 4.0, 12.0)  # the added scenes skip 0.5x, the costliest reference (most pixels)
# (name, TOML, camera distances): see the module docstring for what kind of frame each covers.
SCENES = (("marble_sphere", ROOT / "examples/marble_sphere.toml", DISTANCES),
          ("ketchup_plane", ROOT / "examples/ketchup_plane.toml", DISTANCES),
          ("skin_backlit", ROOT / "examples/skin_backlit.toml", DISTANCES),
          ("marble_plane", ROOT / "benchmarks/calibration_scenes/marble_plane.toml", NEW_DISTANCES),
          ("ketchup_sphere", ROOT / "benchmarks/calibration_scenes/ketchup_sphere.toml", NEW_DISTANCES),
          ("marble_backlit", ROOT / "benchmarks/calibration_scenes/marble_backlit.toml", NEW_DISTANCES),
          ("skin_studio", ROOT / "examples/skin_studio.toml", NEW_DISTANCES),
          ("ketchup_grazing", ROOT / "benchmarks/calibration_scenes/ketchup_grazing.toml", NEW_DISTANCES))
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
                        "(default 96 x 72, 150k)")
    parser.add_argument("--calibrate", action="store_true", help="write jsss/data/calibration.json")
    parser.add_argument("--figure", type=Path, default=None, help="save the near frames and error maps")
    parser.add_argument("--validate-only", action="store_true", help="only the leave-one-scene-out check of the table")
    args = parser.parse_args()
    if args.validate_only:
        validate()
        return 0
    width, height, points = (64, 48, 100_000) if args.quick else (96, 72, 150_000)
    stamp = f"{time.strftime('%Y-%m-%d')}, {platform.machine()} CPU x{jax.local_device_count()} " \
            f"({jax.devices()[0].platform}), {width}x{height}, {points} reference points"
    print(f"# benchmarks/methods.py, {stamp}")
    print("| scene | distance | blur px | method | knob | error | ms/frame | own prep ms | all prep ms | "
          "x faster than reference |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    rows, near = [], []
    started = time.perf_counter()
    for name, path, distances in SCENES:
        base = load_scene(path)
        print(f"<!-- {name}: profile {base.material.profile_model}{' (layered)' if base.material.layers else ''}, "
              f"{time.perf_counter() - started:.0f} s into the run -->", flush=True)
        for factor in distances:
            scene = scene_at_distance(base, factor, width=width, height=height)
            t0 = time.perf_counter()
            reference = reference_radiance(scene, samples=points, profile_model="transport")
            reference_ms = 1000 * (time.perf_counter() - t0)
            # 9 repeats: a median of 3 read Lambert's 0.2 ms frame as 1-8 ms on a shared machine.
            _, frames = compare_methods(scene, name, reference=reference, repeats=9)
            for f in frames:
                r = f.row
                knob = r.knob + (f" ({f.gaussians} Gaussians)" if f.gaussians else "")
                print(f"| {name} | {factor:g}x | {r.blur_pixels:.3g} | {r.method} | {knob} | {100 * r.error:.2f} % | "
                      f"{r.ms:.3g} | {r.prep_ms:.0f} | {f.prep_ms:.0f} | {reference_ms / max(r.ms, 1e-3):.0f} |", flush=True)
                rows.append(r)
            print(f"| {name} | {factor:g}x | | reference ({reference.profile}) | {points} points | "
                  f"noise {100 * reference.noise:.2f} % | {reference_ms:.0f} | | | 1 |", flush=True)
            if factor == 1.0 and args.figure:
                near.append((name, reference, frames))
    print(f"\nrendering and references took {(time.perf_counter() - started) / 60:.1f} min")
    if args.calibrate:
        print(f"calibration: {save_calibration(rows, measured=stamp)}")
    if args.figure:
        figure(near, args.figure)
    print("\nplanner's choice for the example scenes (their own size), from the table in use:")
    print("| scene | target | method | knob | predicted error | predicted ms |")
    print("|---|---|---|---|---|---|")
    for name, path, _ in SCENES:
        scene = load_scene(path)
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
    print("| held-out scene | reach in frame | features | target | chosen | predicted | measured | meets | from |")
    print("|---|---|---|---|---|---|---|---|---|")
    misses, total, gaps, alike = 0, 0, [], 0
    for target in targets:
        for frame in leave_one_scene_out(rows, target):
            f = frame["features"]
            method, knob = frame["chosen"]
            total += 1
            misses += not frame["meets"]
            alike += frame["alike"]
            basis = frame["basis"].split(": ", 1)
            source = f"alike: {basis[1]}" if frame["alike"] else "fallback: worst of its kind"
            gaps.extend(abs(p - m) for p, m in frame["errors"].values())
            print(f"| {frame['scene']} | {f.blur_frame:.3g} | {f.describe().rsplit(', reach', 1)[0]} | "
                  f"{100 * target:g} % | {method} {knob} | {100 * frame['predicted']:.2f} % | "
                  f"{100 * frame['measured']:.2f} % | {'yes' if frame['meets'] else 'NO'} | {source} |")
    print(f"\n{total - misses} of {total} held-out choices met their target; {alike} of {total} predictions rest on "
          f"alike frames, {total - alike} fall back to the worst frame of their kind; median |predicted - measured| "
          f"over every method and knob: {100 * np.median(gaps):.2f} points")


if __name__ == "__main__":
    sys.exit(main())
