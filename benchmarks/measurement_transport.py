"""fit-params on camera images whose truth is radiative transfer: error, z-score and time per model.

Images: :func:`measure.synth_transport.synthesize_walk` (own random walks, not the tables;
one channel; transport length 1 mm; Gaussian beam 0.05 mm; 128 px of 0.05 mm). The camera
accepts photons within ``--cone`` degrees of the normal (default 20.7, the tables' top
exit-angle bin, so model and truth average the same directions). Models, each on the
same image, all reading the image as a camera's radiance at 0 degrees (the contract):
``dipole`` (diffusion exit law) and ``transport`` (scaled Monte Carlo tables); and, to show
what the contract fixes, ``transport`` reading the image as exitance.

Per row: relative error and z = (estimate - truth) / stated standard error of sigma_a and
sigma_s', chi^2/dof, and the median time of a fit after warm-up.

Run: ``python benchmarks/measurement_transport.py [--photons 300000] [--cone 20.7] [--quick]``
"""

from __future__ import annotations

import argparse
import datetime
import itertools
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
from measure.synth_transport import synthesize_walk  # noqa: E402

MODELS = (("dipole", 0.0), ("transport", 0.0), ("transport", None))  # (model, view angle; None = as exitance)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--photons", type=int, default=300_000)
    parser.add_argument("--cone", type=float, default=float(np.degrees(np.arccos(np.sqrt(0.875)))))
    parser.add_argument("--quick", action="store_true", help="albedo 0.9 and 0.99 at eta 1.3, g 0 only")
    args = parser.parse_args()
    grid = hankel.hankel_grid()
    albedos, etas, gs = ((0.9, 0.99), (1.3,), (0.0,)) if args.quick else ((0.5, 0.9, 0.99, 0.999), (1.0, 1.3, 1.5),
                                                                         (0.0, 0.9))
    print(f"# fit-params on walk camera images ({datetime.date.today().isoformat()}, {args.photons} photons, "
          f"cone {args.cone:.1f} deg)")
    print("| albedo | eta | g | model | reads as | sigma_a error (z) | sigma_s' error (z) | chi2/dof | ms per fit |")
    print("|---:|---:|---:|---|---|---:|---:|---:|---:|")
    for albedo, eta, g in itertools.product(albedos, etas, gs):
        medium = Medium(1 - albedo, albedo, eta)
        start = time.perf_counter()
        image = synthesize_walk(medium, g=g, photons=args.photons, cone_deg=args.cone, seed=7)
        walk_s = time.perf_counter() - start
        for model, view in MODELS:
            def fit():
                return fit_measurement(image.measurement, image.reference, 0.05, eta, model=model, g=g,
                                       view_angle_deg=view, channels=("Y",), grid=grid)

            table = fit().table()
            seconds = median_seconds(fit, repeats=3, warmup=0)
            cells = []
            for key, true in (("sigma_a", 1 - albedo), ("sigma_s_prime", albedo)):
                value, err = table[key][0], table[f"{key}_err"][0]
                cells.append(f"{value / true - 1:+.1%} ({(value - true) / err:+.1f})")
            reads = "exitance" if view is None else "radiance 0 deg"
            print(f"| {albedo} | {eta} | {g} | {model} | {reads} | {cells[0]} | {cells[1]} | "
                  f"{table['chi2_reduced'][0]:.3g} | {1000 * seconds:.0f} |", flush=True)
        print(f"<!-- walk {walk_s:.0f} s -->", flush=True)


if __name__ == "__main__":
    main()
