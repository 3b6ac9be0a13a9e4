"""Measurement pipeline: time per measurement and accuracy against noise and image size.

1. Time for profile extraction + fit of one 512 x 512 RGB measurement after warm-up
   (median of repeats), and for a batch of 50 (one Hankel grid shared, as fit-params batch does).
2. Accuracy vs noise: photo-electrons per unit value 1e3 .. 1e7 (marble and skin1, 256 px),
   the worst relative error of sigma_a and sigma_s' over channels, and the time.
3. Accuracy vs image size: 64 .. 512 px at a fixed 12.8 mm field of view.

Images are camera images made from the transport tables and fitted with the transport model
(the default of fit-params): a self-consistency and speed check. Truth outside the model is
in ``benchmarks/measurement_transport.py`` (independent random walks).

Run: ``python benchmarks/measurement.py [--batch 50]``
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(__file__))
from _timing import median_seconds  # noqa: E402

from jsss import hankel  # noqa: E402
from jsss.materials import jensen2001  # noqa: E402
from measure.checks import MeasurementError  # noqa: E402
from measure.pipeline import fit_measurement  # noqa: E402
from measure.synth import synthesize  # noqa: E402


def worst_errors(result, medium):
    t = result.table()
    ea = np.max(np.abs(np.array(t["sigma_a"]) / np.asarray(medium.sigma_a) - 1))
    es = np.max(np.abs(np.array(t["sigma_s_prime"]) / np.asarray(medium.sigma_s_prime) - 1))
    return ea, es


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--batch", type=int, default=50)
    args = parser.parse_args()
    today = datetime.date.today().isoformat()
    grid = hankel.hankel_grid()
    marble = jensen2001("marble")

    size, pixel = 512, 0.025
    print(f"measurement pipeline, {jax.devices()[0].platform} x{os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.1f}, {today}")
    print("one 512x512 RGB camera image of marble (transport tables; extraction + fit, after warm-up, median of 5);")
    print("baseline in the same run: 7 Levenberg-Marquardt starts per channel (init='multistart', before 2026-12-01)\n")
    print("| model | start | ms | x baseline | sigma_a worst error | sigma_s' worst error |")
    print("|---|---|---:|---:|---:|---:|")
    synthetic = synthesize(marble, size=size, pixel_mm=pixel, photons_per_unit=1e5, grid=grid, model="transport")
    for model in ("transport", "dipole"):
        base = None
        for init in ("multistart", "scan"):
            def one():
                return fit_measurement(synthetic.measurement, synthetic.reference, pixel, 1.5, dark=synthetic.dark,
                                       grid=grid, model=model, fit_options={"init": init})

            seconds = median_seconds(one, repeats=5)
            base = base or seconds
            ea, es = worst_errors(one(), marble)
            print(f"| {model} | {init} | {1e3 * seconds:.0f} | {base / seconds:.1f} | {ea:.2%} | {es:.2%} |")
    batch = [synthesize(marble, size=size, pixel_mm=pixel, photons_per_unit=1e5, seed=s, grid=grid, model="transport")
             for s in range(args.batch)]
    start = time.perf_counter()
    errors = [worst_errors(fit_measurement(b.measurement, b.reference, pixel, 1.5, dark=b.dark, grid=grid,
                                           model="transport"), marble)
              for b in batch]
    t_batch = time.perf_counter() - start
    print(f"\nbatch of {args.batch} (512^2, transport, in one process): {t_batch:.1f} s "
          f"({1e3 * t_batch / args.batch:.0f} ms each); worst rel. error "
          f"sigma_a {max(e[0] for e in errors):.2%}, sigma_s' {max(e[1] for e in errors):.2%}\n")

    print(f"accuracy vs noise (256 px of 0.05 mm; worst channel; median of 3 seeds), {today}")
    print(f"{'material':<8} {'e-/unit':>8} {'sigma_a err':>12} {'sigma_s err':>12} {'ms':>6}")
    for name in ("marble", "skin1"):
        medium = jensen2001(name)
        for photons in (1e3, 1e4, 1e5, 1e6, 1e7):
            results, times = [], []
            for seed in range(3):
                s = synthesize(medium, photons_per_unit=photons, seed=seed, grid=grid, model="transport")
                start = time.perf_counter()
                try:
                    r = fit_measurement(s.measurement, s.reference, 0.05, float(medium.eta[0]), dark=s.dark,
                                        grid=grid, model="transport")
                except MeasurementError as error:  # refused as no measurement: say so, not a number
                    print(f"{name:<8} {photons:>8.0e} refused: {error}")
                    break
                times.append(time.perf_counter() - start)
                results.append(worst_errors(r, medium))
            if not results:
                continue
            ea, es = np.median(results, axis=0)
            print(f"{name:<8} {photons:>8.0e} {ea:>12.3%} {es:>12.3%} {1e3 * np.median(times):>6.0f}")

    print(f"\naccuracy vs image size (12.8 mm field, 1e5 e-/unit, marble), {today}")
    print(f"{'pixels':>7} {'pixel mm':>9} {'sigma_a err':>12} {'sigma_s err':>12} {'ms':>6}")
    for n in (64, 128, 256, 512):
        pixel = 12.8 / n
        s = synthesize(marble, size=n, pixel_mm=pixel, beam_sigma_mm=max(0.05, pixel), photons_per_unit=1e5, grid=grid,
                       model="transport")
        fit_measurement(s.measurement, s.reference, pixel, 1.5, dark=s.dark, grid=grid, model="transport")  # warm-up
        start = time.perf_counter()
        r = fit_measurement(s.measurement, s.reference, pixel, 1.5, dark=s.dark, grid=grid, model="transport")
        t = time.perf_counter() - start
        ea, es = worst_errors(r, marble)
        print(f"{n:>7} {pixel:>9.4f} {ea:>12.3%} {es:>12.3%} {1e3 * t:>6.0f}")


if __name__ == "__main__":
    main()
