"""How fast is jsss's random walk? Against a compiled single-thread walk (numba) on the same medium.

Semi-infinite medium, sigma_t = 1/mm, g = 0, eta = 1.3, a pencil beam entering at normal
incidence, absorption by weight with Russian roulette below 1e-4 (one in ten survives),
Fresnel reflection at the boundary: the same physics as `jsss.transport.montecarlo.random_walk`. Both
walks must give the same total reflectance within standard errors; the table gives photons
per second (median of repeats, after a warm-up that compiles both) and their ratio.

The numba walk lives here, not in the package: it is the baseline, not a dependency
(`pip install numba`).

Run: ``python benchmarks/montecarlo_walk.py [--photons 200000] [--repeats 3]``
"""

from __future__ import annotations

import argparse
import datetime
import os
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

from jsss import Medium  # noqa: E402
from jsss.transport.montecarlo import random_walk  # noqa: E402

try:
    import numba
except ImportError:  # pragma: no cover - the baseline is optional
    numba = None


def _numba_walk():
    @numba.njit(cache=False)
    def walk(n, albedo, eta, seed):
        # eta: index inside relative to outside, so sin(t) = eta sin(i) on the way out.
        np.random.seed(seed)
        total = 0.0
        total2 = 0.0
        for _ in range(n):
            x = y = z = 0.0
            ux, uy, uz = 0.0, 0.0, 1.0
            w = 1.0
            out = 0.0
            while True:
                s = -np.log(1.0 - np.random.random())
                if uz < 0 and z + s * uz <= 0:
                    d = -z / uz
                    x += d * ux
                    y += d * uy
                    z = 0.0
                    ci = -uz
                    sin_t2 = eta * eta * (1 - ci * ci)
                    if sin_t2 >= 1:
                        r = 1.0
                    else:
                        ct = np.sqrt(1 - sin_t2)
                        rs = (eta * ci - ct) / (eta * ci + ct)
                        rp = (eta * ct - ci) / (eta * ct + ci)
                        r = 0.5 * (rs * rs + rp * rp)
                    if np.random.random() < r:
                        uz = -uz
                        continue
                    out = w
                    break
                x += s * ux
                y += s * uy
                z += s * uz
                w *= albedo
                if w < 1e-4:
                    if np.random.random() < 0.1:
                        w *= 10
                    else:
                        break
                ct = 2 * np.random.random() - 1
                st = np.sqrt(max(0.0, 1 - ct * ct))
                phi = 2 * np.pi * np.random.random()
                ux, uy, uz = st * np.cos(phi), st * np.sin(phi), ct  # isotropic: a fresh direction
            total += out
            total2 += out * out
        mean = total / n
        return mean, np.sqrt(max(total2 / n - mean * mean, 0.0) / n)

    return walk


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--photons", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    today = datetime.date.today().isoformat()
    load = os.getloadavg()[0]
    print(f"random walk speed, semi-infinite, g = 0, eta = 1.3, {args.photons} photons, "
          f"{jax.devices()[0].platform}, {os.cpu_count()} cores, load {load:.1f}, {today}")
    print(f"{'albedo':>7} {'walk':>14} {'R':>16} {'photons/s':>10} {'ratio':>7}")
    walk = _numba_walk() if numba is not None else None
    eta = 1.3
    for albedo in (0.9, 0.999):
        medium = Medium(1 - albedo, albedo, eta)
        random_walk(medium, n_photons=4096, max_steps=10**7, seed=99, progress=False)  # compile
        jsss_times, result = [], None
        for rep in range(args.repeats):
            start = time.perf_counter()
            result = random_walk(medium, n_photons=args.photons, max_steps=10**7, seed=rep, progress=False)
            jsss_times.append(time.perf_counter() - start)
        jsss_rate = args.photons / statistics.median(jsss_times)
        baseline_rate = None
        if walk is not None:
            walk(1000, albedo, eta, 0)  # compile
            numba_times = []
            for rep in range(args.repeats):
                start = time.perf_counter()
                R, R_err = walk(args.photons, albedo, eta, rep)
                numba_times.append(time.perf_counter() - start)
            baseline_rate = args.photons / statistics.median(numba_times)
            print(f"{albedo:>7} {'numba 1 thread':>14} {R:>8.5f}+-{R_err:.5f} {baseline_rate:>10.0f} {1.0:>7.2f}")
        ratio = f"{jsss_rate / baseline_rate:>7.2f}" if baseline_rate else f"{'-':>7}"
        print(f"{albedo:>7} {'jsss':>14} {result.R:>8.5f}+-{result.R_err:.5f} {jsss_rate:>10.0f} {ratio}"
              f"   (lost {result.lost:.1e})")


if __name__ == "__main__":
    main()
