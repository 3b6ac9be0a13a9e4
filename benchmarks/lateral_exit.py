"""Where a default render misses the path tracer per pixel: the plane's edges, and the lateral
steps of the light's first leg (along the light) and last leg (toward the camera).

    pip install -e '.[truth]' && python benchmarks/lateral_exit.py [--scene ketchup_plane] [--black-walls]
        [--cache DIR]

The truth is Mitsuba 3's index-matched frame of the example scene (``transport_truth.py``'s
``index_matched_truth``: the plane is the top of a 30 mm deep box, eta 1, 80 x 60, 4 x 512 spp
per channel; ``--black-walls``: curtains keep a low light off the box's walls). jsss renders the
scene as a user gets it (the planner's method and passes, specular off), and again with the
pass "first leg", "last leg" or both off. Printed per channel: the relative RMS error over the
pixels that lie more than ``d`` mm inside the plane's edges (the path tracer's noise taken out)
and the ratio of sums.

**The last leg** (:mod:`jsss.render.last_leg`; :mod:`jsss.diffusion.lateral_step` derives the
step and tests it against a random walk): light leaving toward the camera was last scattered
under a point farther from the camera. **The first leg** (:mod:`jsss.render.first_leg`): light
entering slanted is first scattered farther along its way.
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import benchmarks.transport_truth as truth_tools  # enables float64
from jsss.render import load_scene
from jsss.render.image_space import camera_buffers

EDGE_MARGINS = (0, 3, 5, 10)  # mm inside the plane's edges


def errors(ours, truth, chunks, keep):
    """Relative RMS per channel over ``keep`` with the path tracer's noise taken out, and the sums' ratio."""
    noise = np.var(chunks, axis=0, ddof=1)[keep].mean(0) / len(chunks)
    mse = ((ours - truth)[keep] ** 2).mean(0) - noise
    power = (truth[keep] ** 2).mean(0) - noise
    return np.sqrt(np.maximum(mse, 0) / power), ours[keep].sum(0) / truth[keep].sum(0)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="ketchup_plane", help="an example or calibration scene with a plane")
    parser.add_argument("--black-walls", action="store_true", help="black curtains around the path tracer's box walls")
    parser.add_argument("--spp", type=int, default=512)
    parser.add_argument("--chunks", type=int, default=4)
    parser.add_argument("--cache", help="folder keeping the path tracer's frames between runs")
    args = parser.parse_args(argv)

    truth_tools.BLACK_WALLS = args.black_walls
    scene = load_scene(truth_tools._scene_file(args.scene))
    scene = truth_tools.index_matched(truth_tools._with_resolution(scene, 80, 60))
    if np.ptp(scene.mesh.vertices[:, 2]) > 1e-9:
        raise SystemExit(f"{args.scene}: this benchmark needs a plane (its edges are measured in mm)")
    walls = "_black_walls" if args.black_walls else ""
    cached = args.cache and os.path.join(args.cache, f"{args.scene}_{args.spp}x{args.chunks}_index_matched{walls}.npy")
    if cached and os.path.exists(cached):
        chunks = np.load(cached)
    else:
        mi = truth_tools._mitsuba("scalar_rgb")
        with tempfile.TemporaryDirectory() as folder:
            _, chunks = truth_tools.index_matched_truth(mi, scene, truth_tools._mesh_file(scene, folder), args.spp,
                                                        args.chunks)
        if cached:
            os.makedirs(args.cache, exist_ok=True)
            np.save(cached, chunks)
    truth = chunks.mean(0)
    buffers = camera_buffers(scene.mesh, scene.camera)
    inner = truth_tools._interior(buffers.mask)
    half = np.ptp(scene.mesh.vertices[:, :2], axis=0) / 2
    centre = scene.mesh.vertices[:, :2].mean(0)
    inside = np.min(half - np.abs(buffers.position[..., :2] - centre), axis=-1)  # mm to the nearest edge

    ours, passes, plan = truth_tools._ours(scene, None)
    ours = np.asarray(ours)
    frames = {"as rendered": ours}
    for off in (("first leg",), ("last leg",), ("first leg", "last leg")):
        frames[" and ".join(off) + " off"] = np.asarray(truth_tools._ours(scene, None, off=off)[0])
    walls = ", box walls behind black curtains" if args.black_walls else ""
    print(f"# {args.scene}, index-matched{walls}, 80 x 60, Mitsuba {args.chunks} x {args.spp} spp; jsss default: "
          f"{plan.method} {plan.knob} ({passes}); {datetime.date.today()}\n")
    print("| jsss frame | pixels | inside the edges | RMS R / G / B | sums R / G / B |")
    print("|---|---:|---|---|---|")
    for name, frame in frames.items():
        for margin in EDGE_MARGINS:
            keep = inner & (inside > margin)
            rms, sums = errors(frame, truth, chunks, keep)
            print(f"| {name} | {keep.sum()} | > {margin} mm | " + " / ".join(f"{100 * v:.1f} %" for v in rms)
                  + " | " + " / ".join(f"{v:.3f}" for v in sums) + " |")


if __name__ == "__main__":
    main()
