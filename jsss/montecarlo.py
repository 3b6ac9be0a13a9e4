r"""Monte Carlo photon random walk: the ground truth the diffusion models are checked against.

A normally incident pencil beam *enters* a slab (thickness ``d`` mm, ``inf`` for a
semi-infinite medium) at the origin: results are per unit flux entering, as for the dipole
(multiply by the entry Fresnel transmittance for flux incident from outside). Each photon
takes exponential free paths with :math:`\sigma_t = \sigma_a + \sigma_s`,
:math:`\sigma_s = \sigma_s'/(1-g)`; at each collision its weight is multiplied by the albedo
:math:`\sigma_s/\sigma_t` (absorption by weight) and it scatters by Henyey-Greenstein with
``g``. At a boundary it is reflected with the exact Fresnel probability for its angle
(relative index ``eta_top``/``eta_bottom``; total internal reflection included), otherwise it
leaves and its weight is tallied as reflectance (top) or transmittance (bottom) at its exit
radius. Below weight 1e-4, Russian roulette keeps one photon in ten at ten times the
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

__all__ = ["MonteCarloResult", "random_walk", "sample_henyey_greenstein"]


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
    """One photon: (exit radius, exit weight, side): side 0 still inside (lost), 1 top, 2 bottom
    after scattering, 3 absorbed (roulette), 4 bottom without any collision."""
    sigma_t, albedo, g, thickness, rel_top, rel_bottom = params

    def body(state):
        pos, direction, weight, side, exit_r, key, steps, collided = state
        active = side == 0
        key, sub = jax.random.split(key)
        u_path, u_fresnel, u_theta, u_phi, u_roulette = jax.random.uniform(sub, (5,), dtype=pos.dtype)
        s = -jnp.log1p(-u_path) / sigma_t
        dz = direction[2]
        to_top = jnp.where(dz < 0, -pos[2] / jnp.where(dz < 0, dz, -1.0), jnp.inf)
        to_bottom = jnp.where(dz > 0, (thickness - pos[2]) / jnp.where(dz > 0, dz, 1.0), jnp.inf)
        to_boundary = jnp.minimum(to_top, to_bottom)
        hits = s >= to_boundary
        step = jnp.where(hits, to_boundary, s)
        new_pos = pos + direction * step
        # Boundary: Fresnel reflection from inside (relative index outside/inside).
        top = to_top <= to_bottom
        reflectance = fresnel_reflectance(jnp.abs(dz), jnp.where(top, rel_top, rel_bottom))
        reflects = u_fresnel < reflectance
        leaves = hits & ~reflects
        mirrored = direction * jnp.array([1.0, 1.0, -1.0], dtype=pos.dtype)
        # Collision: absorb by weight, scatter by HG.
        cos_theta = sample_henyey_greenstein(g, u_theta)
        phi = 2 * jnp.pi * u_phi
        scattered = _scatter(direction, cos_theta, phi)
        collided_weight = weight * albedo
        survive = u_roulette < 0.1
        low = collided_weight < 1e-4
        collided_weight = jnp.where(low, jnp.where(survive, collided_weight * 10, 0.0), collided_weight)
        new_direction = jnp.where(hits, jnp.where(reflects, mirrored, direction), scattered)
        new_weight = jnp.where(hits, weight, collided_weight)
        new_side = jnp.where(leaves, jnp.where(top, 1, 2), jnp.where(new_weight == 0, 3, 0))
        new_exit_r = jnp.where(leaves, jnp.hypot(new_pos[0], new_pos[1]), exit_r)
        keep = lambda new, old: jnp.where(active, new, old)  # noqa: E731
        return (keep(new_pos, pos), keep(new_direction, direction), keep(new_weight, weight),
                keep(new_side, side), keep(new_exit_r, exit_r), key, steps + 1, collided | (active & ~hits))

    def walking(state):
        return (state[3] == 0) & (state[6] < max_steps)

    dtype = sigma_t.dtype
    state = (jnp.zeros(3, dtype), jnp.array([0.0, 0.0, 1.0], dtype), jnp.ones((), dtype), jnp.zeros((), jnp.int32),
             jnp.zeros((), dtype), key, jnp.zeros((), jnp.int32), jnp.zeros((), bool))
    _, _, weight, side, exit_r, _, _, collided = jax.lax.while_loop(walking, body, state)
    # Side 4: crossed the slab without any collision (the unscattered beam).
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
    import time

    if medium.shape != ():
        raise ValueError(f"random_walk needs a single-channel medium; got shape {medium.shape}.")
    if not (-1 < g < 1):
        raise ValueError(f"random_walk(g=...) must lie in (-1, 1); got {g!r}.")
    if not (thickness > 0):
        raise ValueError(f"random_walk(thickness=...) must be > 0 [mm]; got {thickness!r}.")
    dtype = medium.dtype
    sigma_s = medium.sigma_s_prime / (1 - g)
    sigma_t = medium.sigma_a + sigma_s
    albedo = sigma_s / sigma_t
    eta_top = medium.eta if eta_top is None else jnp.asarray(eta_top, dtype)
    eta_bottom = medium.eta if eta_bottom is None else jnp.asarray(eta_bottom, dtype)
    params = (jnp.asarray(sigma_t, dtype), jnp.asarray(albedo, dtype), jnp.asarray(g, dtype),
              jnp.asarray(thickness, dtype), 1.0 / eta_top, 1.0 / eta_bottom)
    mfp = float(medium.mean_free_path)
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
