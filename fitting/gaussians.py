r"""Sum-of-Gaussians fits by Levenberg-Marquardt (d'Eon et al. 2007 sec. 4, eqs. 6-10).

Minimises the d'Eon objective :math:`\int_0^\infty r\,(R(r) - \sum_i w_i G(v_i, r))^2\,dr`
on a radial grid (trapezoid weights), with weights and variances kept positive by
parameterisation (:math:`w_i = e^{a_i}`, :math:`v_i = e^{b_i}`; with a prescribed total,
:math:`w = R_d\,\mathrm{softmax}(a)`). The objective has many local minima. By default
(``init="seed"``) each fit starts once from a closed-form seed (variances log-spaced across
the profile's own radii, weights from the linear least-squares problem they leave) and only
the profiles whose error then exceeds ``retry_above`` get ``n_starts`` random starts as
well; ``init="random"`` runs the random starts for every profile. All starts and profiles
run in one jitted, ``vmap``-ped call of optimistix's Levenberg-Marquardt per round, and the
best is kept. Gradients of the result with respect to the profile flow through the solver
by the implicit function theorem (optimistix's ``ImplicitAdjoint``).
"""

from __future__ import annotations

from functools import partial
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from jsss.diffusion import dipole
from jsss.gaussians.gaussian_sum import GaussianSum
from jsss.medium import Medium
from jsss.numerics import warn_if_low_precision

__all__ = ["GaussianFit", "fit_gaussians", "fit_gaussians_to_medium", "jensen2001_profiles", "radial_grid"]


class GaussianFit(eqx.Module):
    """Result of :func:`fit_gaussians`; leading axes are the profile's batch axes ``B``.

    Attributes
    ----------
    weights, variances : Array ``B + (n,)``
        Weights (dimensionless) and variances [mm^2], variances increasing.
    rel_rms : Array ``B``
        d'Eon's relative RMS power error (eq. 10) on the fit grid, as a fraction
        (0.0152 means 1.52 %).
    n_iterations : Array ``B``
        Levenberg-Marquardt steps of the best start.
    converged : Array ``B``
        Whether the best start met the tolerances within ``max_steps``.
    """

    weights: jax.Array
    variances: jax.Array
    rel_rms: jax.Array
    n_iterations: jax.Array
    converged: jax.Array

    def gaussian_sum(self) -> GaussianSum:
        """As a :class:`jsss.gaussians.GaussianSum`: one channel axis at most, block weights."""
        if self.weights.ndim == 1:
            return GaussianSum(self.weights, self.variances)
        if self.weights.ndim != 2:
            raise ValueError("gaussian_sum() needs a single channel axis; index the batch first.")
        n_channels, n = self.weights.shape
        eye = jnp.eye(n_channels, dtype=self.weights.dtype)
        block = (self.weights[:, :, None] * eye[:, None, :]).reshape(n_channels * n, n_channels)
        return GaussianSum(block, self.variances.reshape(-1))


def _trapezoid_weights(r):
    h = jnp.diff(r)
    q = jnp.zeros_like(r).at[:-1].add(h / 2).at[1:].add(h / 2)
    return q


def _unpack(params, total):
    a, b = params
    variances = jnp.exp(b)
    weights = jnp.exp(a) if total is None else total * jax.nn.softmax(a)
    return weights, variances


def _model(params, r, total):
    weights, variances = _unpack(params, total)
    g = jnp.exp(-(r[:, None] ** 2) / (2 * variances)) / (2 * jnp.pi * variances)
    return g @ weights


def _residuals(params, args):
    r, profile, sqrt_q, norm, total = args
    return sqrt_q * (profile - _model(params, r, total)) / norm


def _fit_one(profile, total, starts, r, sqrt_q, solver, max_steps):
    """All starts for one profile; returns the best start's parameters and diagnostics."""
    norm = jnp.sqrt(jnp.sum((sqrt_q * profile) ** 2))
    args = (r, profile, sqrt_q, norm, total)

    def solve(start):
        sol = optx.least_squares(_residuals, solver, start, args, max_steps=max_steps, throw=False)
        loss = jnp.sum(_residuals(sol.value, args) ** 2)
        loss = jnp.where(jnp.isfinite(loss), loss, jnp.inf)
        return sol.value, loss, sol.stats["num_steps"], sol.result == optx.RESULTS.successful

    values, losses, steps, ok = jax.vmap(solve)(starts)
    best = jnp.argmin(losses)
    params = jax.tree_util.tree_map(lambda x: x[best], values)
    weights, variances = _unpack(params, total)
    order = jnp.argsort(variances)
    return weights[order], variances[order], jnp.sqrt(losses[best]), steps[best], ok[best]


def _starts(key, n_starts, n, r, profile_total_guess):
    """Log-uniform random variances between (2 r_min)^2 and (r_max / 2)^2 (sorted), equal weights."""
    lo, hi = jnp.log((2 * r[0]) ** 2), jnp.log((r[-1] / 2) ** 2)
    b = jnp.sort(jax.random.uniform(key, (n_starts, n), dtype=r.dtype, minval=lo, maxval=hi), axis=1)
    a = jnp.full((n_starts, n), jnp.log(profile_total_guess / n), dtype=r.dtype)
    return a, b


def _seed(r, profile, q, n, constrained):
    """A closed-form start: variances log-spaced between the squares of the radii that hold
    1 % and 99 % of the profile's light, weights from the d'Eon objective's normal equations
    at those variances (linear in the weights), floored at 1e-6 of the largest."""
    energy = jnp.cumsum(2 * jnp.pi * q * jnp.maximum(profile, 0))
    energy = energy / jnp.maximum(energy[-1], 1e-300)
    r_lo = jnp.interp(0.01, energy, r)
    r_hi = jnp.maximum(jnp.interp(0.99, energy, r), 1.01 * r_lo)
    variances = jnp.geomspace(r_lo**2 / 2, r_hi**2 / 2, n)
    g = jnp.exp(-(r[:, None] ** 2) / (2 * variances)) / (2 * jnp.pi * variances)  # (N, n)
    gram = (g * q[:, None]).T @ g
    rhs = (g * q[:, None]).T @ profile
    scale = jnp.trace(gram) / n
    weights = jnp.linalg.solve(gram + 1e-10 * scale * jnp.eye(n, dtype=r.dtype), rhs)
    weights = jnp.maximum(weights, 1e-6 * jnp.max(jnp.abs(weights)) + 1e-300)
    a = jnp.log(weights / jnp.sum(weights)) if constrained else jnp.log(weights)
    return a[None], jnp.log(variances)[None]


@partial(jax.jit, static_argnames=("n", "n_starts", "max_steps", "constrained", "seeded"))
def _fit_batch(radii, profiles, totals, keys, *, n, n_starts, max_steps, rtol, atol, constrained, seeded):
    """Fit every row of ``profiles`` (M, N) on its own grid ``radii`` (M, N), all in one call:
    from the closed-form seed alone (``seeded``) or from ``n_starts`` random starts drawn
    with each profile's own key (so a profile's random starts do not depend on the others)."""
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)

    def one(r, profile, total, k):
        q = _trapezoid_weights(r) * r
        if seeded:
            a, b = _seed(r, profile, q, n, constrained)
        else:
            guess = jnp.maximum(2 * jnp.pi * jnp.sum(q * profile), 1e-12)
            a, b = _starts(k, n_starts, n, r, guess)
            if constrained:
                a = jnp.zeros_like(a)  # softmax weights: equal shares of the total
        return _fit_one(profile, total if constrained else None, (a, b), r, jnp.sqrt(q), solver, max_steps)

    return jax.vmap(one)(radii, profiles, totals, keys)


def fit_gaussians(r, profile, n: int = 4, *, weight: Literal["r"] = "r", total=None,
                  init: Literal["seed", "random"] = "seed", n_starts: int = 8, retry_above: float = 0.02,
                  key=None, max_steps: int = 400, rtol: float = 1e-8, atol: float = 1e-10) -> GaussianFit:
    r"""Fit :math:`\sum_{i=1}^n w_i G(v_i, r)` to radial profiles (d'Eon 2007 eq. 6).

    Parameters
    ----------
    r : array_like, shape ``(N,)`` or ``(N,) + B``, increasing along axis 0, > 0 [mm]
        The radial grid, shared or one per profile; log-spaced grids from well inside the
        mean free path to where the profile has fallen by many decades work best
        (:func:`radial_grid`).
    profile : array_like, shape ``(N,) + B`` [1/mm^2]
        One profile per trailing index (channels, materials, ...).
    n : int
        Number of Gaussians.
    weight : {"r"}, keyword-only
        The objective's weight: ``"r"``, d'Eon's, the only one offered.
    total : array_like, optional, keyword-only
        If given (broadcast to ``B``), the weights are constrained to sum to it (eq. 9).
    init : {"seed", "random"}, keyword-only
        ``"seed"`` (default): one start from the closed-form seed, then ``n_starts`` random
        starts only for the profiles whose relative RMS error is still above
        ``retry_above`` (the better of the two results is kept). ``"random"``: ``n_starts``
        random starts for every profile.
    n_starts : int, keyword-only
        Random starts per profile (all of them with ``"random"``, the retries with ``"seed"``).
    retry_above : float, keyword-only
        Relative RMS error (a fraction; 0.02 is 2 %) above which a seeded fit is retried from
        random starts; ``inf`` never retries, 0 always does.
    key : jax.random key, optional, keyword-only
        Seed for the starts (default ``jax.random.PRNGKey(0)``: reproducible).
    max_steps, rtol, atol : keyword-only
        Levenberg-Marquardt limits and tolerances.

    Returns
    -------
    GaussianFit

    Raises
    ------
    ValueError
        Bad shapes, non-increasing or non-positive radii, non-finite profiles, unknown ``weight``.
    """
    if weight != "r":
        raise ValueError(f"fit_gaussians(weight={weight!r}): the only supported weight is 'r'.")
    if n < 1 or n_starts < 1:
        raise ValueError(f"fit_gaussians needs n >= 1 and n_starts >= 1; got n={n}, n_starts={n_starts}.")
    if init not in ("seed", "random"):
        raise ValueError(f"fit_gaussians(init={init!r}): one of 'seed', 'random'.")
    if not retry_above >= 0:
        raise ValueError(f"fit_gaussians(retry_above={retry_above!r}) must be >= 0 (a relative RMS error).")
    # Fits run in the widest float JAX offers (float64 under jax_enable_x64): the objective
    # spans many decades and LM's damping mixes in default-precision scalars.
    dtype = jnp.promote_types(jnp.asarray(profile).dtype, jnp.result_type(float))
    profile = jnp.asarray(profile, dtype=dtype)
    r = jnp.asarray(r, dtype=dtype)
    if profile.ndim < 1 or r.shape[:1] != profile.shape[:1] or (r.ndim > 1 and r.shape != profile.shape):
        raise ValueError("fit_gaussians needs r of shape (N,) or like the profile, and profile of shape "
                         f"(N, ...); got {r.shape} and {profile.shape}.")
    if not isinstance(r, jax.core.Tracer):
        r_np = np.asarray(r)
        if np.any(r_np <= 0) or np.any(np.diff(r_np, axis=0) <= 0):
            raise ValueError("fit_gaussians(r=...) must be positive and strictly increasing along axis 0.")
    if not isinstance(profile, jax.core.Tracer) and not np.all(np.isfinite(np.asarray(profile))):
        raise ValueError("fit_gaussians(profile=...) has non-finite values; mask them first.")
    warn_if_low_precision(profile, what="fit_gaussians", needs="the published 4-Gaussian errors (enable jax_enable_x64)")
    batch = profile.shape[1:]
    flat = jnp.moveaxis(profile.reshape(r.shape[0], -1), 0, 1)
    radii = jnp.moveaxis(jnp.broadcast_to(r.reshape(r.shape + (1,) * (profile.ndim - r.ndim)), profile.shape)
                         .reshape(r.shape[0], -1), 0, 1)
    totals = jnp.zeros(flat.shape[0], flat.dtype) if total is None else jnp.broadcast_to(jnp.asarray(total, flat.dtype), batch).reshape(-1)
    keys = jax.random.split(jax.random.PRNGKey(0) if key is None else key, flat.shape[0])
    options = dict(n=n, n_starts=n_starts, max_steps=max_steps, rtol=rtol, atol=atol, constrained=total is not None)
    result = _fit_batch(radii, flat, totals, keys, seeded=init == "seed", **options)
    if init == "seed":
        # Random starts only where the seed's result is not good enough (NaN errors included).
        # Concrete errors: fit just those profiles again. Traced ones (vmap, grad): every
        # profile, selected alike, so the answer is the same either way.
        traced = isinstance(result[2], jax.core.Tracer)
        retry = np.arange(flat.shape[0]) if traced else np.flatnonzero(~(np.asarray(result[2]) <= retry_above))
        if retry.size:
            again = _fit_batch(radii[retry], flat[retry], totals[retry], keys[retry], seeded=False, **options)
            take = (again[2] < result[2][retry]) & ~(result[2][retry] <= retry_above)
            result = tuple(x.at[retry].set(jnp.where(take.reshape((-1,) + (1,) * (y.ndim - 1)), y, x[retry]))
                           for x, y in zip(result, again))
    w, v, rel, steps, ok = result
    return GaussianFit(w.reshape(batch + (n,)), v.reshape(batch + (n,)), rel.reshape(batch),
                       steps.reshape(batch), ok.reshape(batch))


def radial_grid(medium: Medium, n: int = 256):
    r"""A log-spaced grid for fitting the medium's dipole, from its length scales [mm].

    From :math:`10^{-3}` of the shortest mean free path to where the slowest-decaying
    channel has fallen by :math:`e^{-25}` (:math:`25/\sigma_{tr}`), at most 1000 of the
    longest mean free paths (the reach used when :math:`\sigma_a = 0`).
    """
    mfp = np.asarray(medium.mean_free_path, dtype=float)
    sigma_tr = np.asarray(medium.sigma_tr, dtype=float)
    with np.errstate(divide="ignore"):
        reach = np.where(sigma_tr > 0, 25.0 / sigma_tr, np.inf)
    r_max = float(np.max(np.minimum(reach, 1000 * mfp)))
    return jnp.geomspace(1e-3 * float(np.min(mfp)), r_max, n)


def fit_gaussians_to_medium(medium: Medium, n: int = 4, *, conserve_total: bool = False, **options) -> GaussianFit:
    """Fit ``n`` Gaussians to each channel of the medium's dipole profile on :func:`radial_grid`.

    ``conserve_total=True`` constrains each fit's weights to the dipole's total diffuse
    reflectance; other keyword options go to :func:`fit_gaussians`.
    """
    r = radial_grid(medium)
    profile = dipole.profile(medium, r)
    total = dipole.total_reflectance(medium) if conserve_total else None
    return fit_gaussians(r, profile, n, total=total, **options)


def jensen2001_profiles(n: int = 256):
    """Dipole profiles of all 36 Jensen 2001 channels, each on its own :func:`radial_grid`.

    Returns
    -------
    radii, profiles : Arrays ``(n, 36)`` [mm, 1/mm^2], ready for one batched :func:`fit_gaussians`
    labels : list of str
        ``"Material R"``, ``"Material G"``, ... in the same column order.
    """
    from jsss.materials import jensen2001, jensen2001_names

    radii, profiles, labels = [], [], []
    for name in jensen2001_names():
        medium = jensen2001(name)
        r = radial_grid(medium, n)
        radii.append(jnp.broadcast_to(r[:, None], (n, 3)))
        profiles.append(dipole.profile(medium, r))
        labels += [f"{name} {c}" for c in "RGB"]
    return jnp.concatenate(radii, 1), jnp.concatenate(profiles, 1), labels
