"""Where a default render misses the path tracer per pixel: the plane's edges, and the lateral
step of the light's last leg toward the camera (the pass "last leg").

    pip install -e '.[truth]' && python benchmarks/lateral_exit.py [--scene ketchup_plane] [--cache DIR]

The truth is Mitsuba 3's index-matched frame of the example scene (``transport_truth.py``'s
``index_matched_truth``: the plane is the top of a 30 mm deep box, eta 1, 80 x 60, 4 x 512 spp
per channel). jsss renders the scene as a user gets it (the planner's method and passes,
specular off), and again with the pass "last leg" off. Printed per channel: the relative RMS
error over the pixels that lie more than ``d`` mm inside the plane's edges (the path tracer's
noise taken out) and the ratio of sums.

**The last leg** (:mod:`jsss.render.last_leg`; :mod:`jsss.diffusion.lateral_step` derives the
step and tests it against a random walk): light leaving toward the camera was last scattered
under a point farther from the camera. **The first leg**, light entering slanted first
scattered farther from the light, is not a pass: the last row resamples the default frame
there (linear interpolation over the plane's pixels) to measure what it would change.
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
from jsss.diffusion.lateral_step import first_leg_step
from jsss.render import load_scene
from jsss.render.image_space import camera_buffers

EDGE_MARGINS = (0, 3, 5, 10)  # mm inside the plane's edges


def displaced(frame, buffers, scene):
    """``frame`` read where the light entered: each pixel's plane position moved back along the
    mean first leg (:func:`jsss.diffusion.lateral_step.first_leg_step`)."""
    from scipy.interpolate import LinearNDInterpolator

    where = buffers.position

    def unit(v):
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    to_eye = unit(np.asarray(scene.camera.position, float) - where)
    to_light = unit(np.asarray(scene.lights[0].position, float) - where)
    cos_exit, cos_light = np.clip(to_eye[..., 2], 0.0, 1.0), np.clip(to_light[..., 2], 0.0, 1.0)
    first = np.asarray(first_leg_step(scene.material.medium, cos_light, cos_exit))   # (H, W, C) mm
    away_from_light = -to_light[..., :2] / np.maximum(np.linalg.norm(to_light[..., :2], axis=-1, keepdims=True), 1e-12)
    plane = where[..., :2]
    out = frame.copy()
    mask = buffers.mask
    for c in range(frame.shape[-1]):
        values = LinearNDInterpolator(plane[mask], frame[mask][:, c])(plane - first[..., c, None] * away_from_light)
        out[..., c] = np.where(np.isfinite(values), values, frame[..., c])
    return out


def errors(ours, truth, chunks, keep):
    """Relative RMS per channel over ``keep`` with the path tracer's noise taken out, and the sums' ratio."""
    noise = np.var(chunks, axis=0, ddof=1)[keep].mean(0) / len(chunks)
    mse = ((ours - truth)[keep] ** 2).mean(0) - noise
    power = (truth[keep] ** 2).mean(0) - noise
    return np.sqrt(np.maximum(mse, 0) / power), ours[keep].sum(0) / truth[keep].sum(0)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="ketchup_plane", help="an example scene with a plane and one point light")
    parser.add_argument("--spp", type=int, default=512)
    parser.add_argument("--chunks", type=int, default=4)
    parser.add_argument("--cache", help="folder keeping the path tracer's frames between runs")
    args = parser.parse_args(argv)

    scene = load_scene(os.path.join(truth_tools.EXAMPLES, f"{args.scene}.toml"))
    scene = truth_tools.index_matched(truth_tools._with_resolution(scene, 80, 60))
    if np.ptp(scene.mesh.vertices[:, 2]) > 1e-9 or len(scene.lights) != 1 or scene.lights[0].kind != "point":
        raise SystemExit(f"{args.scene}: this benchmark needs a plane under one point light")
    cached = args.cache and os.path.join(args.cache, f"{args.scene}_{args.spp}x{args.chunks}_index_matched.npy")
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
    without = np.asarray(truth_tools._ours(scene, None, off=("last leg",))[0])
    frames = {"as rendered": ours, "last leg off": without,
              "as rendered, resampled at the first leg": displaced(ours, buffers, scene)}
    print(f"# {args.scene}, index-matched, 80 x 60, Mitsuba {args.chunks} x {args.spp} spp; jsss default: "
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
