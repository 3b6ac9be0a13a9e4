"""Sum-of-Gaussian fits of all 36 Jensen 2001 channels: accuracy against time.

Table 1: batched, jitted optimistix Levenberg-Marquardt (``fitting.fit_gaussians``, all
starts and channels in one vmapped call) against SciPy's ``least_squares(method="lm")``
run one start at a time, with the same grid, parameterisation, starts and number of
starts; and ``fit_gaussians``' default, one start from its closed-form seed with random
starts only where the seed's error exceeds 2 % (the same SciPy multistart is the baseline).
Table 2: number of Gaussians against error and time, for the default fit and for the
closed-form empirical fit (``jsss.gaussians.empirical_dipole_fit``, 8 Gaussians).

Run: ``python benchmarks/gaussian_fits.py [--starts 8]``
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

sys.path.insert(0, os.path.dirname(__file__))
from _timing import median_seconds  # noqa: E402

from fitting import fit_gaussians, jensen2001_profiles  # noqa: E402
from fitting.gaussians import _starts, _trapezoid_weights  # noqa: E402
from jsss import dipole  # noqa: E402
from jsss.gaussians import empirical_dipole_fit, relative_rms_error  # noqa: E402
from jsss.materials import jensen2001, jensen2001_names  # noqa: E402


def scipy_fit(r, profile, n, n_starts, key):
    """The baseline: the same objective and starts, scipy LM, one start at a time."""
    q = np.asarray(_trapezoid_weights(jnp.asarray(r)) * r)
    sqrt_q = np.sqrt(q)
    norm = np.sqrt(np.sum(q * profile**2))
    guess = max(2 * np.pi * np.sum(q * profile), 1e-12)
    a0, b0 = (np.asarray(x) for x in _starts(key, n_starts, n, jnp.asarray(r), guess))

    def residuals(p):
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            w, v = np.exp(p[:n]), np.exp(p[n:])
            model = np.exp(-(r[:, None] ** 2) / (2 * v)) / (2 * np.pi * v) @ w
        return np.nan_to_num(sqrt_q * (profile - model) / norm, nan=1e10, posinf=1e10, neginf=-1e10)

    best = np.inf
    for s in range(n_starts):
        sol = least_squares(residuals, np.concatenate([a0[s], b0[s]]), method="lm", xtol=1e-10, ftol=1e-10)
        best = min(best, float(np.sqrt(np.sum(sol.fun**2))))
    return best


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--starts", type=int, default=8)
    args = parser.parse_args()
    today = datetime.date.today().isoformat()
    platform = jax.devices()[0].platform
    R, P, _ = jensen2001_profiles()
    R_np, P_np = np.asarray(R), np.asarray(P)
    keys = jax.random.split(jax.random.PRNGKey(0), P.shape[1])

    print(f"36 Jensen 2001 channels, {args.starts} starts each, {platform}, {today}")
    print(f"{'method':<34} {'n':>2} {'max rel_rms %':>14} {'median %':>9} {'wall s':>8} {'speed vs scipy':>15}")
    for n in (4, 8):
        start = time.perf_counter()
        errors = [scipy_fit(R_np[:, c], P_np[:, c], n, args.starts, keys[c]) for c in range(P.shape[1])]
        t_scipy = time.perf_counter() - start
        e_sp = 100 * np.asarray(errors)
        print(f"{'scipy least_squares(lm), serial':<34} {n:>2} {e_sp.max():>14.3f} {np.median(e_sp):>9.3f} {t_scipy:>8.2f} {1.0:>14.1f}x")
        for label, init in (("optimistix LM, random starts", "random"), ("optimistix LM, seed (+ retries)", "seed")):
            fit = fit_gaussians(R, P, n, n_starts=args.starts, init=init)
            jax.block_until_ready(fit.rel_rms)
            t_jax = median_seconds(lambda: jax.block_until_ready(
                fit_gaussians(R, P, n, n_starts=args.starts, init=init).rel_rms), repeats=3)
            e_jax = 100 * np.asarray(fit.rel_rms)
            lost = int(np.sum(e_jax > e_sp + 1e-2))  # channels where it misses scipy's best by > 0.01 points
            print(f"{label:<34} {n:>2} {e_jax.max():>14.3f} {np.median(e_jax):>9.3f} {t_jax:>8.2f} {t_scipy / t_jax:>14.1f}x"
                  f"   (worse than scipy's multistart on {lost} channels)")

    print(f"\naccuracy vs time (36 channels, {today})")
    print(f"{'method':<28} {'n':>2} {'max rel_rms %':>14} {'median %':>9} {'wall ms':>9}")
    for n in range(1, 9):
        fit = fit_gaussians(R, P, n, n_starts=args.starts)
        t = median_seconds(lambda: jax.block_until_ready(fit_gaussians(R, P, n, n_starts=args.starts).rel_rms), repeats=3)
        e = 100 * np.asarray(fit.rel_rms)
        print(f"{'LM (seed + retries)':<28} {n:>2} {e.max():>14.3f} {np.median(e):>9.3f} {1e3 * t:>9.1f}")
    media = [jensen2001(name) for name in jensen2001_names()]
    empirical = jax.jit(lambda ms: [empirical_dipole_fit(m) for m in ms])
    jax.block_until_ready(empirical(media))
    t = median_seconds(lambda: jax.block_until_ready(empirical(media)))
    errors = []
    for i, (m, gs) in enumerate(zip(media, empirical(media))):
        r = R_np[:, 3 * i]
        errors.extend(np.asarray(relative_rms_error(gs, r, dipole.profile(m, r))))
    e = 100 * np.asarray(errors)
    print(f"{'empirical (closed form)':<28} {8:>2} {e.max():>14.3f} {np.median(e):>9.3f} {1e3 * t:>9.1f}")


if __name__ == "__main__":
    main()
