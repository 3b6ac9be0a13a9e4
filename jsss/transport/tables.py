r"""Scaled ("white") Monte Carlo tables: one absorption-free walk per (eta, g), any medium after.

Lengths here are in **transport lengths** :math:`\ell' = 1/\sigma_s'` and absorption enters
as :math:`a' = \sigma_a/\sigma_s'`. A walk with :math:`\sigma_a = 0`, :math:`\sigma_s' = 1`
records for each photon that leaves its exit radius :math:`\rho'`, its total path length
:math:`L'` and the cosine :math:`\mu` of its exit direction outside. Absorption only weights a
path by Beer-Lambert, :math:`e^{-\sigma_a L} = e^{-a' L'}`, so for any medium of the same
(eta, g) the exitance per unit entering flux is exactly

.. math::

    R(r) = \sigma_s'^2\, T\big(\rho' = r\sigma_s',\ a'\big), \qquad
    T(\rho', a') = \frac{1}{N}\sum_{i\ \text{in the annulus of}\ \rho'}
        \frac{e^{-a' L'_i}}{\text{area}},

the Laplace transform in :math:`a'` of the path-length histogram of each annulus. It is
tabulated here at nodes :math:`a'_j` (exactly, photon by photon, no path-length bins) and
per exit-cosine bin, so that :mod:`jsss.transport` interpolates a smooth, completely
monotone function of :math:`\log a'`.

**The heavy tail.** Exit path lengths of a half space have density
:math:`p(L') \approx C L'^{-3/2}` at large :math:`L'`: walks are capped at
:math:`L'_{\max}` and the photons still inside are not dropped but modelled. Beyond a
thousand transport lengths a photon is fully diffused: it leaves at a radius distributed as
a 2D Gaussian of variance :math:`2L'/3` (diffusion coefficient 1/3) and with the exit-cosine
distribution of the longest recorded paths. :math:`C` follows from the fraction still walking
at the cap, :math:`P(L' > L'_{\max}) = 2C/\sqrt{L'_{\max}}`; the tail adds
:math:`C\int_{L'_{\max}}^\infty L^{-3/2} e^{-a'L} G(\rho'; 2L/3)\,dL` to each annulus and
:math:`C\int L^{-3/2}e^{-a'L}dL` to the total. At :math:`a' = 0` the tail carries exactly
the photons still walking at the cap, so a non-absorbing medium returns all the light that
entered; that the tail really is :math:`CL'^{-3/2}` is checked by the tests against walks
with a ten times longer cap.

**The early part.** A low albedo's light is made of the few paths shorter than a few transport
lengths (:math:`e^{-a'L'}` with :math:`a' = 14` for ketchup's green), and a full walk holds too
few of them: with 2 x 10^6 photons the totals at reduced albedo 0.02-0.1 were up to 2 % off
adding-doubling at g = 0, 3.9 % at g = 0.9. Those paths are cheap to walk, so each shipped cell
holds the full walk's paths beyond a cap of 4 transport lengths, and, up to it, a separate
walk's (``model_tail=False``: a short walk tallies only what left before its cap; its first
free paths importance-sampled toward the surface, ``weight``) blended with the full walk's own.
``scripts/generate_transport_tables.py`` (``add_early``) says how they are joined.
"""

from __future__ import annotations

import numpy as np

__all__ = ["TableGrid", "tabulate"]


class TableGrid:
    """Bin edges and absorption nodes shared by every table.

    ``rho_edges`` [transport lengths]: 0, then log-spaced from ``1e-3`` to ``1e3``;
    ``mu_edges``: exit cosines, uniform in :math:`\\mu^2` (equal projected solid angle);
    ``absorption``: the :math:`a'` nodes, 0 then log-spaced from 1e-5 to 1e3 (reduced albedo
    down to 0.001: ketchup's blue is 0.02).
    """

    def __init__(self, *, rho_per_decade=12, mu_bins=8, absorption_per_decade=5):
        self.rho_edges = np.concatenate([[0.0], np.logspace(-3, 3, 6 * rho_per_decade + 1)])
        self.mu_edges = np.sqrt(np.linspace(0.0, 1.0, mu_bins + 1))
        self.absorption = np.concatenate([[0.0], np.logspace(-5, 3, 8 * absorption_per_decade + 1)])

    @property
    def annulus_area(self):
        return np.pi * np.diff(self.rho_edges**2)


def _tail_weights(grid: TableGrid, max_path: float, nodes: int = 400):
    """Per unit C: the capped tail's contribution to each annulus (per area) and to the total,
    at every absorption node. Shapes (n_rho, n_a) and (n_a,)."""
    # Substitute L = max_path / s^2, s in (0, 1]: C L^{-3/2} dL = 2 C s ds / sqrt(max_path)... per unit s.
    s, w = np.polynomial.legendre.leggauss(nodes)
    s, w = 0.5 * (s + 1), 0.5 * w
    length = max_path / s**2
    jacobian = 2.0 / np.sqrt(max_path)  # int_Lmax^inf L^-3/2 f(L) dL = (2/sqrt(Lmax)) int_0^1 f(Lmax/s^2) ds
    decay = np.exp(-np.outer(grid.absorption, length))                      # (n_a, nodes)
    variance = 2.0 * length / 3.0
    outer = np.exp(-np.minimum(grid.rho_edges[:, None] ** 2, 1e300) / (2 * variance[None, :]))  # (n_edges, nodes)
    annulus_mass = (outer[:-1] - outer[1:]) / grid.annulus_area[:, None]    # (n_rho, nodes) per unit area
    per_area = jacobian * np.einsum("kn,jn,n->kj", annulus_mass, decay, w)
    total = jacobian * decay @ w
    return per_area, total


def tabulate(radius, path, exit_cos, left, lost, *, grid: TableGrid, max_path: float, model_tail: bool = True,
             weight=None):
    r"""Tables of one white walk, in transport lengths.

    Parameters
    ----------
    radius, path, exit_cos : (N,) arrays
        Every photon's exit radius :math:`\rho'`, path :math:`L'` and exit cosine outside.
    left, lost : (N,) bool arrays
        Photons that left through the surface; photons still walking at ``max_path``.
    grid : TableGrid
    max_path : float
        The cap :math:`L'_{\max}` of the walk.
    model_tail : bool
        Add the modelled tail of the photons still walking at the cap (the default). ``False``
        for a short walk that tallies only the paths up to its cap, :math:`L' \le L'_{\max}`
        (the tables' early part, joined to a full walk's paths beyond that cap).
    weight : (N,) array, optional
        Each photon's weight where it left (an importance-sampled walk's); 1 by default.

    Returns
    -------
    dict
        ``exitance`` (n_rho, n_a, n_mu): per unit entering flux and unit area, the light
        leaving each annulus into each exit-cosine bin (its sum over the last axis is
        :math:`T(\rho', a')`); ``total`` (n_a,): total diffuse reflectance per unit entering
        flux (exact, not binned in radius); ``tail_constant`` C; ``tail_mass`` the tail's
        total at :math:`a' = 0` (compare ``lost``); ``lost`` the fraction capped;
        ``error_total`` the totals' standard errors; ``second`` (n_rho, n_a, n_mu) each cell's
        second moment per photon times its area, :math:`E[(w e^{-a'L'})^2 1_{cell}]/A` (the
        tail's share left out: it is not a tally), whose identity with the cell at :math:`2a'`
        holds for unit weights only.
    """
    n = radius.size
    photon_weight = np.ones(int(np.sum(left))) if weight is None else np.asarray(weight, float)[left]
    radius, path, exit_cos = radius[left], path[left], exit_cos[left]
    k = np.clip(np.searchsorted(grid.rho_edges, radius, side="right") - 1, 0, grid.rho_edges.size - 2)
    m = np.clip(np.searchsorted(grid.mu_edges, exit_cos, side="right") - 1, 0, grid.mu_edges.size - 2)
    n_rho, n_mu, n_a = grid.rho_edges.size - 1, grid.mu_edges.size - 1, grid.absorption.size
    exitance, second = np.zeros((n_rho, n_a, n_mu)), np.zeros((n_rho, n_a, n_mu))
    total, error_total = np.zeros(n_a), np.zeros(n_a)
    cell = k * n_mu + m
    for j, a in enumerate(grid.absorption):
        tally = photon_weight * np.exp(-a * path)
        exitance[:, j, :] = np.bincount(cell, tally, minlength=n_rho * n_mu).reshape(n_rho, n_mu)
        second[:, j, :] = np.bincount(cell, tally**2, minlength=n_rho * n_mu).reshape(n_rho, n_mu)
        total[j] = tally.sum() / n
        error_total[j] = np.sqrt(max(np.sum(tally**2) / n - total[j] ** 2, 0.0) / n)
    exitance /= n * grid.annulus_area[:, None, None]
    second /= n * grid.annulus_area[:, None, None]
    # The tail beyond the cap: P(L' > Lmax) = 2 C / sqrt(Lmax) is the fraction still walking,
    # so C follows from it and a non-absorbing medium returns exactly what entered. The exit
    # cosines of the tail are those of the recorded paths in [Lmax/4, Lmax].
    if not model_tail:
        return {"exitance": exitance, "total": total, "tail_constant": 0.0, "tail_mass": 0.0,
                "lost": float(np.mean(lost)), "error_total": error_total, "second": second}
    late = path >= max_path / 4
    tail_constant = np.mean(lost) * np.sqrt(max_path) / 2.0
    mu_share = np.bincount(m[late], minlength=n_mu) / max(late.sum(), 1)
    per_area, tail_total = _tail_weights(grid, max_path)
    exitance += tail_constant * per_area[:, :, None] * mu_share[None, None, :]
    total += tail_constant * tail_total
    return {"exitance": exitance, "total": total, "tail_constant": tail_constant,
            "tail_mass": tail_constant * 2 / np.sqrt(max_path), "lost": float(np.mean(lost)),
            "error_total": error_total, "second": second}


def tail_total_closed_form(absorption, max_path):
    r""":math:`\int_{L}^\infty x^{-3/2} e^{-a x} dx = 2e^{-aL}/\sqrt{L} - 2\sqrt{\pi a}\,\mathrm{erfc}\sqrt{aL}`."""
    from scipy import special  # here: importing it with the package was 0.2 s of every render's start

    a = np.asarray(absorption, float)
    return 2 * np.exp(-a * max_path) / np.sqrt(max_path) - 2 * np.sqrt(np.pi * a) * special.erfc(np.sqrt(a * max_path))
