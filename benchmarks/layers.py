"""Three-layer skin profile (3 channels): accuracy against time.

Two tables, printed with the date and platform:

1. Speed: ``jsss.layers.stack`` (exact multipole spectra + Kubelka-Munk + one inverse
   Hankel transform) jitted, against the same computation written in NumPy/SciPy, both on
   the same 2048-node grid.
2. Accuracy vs time: the exact-spectrum pipeline over Hankel grid sizes, and the classic
   pipeline of Donner & Jensen / d'Eon (truncated multipole profiles -> forward Hankel ->
   KM -> inverse Hankel) over ``n_dipoles``. Errors of R(r) for r in [0.01, 5] mm against a
   converged reference (exact spectra, 4096 nodes): the largest difference as a fraction of
   the peak, and the largest relative error where R exceeds 1e-3 of its peak.

Run: ``python benchmarks/layers.py``
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

from jsss import dipole, hankel  # noqa: E402
from jsss.layers.kubelka_munk import combine_spectra, layer_boundaries, relative_to, skin_three_layer, stack  # noqa: E402
from jsss.diffusion.multipole import slab_profiles, unscattered_transmittance  # noqa: E402


# ----------------------------------------------------------------------------- NumPy baseline
def _np_train(c, period, beta):
    c = np.mod(c, period)
    with np.errstate(invalid="ignore", divide="ignore"):
        value = (np.expm1(-beta * c) - np.expm1(-beta * (period - c))) / -np.expm1(-beta * period)
    return np.where(beta > 0, value, 1 - 2 * c / period)


def _np_slab(sa, ss, eta, d, eta_top, eta_bottom, k):
    st = sa + ss
    ell, D = 1 / st, 1 / (3 * st)
    fdr = lambda e: np.where(e >= 1, -1.440 / e**2 + 0.710 / e + 0.668 + 0.0636 * e,  # noqa: E731
                             -0.4400 + 0.7099 / e - 0.3319 / e**2 + 0.0636 / e**3)
    A = lambda e: (1 + fdr(e)) / (1 - fdr(e))  # noqa: E731
    zt, zb = 2 * A(eta_top) * D, 2 * A(eta_bottom) * D
    x = d / ell
    z0 = ell * (1 - x * np.exp(-x) / -np.expm1(-x))
    w = -np.expm1(-x)
    P = 2 * (d + zt + zb)
    beta = np.sqrt(k[:, None] ** 2 + 3 * sa * st)
    s = 0.5 * w * ss / st
    R = s * (_np_train(z0, P, beta) - _np_train(-z0 - 2 * zt, P, beta))
    T = s * (_np_train(d - z0, P, beta) - _np_train(d + z0 + 2 * zt, P, beta))
    return R, T


def numpy_stack(layers, base, inverse_matrix, k):
    np_layers = [(np.asarray(L.medium.sigma_a), np.asarray(L.medium.sigma_s_prime), np.asarray(L.medium.eta),
                  float(L.thickness)) for L in layers]
    etas = [1.0] + [lay[2] for lay in np_layers]
    result = None
    for j, (sa, ss, eta, d) in enumerate(np_layers):
        eta_next = np_layers[j + 1][2] if j + 1 < len(np_layers) else np.asarray(base.eta)
        coll = np.exp(-d * (sa + ss))
        Rd, Td = _np_slab(sa, ss, eta, d, eta / etas[j], eta / eta_next, k)
        Ru, Tu = _np_slab(sa, ss, eta, d, eta / eta_next, eta / etas[j], k)
        spectra = (Rd, Td + coll, Ru, Tu + coll)
        result = spectra if result is None else combine_spectra(result, spectra)
    sa, ss, eta = (np.asarray(x) for x in (base.sigma_a, base.sigma_s_prime, base.eta))
    rel = eta / etas[-1]
    st = sa + ss
    fdr = -1.440 / rel**2 + 0.710 / rel + 0.668 + 0.0636 * rel
    A = (1 + fdr) / (1 - fdr)
    beta = np.sqrt(k[:, None] ** 2 + 3 * sa * st)
    zr, zv = 1 / st, 1 / st + 4 * A / (3 * st)
    Rb = 0.5 * ss / st * (np.exp(-beta * zr) + np.exp(-beta * zv))
    zeros = np.zeros_like(Rb)
    R = combine_spectra(result, (Rb, zeros, zeros, zeros))[0]
    return inverse_matrix @ np.asarray(R)


# ----------------------------------------------------------------------------- classic pipeline
def classic_stack(layers, base, grid, n_dipoles):
    """Truncated multipole profiles -> numerical forward Hankel -> KM -> inverse Hankel."""
    sides, above_base = layer_boundaries(layers, base)
    result = None
    for L, (above, below) in zip(layers, sides):
        m, d = L.medium, L.thickness
        Rd, Td = slab_profiles(m, d, grid.r, eta_top=m.eta / above, eta_bottom=m.eta / below, n_dipoles=n_dipoles)
        Ru, Tu = slab_profiles(m, d, grid.r, eta_top=m.eta / below, eta_bottom=m.eta / above, n_dipoles=n_dipoles)
        coll = unscattered_transmittance(m, d)
        spectra = (hankel.forward(grid, Rd), hankel.forward(grid, Td) + coll,
                   hankel.forward(grid, Ru), hankel.forward(grid, Tu) + coll)
        result = spectra if result is None else combine_spectra(result, spectra)
    relative = relative_to(base, above_base)
    Rb = hankel.forward(grid, dipole.profile(relative, grid.r))
    zeros = jnp.zeros_like(Rb)
    return hankel.inverse(grid, combine_spectra(result, (Rb, zeros, zeros, zeros))[0])


def profile_errors(r, R, r_ref, R_ref, lo=0.01, hi=5.0, floor=1e-3):
    """(max |R - R_ref| / peak, max relative error where R_ref > floor * peak), r in [lo, hi]."""
    keep = (r >= lo) & (r <= hi)
    ref = np.stack([np.interp(np.log(r[keep]), np.log(r_ref), R_ref[:, c]) for c in range(R_ref.shape[1])], -1)
    peak = np.max(np.abs(R_ref), axis=0)
    of_peak = float(np.max(np.abs(R[keep] - ref) / peak))
    visible = np.abs(ref) > floor * peak
    relative = float(np.max((np.abs(R[keep] - ref) / np.abs(ref))[visible]))
    return of_peak, relative


def main():
    layers, base = skin_three_layer()
    today = datetime.date.today().isoformat()
    platform = jax.devices()[0].platform

    ref_grid = hankel.hankel_grid(n=4096)
    R_ref = np.asarray(stack(layers, base, grid=ref_grid).R)
    r_ref = np.asarray(ref_grid.r)

    grid = hankel.hankel_grid(n=2048)
    jitted = jax.jit(lambda ls, b, g: stack(ls, b, grid=g).R)
    t_jax = median_seconds(lambda: jitted(layers, base, grid).block_until_ready())
    inverse_np, k_np = np.asarray(grid.inverse_matrix), np.asarray(grid.k)
    R_np = numpy_stack(layers, base, inverse_np, k_np)
    t_np = median_seconds(lambda: numpy_stack(layers, base, inverse_np, k_np))
    agree = float(np.max(np.abs(R_np - np.asarray(jitted(layers, base, grid)))) / np.max(np.abs(R_np)))

    print(f"3-layer skin profile, 3 channels, 2048-node grid, {platform}, {today}")
    print(f"{'implementation':<28} {'median ms':>10} {'speed vs numpy':>15}")
    print(f"{'numpy/scipy':<28} {1e3 * t_np:>10.2f} {1.0:>14.2f}x")
    print(f"{'jax.jit(layers.stack)':<28} {1e3 * t_jax:>10.2f} {t_np / t_jax:>14.2f}x")
    print(f"(max |difference| between the two: {agree:.1e} of the peak)\n")

    print(f"accuracy vs time: R(r), 0.01 <= r <= 5 mm, vs 4096-node exact reference, {today}")
    print(f"{'pipeline':<40} {'err/peak':>9} {'rel err (R>1e-3 peak)':>22} {'median ms':>10}")
    for n in (256, 512, 1024, 2048):
        g = hankel.hankel_grid(n=n)
        R = np.asarray(jitted(layers, base, g))
        t = median_seconds(lambda: jitted(layers, base, g).block_until_ready())
        e_peak, e_rel = profile_errors(np.asarray(g.r), R, r_ref, R_ref)
        print(f"{'exact spectra, grid n=' + str(n):<40} {e_peak:>9.1e} {e_rel:>22.1e} {1e3 * t:>10.2f}")
    g = hankel.hankel_grid(n=1024)
    for n_dipoles in (0, 1, 2, 5, 10, 20):
        fn = jax.jit(lambda ls, b, gg, n=n_dipoles: classic_stack(ls, b, gg, n))
        R = np.asarray(fn(layers, base, g))
        t = median_seconds(lambda: fn(layers, base, g).block_until_ready())
        label = f"classic, n_dipoles={n_dipoles}, grid n=1024"
        e_peak, e_rel = profile_errors(np.asarray(g.r), R, r_ref, R_ref)
        print(f"{label:<40} {e_peak:>9.1e} {e_rel:>22.1e} {1e3 * t:>10.2f}")


if __name__ == "__main__":
    main()
