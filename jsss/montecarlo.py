r"""Monte Carlo photon random walk: the ground truth the diffusion models are checked against.

A normally incident pencil beam *enters* a slab (thickness ``d`` mm, ``inf`` for a
semi-infinite medium), or a stack of layers (:func:`random_walk_layers`), at the origin: results are per unit flux entering, as for the dipole
(multiply by the entry Fresnel transmittance for flux incident from outside). Each photon
takes exponential free paths with :math:`\sigma_t = \sigma_a + \sigma_s`,
:math:`\sigma_s = \sigma_s'/(1-g)`; at each collision its weight is multiplied by the albedo
:math:`\sigma_s/\sigma_t` (absorption by weight) and it scatters by Henyey-Greenstein with
``g``. At a boundary it is reflected with the exact Fresnel probability for its angle
(relative index ``eta_top``/``eta_bottom``; total internal reflection included), otherwise it
leaves and its weight is tallied as reflectance (top) or transmittance (bottom) at its exit
radius; between layers a transmitted photon refracts (Snell) into the next layer. Below weight 1e-4, Russian roulette keeps one photon in ten at ten times the
weight (unbiased). A photon still inside after ``max_steps`` collisions is counted as lost.

Photons run in parallel (``vmap`` of a ``lax.while_loop``: a batch runs until its last
photon leaves, is absorbed, or reaches ``max_steps``), in batches with explicit PRNG keys:
a seed reproduces a run exactly.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .fresnel import fresnel_reflectance
from .medium import Medium

__all__ = ["MonteCarloResult", "random_walk", "random_walk_layers", "sample_henyey_greenstein"]


def sample_henyey_greenstein(g, xi):
    r"""Cosine of the scattering angle from the HG distribution (inverse CDF); ``g = 0`` isotropic."""
    small = jnp.abs(g) < 1e-6
    safe_g = jnp.where(small, 0.5, g)
    frac = (1 - safe_g**2) / (1 - safe_g + 2 * safe_g * xi)
    cos_hg = (1 + safe_g**2 - frac**2) / (2 * safe_g)
    return jnp.clip(jnp.where(small, 2 * xi - 1, cos_hg), -1.0, 1.0)


def _scatter(direction, cos_theta, phi):
    """Rotate ``direction`` by polar angle acos(cos_theta) and azimuth phi."""
    ux, uy, uz = direction
    sin_theta = jnp.sqrt(jnp.maximum(1 - cos_theta**2, 0.0))
    cos_phi, sin_phi = jnp.cos(phi), jnp.sin(phi)
    near_pole = jnp.abs(uz) > 0.99999
    denom = jnp.sqrt(jnp.maximum(1 - uz**2, 1e-300))
    nx = sin_theta * (ux * uz * cos_phi - uy * sin_phi) / denom + ux * cos_theta
    ny = sin_theta * (uy * uz * cos_phi + ux * sin_phi) / denom + uy * cos_theta
    nz = -sin_theta * cos_phi * denom + uz * cos_theta
    px, py, pz = sin_theta * cos_phi, sin_theta * sin_phi, jnp.sign(uz) * cos_theta
    return jnp.where(near_pole, jnp.stack([px, py, pz]), jnp.stack([nx, ny, nz]))


def _walk(key, params, max_steps):
    """One photon through a stack of layers; returns (exit radius, exit weight, side).

    Side 0: still inside after ``max_steps`` (lost); 1: left through the top; 2: left
    through the bottom after scattering; 3: absorbed (roulette); 4: left through the
    bottom without any collision (the unscattered beam).
    """
    sigma_t, albedo, g, tops, bottoms, index, eta_above, eta_below = params
    n_layers = sigma_t.shape[0]

    def body(state):
        pos, direction, weight, side, exit_r, key, steps, collided, layer = state
        active = side == 0
        key, sub = jax.random.split(key)
        u_path, u_fresnel, u_theta, u_phi, u_roulette = jax.random.uniform(sub, (5,), dtype=pos.dtype)
        s = -jnp.log1p(-u_path) / sigma_t[layer]
        dz = direction[2]
        to_top = jnp.where(dz < 0, (pos[2] - tops[layer]) / jnp.where(dz < 0, -dz, 1.0), jnp.inf)
        to_bottom = jnp.where(dz > 0, (bottoms[layer] - pos[2]) / jnp.where(dz > 0, dz, 1.0), jnp.inf)
        to_boundary = jnp.minimum(to_top, to_bottom)
        hits = s >= to_boundary
        up = to_top <= to_bottom
        step = jnp.where(hits, to_boundary, s)
        new_pos = pos + direction * step
        new_pos = new_pos.at[2].set(jnp.where(hits, jnp.where(up, tops[layer], bottoms[layer]), new_pos[2]))
        # Boundary: Fresnel reflection or transmission (with refraction into the next layer).
        neighbour = jnp.where(up, layer - 1, layer + 1)
        outside = (neighbour < 0) | (neighbour >= n_layers)
        n1 = index[layer]
        n2 = jnp.where(neighbour < 0, eta_above, jnp.where(neighbour >= n_layers, eta_below,
                                                             index[jnp.clip(neighbour, 0, n_layers - 1)]))
        reflects = u_fresnel < fresnel_reflectance(jnp.abs(dz), n2 / n1)
        leaves = hits & ~reflects & outside
        crosses = hits & ~reflects & ~outside
        ratio = n1 / n2
        cos_t = jnp.sqrt(jnp.maximum(1 - ratio**2 * (1 - dz**2), 0.0))
        refracted = jnp.stack([direction[0] * ratio, direction[1] * ratio, jnp.sign(dz) * cos_t])
        mirrored = direction * jnp.array([1.0, 1.0, -1.0], dtype=pos.dtype)
        # Collision: absorb by weight, scatter by HG.
        cos_theta = sample_henyey_greenstein(g[layer], u_theta)
        scattered = _scatter(direction, cos_theta, 2 * jnp.pi * u_phi)
        collided_weight = weight * albedo[layer]
        low = collided_weight < 1e-4
        collided_weight = jnp.where(low, jnp.where(u_roulette < 0.1, collided_weight * 10, 0.0), collided_weight)
        new_direction = jnp.where(hits, jnp.where(reflects, mirrored, jnp.where(crosses, refracted, direction)),
                                  scattered)
        new_weight = jnp.where(hits, weight, collided_weight)
        new_layer = jnp.where(crosses, neighbour, layer)
        new_side = jnp.where(leaves, jnp.where(up, 1, 2), jnp.where(new_weight == 0, 3, 0))
        new_exit_r = jnp.where(leaves, jnp.hypot(new_pos[0], new_pos[1]), exit_r)
        keep = lambda new, old: jnp.where(active, new, old)  # noqa: E731
        return (keep(new_pos, pos), keep(new_direction, direction), keep(new_weight, weight),
                keep(new_side, side), keep(new_exit_r, exit_r), key, steps + 1, collided | (active & ~hits),
                keep(new_layer, layer))

    def walking(state):
        return (state[3] == 0) & (state[6] < max_steps)

    dtype = sigma_t.dtype
    state = (jnp.zeros(3, dtype), jnp.array([0.0, 0.0, 1.0], dtype), jnp.ones((), dtype), jnp.zeros((), jnp.int32),
             jnp.zeros((), dtype), key, jnp.zeros((), jnp.int32), jnp.zeros((), bool), jnp.zeros((), jnp.int32))
    _, _, weight, side, exit_r, _, _, collided, _ = jax.lax.while_loop(walking, body, state)
    side = jnp.where((side == 2) & ~collided, 4, side)
    return exit_r, jnp.where((side == 1) | (side == 2) | (side == 4), weight, 0.0), side


@dataclass(frozen=True)
class MonteCarloResult:
    """Totals with standard errors, the radial reflectance profile, and bookkeeping.

    ``R_profile``/``T_profile`` [1/mm^2] are per unit entering flux on the annuli between
    ``bin_edges`` (their mean radii ``r``); the profile errors are standard errors. ``T``
    is diffuse (scattered at least once); ``T_unscattered`` is the beam that crossed without
    a collision (a delta at r = 0, not in ``T_profile``). ``lost`` is the fraction of photons
    still walking after ``max_steps``.
    """

    R: float
    R_err: float
    T: float
    T_err: float
    T_unscattered: float
    lost: float
    r: np.ndarray
    bin_edges: np.ndarray
    R_profile: np.ndarray
    R_profile_err: np.ndarray
    T_profile: np.ndarray
    T_profile_err: np.ndarray
    n_photons: int
    seconds: float

    @property
    def photons_per_second(self) -> float:
        return self.n_photons / self.seconds


def random_walk(medium: Medium, *, thickness=jnp.inf, g: float = 0.0, eta_top=None, eta_bottom=None,
                n_photons: int = 100_000, batch_size: int = 4096, max_steps: int = 2000, bin_edges=None,
                seed: int = 0, progress: bool | None = None) -> MonteCarloResult:
    """Run the random walk for a single-channel medium.

    Parameters
    ----------
    medium : Medium
        One channel (shape ``()``).
    thickness : float [mm], keyword-only
        Slab thickness; ``inf`` (default) for a semi-infinite medium.
    g : float, keyword-only
        Henyey-Greenstein mean cosine; ``sigma_s = sigma_s' / (1 - g)``.
    eta_top, eta_bottom : float, keyword-only
        Index of the medium relative to the outside above / below (default ``medium.eta``).
    n_photons, batch_size, max_steps : int, keyword-only
    bin_edges : array_like [mm], optional, keyword-only
        Radial bins (default: 64 log-spaced edges from 0.01 to 100 mean free paths, plus 0
        and infinity so every exiting photon is in a bin).
    seed : int, keyword-only
    progress : bool, optional, keyword-only
        Print a progress line per batch to stderr (default: when more than 4 batches).

    Returns
    -------
    MonteCarloResult
    """
    if medium.shape != ():
        raise ValueError(f"random_walk needs a single-channel medium; got shape {medium.shape}.")
    # One layer whose index is 1 inside, seen through the given relative indices outside.
    eta_top = medium.eta if eta_top is None else eta_top
    eta_bottom = medium.eta if eta_bottom is None else eta_bottom
    return _run([medium], [thickness], g=g, eta_above=1.0 / eta_top, eta_below=1.0 / eta_bottom, relative=True,
                n_photons=n_photons, batch_size=batch_size, max_steps=max_steps, bin_edges=bin_edges, seed=seed,
                progress=progress)


def random_walk_layers(layers, base: Medium | None = None, *, g: float = 0.0, eta_above: float = 1.0,
                       eta_below: float = 1.0, n_photons: int = 100_000, batch_size: int = 4096,
                       max_steps: int = 2000, bin_edges=None, seed: int = 0,
                       progress: bool | None = None) -> MonteCarloResult:
    """Random walk through a stack of :class:`jsss.layers.Layer` (top first), over an optional
    semi-infinite ``base``. Each ``medium.eta`` is the layer's absolute index; photons refract
    (Snell) and reflect (Fresnel) at every interface. Other options as :func:`random_walk`.
    """
    media = [layer.medium for layer in layers] + ([base] if base is not None else [])
    thicknesses = [float(layer.thickness) for layer in layers] + ([np.inf] if base is not None else [])
    if not media:
        raise ValueError("random_walk_layers needs at least one layer or a base.")
    return _run(media, thicknesses, g=g, eta_above=eta_above, eta_below=eta_below, relative=False,
                n_photons=n_photons, batch_size=batch_size, max_steps=max_steps, bin_edges=bin_edges, seed=seed,
                progress=progress)


def _run(media, thicknesses, *, g, eta_above, eta_below, relative, n_photons, batch_size, max_steps, bin_edges,
         seed, progress):
    import time

    for m in media:
        if m.shape != ():
            raise ValueError(f"random_walk needs single-channel media; got shape {m.shape}.")
    if not (-1 < g < 1):
        raise ValueError(f"random_walk(g=...) must lie in (-1, 1); got {g!r}.")
    if any(not (d > 0) for d in thicknesses):
        raise ValueError(f"random_walk(thickness=...) must be > 0 [mm]; got {thicknesses!r}.")
    dtype = jnp.result_type(*[m.dtype for m in media])
    sigma_s = jnp.stack([m.sigma_s_prime / (1 - g) for m in media]).astype(dtype)
    sigma_t = jnp.stack([m.sigma_a for m in media]).astype(dtype) + sigma_s
    albedo = sigma_s / sigma_t
    bottoms = np.cumsum(thicknesses)
    tops = np.concatenate([[0.0], bottoms[:-1]])
    index = jnp.ones(len(media), dtype) if relative else jnp.stack([jnp.asarray(m.eta, dtype) for m in media])
    params = (sigma_t, albedo, jnp.full(len(media), g, dtype), jnp.asarray(tops, dtype), jnp.asarray(bottoms, dtype),
              index, jnp.asarray(eta_above, dtype), jnp.asarray(eta_below, dtype))
    mfp = float(min(float(m.mean_free_path) for m in media))
    if bin_edges is None:
        bin_edges = np.concatenate([[0.0], np.geomspace(0.01 * mfp, 100 * mfp, 64), [np.inf]])
    bin_edges = np.asarray(bin_edges, dtype=float)
    walk = jax.jit(jax.vmap(lambda k: _walk(k, params, max_steps)))

    n_batches = int(np.ceil(n_photons / batch_size))
    progress = n_batches > 4 if progress is None else progress
    keys = jax.random.split(jax.random.PRNGKey(seed), n_batches)
    radii, weights, sides = [], [], []
    start = time.perf_counter()
    for b in range(n_batches):
        size = min(batch_size, n_photons - b * batch_size)
        r, w, side = walk(jax.random.split(keys[b], batch_size))
        radii.append(np.asarray(r)[:size])
        weights.append(np.asarray(w)[:size])
        sides.append(np.asarray(side)[:size])
        if progress:
            print(f"\rrandom_walk: {min((b + 1) * batch_size, n_photons)}/{n_photons} photons", end="",
                  file=sys.stderr, flush=True)
    if progress:
        print(file=sys.stderr)
    seconds = time.perf_counter() - start
    r, w, side = np.concatenate(radii), np.concatenate(weights), np.concatenate(sides)
    n = r.size

    def tally(mask):
        contribution = np.where(mask, w, 0.0)
        total, total_err = contribution.mean(), contribution.std() / np.sqrt(n)
        index = np.clip(np.searchsorted(bin_edges, r, side="right") - 1, 0, bin_edges.size - 2)
        sums = np.bincount(index, contribution, minlength=bin_edges.size - 1)
        squares = np.bincount(index, contribution**2, minlength=bin_edges.size - 1)
        area = np.pi * np.diff(bin_edges**2)
        mean = sums / n
        err = np.sqrt(np.maximum(squares / n - mean**2, 0.0) / n)
        with np.errstate(invalid="ignore"):
            return total, total_err, mean / area, err / area

    R, R_err, R_prof, R_prof_err = tally(side == 1)
    T, T_err, T_prof, T_prof_err = tally(side == 2)
    centres = np.sqrt(0.5 * (bin_edges[:-1] ** 2 + np.minimum(bin_edges[1:], 1e150) ** 2))
    T_direct = float(np.mean(np.where(side == 4, w, 0.0)))
    return MonteCarloResult(float(R), float(R_err), float(T), float(T_err), T_direct, float(np.mean(side == 0)),
                            centres, bin_edges, R_prof, R_prof_err, T_prof, T_prof_err, n, seconds)
