"""An independent random walk for the lateral steps of light in a half space. NumPy only.

What it simulates
-----------------
A semi-infinite, index-matched medium z < 0 (no interface: a photon that reaches z = 0
leaves), extinction 1 (lengths in mean free paths), isotropic scattering with albedo
``albedo``. A pencil beam enters at the origin at cosine ``cos_incident`` to the normal, moving
toward +x. Free flights are exponential; each scattering multiplies the weight by the albedo
(implicit capture), with Russian roulette below weight 1e-2.

Recorded for each photon that leaves: where it crosses z = 0 (x, y), its direction's cosine
to the normal and its tangential direction, its weight, and how many times it scattered.

What it shares with jsss
------------------------
Nothing: no jsss, no JAX, no H function.
"""

from __future__ import annotations

import numpy as np

__all__ = ["exits"]


def exits(albedo, cos_incident, *, photons, seed):
    """Escaped photons: dict of ``x, y, cos, tx, ty`` (unit tangential exit direction),
    ``weight`` and ``orders`` (scatterings), one entry per photon that left."""
    rng = np.random.default_rng(seed)
    sin_incident = np.sqrt(max(1.0 - cos_incident**2, 0.0))
    pos = np.zeros((photons, 3))
    direction = np.tile([sin_incident, 0.0, -cos_incident], (photons, 1))
    weight = np.ones(photons)
    orders = np.zeros(photons, dtype=np.int64)
    out = {key: [] for key in ("x", "y", "cos", "tx", "ty", "weight", "orders")}
    alive = np.arange(photons)
    while alive.size:
        p, d = pos[alive], direction[alive]
        step = -np.log(1.0 - rng.random(alive.size))
        new = p + step[:, None] * d
        left = new[:, 2] >= 0.0
        if left.any():
            i = alive[left]
            t = -p[left, 2] / d[left, 2]                     # the flight's crossing of z = 0
            cross = p[left] + t[:, None] * d[left]
            tangential = np.hypot(d[left, 0], d[left, 1])
            out["x"].append(cross[:, 0])
            out["y"].append(cross[:, 1])
            out["cos"].append(d[left, 2])
            out["tx"].append(d[left, 0] / np.maximum(tangential, 1e-300))
            out["ty"].append(d[left, 1] / np.maximum(tangential, 1e-300))
            out["weight"].append(weight[i])
            out["orders"].append(orders[i])
        stay = alive[~left]
        pos[stay] = new[~left]
        weight[stay] *= albedo
        orders[stay] += 1
        cos_new = 2.0 * rng.random(stay.size) - 1.0
        phi = 2.0 * np.pi * rng.random(stay.size)
        sin_new = np.sqrt(1.0 - cos_new**2)
        direction[stay] = np.stack([sin_new * np.cos(phi), sin_new * np.sin(phi), cos_new], axis=1)
        low = weight[stay] < 1e-2
        survive = rng.random(stay.size) < 0.1
        weight[stay[low & survive]] *= 10.0
        alive = stay[~low | survive]
    return {key: np.concatenate(value) for key, value in out.items()}
