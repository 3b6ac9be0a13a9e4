"""fit-params on camera images whose truth is radiative transfer: error, z-score and time per model.

Images: :func:`measure.synth_transport.synthesize_walk` (own random walks with absorption in
the walk and their own seeds, not the tables; one channel; transport length 1 mm). The
camera looks from exactly 0 degrees (next-event estimates of an independent walk,
:func:`measure.synth_transport.camera_walk`, since 2026-12-06); ``--cone 20.7`` instead accepts
a jsss walk's photons within that angle of the normal, as the tables held before. Models, each on the
same image, all reading the image as a camera's radiance at 0 degrees (the contract):
``dipole`` (diffusion exit law) and ``transport`` (scaled Monte Carlo tables); and, to show
what the contract fixes, ``transport`` reading the image as exitance.

The field of view is an experiment design choice, and it decides whether sigma_a can be
measured at all: at high albedo the profile's decay, which carries sigma_a, happens at the
diffusion length 1/sigma_tr (18 transport lengths at albedo' 0.999). Each image's half-width
is ``--field`` diffusion lengths of its material (pixels of at least 0.05 mm), as a user
would frame the visible glow; ``--pixel-mm 0.05 --size 128`` reproduces the 6.4 mm field of
the 2026-11-25 table, where sigma_a at albedo' 0.999 was not in the data (stated errors 10-100 %).
The beam's standard deviation is one pixel.

Per row: relative error and z = (estimate - truth) / stated standard error of sigma_a and
sigma_s', chi^2/dof, and the median time of a fit after warm-up. Walks are slow at high
albedo and g = 0.9 (minutes per image), so ``--cache DIR`` keeps each image (keyed by its
parameters and seed) and ``--albedos/--etas/--gs`` pick a subset; two processes with one
cache fill it in parallel (the walk uses about one core).

Run: ``python benchmarks/measurement_transport.py [--cache DIR] [--quick]``
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import json
import os
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(__file__))
from _timing import median_seconds  # noqa: E402

from jsss import Medium, hankel  # noqa: E402
from measure.pipeline import fit_measurement  # noqa: E402
from measure.synth import SyntheticMeasurement  # noqa: E402
from measure.synth_transport import pixel_beam_reference, synthesize_walk  # noqa: E402

MODELS = (("dipole", 0.0), ("transport", 0.0), ("transport", None))  # (model, view angle; None = as exitance)
# Photons per image: the stated error of sigma_a at albedo' 0.999 with a 4-length field was
# 3.6 % at 3e5 photons (g = 0) and 5.4 % at 1e5 (g = 0.9); these aim at about 1.5-2 %.
PHOTONS = {0.5: 1_000_000, 0.9: 1_000_000, 0.99: 1_000_000, 0.999: 2_000_000}
PHOTONS_G09_HIGH = 1_500_000  # albedo' 0.999, g = 0.9: ten times the events per photon


def _geometry(albedo, *, field, pixel_mm, size):
    """Pixel size [mm] for a half-field of ``field`` diffusion lengths (transport length 1 mm)."""
    if pixel_mm is not None:
        return pixel_mm
    sigma_tr = np.sqrt(3 * (1 - albedo))
    return max(0.05, field / sigma_tr / (size / 2))


def cached_image(path, make):
    """``make()``'s walk image, or the one stored at ``path`` (npz; None: no cache), and the
    seconds its walk took. The reference is rebuilt from the stored truth, not read: it is cheap,
    and this keeps a cache written before the references were integrated over pixels (2026-12-02)
    valid. Written atomically, so two processes may fill one cache."""
    if path and os.path.exists(path):
        with np.load(path) as stored:
            truth = json.loads(str(stored["truth"]))
            reference = pixel_beam_reference(truth["size"], truth["center"], truth["pixel_mm"], truth["beam_sigma_mm"],
                                             channels=len(truth["eta"]), reflectance=truth["reference_reflectance"])
            return SyntheticMeasurement(stored["measurement"], reference, None, truth=truth), float(stored["seconds"])
    start = time.perf_counter()
    image = make()
    seconds = time.perf_counter() - start
    if path:
        partial = path + f".{os.getpid()}.tmp.npz"
        np.savez(partial, measurement=image.measurement, truth=json.dumps(image.truth), seconds=seconds)
        os.replace(partial, path)
    return image, seconds


def _image(medium, *, g, photons, cone, pixel_mm, size, seed, cache):
    """One walk image, from ``cache`` when it holds one with these parameters."""
    key = dict(sigma_a=float(medium.sigma_a), sigma_s_prime=float(medium.sigma_s_prime), eta=float(medium.eta),
               g=float(g), photons=int(photons), cone="exact" if cone is None else round(float(cone), 6),
               pixel_mm=round(float(pixel_mm), 9),
               size=int(size), seed=int(seed))
    path = None
    if cache:
        os.makedirs(cache, exist_ok=True)
        path = os.path.join(cache, "_".join(f"{k}{v}" for k, v in key.items()) + ".npz")
    return cached_image(path, lambda: synthesize_walk(medium, g=g, photons=photons, cone_deg=cone, seed=seed,
                                                      pixel_mm=pixel_mm, size=size, beam_sigma_mm=pixel_mm))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--photons", type=int, default=None, help="photons per image (default: per albedo, above)")
    parser.add_argument("--cone", type=float, default=None, help="a cone camera [degrees] instead of the exact direction")
    parser.add_argument("--field", type=float, default=4.0, help="half-width of the image in diffusion lengths")
    parser.add_argument("--size", type=int, default=256, help="image side [pixels]")
    parser.add_argument("--pixel-mm", type=float, default=None, help="fixed pixel size (overrides --field)")
    parser.add_argument("--albedos", type=float, nargs="+", default=[0.5, 0.9, 0.99, 0.999])
    parser.add_argument("--etas", type=float, nargs="+", default=[1.0, 1.3, 1.5])
    parser.add_argument("--gs", type=float, nargs="+", default=[0.0, 0.9])
    parser.add_argument("--cache", default=None, help="directory that keeps the walk images between runs")
    parser.add_argument("--walk-only", action="store_true", help="fill the cache, fit nothing")
    parser.add_argument("--quick", action="store_true", help="albedo 0.9 and 0.99 at eta 1.3, g 0, 3e5 photons")
    args = parser.parse_args()
    if args.quick:
        args.albedos, args.etas, args.gs, args.photons = [0.9, 0.99], [1.3], [0.0], args.photons or 300_000
    grid = hankel.hankel_grid()
    camera = "exact 0 deg" if args.cone is None else f"cone {args.cone:.1f} deg"
    print(f"# fit-params on walk camera images ({datetime.date.today().isoformat()}, {camera}, "
          f"{args.size} px, half-field {args.field} diffusion lengths)")
    print("| albedo' | eta | g | photons | pixel mm | model | reads as | sigma_a error (z) | sigma_s' error (z) "
          "| chi2/dof | converged | ms per fit |")
    print("|---:|---:|---:|---:|---:|---|---|---:|---:|---:|---|---:|")
    for albedo, eta, g in itertools.product(args.albedos, args.etas, args.gs):
        medium = Medium(1 - albedo, albedo, eta)
        photons = args.photons or (PHOTONS_G09_HIGH if albedo >= 0.999 and g > 0 else PHOTONS[albedo])
        pixel_mm = _geometry(albedo, field=args.field, pixel_mm=args.pixel_mm, size=args.size)
        image, walk_s = _image(medium, g=g, photons=photons, cone=args.cone, pixel_mm=pixel_mm, size=args.size,
                               seed=7, cache=args.cache)
        if args.walk_only:
            print(f"<!-- albedo' {albedo} eta {eta} g {g}: walk {walk_s:.0f} s -->", flush=True)
            continue
        for model, view in MODELS:
            def fit():
                return fit_measurement(image.measurement, image.reference, pixel_mm, eta, model=model, g=g,
                                       view_angle_deg=view, channels=("Y",), grid=grid)

            table = fit().table()
            seconds = median_seconds(fit, repeats=3, warmup=0)
            cells = []
            for key, true in (("sigma_a", 1 - albedo), ("sigma_s_prime", albedo)):
                value, err = table[key][0], table[f"{key}_err"][0]
                cells.append(f"{value / true - 1:+.1%} ({(value - true) / err:+.1f})")
            reads = "exitance" if view is None else "radiance 0 deg"
            print(f"| {albedo} | {eta} | {g} | {photons:.1e} | {pixel_mm:.3g} | {model} | {reads} | {cells[0]} | "
                  f"{cells[1]} | {table['chi2_reduced'][0]:.3g} | {table['converged'][0]} | {1000 * seconds:.0f} |",
                  flush=True)
        print(f"<!-- walk {walk_s:.0f} s -->", flush=True)


if __name__ == "__main__":
    main()
