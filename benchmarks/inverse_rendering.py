"""Materials recovered from path-traced photos of the example scenes: inverse rendering against transport truth.

    pip install -e '.[truth]' && python benchmarks/inverse_rendering.py [--quick]

The "photo" is Mitsuba 3's volumetric path tracing of the scene, so nothing in it comes from
jsss's profiles or shading. By default the object is **index-matched** (eta set to 1 in the
photo and in the fit, a ``null`` boundary in Mitsuba): a path tracer's next-event estimation
then reaches the lights from every scattering vertex, and 4 x 256 spp give 2.4 % noise per
pixel at 320 x 240 (1.2 % in the 2 x 2 tiles fitted). Through the scenes' own dielectric
(``--interface dielectric``: rough dielectrics extrapolated to smooth, as in
`transport_truth.py`) a point or directional light is reached only where a path leaves the
surface, and the noise was 45-102 % per pixel at 1024 spp. Each pixel's noise is known from
the path tracer's independent chunks; ``--noise`` adds relative Gaussian noise on top (default
0: the photo's own noise is already at the issue's 1 % level once tiled).

jsss then fits sigma_a and sigma_s' per channel, with the exposure gain fitted or held at 1
(Mitsuba's frames are in jsss's units), with ``fitting.fit_render`` (specular off on both
sides: the photo holds subsurface light only), once with the dipole and once with the
transport profile. Printed per scene: R_d and mean free path 1/sigma_t' per channel, fitted /
true - 1 with the stated standard error (R_d of both from the transport tables), chi^2/dof,
solver steps and seconds per fit after compilation. The fit starts from 2x the true
absorption and 2/3 of the scattering. Path-traced frames are cached in ``--cache`` (default
``$TMPDIR/jsss_inverse_truth``), so a second run only fits.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import transport_truth as tt  # noqa: E402 -- also enables float64

import jax.numpy as jnp  # noqa: E402

from jsss import transport  # noqa: E402
from jsss.medium import Medium  # noqa: E402
from jsss.render import Method, Pass, load_scene, plan_scene, render  # noqa: E402


def path_traced(scene, name, *, spp, chunks, cache, interface="index-matched", variant="auto"):
    """Subsurface radiance (H, W, 3) of ``scene`` and its per-pixel standard error, from the cache or Mitsuba.

    ``interface`` "index-matched" renders the scene as given (its eta must be 1, see
    :func:`transport_truth.index_matched`); "dielectric" renders its Fresnel boundary by the
    rough-dielectric extrapolation of :func:`transport_truth.subsurface_truth`.
    """
    cam = scene.camera
    path = os.path.join(cache, f"{name}_{interface}_{cam.width}x{cam.height}_{chunks}x{spp}.npz")
    if os.path.exists(path):
        data = np.load(path)
        return data["truth"], data["stderr"]
    mi = tt._mitsuba(variant)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        ply = tt._mesh_file(scene, folder)
        if interface == "index-matched":
            truth, per_chunk = tt.index_matched_truth(mi, scene, ply, spp, chunks)
        else:
            truth, per_chunk = tt.subsurface_truth(mi, scene, ply, spp, chunks)
    stderr = np.std(per_chunk, axis=0, ddof=1) / np.sqrt(chunks)
    os.makedirs(cache, exist_ok=True)
    np.savez(path + ".part.npz", truth=truth, stderr=stderr)
    os.replace(path + ".part.npz", path)  # a killed run leaves no truncated cache entry
    print(f"{name}: path traced in {time.perf_counter() - t0:.0f} s ({chunks} x {spp} spp, {mi.variant()})")
    return truth, stderr


def noise_model(scene, truth, stderr, relative):
    """Each pixel's standard error: the path tracer's, as a smooth shot-noise law, plus ``relative``.

    Four chunks give each pixel's variance with 3 degrees of freedom, so a few pixels would
    claim almost no noise and dominate the fit; instead s^2 = a_c m(p) + (relative m(p))^2,
    with m the photo smoothed over 2 pixels on the object and a_c the median of the chunks'
    variance over m (per channel).
    """
    from scipy import ndimage

    from jsss.render import camera_buffers

    mask = camera_buffers(scene.mesh, scene.camera).mask.astype(float)
    smooth = np.stack([ndimage.gaussian_filter(truth[..., c] * mask, 2.0) for c in range(3)], -1)
    smooth = np.abs(smooth / np.maximum(ndimage.gaussian_filter(mask, 2.0), 1e-9)[..., None])
    inside = mask > 0
    a = np.median(stderr[inside] ** 2 / np.maximum(smooth[inside], 1e-300), axis=0)
    floor = 1e-3 * np.percentile(smooth[inside], 99, axis=0)
    smooth = np.maximum(smooth, floor)
    return np.sqrt(a * smooth + (relative * smooth) ** 2)


def true_artist_parameters(material):
    """R_d (3,) of the material under its profile model (the transport tables: exact to
    transport) and the mean free path 1 / sigma_t' [mm]."""
    medium = material.medium
    rd = transport.total_reflectance(medium, g=0.0)
    mfp = 1.0 / (np.asarray(medium.sigma_a) + np.asarray(medium.sigma_s_prime))
    return np.asarray(rd), mfp


def main(argv=None):
    from fitting import fit_render

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="80 x 60 pixels, 2 chunks x 64 spp")
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--chunks", type=int, default=4)
    parser.add_argument("--size", type=int, nargs=2, default=(320, 240), metavar=("W", "H"))
    parser.add_argument("--scenes", nargs="*", default=["marble_sphere", "ketchup_plane"])
    parser.add_argument("--profiles", nargs="*", default=["dipole", "transport"], choices=["dipole", "transport"])
    parser.add_argument("--noise", type=float, default=0.0,
                        help="relative photo noise added to the path-traced frame (on top of its own)")
    parser.add_argument("--cache", default=os.path.join(tempfile.gettempdir(), "jsss_inverse_truth"))
    parser.add_argument("--block", type=int, default=2,
                        help="fit path-traced photos summed over BLOCK^2 pixel tiles (their noise is heavy-tailed)")
    parser.add_argument("--variant", default="auto", choices=["auto", "llvm_ad_rgb", "scalar_rgb"],
                        help="Mitsuba variant (auto: LLVM with libLLVM 19, else scalar)")
    parser.add_argument("--truth-only", action="store_true", help="path trace (fill the cache) and stop")
    parser.add_argument("--interface", default="index-matched", choices=["index-matched", "dielectric"],
                        help="index-matched: eta set to 1 on both sides (the path tracer's noise is low); "
                             "dielectric: the scene's eta, extrapolated from rough dielectrics (noisy)")
    parser.add_argument("--rim-mm", type=float, default=0.0,
                        help="leave out pixels this close to an open surface's rim (Mitsuba's plane is a box whose "
                             "sides lose light, jsss's an open surface); default 0: on ketchup, 3-6 mm made chi2/dof "
                             "smaller and every estimate worse")
    parser.add_argument("--consistency", action="store_true",
                        help="also fit a jsss transport render (+1 %% noise) of the same size: "
                             "the fit's own consistency")
    args = parser.parse_args(argv)
    width, height = (80, 60) if args.quick else args.size
    spp, chunks = (64, 2) if args.quick else (args.spp, args.chunks)
    print(f"inverse rendering against path-traced photos, {width}x{height}, {chunks} x {spp} spp, "
          f"+{100 * args.noise:.0f} % noise, {time.strftime('%Y-%m-%d')}")
    rng = np.random.default_rng(0)
    for name in args.scenes:
        base = load_scene(os.path.join(tt.EXAMPLES, f"{name}.toml"))
        if args.interface == "index-matched":
            base = tt.index_matched(base)
        scene = tt._with_resolution(base, width, height)
        truth, stderr = path_traced(scene, name, spp=spp, chunks=chunks, cache=args.cache, interface=args.interface,
                                    variant=args.variant)
        if args.truth_only:
            continue
        rd_true, mfp_true = true_artist_parameters(scene.material)
        print(f"\n## {name}: true R_d " + " / ".join(f"{x:.4f}" for x in rd_true)
              + ", mean free path " + " / ".join(f"{x:.3f}" for x in mfp_true) + " mm")
        rel = np.median(stderr[truth > 0] / truth[truth > 0])
        photos = [(f"path-traced {width}x{height} (own noise {100 * rel:.0f} % per pixel, median), {args.block}^2 tiles",
                   scene, truth * (1 + args.noise * rng.standard_normal(truth.shape)),
                   noise_model(scene, truth, stderr, args.noise), args.block)]
        if args.consistency:
            big = scene
            material = dataclasses.replace(big.material, profile_model="transport")
            big = dataclasses.replace(big, material=material)
            plan = plan_scene(big, accuracy=0.001, method=Method.TEXTURE_SPACE).replace(Pass.SPECULAR, False,
                                                                                          "subsurface")
            clean = render(big, plan, dtype=jnp.float64).radiance
            photos.append((f"jsss transport render {big.camera.width}x{big.camera.height}, +1 % noise "
                           "(consistency for the transport fit; truth for the dipole's bias)", big,
                           clean * (1 + 0.01 * rng.standard_normal(clean.shape)), None, args.block))
        print("| photo | profile | gain | R_d error R / G / B (stated) | mean free path error R / G / B (stated) | "
              "chi2/dof | steps | s per fit |")
        print("|---|---|---|---|---|---:|---:|---:|")
        medium = scene.material.medium  # the start: 2x the absorption, 2/3 of the scattering
        init = Medium(2 * np.asarray(medium.sigma_a), np.asarray(medium.sigma_s_prime) / 1.5, medium.eta)
        for label, photo_scene, photo, sigma, block in photos:
            for profile in args.profiles:
                # Mitsuba's frames are in jsss's units (the white Lambertian check of
                # transport_truth.py agrees to 0.01-0.03 %), so the gain can also be held at 1.
                for gain in (True, False):
                    kwargs = dict(sigma=sigma, profile_model=profile, specular=False, init=init, gain=gain,
                                  block=block, rim_mm=args.rim_mm)
                    result = fit_render(photo_scene, photo, **kwargs)  # compiles
                    t0 = time.perf_counter()
                    result = fit_render(photo_scene, photo, **kwargs)
                    seconds = time.perf_counter() - t0
                    print(f"| {label} | {profile} | {'fitted' if gain else 'known'} | "
                          f"{_errors(result, rd_true, mfp_true)} | {result.chi2_reduced:.2f} | {result.steps} | "
                          f"{seconds:.1f} |", flush=True)
                    for warning in result.warnings:
                        print(f"  warning: {warning[:160]}", flush=True)


def _errors(result, rd_true, mfp_true):
    """R_d and mean free path, fitted / true - 1 (stated relative error), as table cells."""
    try:  # R_d of the estimate under the truth's own model (the transport tables)
        rd = np.asarray(transport.total_reflectance(result.medium, g=0.0)) / rd_true - 1
    except ValueError:  # the estimate left the tables (an albedo below 0.001): it ran away
        return "ran away (albedo' < 0.001) | ran away"
    rd_err = result.reflectance_err / result.reflectance
    mfp = result.mean_free_path / mfp_true - 1
    mfp_err = result.mean_free_path_err / result.mean_free_path
    cell = lambda errors, stated: " / ".join(f"{100 * e:+.1f} % ({100 * s:.1f})" for e, s in zip(errors, stated))  # noqa: E731
    return cell(rd, rd_err) + " | " + cell(mfp, mfp_err)


if __name__ == "__main__":
    main()
