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
radius; between layers a transmitted photon refracts (Snell) into the next layer. Below
weight 1e-4, Russian roulette keeps one photon in ten at ten times the weight (unbiased). A
photon still inside after ``max_steps`` events is counted as lost.

The walk itself is :mod:`jsss.transport.photon_walk`: lanes that finish take the next photon, so no
lane waits for the longest walk, and a seed reproduces a run bit for bit whatever the lane
count (``batch_size``).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from ..medium import Medium
from .photon_walk import run_walk, sample_henyey_greenstein

__all__ = ["MonteCarloResult", "random_walk", "random_walk_layers", "sample_henyey_greenstein"]


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
                n_photons: int = 100_000, batch_size: int = 4096, max_steps: int = 1_000_000, bin_edges=None,
                seed: int = 0, progress: bool = False, cos_incident: float = 1.0) -> MonteCarloResult:
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
    n_photons : int, keyword-only
    batch_size : int, keyword-only
        Photons walking at once (lanes of the vectorised walk); the result does not depend on it.
    max_steps : int, keyword-only
        Events (collisions and boundary hits) after which a photon still inside is lost. The
        default, 10^6, cuts no photon of an absorbing medium short (Russian roulette ends
        every walk long before); a non-absorbing half space has a heavy path-length tail
        (about 2.5 / sqrt(L) of the photons walk more than L transport lengths), so there
        ``lost`` is what the cap leaves inside. Refilled lanes keep long walks cheap.
    bin_edges : array_like [mm], optional, keyword-only
        Radial bins (default: 64 log-spaced edges from 0.01 to 100 mean free paths, plus 0
        and infinity so every exiting photon is in a bin).
    seed : int, keyword-only
    progress : bool, keyword-only
        Print a progress line per batch to stderr (default False: the library prints nothing
        unless asked).
    cos_incident : float in (0, 1], keyword-only
        Cosine of the beam's direction to the normal *outside* (default 1: along the normal).
        It refracts into the medium; every result stays per unit *entering* flux (the entry
        Fresnel loss is not counted), and radii are measured from the entry point.

    Returns
    -------
    MonteCarloResult
    """
    if medium.shape != ():
        raise ValueError(f"random_walk needs a single-channel medium; got shape {medium.shape}.")
    if not (0 < cos_incident <= 1):
        raise ValueError(f"random_walk(cos_incident=...) must lie in (0, 1]; got {cos_incident!r}.")
    # One layer whose index is 1 inside, seen through the given relative indices outside.
    eta_top = medium.eta if eta_top is None else eta_top
    eta_bottom = medium.eta if eta_bottom is None else eta_bottom
    cos_inside = float(np.sqrt(1 - (1 - cos_incident**2) / float(eta_top) ** 2))  # Snell
    return _run([medium], [thickness], g=g, eta_above=1.0 / eta_top, eta_below=1.0 / eta_bottom, relative=True,
                n_photons=n_photons, batch_size=batch_size, max_steps=max_steps, bin_edges=bin_edges, seed=seed,
                progress=progress, cos_start=cos_inside)


def random_walk_layers(layers, base: Medium | None = None, *, g: float = 0.0, eta_above: float = 1.0,
                       eta_below: float = 1.0, n_photons: int = 100_000, batch_size: int = 4096,
                       max_steps: int = 1_000_000, bin_edges=None, seed: int = 0,
                       progress: bool = False) -> MonteCarloResult:
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


def _params(media, thicknesses, *, g, eta_above, eta_below, relative):
    """The walk engine's per-layer arrays for ``media`` (top first) of ``thicknesses`` [mm]."""
    dtype = jnp.result_type(*[m.dtype for m in media])
    sigma_s = jnp.stack([m.sigma_s_prime / (1 - g) for m in media]).astype(dtype)
    sigma_t = jnp.stack([m.sigma_a for m in media]).astype(dtype) + sigma_s
    albedo = sigma_s / sigma_t
    bottoms = np.cumsum(thicknesses)
    tops = np.concatenate([[0.0], bottoms[:-1]])
    index = jnp.ones(len(media), dtype) if relative else jnp.stack([jnp.asarray(m.eta, dtype) for m in media])
    return (sigma_t, albedo, jnp.full(len(media), g, dtype), jnp.asarray(tops, dtype), jnp.asarray(bottoms, dtype),
            index, jnp.asarray(eta_above, dtype), jnp.asarray(eta_below, dtype))


def _run(media, thicknesses, *, g, eta_above, eta_below, relative, n_photons, batch_size, max_steps, bin_edges,
         seed, progress, cos_start=1.0):
    for m in media:
        if m.shape != ():
            raise ValueError(f"random_walk needs single-channel media; got shape {m.shape}.")
    if not (-1 < g < 1):
        raise ValueError(f"random_walk(g=...) must lie in (-1, 1); got {g!r}.")
    if any(not (d > 0) for d in thicknesses):
        raise ValueError(f"random_walk(thickness=...) must be > 0 [mm]; got {thicknesses!r}.")
    params = _params(media, thicknesses, g=g, eta_above=eta_above, eta_below=eta_below, relative=relative)
    if cos_start != 1.0:
        params = params + (jnp.asarray(cos_start, params[0].dtype),)
    mfp = float(min(float(m.mean_free_path) for m in media))
    if bin_edges is None:
        bin_edges = np.concatenate([[0.0], np.geomspace(0.01 * mfp, 100 * mfp, 64), [np.inf]])
    bin_edges = np.asarray(bin_edges, dtype=float)
    records = run_walk(params, n_photons=n_photons, lanes=batch_size, max_steps=max_steps, seed=seed,
                       progress=progress)
    seconds, r, w, side = records.seconds, records.radius, records.weight, records.side
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
