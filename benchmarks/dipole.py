"""Dipole profile: 1e6 radii x 3 channels, jitted JAX against plain NumPy in the same run.

Run: ``python benchmarks/dipole.py`` (prints a table: implementation, dtype, median ms,
ratio to NumPy float64, max relative difference to NumPy float64).
"""

from __future__ import annotations

import datetime
import os
import sys

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(__file__))
from _timing import median_seconds  # noqa: E402

from jsss.diffusion.dipole import profile  # noqa: E402
from jsss.materials import jensen2001  # noqa: E402


def numpy_profile(sa, ss, eta, r):
    """Eq. 4 in NumPy, the baseline."""
    st = sa + ss
    alpha = ss / st
    sigma_tr = np.sqrt(3 * sa * st)
    fdr = -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta
    A = (1 + fdr) / (1 - fdr)
    zr = 1 / st
    zv = zr + 4 * A / (3 * st)
    r = r[:, None]
    dr = np.sqrt(r**2 + zr**2)
    dv = np.sqrt(r**2 + zv**2)
    return alpha / (4 * np.pi) * (
        zr * (1 + sigma_tr * dr) * np.exp(-sigma_tr * dr) / dr**3
        + zv * (1 + sigma_tr * dv) * np.exp(-sigma_tr * dv) / dv**3
    )


def main(n: int = 1_000_000) -> None:
    medium = jensen2001("marble")
    r = np.linspace(0.0, 20.0, n)
    sa, ss, eta = (np.asarray(x) for x in (medium.sigma_a, medium.sigma_s_prime, medium.eta))
    reference = numpy_profile(sa, ss, eta, r)
    t_numpy = median_seconds(lambda: numpy_profile(sa, ss, eta, r))

    rows = [("numpy", "float64", t_numpy, 0.0)]
    jitted = jax.jit(profile)
    for dtype in (jnp.float64, jnp.float32):
        m = jensen2001("marble", dtype=dtype)
        rj = jnp.asarray(r, dtype=dtype)
        out = jitted(m, rj).block_until_ready()
        err = float(np.max(np.abs(np.asarray(out, dtype=np.float64) - reference) / reference))
        t = median_seconds(lambda: jitted(m, rj).block_until_ready())
        rows.append(("jax.jit", np.dtype(dtype).name, t, err))

    print(f"dipole profile, {n:.0e} radii x 3 channels, {jax.devices()[0].platform}, "
          f"{datetime.date.today().isoformat()}")
    print(f"{'implementation':<15} {'dtype':<8} {'median ms':>10} {'speed vs numpy':>15} {'max rel err':>12}")
    for name, dtype, t, err in rows:
        print(f"{name:<15} {dtype:<8} {1e3 * t:>10.2f} {t_numpy / t:>14.2f}x {err:>12.1e}")


if __name__ == "__main__":
    main()
