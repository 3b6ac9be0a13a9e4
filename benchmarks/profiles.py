"""Profile models against radiative-transfer truth: dipole vs the scaled Monte Carlo tables.

Truth: `jsss.transport.montecarlo.random_walk` with absorption in the walk (not applied afterwards),
seeds unrelated to the tables', tallied on annuli of +-10 % around each radius. A model's
value is its own average over the same annulus (Gauss-Legendre over r dr). Reported per
(albedo', eta, g): the relative error of R(r) at 0.1-20 transport lengths (blank where the
truth's own standard error exceeds 1 %), of the total, and the worst |error| / truth's
error over them (about 2-3 for a model that is right: noise alone). Then the time of one evaluation (1000 radii x 3 channels, jit, median of repeats).

Run: ``python benchmarks/profiles.py [--photons 200000] [--quick]``
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(__file__))
from _timing import median_seconds  # noqa: E402

from jsss import Medium, dipole, transport  # noqa: E402
from jsss.transport.montecarlo import random_walk  # noqa: E402

RADII = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0)  # transport lengths 1/(sigma_a + sigma_s')
ALBEDOS = (0.5, 0.9, 0.99, 0.999, 0.9999)  # reduced albedo sigma_s' / (sigma_a + sigma_s')


def annulus_edges(radii, width=0.25):
    inner = sorted(x for r in radii for x in (r * (1 - width), r * (1 + width)))
    return np.concatenate([[0.0], inner, [np.inf]])


def annulus_mean(fn, lo, hi, nodes=32):
    x, w = np.polynomial.legendre.leggauss(nodes)
    r = 0.5 * (hi - lo) * x + 0.5 * (hi + lo)
    values = np.asarray(fn(jnp.asarray(r)))
    return np.sum(w * 0.5 * (hi - lo) * 2 * np.pi * r * values) / (np.pi * (hi**2 - lo**2))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--photons", type=int, default=200_000)
    parser.add_argument("--quick", action="store_true", help="fewer cases (a smoke run)")
    args = parser.parse_args()
    today = datetime.date.today().isoformat()
    info = transport.table_info()
    cases = [(a, eta, g) for g in (0.0, 0.9) for eta in (1.0, 1.3, 1.55) for a in ALBEDOS]
    if args.quick:
        cases = [(0.99, 1.0, 0.0), (0.99, 1.55, 0.9), (0.9, 1.55, 0.0)]
    edges = annulus_edges(RADII)
    print(f"profiles vs independent Monte Carlo ({args.photons} photons per case; tables: "
          f"{int(info['photons'])} photons per (eta, g)), {jax.devices()[0].platform}, "
          f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}, {today}")
    print("relative error [%] of R(r) at r = " + ", ".join(f"{r:g}" for r in RADII)
          + " transport lengths, and of the total; '.' where the truth's error > 1 %")
    print(f"{'albedo':>7} {'eta':>5} {'g':>4} {'model':>9} " + " ".join(f"{r:>7g}" for r in RADII)
          + f" {'total':>7} {'max|e|/err':>10}")
    worst = {"dipole": 0.0, "transport": 0.0}
    for albedo, eta, g in cases:
        medium = Medium(1 - albedo, albedo, eta)  # sigma_s' + sigma_a = 1/mm: r in mm = transport lengths
        truth = random_walk(medium, g=g, n_photons=args.photons, max_steps=2**31 - 1, bin_edges=edges,
                            seed=7919 + int(1e4 * albedo) + int(100 * eta), progress=False)
        models = {"dipole": lambda r, m=medium: dipole.profile(m, r),
                  "transport": lambda r, m=medium: transport.profile(m, r, g=g)}
        totals = {"dipole": float(dipole.total_reflectance(medium)),
                  "transport": float(transport.total_reflectance(medium, g=g))}
        for name, fn in models.items():
            cells, ratios = [], []
            for i, r in enumerate(RADII):
                k = 2 * i + 1  # the annulus around r (bins alternate gap / annulus)
                lo, hi = edges[k], edges[k + 1]
                mc, err = truth.R_profile[k], truth.R_profile_err[k]
                if not mc > 0 or err / mc > 0.01:
                    cells.append(f"{'.':>7}")
                    continue
                model = annulus_mean(fn, lo, hi)
                cells.append(f"{100 * (model / mc - 1):>7.2f}")
                ratios.append(abs(model - mc) / err)
                if name in worst and r >= 0.1:
                    worst[name] = max(worst[name], abs(model / mc - 1))
            total_error = 100 * (totals[name] / truth.R - 1)
            ratios.append(abs(totals[name] - truth.R) / truth.R_err)
            print(f"{albedo:>7} {eta:>5} {g:>4} {name:>9} " + " ".join(cells) + f" {total_error:>7.2f}"
                  f" {max(ratios):>10.1f}")
    print(f"worst |relative error| of R(r) where the truth resolves it: dipole {100 * worst['dipole']:.1f} %, "
          f"transport tables {100 * worst['transport']:.1f} %")

    print(f"\ntime per evaluation: 1000 radii x 3 channels, jit, median ({today})")
    medium = Medium(jnp.array([0.01, 0.05, 0.2]), jnp.array([1.0, 1.2, 1.5]), 1.4)
    r = jnp.geomspace(0.01, 20.0, 1000)
    fns = {"dipole": jax.jit(lambda m, r: dipole.profile(m, r)),
           "transport": jax.jit(lambda m, r: transport.profile(m, r, g=0.0))}
    base = None
    for name, fn in fns.items():
        seconds = median_seconds(lambda fn=fn: fn(medium, r).block_until_ready(), repeats=21, warmup=2)
        base = base or seconds
        print(f"{name:>10} {1e3 * seconds:>8.3f} ms  {seconds / base:>6.2f} x dipole")


if __name__ == "__main__":
    main()
