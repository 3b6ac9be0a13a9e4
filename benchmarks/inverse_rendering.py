"""Materials recovered from path-traced photos of the example scenes: inverse rendering against transport truth.

    pip install -e '.[truth]' && python benchmarks/inverse_rendering.py [--quick]

The "photo" is Mitsuba 3's volumetric path tracing of the scene (the subsurface light of
`transport_truth.py`: medium frame minus absorbing-interior frame, smooth-interface limit),
so nothing in it comes from jsss's profiles or shading. Each pixel's noise is known from
the path tracer's independent chunks; 1 % Gaussian noise is added on top (the issue's
"photo noise"). jsss then fits sigma_a and sigma_s' per channel and an unknown exposure gain
with `fitting.fit_render` (specular off on both sides: the photo holds subsurface light
only), once with the dipole and once with the transport profile.

Printed per scene and profile model: total diffuse reflectance R_d and mean free path
1/sigma_t' per channel, fitted / true - 1, with the stated standard error, the number of
solver steps and seconds per fit (after compilation). The path-traced frames are cached in
``--cache`` (default ``$TMPDIR/jsss_inverse_truth``) so a second run only fits.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import transport_truth as tt  # noqa: E402 -- also enables float64

import jax.numpy as jnp  # noqa: E402

from jsss import dipole, transport  # noqa: E402
from jsss.render import load_scene  # noqa: E402


def path_traced(scene, name, *, spp, chunks, cache, variant="auto"):
    """Subsurface radiance (H, W, 3) of ``scene`` and its per-pixel standard error, from the cache or Mitsuba."""
    cam = scene.camera
    path = os.path.join(cache, f"{name}_{cam.width}x{cam.height}_{chunks}x{spp}.npz")
    if os.path.exists(path):
        data = np.load(path)
        return data["truth"], data["stderr"]
    mi = tt._mitsuba(variant)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        ply = tt._mesh_file(scene, folder)
        truth, per_chunk = tt.subsurface_truth(mi, scene, ply, spp, chunks)
    stderr = np.std(per_chunk, axis=0, ddof=1) / np.sqrt(chunks)
    os.makedirs(cache, exist_ok=True)
    np.savez(path, truth=truth, stderr=stderr)
    print(f"{name}: path traced in {time.perf_counter() - t0:.0f} s ({chunks} x {spp} spp, {mi.variant()})")
    return truth, stderr


def true_artist_parameters(material):
    """R_d (3,) of the material under its profile model (the transport tables: exact to
    transport) and the mean free path 1 / sigma_t' [mm]."""
    medium = material.medium
    rd = transport.total_reflectance(medium, g=0.0)
    mfp = 1.0 / (np.asarray(medium.sigma_a) + np.asarray(medium.sigma_s_prime))
    return np.asarray(rd), mfp


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="40 x 30 pixels, 2 chunks x 128 spp")
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--chunks", type=int, default=4)
    parser.add_argument("--size", type=int, nargs=2, default=(80, 60), metavar=("W", "H"))
    parser.add_argument("--scenes", nargs="*", default=["marble_sphere", "ketchup_plane"])
    parser.add_argument("--profiles", nargs="*", default=["dipole", "transport"], choices=["dipole", "transport"])
    parser.add_argument("--noise", type=float, default=0.01, help="relative photo noise added to the path-traced frame")
    parser.add_argument("--cache", default=os.path.join(tempfile.gettempdir(), "jsss_inverse_truth"))
    parser.add_argument("--truth-only", action="store_true", help="path trace (fill the cache) and stop")
    args = parser.parse_args(argv)
    width, height = (40, 30) if args.quick else args.size
    spp, chunks = (128, 2) if args.quick else (args.spp, args.chunks)
    print(f"inverse rendering against path-traced photos, {width}x{height}, {chunks} x {spp} spp, "
          f"+{100 * args.noise:.0f} % noise, {time.strftime('%Y-%m-%d')}")
    rng = np.random.default_rng(0)
    for name in args.scenes:
        scene = tt._with_resolution(load_scene(os.path.join(tt.EXAMPLES, f"{name}.toml")), width, height)
        truth, stderr = path_traced(scene, name, spp=spp, chunks=chunks, cache=args.cache)
        if args.truth_only:
            continue
        photo = truth * (1 + args.noise * rng.standard_normal(truth.shape))
        sigma = np.sqrt(stderr**2 + (args.noise * np.abs(truth)) ** 2)
        rd_true, mfp_true = true_artist_parameters(scene.material)
        from fitting import fit_render

        print(f"\n## {name}: true R_d " + " / ".join(f"{x:.4f}" for x in rd_true)
              + ", mean free path " + " / ".join(f"{x:.3f}" for x in mfp_true) + " mm")
        print("| profile | R_d error R / G / B (stated) | mean free path error R / G / B (stated) | steps | s per fit |")
        print("|---|---|---|---:|---:|")
        for profile in args.profiles:
            result = fit_render(scene, photo, sigma=sigma, profile_model=profile, specular=False)
            t0 = time.perf_counter()
            result = fit_render(scene, photo, sigma=sigma, profile_model=profile, specular=False)
            seconds = time.perf_counter() - t0
            rd = result.reflectance / rd_true - 1
            mfp = result.mean_free_path / mfp_true - 1
            rd_err = result.reflectance_err / rd_true
            mfp_err = result.mean_free_path_err / mfp_true
            print(f"| {profile} | " + " / ".join(f"{100 * e:+.1f} % ({100 * s:.1f})" for e, s in zip(rd, rd_err))
                  + " | " + " / ".join(f"{100 * e:+.1f} % ({100 * s:.1f})" for e, s in zip(mfp, mfp_err))
                  + f" | {result.steps} | {seconds:.1f} |")
            for warning in result.warnings:
                print(f"  warning: {warning}")


if __name__ == "__main__":
    main()
