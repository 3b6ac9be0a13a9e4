"""How wrong is diffusion? The dipole and multipole against the Monte Carlo random walk.

Table 1: semi-infinite media (sigma_t' = 1/mm, g = 0), reduced albedo 0.5..0.999 and
eta 1.0..1.5: total diffuse reflectance (MC +- standard error vs dipole) and the profile at
0.5, 1, 2 and 5 mean free paths (relative error of the dipole averaged over the same narrow
annulus as the MC tally), with the MC's photons per second.
Table 2: slabs of 2 mfp: multipole R and diffuse T against MC (the unscattered beam removed).
Table 3: the MC's accuracy against time (photons, standard error of R, seconds).
A plot of Table 1's errors is saved to benchmarks/out/diffusion_vs_montecarlo.png.

Run: ``python benchmarks/diffusion_vs_montecarlo.py [--photons 20000]``
"""

from __future__ import annotations

import argparse
import datetime
import os
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402
from scipy.integrate import quad  # noqa: E402

from jsss import Medium, dipole  # noqa: E402
from jsss.transport.montecarlo import random_walk  # noqa: E402
from jsss.diffusion.multipole import slab_totals  # noqa: E402

ALBEDOS = (0.5, 0.8, 0.9, 0.95, 0.99, 0.999)
ETAS = (1.0, 1.3, 1.5)
RADII = (0.5, 1.0, 2.0, 5.0)  # in mean free paths (sigma_t' = 1/mm, so mm)


def edges_around(radii, width=0.1):
    inner = sorted(x for r in radii for x in (r * (1 - width), r * (1 + width)))
    return np.concatenate([[0.0], inner, [np.inf]])


def annulus_mean(medium, lo, hi):
    integral = quad(lambda r: 2 * np.pi * r * float(dipole.profile(medium, r)), lo, hi)[0]
    return integral / (np.pi * (hi**2 - lo**2))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--photons", type=int, default=20000)
    args = parser.parse_args()
    today = datetime.date.today().isoformat()
    edges = edges_around(RADII)
    rows = []
    print(f"dipole vs Monte Carlo, semi-infinite, g = 0, {args.photons} photons each, {jax.devices()[0].platform}, {today}")
    print(f"{'albedo':>6} {'eta':>4} {'MC R':>14} {'dipole R':>9} {'rel err':>8} "
          + " ".join(f"{'R(' + str(r) + ')':>8}" for r in RADII) + f" {'photons/s':>10}")
    for eta in ETAS:
        for albedo in ALBEDOS:
            medium = Medium(1 - albedo, albedo, eta)
            mc = random_walk(medium, n_photons=args.photons, max_steps=20000, bin_edges=edges, seed=0, progress=False)
            total = float(dipole.total_reflectance(medium))
            profile_errors = []
            for i, r in enumerate(RADII):
                b = 2 * i + 1  # the annulus [r (1 - w), r (1 + w)]
                model = annulus_mean(medium, edges[b], edges[b + 1])
                profile_errors.append(model / mc.R_profile[b] - 1 if mc.R_profile[b] > 0 else np.nan)
            rows.append((albedo, eta, mc.R, total, profile_errors))
            print(f"{albedo:>6} {eta:>4} {mc.R:>7.4f}+-{mc.R_err:.4f} {total:>9.4f} {total / mc.R - 1:>8.1%} "
                  + " ".join(f"{e:>8.1%}" for e in profile_errors) + f" {mc.photons_per_second:>10.0f}")

    print(f"\nmultipole vs Monte Carlo, slabs of 2 mfp, g = 0, {today}")
    print(f"{'albedo':>6} {'eta':>4} {'MC R':>14} {'multipole R':>12} {'MC T':>14} {'multipole T':>12}")
    for eta in (1.0, 1.4):
        for albedo in (0.8, 0.95, 0.99):
            medium = Medium(1 - albedo, albedo, eta)
            mc = random_walk(medium, thickness=2.0, n_photons=args.photons, max_steps=20000, seed=1, progress=False)
            R, T = slab_totals(medium, 2.0)
            print(f"{albedo:>6} {eta:>4} {mc.R:>7.4f}+-{mc.R_err:.4f} {float(R):>12.4f} "
                  f"{mc.T:>7.4f}+-{mc.T_err:.4f} {float(T):>12.4f}")

    print(f"\nMonte Carlo accuracy vs time (albedo 0.9, eta 1.3, semi-infinite), {today}")
    print(f"{'photons':>8} {'R':>8} {'std err':>8} {'seconds':>8}")
    medium = Medium(0.1, 0.9, 1.3)
    random_walk(medium, n_photons=1024, batch_size=4096, seed=9, progress=False)  # compile
    for n in (4096, 16384, 65536):
        start = time.perf_counter()
        mc = random_walk(medium, n_photons=n, batch_size=4096, seed=10, progress=False)
        print(f"{n:>8} {mc.R:>8.4f} {mc.R_err:>8.4f} {time.perf_counter() - start:>8.2f}")

    os.makedirs(os.path.join(os.path.dirname(__file__), "out"), exist_ok=True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for eta in ETAS:
        sub = [row for row in rows if row[1] == eta]
        ax.semilogx([1 - r[0] for r in sub], [100 * (r[3] / r[2] - 1) for r in sub], "o-", label=f"total, eta {eta}")
        ax.semilogx([1 - r[0] for r in sub], [100 * r[4][1] for r in sub], "x--", label=f"R(1 mfp), eta {eta}")
    ax.axhline(0, color="k", lw=0.5)
    ax.set(xlabel="1 - reduced albedo", ylabel="dipole error vs Monte Carlo [%]", title=f"diffusion vs MC ({today})")
    ax.legend(fontsize=7)
    path = os.path.join(os.path.dirname(__file__), "out", "diffusion_vs_montecarlo.png")
    fig.savefig(path, dpi=120, bbox_inches="tight")
    print(f"\nplot saved to {path}")


if __name__ == "__main__":
    main()
