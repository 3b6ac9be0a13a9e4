"""An independent Monte Carlo truth for colour maps (d'Eon et al. 2007, sec 5.3): NumPy only.

What it simulates
-----------------
A semi-infinite homogeneous medium, z < 0, under a smooth dielectric interface at z = 0 with
relative index ``eta`` (medium over outside; outside index 1). Isotropic scattering (g = 0),
coefficients ``sigma_a``, ``sigma_s`` in 1/mm per RGB channel; lengths in mm. Each channel is
walked with its own photons (independent streams of one seeded ``numpy.random.Generator``).

* Illumination: a collimated beam at normal incidence, irradiance 1, uniform over the strip
  -half_width <= x <= half_width (and every y: the strip mode, the default) or over the
  rectangle |x| <= half_width, |y| <= half_height. Entry points are drawn uniformly.
* Entry: every photon enters with weight 1 - F(0), F(0) = ((eta - 1) / (eta + 1))^2, the exact
  unpolarised Fresnel reflectance at normal incidence (deterministic weight, not sampled). The
  specular reflection F(0) is *not* tallied.
* Inside: free paths ~ Exp(sigma_t), implicit capture (the weight is multiplied by the albedo
  sigma_s / sigma_t at every scattering), isotropic new directions, Russian roulette below a
  weight of ``roulette_weight`` (survival 1/``roulette_boost``; unbiased).
* At every hit of the surface from inside: exact unpolarised Fresnel reflectance R(cos) for
  eta -> 1 (total internal reflection beyond the critical angle). The weight is split: the
  part (1 - R) leaves (refracted out; tallied at the hit point), the part R is reflected
  specularly back into the medium and walked on (a fresh exponential free path from the
  surface, which is exact because the free path is memoryless).
* Colour layer: the colour map c(x, y) (per channel, in [0, 1]) is an infinitesimal absorbing
  layer on the surface crossed once on entry and once on exit, so an exiting contribution is
  multiplied by sqrt(c(x_entry)) * sqrt(c(x_exit)). The roulette acts on the path weight
  without the colour factors, so the random numbers and roulette decisions do not depend on
  the colour map (a constant map k scales every tally by exactly k for the same seed).
* Tally: the exitance M (flux leaving the surface per unit area) per unit incident irradiance,
  in bins of x (strip mode; per unit length in y) or of x and y (rectangle mode), and the
  total flux out per unit incident flux. Standard errors from ``batches`` independent batches.

For c = 1 and an infinitely wide beam, M is the same everywhere and equals the collimated
diffuse reflectance of the half-space per unit incident irradiance *including* the entry
transmittance 1 - F(0) and *excluding* the specular reflection F(0): adding-doubling's
UR1 - F(0) (iadpython's UR1 includes F(0)). ``uniform_total`` returns this number.

What it shares with jsss
------------------------
Nothing: no imports from jsss, fitting or measure, no JAX; Fresnel, sampling and tallies are
written here from the physics.

How to call it
--------------
>>> centres, M, err = step_exitance([0.05] * 3, [1.0] * 3, 1.4, (1, 0.5, 0.2), (0.3, 0.9, 1),
...                                 photons=100_000, half_width=20.0, bin_width=0.5, seed=1)
>>> total, total_err = uniform_total([0.05] * 3, [1.0] * 3, 1.4, photons=100_000, seed=1)

or ``walk(sigma_a, sigma_s, eta, colour, photons=..., half_width=..., x_edges=..., seed=...)``
with any callable colour(x, y) -> (N, 3) for the general map (returns a ``WalkResult``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["WalkResult", "fresnel_unpolarised", "walk", "step_colour", "step_exitance", "uniform_total"]


def fresnel_unpolarised(cos_i, n1, n2):
    """Exact unpolarised Fresnel reflectance for light in index n1 meeting index n2 at
    incidence cosine cos_i (>= 0); 1 beyond the critical angle."""
    cos_i = np.clip(np.asarray(cos_i, dtype=float), 0.0, 1.0)
    sin_t = (n1 / n2) * np.sqrt(np.maximum(0.0, 1.0 - cos_i * cos_i))
    total = sin_t >= 1.0
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin_t * sin_t))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
        rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t)
        r = 0.5 * (rs * rs + rp * rp)
    return np.where(total, 1.0, np.where(np.isfinite(r), r, 1.0))


@dataclass
class WalkResult:
    """Tallies of one walk. Exitance per unit incident irradiance.

    x_edges, y_edges: the bins' edges (y_edges None in strip mode). centres: x centres.
    exitance, stderr: (Bx, 3) in strip mode, (Bx, By, 3) in rectangle mode.
    total, total_err: (3,) flux out per unit flux in (all exits, in the bins or not).
    lost: (3,) weight per entering photon dropped by the max_steps cap (0 unless capped).
    steps: the number of vectorised iterations."""

    x_edges: np.ndarray
    y_edges: np.ndarray | None
    centres: np.ndarray
    exitance: np.ndarray
    stderr: np.ndarray
    total: np.ndarray
    total_err: np.ndarray
    lost: np.ndarray
    steps: int


def _per_channel(value, name):
    value = np.broadcast_to(np.asarray(value, dtype=float), (3,)).copy()
    if np.any(value < 0):
        raise ValueError(f"{name} must be >= 0")
    return value


def walk(sigma_a, sigma_s, eta, colour=None, *, photons, half_width, x_edges, seed,
         half_height=None, y_edges=None, batches=32, roulette_weight=1e-2, roulette_boost=10.0,
         max_steps=1_000_000, chunk=1 << 16):
    """Walk ``photons`` photons per channel; see the module docstring.

    sigma_a, sigma_s: scalars or 3 values, 1/mm. eta: medium index over outside (>= 1 or < 1).
    colour: None (c = 1) or callable colour(x, y) -> (N, 3) (or broadcastable, e.g. (N, 1)) in
    [0, 1]; in strip mode (half_height None) photons enter at y = 0 and the map must not depend
    on y. x_edges (and y_edges in rectangle mode): the tally bins, mm."""
    sigma_a = _per_channel(sigma_a, "sigma_a")
    sigma_s = _per_channel(sigma_s, "sigma_s")
    sigma_t = sigma_a + sigma_s
    if np.any(sigma_t <= 0):
        raise ValueError("sigma_t must be > 0")
    albedo = sigma_s / sigma_t
    eta = float(eta)
    photons = int(photons)
    batches = int(batches)
    if photons < 2 * batches:
        raise ValueError("photons must be at least 2 * batches")
    x_edges = np.asarray(x_edges, dtype=float)
    rectangle = half_height is not None
    if rectangle:
        if y_edges is None:
            raise ValueError("rectangle mode needs y_edges")
        y_edges = np.asarray(y_edges, dtype=float)
    else:
        y_edges = None
    nx = len(x_edges) - 1
    ny = len(y_edges) - 1 if rectangle else 1
    nbins = nx * ny

    def colour_of(x, y, ch):
        if colour is None:
            return np.ones_like(x)
        c = np.broadcast_to(np.asarray(colour(x, y), dtype=float), (len(x), 3))
        if np.any(c < 0):
            raise ValueError("colour must be >= 0")
        return c[np.arange(len(x)), ch]

    rng = np.random.default_rng(seed)
    f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
    bin_sums = np.zeros(3 * batches * nbins)
    total_sums = np.zeros(3 * batches)
    lost = np.zeros(3)
    steps = 0
    # Chunks of photons keep the arrays in cache (10^6 photons at once ran 1.6x slower per photon).
    for first in range(0, photons, int(chunk)):
        count = min(int(chunk), photons - first)
        n = 3 * count
        ch = np.repeat(np.arange(3), count)                         # channel of each photon
        batch = np.tile((first + np.arange(count)) % batches, 3)    # its batch within its channel
        x = rng.uniform(-half_width, half_width, n)
        y = rng.uniform(-half_height, half_height, n) if rectangle else np.zeros(n)
        z = np.zeros(n)
        ux = np.zeros(n)
        uy = np.zeros(n)
        uz = -np.ones(n)
        w = np.full(n, 1.0 - f0)                                    # path weight, colour excluded
        sqrt_c_in = np.sqrt(colour_of(x, y, ch))
        st = sigma_t[ch]
        al = albedo[ch]

        step = 0
        while len(w) and step < max_steps:
            step += 1
            s = -np.log1p(-rng.random(len(w))) / st                # Exp(sigma_t), never log(0)
            z_new = z + s * uz
            hit = (z_new >= 0.0) & (uz > 0.0)                      # reaches the surface from inside
            # Distance actually travelled: to the surface for hits, the whole free path otherwise.
            with np.errstate(divide="ignore", invalid="ignore"):
                travel = np.where(hit, -z / uz, s)
            x += travel * ux
            y += travel * uy
            z = np.where(hit, 0.0, z_new)
            # -- surface hits: tally the transmitted part, reflect the rest specularly
            reflect = np.ones(len(w))
            h = np.nonzero(hit)[0]
            if len(h):
                xh = x[h]
                yh = y[h]
                r = fresnel_unpolarised(uz[h], eta, 1.0)
                reflect[h] = r
                out = w[h] * (1.0 - r) * sqrt_c_in[h] * np.sqrt(colour_of(xh, yh, ch[h]))
                chan_batch = ch[h] * batches + batch[h]
                total_sums += np.bincount(chan_batch, weights=out, minlength=3 * batches)
                ix = np.searchsorted(x_edges, xh, side="right") - 1
                inside = (ix >= 0) & (ix < nx)
                if rectangle:
                    iy = np.searchsorted(y_edges, yh, side="right") - 1
                    inside &= (iy >= 0) & (iy < ny)
                    flat = ix * ny + iy
                else:
                    flat = ix
                if np.any(inside):
                    key = chan_batch[inside] * nbins + flat[inside]
                    bin_sums += np.bincount(key, weights=out[inside], minlength=3 * batches * nbins)
            # -- hits keep their weight times R and mirror uz; the rest scatter isotropically with
            #    implicit capture (weight times the albedo)
            w *= np.where(hit, reflect, al)
            mu = 2.0 * rng.random(len(w)) - 1.0
            phi = 2.0 * np.pi * rng.random(len(w))
            sin_theta = np.sqrt(np.maximum(0.0, 1.0 - mu * mu))
            ux = np.where(hit, ux, sin_theta * np.cos(phi))
            uy = np.where(hit, uy, sin_theta * np.sin(phi))
            uz = np.where(hit, -uz, mu)
            # -- Russian roulette on the path weight (independent of the colour map)
            low = np.nonzero(w < roulette_weight)[0]               # weight 0 (left at eta = 1) dies here
            if len(low):
                survive = rng.random(len(low)) < 1.0 / roulette_boost
                w[low] = np.where(survive, w[low] * roulette_boost, 0.0)
            # Drop the dead (weight 0 walks on harmlessly, tallying 0) once they are 1/8 of the array.
            dead = np.count_nonzero(w == 0.0)
            if dead and (dead * 8 >= len(w) or dead == len(w)):
                keep = np.nonzero(w > 0.0)[0]
                x, y, z, ux, uy, uz, w = x[keep], y[keep], z[keep], ux[keep], uy[keep], uz[keep], w[keep]
                sqrt_c_in, st, al, ch, batch = sqrt_c_in[keep], st[keep], al[keep], ch[keep], batch[keep]

        steps = max(steps, step)
        lost += np.bincount(ch, weights=w, minlength=3) / photons

    # Photons per batch (the last batches may hold one fewer).
    per_batch = np.bincount(np.arange(photons) % batches, minlength=batches).astype(float)
    # Strip: each photon carries 2X (per unit y length) of incident flux; rectangle: 4XY.
    area = 2.0 * half_width * (2.0 * half_height if rectangle else 1.0)
    dx = np.diff(x_edges)
    bin_area = (dx[:, None] * np.diff(y_edges)[None, :]) if rectangle else dx[:, None]   # (nx, ny)

    sums = bin_sums.reshape(3, batches, nx, ny)
    batch_est = sums * area / per_batch[None, :, None, None] / bin_area[None, None]
    exitance = sums.sum(axis=1) * area / photons / bin_area[None]               # (3, nx, ny)
    stderr = batch_est.std(axis=1, ddof=1) / np.sqrt(batches)
    tot = total_sums.reshape(3, batches)
    total = tot.sum(axis=1) / photons
    total_err = (tot / per_batch[None]).std(axis=1, ddof=1) / np.sqrt(batches)

    exitance = np.moveaxis(exitance, 0, -1)                                     # (nx, ny, 3)
    stderr = np.moveaxis(stderr, 0, -1)
    if not rectangle:
        exitance, stderr = exitance[:, 0], stderr[:, 0]
    centres = 0.5 * (x_edges[1:] + x_edges[:-1])
    return WalkResult(x_edges, y_edges, centres, exitance, stderr, total, total_err, lost, steps)


def step_colour(c_left, c_right):
    """The map c = c_left for x < 0, c_right for x >= 0 (3 values each), as colour(x, y)."""
    c_left = _per_channel(c_left, "c_left")
    c_right = _per_channel(c_right, "c_right")

    def colour(x, y):
        return np.where((np.asarray(x) < 0.0)[:, None], c_left[None], c_right[None])

    return colour


def step_edges(half_width, bin_width):
    """2 * round(half_width / bin_width) equal bins over [-half_width, half_width]; 0 is an edge
    and the bins are mirror images about it."""
    k = max(1, int(round(half_width / bin_width)))
    return np.linspace(-half_width, half_width, 2 * k + 1)


def step_exitance(sigma_a, sigma_s, eta, c_left, c_right, *, photons, half_width, bin_width, seed,
                  batches=32):
    """Exitance of the step map under the strip beam |x| <= half_width (uniform in y).

    Returns (centres (B,), exitance (B, 3), stderr (B, 3)), per unit incident irradiance, bins of
    ``step_edges(half_width, bin_width)``; ``photons`` per channel. The strip has edges of its
    own at +-half_width: only bins a few transport lengths inside them see the infinite-beam
    answer M(x) = sqrt(c(x)) int R(|x - y|) sqrt(c(y)) dy."""
    result = walk(sigma_a, sigma_s, eta, step_colour(c_left, c_right), photons=photons,
                  half_width=half_width, x_edges=step_edges(half_width, bin_width), seed=seed,
                  batches=batches)
    return result.centres, result.exitance, result.stderr


def uniform_total(sigma_a, sigma_s, eta, *, photons, seed, batches=32):
    """(total (3,), stderr (3,)): the exitance of a uniformly lit half-space per unit incident
    irradiance for c = 1, i.e. the collimated diffuse reflectance including the entry
    transmittance 1 - F(0), excluding the specular reflection F(0) (adding-doubling's
    UR1 - F(0)). ``photons`` per channel."""
    result = walk(sigma_a, sigma_s, eta, None, photons=photons, half_width=0.0,
                  x_edges=np.array([-1.0, 1.0]), seed=seed, batches=batches)
    return result.total, result.total_err
