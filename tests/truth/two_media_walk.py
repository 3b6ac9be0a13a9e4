"""An independent Monte Carlo truth for parameter maps: two media side by side. NumPy only.

What it simulates
-----------------
A semi-infinite medium z < 0 made of two homogeneous media that meet at the plane x = 0:
medium ``left`` for x < 0, medium ``right`` for x >= 0 (each sigma_a, sigma_s [1/mm] per RGB
channel, isotropic scattering, g = 0), under a smooth dielectric interface at z = 0 of
relative index ``eta`` (the same on both sides; 1 is index-matched). This is a sharp edge of
a parameter map, constant with depth -- Mertens et al. 2003's checker, one edge of it.

* Illumination: a collimated beam at normal incidence, irradiance 1, uniform over the strip
  |x| <= half_width and every y. Each photon enters with weight 1 - F(0).
* Free flight: an optical depth tau ~ Exp(1) is spent at sigma_t of the medium the photon is
  in; a straight segment crossing x = 0 spends the rest at the other medium's sigma_t (exact
  for a piecewise-constant medium: a segment crosses the plane at most once). Implicit capture
  with the albedo of the medium where the photon scatters; Russian roulette below weight 1e-2.
* Surface hits: exact unpolarised Fresnel (`colour_layer_walk.fresnel_unpolarised`); the
  transmitted part is tallied at the hit's x, the rest reflected specularly.
* Tally: exitance per unit incident irradiance in x bins, standard errors from batches.

What it shares with jsss
------------------------
Nothing: no jsss, no JAX. Far from the edge each side tends to its own medium's uniform
exitance (adding-doubling's UR1 - F(0), as `colour_layer_walk.uniform_total`).
"""

from __future__ import annotations

import numpy as np

from .colour_layer_walk import _per_channel, fresnel_unpolarised

__all__ = ["edge_exitance"]


def edge_exitance(left, right, eta, *, photons, half_width, x_edges, seed, batches=16, chunk=1 << 16):
    """(centres (B,), exitance (B, 3), stderr (B, 3)) across the edge x = 0.

    left, right: (sigma_a, sigma_s), each a scalar or 3 values [1/mm]; ``photons`` per channel.
    """
    sigma_a = np.stack([_per_channel(left[0], "sigma_a"), _per_channel(right[0], "sigma_a")])  # (2, 3)
    sigma_s = np.stack([_per_channel(left[1], "sigma_s"), _per_channel(right[1], "sigma_s")])
    sigma_t = sigma_a + sigma_s
    if np.any(sigma_t <= 0):
        raise ValueError("sigma_t must be > 0")
    albedo = sigma_s / sigma_t
    x_edges = np.asarray(x_edges, float)
    nx = len(x_edges) - 1
    rng = np.random.default_rng(seed)
    f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
    sums = np.zeros((3, batches, nx))
    for first in range(0, int(photons), int(chunk)):
        count = min(int(chunk), int(photons) - first)
        ch = np.repeat(np.arange(3), count)
        batch = np.tile((first + np.arange(count)) % batches, 3)
        n = 3 * count
        x, z = rng.uniform(-half_width, half_width, n), np.zeros(n)
        ux, uz = np.zeros(n), -np.ones(n)
        w = np.full(n, 1.0 - f0)
        while len(w):
            side = (x >= 0).astype(int)
            st_here, st_there = sigma_t[side, ch], sigma_t[1 - side, ch]
            tau = -np.log1p(-rng.random(len(w)))
            with np.errstate(divide="ignore", invalid="ignore"):
                to_edge = np.where(ux * x < 0, -x / ux, np.inf)  # distance to x = 0 along the ray
                crosses = st_here * to_edge < tau
                s = np.where(crosses, to_edge + (tau - st_here * np.where(crosses, to_edge, 0)) / st_there,
                             tau / st_here)
                to_surface = np.where(uz > 0, -z / uz, np.inf)
            hit = to_surface <= s
            travel = np.where(hit, to_surface, s)
            x = x + travel * ux
            z = np.where(hit, 0.0, z + travel * uz)
            reflect = np.ones(len(w))
            h = np.nonzero(hit)[0]
            if len(h):
                reflect[h] = fresnel_unpolarised(uz[h], eta, 1.0)
                ix = np.searchsorted(x_edges, x[h], side="right") - 1
                inside = (ix >= 0) & (ix < nx)
                out = w[h] * (1.0 - reflect[h])
                np.add.at(sums, (ch[h][inside], batch[h][inside], ix[inside]), out[inside])
            w = w * np.where(hit, reflect, albedo[(x >= 0).astype(int), ch])
            mu = 2.0 * rng.random(len(w)) - 1.0
            phi = 2.0 * np.pi * rng.random(len(w))
            ux = np.where(hit, ux, np.sqrt(np.maximum(0.0, 1.0 - mu * mu)) * np.cos(phi))
            uz = np.where(hit, -uz, mu)
            low = np.nonzero(w < 1e-2)[0]
            if len(low):
                w[low] = np.where(rng.random(len(low)) < 0.1, w[low] * 10.0, 0.0)
            keep = w > 0
            x, z, ux, uz, w, ch, batch = x[keep], z[keep], ux[keep], uz[keep], w[keep], ch[keep], batch[keep]
    per_batch = np.bincount(np.arange(int(photons)) % batches, minlength=batches).astype(float)
    scale = 2.0 * half_width / np.diff(x_edges)  # each photon carries 2X of flux per unit length in y
    estimates = sums / per_batch[None, :, None] * scale
    exitance = sums.sum(1) / photons * scale
    stderr = estimates.std(1, ddof=1) / np.sqrt(batches)
    return 0.5 * (x_edges[1:] + x_edges[:-1]), exitance.T, stderr.T
