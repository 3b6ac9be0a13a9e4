r"""Radiance toward a camera's exact direction: next-event estimates in a white walk (issue 37).

The transport tables bin each leaving photon's direction in 8 cones of equal projected solid
angle, so "radiance toward the normal" from them is the 0-20.7 degree average. Within half a
transport length of the beam, where a low albedo's light leaves, that average differs from the
radiance along the normal by tens of percent: a photon leaving at 20 degrees from depth
:math:`z` lands :math:`z \tan\theta_i` away from where one leaving along the normal would.

Here every collision of a walk sends a next-event (point-detector) estimate toward each of a
set of view directions (0, 10, ..., 80 degrees outside). For the outside direction at
:math:`\theta_o` the path inside leaves at :math:`\theta_i`, :math:`\sin\theta_i =
\sin\theta_o/\eta`, with a random azimuth :math:`\phi` (the tables are azimuthal averages);
from a collision at depth :math:`z` it runs :math:`d = z/\mu_i` to the surface and meets it
at :math:`\rho' = |(x, y) + d \sin\theta_i (\cos\phi, \sin\phi)|`. The radiance inside,
integrated over a patch :math:`A` of the surface, is a volume integral over the collisions
(:math:`dA\,ds = dV/\mu_i`), so each collision adds

.. math::

    c = w\, p_{HG}(\mathbf{u}\cdot\boldsymbol\omega)\, \frac{e^{-\sigma_t d}}{\mu_i}\,
        \frac{1 - F(\mu_i)}{\eta^2}

to its annulus (``w`` the photon's weight, :math:`\mathbf u` its direction before the
collision; :math:`1 - F` and :math:`1/\eta^2` carry the radiance across the boundary,
:math:`L/n^2` conserved). The walk is white (:math:`\sigma_a = 0`, :math:`\sigma_s' = 1`,
lengths in transport lengths), and each estimate carries its path :math:`L' = L'_v + d` so
that absorption enters exactly, :math:`e^{-a'L'}` per absorption node, as in
:mod:`jsss.transport.tables`.

Only collisions within ``max_path`` of path send estimates, whatever their last leg: the same
split as a capped walk's, which takes its last flight if it began before the cap. The tables
join these to their own paths beyond the early part's cap (4 transport lengths), whose light is diffuse and whose angular dependence the
cones resolve (``scripts/generate_transport_tables.py``, ``add_views``). The first flight is
drawn from the same mixture of faster exponentials as the early walks, with its importance
weight, so that the short paths of a strongly absorbing medium are well sampled. The walk is
NumPy (float64): its cost is the estimates' absorption weights, not the flights.

A point detector on a surface has bounded estimates (:math:`e^{-\sigma_t d}/\mu_i \le
1/\mu_i`, and :math:`\mu_i \ge 0.64` for views to 80 degrees at eta 1.3), so the tally's
variance is finite; it is measured from the spread of independent batches.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse

from .tables import TableGrid

__all__ = ["VIEW_DEGREES", "view_tables"]

VIEW_DEGREES = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0)  # outside, to the normal


def _phase(cos_angle, g):
    """Henyey-Greenstein phase function per steradian."""
    return (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * cos_angle) ** 1.5)


def _leaving_reflectance(cos_inside, eta):
    """Unpolarised Fresnel reflectance from inside a medium of relative index ``eta`` > 1 (NumPy:
    :func:`jsss.fresnel.fresnel_reflectance` is JAX, and compiled anew for every batch's shape)."""
    sin_out2 = eta**2 * (1 - cos_inside**2)
    cos_out = np.sqrt(np.maximum(1 - sin_out2, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):  # 0/0 only at grazing total reflection
        rs = (eta * cos_inside - cos_out) / (eta * cos_inside + cos_out)
        rp = (cos_inside - eta * cos_out) / (cos_inside + eta * cos_out)
    return np.where(sin_out2 >= 1, 1.0, 0.5 * (rs**2 + rp**2))


def _sample_cos(g, u):
    if abs(g) < 1e-6:
        return 2 * u - 1
    frac = (1 - g * g) / (1 - g + 2 * g * u)
    return np.clip((1 + g * g - frac * frac) / (2 * g), -1.0, 1.0)


def _turn(ux, uy, uz, cos_t, phi):
    """Rotate unit directions by polar angle acos(cos_t) and azimuth phi."""
    sin_t = np.sqrt(np.maximum(1 - cos_t**2, 0.0))
    cos_p, sin_p = np.cos(phi), np.sin(phi)
    pole = np.abs(uz) > 0.99999
    denom = np.sqrt(np.maximum(1 - uz**2, 1e-300))
    nx = sin_t * (ux * uz * cos_p - uy * sin_p) / denom + ux * cos_t
    ny = sin_t * (uy * uz * cos_p + ux * sin_p) / denom + uy * cos_t
    nz = -sin_t * cos_p * denom + uz * cos_t
    return (np.where(pole, sin_t * cos_p, nx), np.where(pole, sin_t * sin_p, ny),
            np.where(pole, np.sign(uz) * cos_t, nz))


def _batch(rng, eta, g, inner_cos, carry, *, photons, max_path, rates, grid):
    """One batch's tallies: per view (n_rho, n_a), summed over its photons (not yet divided)."""
    sigma_t = 1.0 / (1.0 - g)
    inner_sin = np.sqrt(1 - inner_cos**2)
    x, y, z = np.zeros(photons), np.zeros(photons), np.zeros(photons)
    ux, uy, uz = np.zeros(photons), np.zeros(photons), np.ones(photons)
    path, weight = np.zeros(photons), np.ones(photons)
    found = [[] for _ in inner_cos]  # per view: (annulus, path, estimate) arrays of each event
    first = True
    while x.size:
        u = 1.0 - rng.random(x.size)  # in (0, 1]
        if first:  # the first flight from the rate mixture, with its weight p / q (it always collides)
            rate = rates[rng.integers(0, rates.size, x.size)]
            step = -np.log(u) / (sigma_t * rate)
            weight = weight * rates.size / np.sum(rates[:, None] * np.exp(-(rates[:, None] - 1) * sigma_t * step),
                                                  axis=0)
            hits = np.zeros(x.size, bool)
            first = False
        else:
            free = -np.log(u) / sigma_t
            to_top = np.where(uz < 0, z / np.where(uz < 0, -uz, 1.0), np.inf)
            hits = free >= to_top
            step = np.where(hits, to_top, free)
        x, y = x + ux * step, y + uy * step
        z = np.where(hits, 0.0, z + uz * step)
        path = path + step
        keep = path < max_path
        reflects = rng.random(x.size) < _leaving_reflectance(np.abs(uz), eta)
        collides = keep & ~hits
        keep &= ~hits | reflects
        uz = np.where(hits, -uz, uz)
        if np.any(collides):
            cx, cy, cz = x[collides], y[collides], z[collides]
            dx, dy, dz = ux[collides], uy[collides], uz[collides]
            cpath, cweight = path[collides], weight[collides]
            for k, (mu, sin) in enumerate(zip(inner_cos, inner_sin)):
                phi = 2 * np.pi * rng.random(cx.size)
                wx, wy = sin * np.cos(phi), sin * np.sin(phi)
                distance = cz / mu
                total = cpath + distance
                estimate = cweight * _phase(dx * wx + dy * wy - dz * mu, g) * np.exp(-sigma_t * distance) * carry[k]
                radius = np.hypot(cx + distance * wx, cy + distance * wy)
                annulus = np.clip(np.searchsorted(grid.rho_edges, radius, side="right") - 1, 0,
                                  grid.rho_edges.size - 2)
                found[k].append((annulus, total, estimate))
            turned = _turn(dx, dy, dz, _sample_cos(g, rng.random(cx.size)), 2 * np.pi * rng.random(cx.size))
            ux, uy, uz = ux.copy(), uy.copy(), uz.copy()
            ux[collides], uy[collides], uz[collides] = turned
        x, y, z, ux, uy, uz, path, weight = (a[keep] for a in (x, y, z, ux, uy, uz, path, weight))
    n_rho = grid.rho_edges.size - 1
    sums = np.zeros((len(inner_cos), n_rho, grid.absorption.size))
    for k, parts in enumerate(found):
        annulus, total, estimate = (np.concatenate(column) for column in zip(*parts))
        for start in range(0, annulus.size, 200_000):  # (chunk, n_a) absorption weights at a time
            rows = slice(start, start + 200_000)
            spread = scipy.sparse.csr_matrix((estimate[rows], (annulus[rows], np.arange(annulus[rows].size))),
                                             shape=(n_rho, annulus[rows].size))
            sums[k] += spread @ np.exp(-np.outer(total[rows], grid.absorption))
    return sums


def view_tables(eta: float, g: float, *, photons: int, max_path: float, seed: int, view_degrees=VIEW_DEGREES,
                first_flight_rates=(1.0,), batches: int = 20, grid: TableGrid | None = None, progress=None) -> dict:
    r"""Radiance toward each view direction from the collisions within ``max_path``, per annulus and absorption.

    Parameters
    ----------
    eta, g : float
        Relative index of the medium and Henyey-Greenstein mean cosine.
    photons : int
        Photons in all, walked in ``batches`` independent batches.
    max_path : float
        Only collisions within ``max_path`` [transport lengths] of path send estimates.
    seed : int
        Seeds ``numpy.random.default_rng``.
    view_degrees : sequence of float
        Directions outside the surface [degrees to the normal], each below 90.
    first_flight_rates : sequence of float
        The first flight's rate mixture (see :func:`jsss.transport.photon_walk._first_flight`).
    progress : callable, optional
        Called with the number of batches done (a script's progress line).

    Returns
    -------
    dict
        ``radiance`` (n_view, n_rho, n_a): per unit entering flux, per unit area [transport
        lengths^-2] and steradian, the radiance leaving each annulus toward each view at each
        absorption node :math:`a'`; ``variance`` the same shape: each cell's variance of the
        mean, from the spread of the batches; ``view_cos`` the views' cosines outside.
    """
    grid = grid or TableGrid()
    view_cos = np.cos(np.radians(np.asarray(view_degrees, float)))
    if not np.all((view_cos > 0) & (view_cos <= 1)):
        raise ValueError(f"view_tables(view_degrees=...) must lie in [0, 90) degrees; got {view_degrees!r}.")
    inner_cos = np.sqrt(1 - (1 - view_cos**2) / eta**2)
    carry = (1 - _leaving_reflectance(inner_cos, eta)) / (eta**2 * inner_cos)
    rates = np.asarray(first_flight_rates, float)
    rng = np.random.default_rng(seed)
    each = int(np.ceil(photons / batches))
    means = []
    for b in range(batches):
        means.append(_batch(rng, eta, g, inner_cos, carry, photons=each, max_path=max_path, rates=rates,
                            grid=grid) / (each * grid.annulus_area[None, :, None]))
        if progress is not None:
            progress(b + 1)
    means = np.asarray(means)
    return {"radiance": means.mean(axis=0), "variance": means.var(axis=0, ddof=1) / batches, "view_cos": view_cos}
