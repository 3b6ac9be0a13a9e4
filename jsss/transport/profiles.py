r"""Profiles exact to radiative transfer, from scaled Monte Carlo tables.

For a semi-infinite homogeneous medium of relative index ``eta`` and Henyey-Greenstein
``g`` under a normally incident pencil beam, the exitance profile per unit *entering* flux
(as :func:`jsss.diffusion.dipole.profile`) is

.. math::

    R(r) = \sigma_s'^2\, T\!\left(r\sigma_s',\ \sigma_a/\sigma_s'\right),

exactly: :math:`T` is the Laplace transform of one absorption-free random walk's exit
path lengths (see :mod:`jsss.transport.tables`; lengths scale with :math:`1/\sigma_s'` and
absorption weights each path by :math:`e^{-\sigma_a L}`). The tables shipped in
``jsss/data/transport_tables.npz`` hold :math:`T` for eta 1.0-1.6 (step 0.1) and
g in {0, 0.5, 0.8, 0.9}; ``eta`` is interpolated (Catmull-Rom), ``g`` must be one of the
tabulated values. Between table nodes :math:`\log T` is interpolated with Catmull-Rom
splines in :math:`\log\rho'` and :math:`\log a'`, so profiles are smooth in ``r``,
``sigma_a``, ``sigma_s_prime`` and ``eta``, and ``jax.grad`` works through them. Their
accuracy is the Monte Carlo noise of the tables (``photons`` in :func:`table_info`, and
``early_photons`` more, first scattered near the surface more often, for the paths up to four
transport lengths that make a low albedo's light) plus the interpolation; ``benchmarks/profiles.py`` measures both against independent walks. The noise
follows from the tables themselves (a cell's second moment is the cell at twice the
absorption): :func:`cell_relative_variance` per cell, :func:`noise_slice` and
:func:`slice_cell_errors` for a fit's slice, :func:`slice_relative_error` per model value
(``fitting.medium`` carries it into the stated errors; ``benchmarks/table_noise.py``).

Valid range: reduced albedo :math:`\alpha' \ge 0.001` (:math:`a' \le 10^3`), radii from
:math:`10^{-3}` to :math:`10^3` transport lengths (constant inside, decaying beyond), any
:math:`\sigma_a \ge 0`. Per unit *incident* flux, multiply by the entry transmittance
:func:`entry_transmittance` (a normally incident beam loses :math:`F(0)`).
"""

from __future__ import annotations

import functools
from importlib import resources

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..fresnel import fresnel_reflectance
from ..medium import Medium
from ..numerics import append_axes, as_float_array, is_concrete

__all__ = ["FixedSlice", "cell_relative_variance", "check_medium", "check_supported", "entry_transmittance",
           "fixed_slice", "noise_slice", "profile", "radiance", "shift_slice", "slice_cell_errors",
           "slice_relative_error", "slice_values", "split_relative_variance", "table_info", "total_reflectance"]

_FLOOR = 1e-30  # added before taking logs: empty table cells (no photon reached them)


def _log_filled(values, axis):
    """``log(values)`` with the empty cells (no photon reached them) filled along ``axis`` (the
    radius): between and before recorded cells linearly in log from their neighbours, so a
    missing photon does not become a hole of depth log(1e-30) for the splines to ring on;
    after the last recorded cell, ``log(_FLOOR)`` (the light there is below what the walk
    resolves)."""
    moved = np.moveaxis(np.asarray(values, float), axis, -1)
    flat = moved.reshape(-1, moved.shape[-1])
    out = np.full(flat.shape, np.log(_FLOOR))
    index = np.arange(flat.shape[-1])
    for row, cells in enumerate(flat):
        recorded = np.flatnonzero(cells > 0)
        if recorded.size:
            upto = index <= recorded[-1]
            out[row, upto] = np.interp(index[upto], recorded, np.log(cells[recorded]))
    return np.moveaxis(out.reshape(moved.shape), -1, axis)


def _centre_values(log_cells, axis, log_step):
    """Log of the value at each annulus's log-centre from the log of its area average.

    Over an annulus of width ``h`` in ln r the area weight r^2 puts the mean of ln r at
    h^2/6 above the log-centre (second moment h^2/12), so for ln R = g(ln r),
    ln(average) = g + g' h^2/6 + (g'' + g'^2) h^2/24 + O(h^4): the average, read as the
    value at the centre, is low by about 0.6 % per unit of -g' at 12 cells a decade (measured
    against walks: a -0.7 % lean before this). Derivatives are central differences over
    recorded neighbours (one-sided at the ends); cells next to unrecorded ones are left as
    they are, and the correction is capped at 10 %. Index 0 of ``axis`` (the inner disc) is
    not an annulus and is left alone.
    """
    moved = np.moveaxis(np.asarray(log_cells, float), axis, -1)
    rings = moved[..., 1:]
    h = np.log(10.0) * log_step
    recorded = rings > np.log(_FLOOR) + 1.0
    slope, curvature = np.zeros_like(rings), np.zeros_like(rings)
    slope[..., 1:-1] = (rings[..., 2:] - rings[..., :-2]) / (2 * h)
    slope[..., 0], slope[..., -1] = (rings[..., 1] - rings[..., 0]) / h, (rings[..., -1] - rings[..., -2]) / h
    curvature[..., 1:-1] = (rings[..., 2:] - 2 * rings[..., 1:-1] + rings[..., :-2]) / h**2
    usable = recorded.copy()
    usable[..., 1:] &= recorded[..., :-1]
    usable[..., :-1] &= recorded[..., 1:]
    shift = np.clip(slope * h**2 / 6 + (curvature + slope**2) * h**2 / 24, -0.1, 0.1)
    corrected = np.where(usable, rings - shift, rings)
    out = np.concatenate([moved[..., :1], corrected], axis=-1)
    return np.moveaxis(out, -1, axis)


def _late_radiance(data):
    """The cones' late part as radiance, (eta, g, rho, a, mu): each shipped cell less its early
    blend ``w new + (1 - w) own`` (the paths whose last collision lies within the early cap),
    per projected solid angle of its bin."""
    weight = data["early_weight"][:, :, None, :, None]
    blend = weight * data["early_exitance"].astype(np.float64) + (1 - weight) * data["own_exitance"].astype(np.float64)
    late = np.maximum(data["exitance"].astype(np.float64) - blend, 0.0)
    return late / (np.pi * np.diff(data["mu_edges"] ** 2))


def _local_slope(log_cones, relative_variance, centres, *, width=2.0, degree=1):
    r"""Relative slope :math:`s = \partial\ln\ell/\partial\mu` of the late light at its outermost
    cone, per cell, with its noise: ``log_cones`` and ``relative_variance`` (..., rho, a, 3),
    the three cones nearest one end of the mu range at ``centres`` (3,) (the outermost first).

    Per cell, a weighted least-squares line of :math:`\ln\ell` in :math:`\mu` through the three
    cones (weights their inverse relative variances :math:`1/v_m`; its slope's variance is
    :math:`1/P`, :math:`P = \sum_m (x_m - \bar x)^2/v_m`); then along the radius a local
    polynomial regression of ``degree`` in the cell index (weights :math:`K_{ij} P_j`, Gaussian
    :math:`K` of ``width`` cells), which follows a slope that changes with radius without
    leaning toward the inner, brighter cells. Its value at cell i is
    :math:`s_i = \sum_j c_{ij}\hat s_j`. Measured at eta 1.0, a' 0.16: widths 1-2 and degrees
    1-2 move the normal's radiance by under 0.2 % at 2-10 transport lengths; width 2, degree 1
    has the least noise.

    Returns ``slope``, ``covariance`` :math:`\mathrm{Cov}(\ln\ell_{\mathrm{outer},i}, s_i)
    = c_{ii}(x_0 - \bar x_i)/P_i` and ``variance`` :math:`\mathrm{Var}(s_i) = \sum_j c_{ij}^2/P_j`
    (cells independent), each (..., rho, a)."""
    weight = 1.0 / np.maximum(relative_variance, 1e-8)                    # (..., rho, a, 3)
    x = centres - centres[0]
    mean_x = np.sum(weight * x, axis=-1) / np.sum(weight, axis=-1)
    spread = np.sum(weight * (x - mean_x[..., None]) ** 2, axis=-1)
    usable = np.all(np.isfinite(log_cones), axis=-1)
    cell_slope = np.sum(weight * (x - mean_x[..., None]) * np.where(usable[..., None], log_cones, 0.0),
                        axis=-1) / spread                                    # (..., rho, a)
    precision = np.where(usable, spread, 0.0)                                # 1 / Var(cell slope)
    index = np.arange(cell_slope.shape[-2], dtype=float)
    offset = index[None, :] - index[:, None]                                 # (i, j): j - i
    # Cut at four widths: far from any usable cell the sums stay 0 rather than underflowing.
    kernel = np.where(np.abs(offset) <= 4 * width, np.exp(-0.5 * (offset / width) ** 2), 0.0)
    powers = np.arange(degree + 1)
    basis = offset ** powers[:, None, None]                                  # (p, i, j)

    def moments(k, values, pairs):
        """sum_j k_ij b_p(i,j) [b_q(i,j)] values_(..., j, a): (..., i, a, p[, q]), as one matrix
        product over j (an einsum of four operands took 0.5 s of each table's first use)."""
        factors = basis[:, None] * basis[None, :] if pairs else basis        # (p, q, i, j) or (p, i, j)
        lead = factors.ndim - 2
        out = np.matmul((k * factors).reshape(-1, index.size), values)       # (..., p q i, a)
        out = out.reshape(values.shape[:-2] + factors.shape[:-1] + values.shape[-1:])
        first = values.ndim - 2
        return np.moveaxis(out, list(range(first, first + lead)), list(range(-lead, 0)))

    normal = moments(kernel, precision, True)                                # (..., i, a, p, q)
    right = moments(kernel, precision * cell_slope, False)                   # (..., i, a, p)
    spread_moments = moments(kernel**2, precision, True)
    # s_i = e0' M^-1 r (M the weighted normal matrix), so its weights on the cells' slopes are
    # c_ij = e0' M^-1 basis_ij K_ij P_j. A row with too few usable cells in reach for the
    # polynomial (ill-conditioned M) keeps only its weighted mean.
    total = normal[..., 0, 0]
    diagonal = np.sqrt(np.maximum(np.diagonal(normal, axis1=-2, axis2=-1), 1e-300))
    with np.errstate(divide="ignore", invalid="ignore"):
        # Its condition number from the eigenvalues (M is symmetric): under half an SVD's time.
        eigen = np.abs(np.linalg.eigvalsh(normal / (diagonal[..., :, None] * diagonal[..., None, :])))
        good = (total > 0) & (eigen.max(-1) < 1e8 * eigen.min(-1))
        row = np.linalg.inv(np.where(good[..., None, None], normal, np.eye(degree + 1)))[..., 0, :]
        mean_row = np.where(total > 0, 1.0 / total, 0.0)[..., None] * (powers == 0)
    row = np.where(good[..., None], row, mean_row)
    slope = np.einsum("...p,...p->...", row, right)
    variance = np.einsum("...p,...pq,...q->...", row, spread_moments, row)
    covariance = np.where(precision > 0, row[..., 0] * (-mean_x), 0.0)
    return slope, covariance, variance


def _late_relative_variance(data, late):
    """Relative variances of the cones' late part (its cells a plain walk's tally), as ``late``
    (eta, g, rho, a, mu)."""
    area = np.pi * np.diff(data["rho_edges"] ** 2)
    moved = np.moveaxis(late, -1, 2)                                         # (eta, g, mu, rho, a)
    return np.moveaxis(cell_relative_variance(moved, data["absorption"], area, data["photons"]), 2, -1)


@functools.lru_cache(maxsize=None)
def _late_parts():
    """The cones' late part of the shipped tables, its relative variances and its mix toward the
    view directions: built once for both the view radiance and its noise table."""
    data = _tables()
    late = _late_radiance(data)
    variance = _late_relative_variance(data, late)
    return late, variance, _late_view_mix(data, late, variance)


def _late_view_mix(data, late, variance=None):
    r"""Per view direction, the cones' late part that makes it (``variance``: the cells' relative
    variances, :func:`_late_relative_variance` by default): a list over views of
    ``(pairs, extra)``, ``pairs`` a list of ``(mu bin, weight)``, each weight a number or an
    (eta, g, rho, a) array, and ``extra`` the variance the weights' own noise adds, relative to
    the outer cone's value squared (0 between the centres).

    Between the cones' centres, linear in mu. Past the outermost centres (0 and 10 degrees lie
    above the top cone's 14.5, 80 below the last one's 75.5) the outermost cone carried on
    with the late light's own slope in mu at that radius (:func:`_local_slope`), weight
    :math:`f = 1 + \Delta\mu\, s`: the light that leaves far from the beam leaves more obliquely
    (at eta 1.0, a' 0.16, an independent walk's radiance falls toward the normal by 0.36-0.50 per
    unit mu at 2.6-5.6 transport lengths, where nearer the beam it rises), so one slope pooled
    over all radii read the normal 1.3-3.5 % high there. At 80 degrees the light falls toward
    grazing. The slope is estimated from the same cells, so to first order
    :math:`\mathrm{Var}(f\ell)/\ell^2 = f^2 v + 2 f\Delta\mu\,\mathrm{Cov}(\ln\ell, s)
    + \Delta\mu^2\,\mathrm{Var}(s)`: ``extra`` is the last two terms (12-15 % of the cone's own
    variance where the late light is)."""
    nodes = data["mu_nodes"]
    variance = _late_relative_variance(data, late) if variance is None else variance
    with np.errstate(divide="ignore"):
        log_late = np.where(late > 0, np.log(np.where(late > 0, late, 1.0)), -np.inf)
    slopes = {}
    mixes = []
    for mu in data["view_cos"]:
        ends = [-1, -2, -3] if mu > nodes[-1] else [0, 1, 2] if mu < nodes[0] else None
        if ends is None:
            mixes.append((_exit_bins(float(mu)), 0.0))
            continue
        outer = ends[0]
        if outer not in slopes:
            slope, covariance, slope_variance = _local_slope(log_late[..., ends], variance[..., ends], nodes[ends])
            # Where the late part vanishes (a' of tens) its slope is noise: diffuse light's
            # relative slope in mu lies within +-3 (Lambertian 0, Fresnel-limited at grazing ~2);
            # a clipped slope no longer moves with the cells.
            kept = np.abs(slope) <= 3.0
            slopes[outer] = (np.clip(slope, -3.0, 3.0), np.where(kept, covariance, 0.0),
                             np.where(kept, slope_variance, 0.0))
        slope, covariance, slope_variance = slopes[outer]
        step = mu - nodes[outer]
        factor = 1 + step * slope
        mixes.append(([(outer % nodes.size, factor)], 2 * factor * step * covariance + step**2 * slope_variance))
    return mixes


def _late_views(mix, cells, variances=None):
    """``cells`` (..., mu) mixed per view as :func:`_late_view_mix` says: (..., view); with
    ``variances`` (the cells' variances, (..., mu)) the variance of each view's mix instead."""
    if variances is None:
        return np.stack([sum(weight * cells[..., m] for m, weight in pairs) for pairs, _ in mix], axis=-1)
    return np.stack([sum(weight**2 * variances[..., m] + extra * cells[..., m] ** 2 for m, weight in pairs)
                     for pairs, extra in mix], axis=-1)


class _Tables(dict):
    """The shipped arrays, and the log-profiles built from them on first use: a scene that only
    asks for totals (the planner's profile choice) does not pay 0.2-0.3 s of cold start to fill
    and centre 73 x 42 x 8 cells per eta and g.

    ``log_view_radiance`` (eta, g, rho, a, view): the radiance toward each exact view direction
    (``view_cos``; issue 37; ``exact=True``, the default). Its early part, the paths whose last
    collision lies within the early cap, is the walk's next-event estimates toward that
    direction (``view_radiance``, :mod:`jsss.transport.view_walk`); its late part is the cones'
    late part, linear in mu between their centres: light that has travelled more than four
    transport lengths is diffuse, and its angular dependence is smooth. ``log_radiance``
    (eta, g, rho, a, mu): the radiance averaged over each exit cone (``exact=False``)."""

    def __missing__(self, key):
        if key not in ("log_exitance", "log_radiance", "log_view_radiance"):
            raise KeyError(key)
        log_step = np.log10(self["rho_edges"][2]) - np.log10(self["rho_edges"][1])
        if key == "log_exitance":                                           # (eta, g, rho, a)
            exitance = self["exitance"].astype(np.float64)
            value = _centre_values(_log_filled(exitance.sum(-1), axis=2), 2, log_step)
        elif key == "log_radiance":                                         # (eta, g, rho, a, mu)
            solid = np.pi * np.diff(self["mu_edges"] ** 2)                  # projected solid angle of each mu bin
            value = _centre_values(_log_filled(self["exitance"].astype(np.float64) / solid, axis=2), 2, log_step)
        else:                                                               # (eta, g, rho, a, view)
            late, _, mix = _late_parts()
            late = _late_views(mix, late)                                   # (eta, g, rho, a, view)
            view = np.moveaxis(self["view_radiance"].astype(np.float64), 2, -1)
            value = _centre_values(_log_filled(late + view, axis=2), 2, log_step)
        self[key] = value
        return value


@functools.lru_cache(maxsize=None)
def _tables():
    with resources.files("jsss.data").joinpath("transport_tables.npz").open("rb") as handle:
        data = _Tables(np.load(handle))
    mu_edges = data["mu_edges"]
    data["log_total"] = np.log(data["total"])                            # (eta, g, a)
    data["mu_nodes"] = np.sqrt(0.5 * (mu_edges[:-1] ** 2 + mu_edges[1:] ** 2))
    return data


def table_info() -> dict:
    """What the shipped tables hold: grids, photons per (eta, g), seed, the walk's cap [transport
    lengths], the fraction capped per table (``lost``) and the totals' standard errors; and the
    early part: ``early_photons`` more photons per (eta, g) for the paths up to
    ``early_max_path`` transport lengths (the light of a low albedo), whose scatterings among
    the first ``early_turns`` events drew ``early_turn_fraction`` (per g) of their directions
    uniformly (importance-weighted); and ``view_photons`` per (eta, g) of next-event estimates
    toward the view directions ``view_cos`` for those paths."""
    data = _tables()
    keys = ("etas", "gs", "rho_edges", "mu_edges", "absorption", "photons", "seed", "max_path", "lost",
            "error_total", "early_photons", "early_max_path", "early_turn_fraction", "early_turns", "view_cos",
            "view_photons")
    return {key: data[key] for key in keys if key in data}


def _g_index(g) -> int:
    gs = _tables()["gs"]
    matches = np.flatnonzero(np.isclose(gs, float(g), atol=1e-9))
    if matches.size == 0:
        raise ValueError(f"transport tables exist for g in {tuple(float(x) for x in gs)}; got g={g!r}. "
                         "Use a tabulated g (the phase function is yours to give; sigma_s_prime carries the rest).")
    return int(matches[0])


def check_supported(eta, g) -> None:
    """Raise ``ValueError`` naming the value when the tables do not cover ``eta`` or ``g``.

    For callers that take a model choice up front (fits, scene files, the command line)."""
    _g_index(g)
    _check_eta(eta)


def check_medium(medium: Medium, *, g: float = 0.0) -> None:
    """Raise ``ValueError`` naming the value when the tables do not cover ``medium`` (its eta,
    sigma_s' > 0, sigma_a / sigma_s' <= 999) or ``g``: the checks the evaluations make on
    concrete input, for callers that then evaluate under ``jit``, where they cannot."""
    _g_index(g)
    _check(medium)


def _check_eta(eta):
    etas = _tables()["etas"]
    eta = np.asarray(eta, float)
    if not np.all((eta >= etas[0] - 1e-9) & (eta <= etas[-1] + 1e-9)):  # also refuses nan
        raise ValueError(f"transport tables cover eta {etas[0]}-{etas[-1]}; got eta={eta.tolist()!r}.")


def _check(medium: Medium):
    if not is_concrete(medium):
        return
    _check_eta(medium.eta)
    if np.any(np.asarray(medium.sigma_s_prime, float) <= 0):
        raise ValueError("transport profiles need sigma_s_prime > 0 [1/mm]; got "
                         f"{np.asarray(medium.sigma_s_prime).tolist()!r}.")
    ratio = np.asarray(medium.sigma_a, float) / np.asarray(medium.sigma_s_prime, float)
    if np.any(ratio > _tables()["absorption"][-1] * (1 + 1e-9)):
        raise ValueError(f"transport tables cover sigma_a / sigma_s_prime <= {_tables()['absorption'][-1]:.3g} "
                         f"(reduced albedo >= 0.001); got {ratio.tolist()!r}.")


def _catmull_rom(position, n, xp=jnp):
    """Indices (..., 4) and weights (..., 4) of a Catmull-Rom spline at fractional node
    ``position`` on ``n`` uniform nodes; ``xp = numpy`` for tables built once (float64 whatever
    JAX's precision).

    Beyond an end the missing neighbour is extrapolated linearly (P_-1 = 2 P_0 - P_1), not
    repeated: a repeated end node halves the end tangent, which put the total reflectance at
    eta 1.55 (between the last two nodes) 0.9 % low at albedo' 0.5 (against the cubic
    through the nodes and against independent walks). With fewer than 3 nodes: linear."""
    base = xp.clip(xp.floor(position), 0, n - 2)
    t = xp.clip(position - base, 0.0, 1.0)  # beyond the end nodes: the end value
    t2, t3 = t * t, t * t * t
    w0, w1 = (-t3 + 2 * t2 - t) / 2, (3 * t3 - 5 * t2 + 2) / 2
    w2, w3 = (-3 * t3 + 4 * t2 + t) / 2, (t3 - t2) / 2
    first, last = base == 0, base == n - 2
    # Fold the phantom node's weight onto the two it is extrapolated from.
    w1, w2, w0 = xp.where(first, w1 + 2 * w0, w1), xp.where(first, w2 - w0, w2), xp.where(first, 0.0, w0)
    w2, w1, w3 = xp.where(last, w2 + 2 * w3, w2), xp.where(last, w1 - w3, w1), xp.where(last, 0.0, w3)
    weights = xp.stack([w0, w1, w2, w3], axis=-1)
    index = xp.clip(base.astype(xp.int32)[..., None] + xp.arange(-1, 3), 0, n - 1)
    return index, weights


@jax.jit  # eager, its 20 small operations were compiled one by one at every start (2 s)
def _interpolate_eta(log_table, eta, etas):
    """``log_table`` (n_eta, *rest) at each channel's eta (Catmull-Rom): shape ``C + rest``."""
    table = jnp.asarray(log_table, jnp.result_type(eta))
    e_index, e_weight = _catmull_rom((eta - etas[0]) / (etas[1] - etas[0]), etas.size)    # C + (4,)
    return jnp.sum(table[e_index] * e_weight.reshape(e_weight.shape + (1,) * (table.ndim - 1)),
                   axis=e_weight.ndim - 1)


def _interpolate_absorption(rows, absorption_ratio, nodes):
    """``rows`` (C + middle + (n_a,)) at each channel's a' = sigma_a / sigma_s': ``C + middle``."""
    middle = rows.ndim - absorption_ratio.ndim - 1

    def spread(x):  # C + (4,) -> C + (1,)*middle + (4,)
        return x.reshape(x.shape[:-1] + (1,) * middle + x.shape[-1:])

    # a': node 0 is a' = 0 and nodes 1.. are uniform in log10 a'; below node 1, linear in a'.
    first, step = np.log10(nodes[1]), np.log10(nodes[2]) - np.log10(nodes[1])
    small = absorption_ratio < nodes[1]
    log_a = jnp.log10(jnp.where(small, nodes[1], absorption_ratio))  # double where: finite grad at a' = 0
    a_index, a_weight = _catmull_rom((log_a - first) / step, nodes.size - 1)
    in_logspace = jnp.sum(jnp.take_along_axis(rows, spread(a_index + 1), axis=-1) * spread(a_weight), axis=-1)
    fraction = (absorption_ratio / nodes[1]).reshape(absorption_ratio.shape + (1,) * middle)
    near_zero = rows[..., 0] + fraction * (rows[..., 1] - rows[..., 0])
    return jnp.where(small.reshape(fraction.shape), near_zero, in_logspace)


def _interpolate_eta_absorption(log_table, eta, absorption_ratio, etas, nodes):
    """``log_table`` (n_eta, *middle, n_a) at each channel's (eta, a'): shape ``C + middle``."""
    return _interpolate_absorption(_interpolate_eta(log_table, eta, etas), absorption_ratio, nodes)


def _radial(log_cells, rho, rho_edges):
    r"""Catmull-Rom in log rho of ``log_cells`` (C + (n + 1,): the inner disc rho' < 1e-3, then
    n annuli whose log-centres are the nodes) at ``rho`` (S + C). Inside the disc (radius
    :math:`\rho_1`) the first annulus's value :math:`A` plus a bump that keeps the disc's light
    (a quarter of ketchup's blue is there; the exact views' disc holds the single scattering
    seen along the beam, up to 10^4 times its rim):

    .. math:: A + \tfrac{45}{32} (D - A) (1 - \rho^8/\rho_1^8)^2,

    whose mean over the disc is the disc's mean :math:`D`, and which joins the annuli with
    value and slope. Its top is flat: the narrower :math:`3 (D - A)(1 - \rho^2/\rho_1^2)^2`
    (three times the mean at the centre) moved the renderer's Gaussian fit of ketchup's
    exitance (flux misplaced beyond a pixel 2.6 % against a budget of 2.5 %), a shape inside a
    thousandth of a transport length that no camera resolves. A disc of constant value made the
    profile jump at its edge, and a fit's loss with it wherever a transform node crossed that
    edge as sigma_s' moved: on the exact views' noise-free ketchup image the loss rose and fell
    tenfold between 1 % and the truth, and Gauss-Newton stopped there. Beyond the last node
    (rho' > 1e3) the end slope continues in log-log, never rising."""
    disc, log_nodes = log_cells[..., 0], log_cells[..., 1:]
    lo = np.log10(rho_edges[1])
    step = np.log10(rho_edges[2]) - lo
    n = log_nodes.shape[-1]
    safe = jnp.where(rho > 0, rho, rho_edges[1] * 1e-3)
    position = (jnp.log10(safe) - lo) / step - 0.5
    index, weight = _catmull_rom(position, n)                                             # S + C + (4,)
    channels = log_nodes.shape[:-1]
    offset = (jnp.arange(int(np.prod(channels)), dtype=jnp.int32) * n).reshape(channels + (1,))
    inside = jnp.sum(log_nodes.reshape(-1)[index + offset] * weight, axis=-1)
    rim = log_nodes[..., 0]
    bump = (1 - jnp.minimum((safe / rho_edges[1]) ** 8, 1.0)) ** 2
    inside_disc = jnp.log(jnp.maximum(jnp.exp(rim) + 45 / 32 * (jnp.exp(disc) - jnp.exp(rim)) * bump, _FLOOR))
    head = jnp.where(rho < rho_edges[1], inside_disc, rim)
    tail = log_nodes[..., -1] + jnp.minimum(log_nodes[..., -1] - log_nodes[..., -2], 0.0) * (position - (n - 1))
    return jnp.where(position < 0, head, jnp.where(position > n - 1, tail, inside))


def _coefficients(medium: Medium):
    sigma_s_prime = medium.sigma_s_prime
    ratio = medium.sigma_a / sigma_s_prime
    return sigma_s_prime, ratio, jnp.broadcast_to(medium.eta, ratio.shape)


def profile(medium: Medium, r, *, g: float = 0.0):
    r"""Exitance profile :math:`R(r)` [1/mm^2] per unit entering flux, exact to transport.

    Parameters
    ----------
    medium : Medium
        Of shape ``C``; ``eta`` in [1.0, 1.6], ``sigma_s_prime > 0``, reduced albedo >= 0.001.
    r : array_like, mm
        Distances from the entry point, any shape ``S``.
    g : float, keyword-only
        Henyey-Greenstein mean cosine: one of the tabulated values (0, 0.5, 0.8, 0.9).

    Returns
    -------
    R : Array of shape ``S + C``, 1/mm^2.
    """
    _check(medium)
    data = _tables()
    sigma_s_prime, ratio, eta = _coefficients(medium)
    log_rows = _interpolate_eta_absorption(data["log_exitance"][:, _g_index(g)], eta, ratio, data["etas"],
                                           data["absorption"])                                  # C + (n_rho,)
    r = append_axes(as_float_array(r), len(medium.shape))
    rho = r * sigma_s_prime
    return sigma_s_prime**2 * jnp.maximum(jnp.exp(_radial(log_rows, rho, data["rho_edges"])) - _FLOOR, 0.0)


def total_reflectance(medium: Medium, *, g: float = 0.0):
    r"""Total diffuse reflectance per unit entering flux, exact to transport (shape ``C``).

    Taken from the walk's paths directly (no radial binning), with the capped tail added."""
    _check(medium)
    data = _tables()
    _, ratio, eta = _coefficients(medium)
    return jnp.exp(_interpolate_eta_absorption(data["log_total"][:, _g_index(g)], eta, ratio, data["etas"],
                                               data["absorption"]))


def _exit_bins(cos_exit: float, exact: bool = False) -> list[tuple[int, float]]:
    """The exit-angle bins (or with ``exact`` the view directions, 0, 10, ..., 80 degrees) toward
    one (concrete) cosine and their weights, linear in mu between their centres. Beyond the
    outermost centres one has all the weight (a camera along the normal: cos 1 lies past the
    cones' last centre); a weight of 0 is not listed, so only what is needed is evaluated."""
    data = _tables()
    nodes = data["view_cos"][::-1] if exact else data["mu_nodes"]          # ascending
    position = float(np.interp(cos_exit, nodes, np.arange(nodes.size)))
    lower = min(int(np.floor(position)), nodes.size - 2)
    t = position - lower
    pairs = [(m, w) for m, w in ((lower, 1 - t), (lower + 1, t)) if w != 0]
    return [(nodes.size - 1 - m, w) for m, w in pairs] if exact else pairs


def radiance(medium: Medium, r, cos_exit, *, g: float = 0.0, exact: bool = True):
    r"""Radiance leaving the surface at ``r`` toward exit cosine ``cos_exit`` [1/(mm^2 sr)],
    per unit entering flux: what a camera at that angle records (before its own units),
    averaged over the azimuth of the direction (the beam is symmetric about the normal).

    By default (``exact=True``) the radiance toward 0, 10, ..., 80 degrees (the early paths'
    next-event estimates toward each; see :class:`_Tables`), linear in :math:`\mu` between them
    and constant past 80 degrees: within 2.7 % of an independent walk near the beam. With
    ``exact=False`` the radiance averaged over the tables' 8 exit cones of equal projected solid
    angle, linear in :math:`\mu` between their centres and constant beyond the outermost ones:
    toward the normal the 0-20.7 degree average, which reads up to +594 % near the beam (what a
    camera with that acceptance cone records; the fits' default before 2026-12-06). ``r`` and
    ``cos_exit`` broadcast together (shape ``S``);
    the result is ``S + C``.
    """
    _check(medium)
    data = _tables()
    sigma_s_prime, ratio, eta = _coefficients(medium)
    key = "log_view_radiance" if exact else "log_radiance"
    table = np.moveaxis(data[key][:, _g_index(g)], -1, 1)                   # (eta, view or mu, rho, a)
    log_rows = _interpolate_eta_absorption(table, eta, ratio, data["etas"], data["absorption"])  # C + (view, rho)
    r, cos_exit = jnp.broadcast_arrays(as_float_array(r), as_float_array(cos_exit))
    r = append_axes(r, len(medium.shape))
    cos_exit = append_axes(cos_exit, len(medium.shape))
    rho = r * sigma_s_prime
    if is_concrete(cos_exit) and np.ptp(np.asarray(cos_exit)) == 0:
        # One exit angle for every radius (a camera, a fit): only its one or two views are
        # evaluated, a fifth of the radial interpolation's cost.
        mixed = sum(weight * jnp.exp(_radial(log_rows[..., m, :], rho, data["rho_edges"]))
                    for m, weight in _exit_bins(float(np.asarray(cos_exit).reshape(-1)[0]), exact))
        return sigma_s_prime**2 * jnp.maximum(mixed - _FLOOR, 0.0)
    nodes = data["view_cos"][::-1] if exact else data["mu_nodes"]             # ascending
    order = range(nodes.size - 1, -1, -1) if exact else range(nodes.size)
    per_view = jnp.stack([jnp.exp(_radial(log_rows[..., m, :], rho, data["rho_edges"])) for m in order],
                         axis=-1)                                              # ascending in mu
    position = jnp.interp(cos_exit, nodes, np.arange(nodes.size, dtype=float))
    lower = jnp.clip(jnp.floor(position).astype(jnp.int32), 0, nodes.size - 2)
    t = position - lower
    pick = lambda i: jnp.take_along_axis(per_view, i[..., None], axis=-1)[..., 0]  # noqa: E731
    value = (1 - t) * pick(lower) + t * pick(lower + 1)
    return sigma_s_prime**2 * jnp.maximum(value - _FLOOR, 0.0)


class FixedSlice(eqx.Module):
    """The tables at a fixed eta per channel and one observable (exitance, or radiance toward
    one exit cosine), for many evaluations at varying sigma_a, sigma_s' (a fit).

    Interpolating the tables in eta touches every cell (all radii, angles and absorptions)
    and dominated an evaluation (10 ms for 3 channels x 2048 radii); a fit holds eta fixed,
    so it is done once here. Build with :func:`fixed_slice`; evaluate with
    :func:`slice_values`. A pytree: pass it into jitted and vmapped code (channels lead).
    """

    log_rows: jax.Array     # C + (n_bins, n_rho + 1, n_a): the exit-angle bins used (1 or 2)
    bin_weights: tuple = eqx.field(static=True)  # weight of each bin (radiance is linear in mu)


def fixed_slice(eta, *, g: float = 0.0, cos_exit: float | None = None, exact: bool = True) -> FixedSlice:
    """The tables at ``eta`` (shape ``C``) for exitance (``cos_exit`` None) or the radiance
    toward ``cos_exit`` (a Python float, as a camera's; ``exact`` as :func:`radiance`): see
    :class:`FixedSlice`."""
    _check_eta(eta)
    data = _tables()
    eta = as_float_array(eta)
    if cos_exit is None:
        return FixedSlice(_interpolate_eta(data["log_exitance"][:, _g_index(g)], eta, data["etas"])[..., None, :, :],
                          (1.0,))
    bins = _exit_bins(float(cos_exit), exact)
    key = "log_view_radiance" if exact else "log_radiance"
    table = np.moveaxis(data[key][:, _g_index(g)], -1, 1)[:, [m for m, _ in bins]]  # (eta, bins, rho, a)
    return FixedSlice(_interpolate_eta(table, eta, data["etas"]), tuple(float(w) for _, w in bins))


def slice_values(fixed: FixedSlice, medium: Medium, r):
    """The slice's observable at ``r`` (shape ``S``) for ``medium`` (its eta is the slice's):
    :func:`profile` or :func:`radiance`, whichever the slice was built for; ``S + C``."""
    data = _tables()
    sigma_s_prime, ratio, _ = _coefficients(medium)
    r = append_axes(as_float_array(r), len(medium.shape))
    rho = r * sigma_s_prime
    mixed = 0.0
    for m, weight in enumerate(fixed.bin_weights):
        log_rows = _interpolate_absorption(fixed.log_rows[..., m, :, :], ratio, data["absorption"])
        mixed = mixed + weight * jnp.exp(_radial(log_rows, rho, data["rho_edges"]))
    return sigma_s_prime**2 * jnp.maximum(mixed - _FLOOR, 0.0)


def entry_transmittance(eta):
    r"""Fraction of a normally incident beam that enters: :math:`1 - F(0) = 1 - ((\eta-1)/(\eta+1))^2`."""
    return 1.0 - fresnel_reflectance(1.0, eta)


# --- The tables' own Monte Carlo noise (issue 37) -----------------------------------------------
#
# A cell of a table is a mean over the walk's N photons of X = e^{-a' L} 1[cell] / A (A the
# cell's area in transport lengths^2, a' = sigma_a / sigma_s'). Its second moment is the same
# tally at twice the absorption, E[X^2] = E[e^{-2a' L} 1[cell]] / A^2 = T(2a') / A, so
#
#     Var(T(a')) = (T(2a') / A - T(a')^2) / N,   relative: (T(2a') / (A T(a')^2) - 1) / N,
#
# from the tables themselves. The shipped tables average four independent runs of equal size,
# which is one run of all their photons. Exit-angle bins divide a cell by its (exact) projected
# solid angle, which leaves the relative variance as it is; the totals are per photon (A = 1).
#
# Each shipped cell blends two walks (scripts/generate_transport_tables.py, ``add_early``): the
# full walks' paths longer than ``early_max_path`` (late), plus w times a separate walk's paths
# up to it (``early_exitance``, of ``early_photons``, first flights importance-sampled) and
# 1 - w times the full walks' own (``own_exitance``), w = ``early_weight`` per absorption node.
# The identity holds for the plain tallies; the weighted walk's second moments are tabulated
# (``early_second``). :func:`split_relative_variance` adds them up.


def _at_double_absorption(values, absorption):
    """``values`` (..., n_a) at the absorption nodes, taken to twice each node's a'.

    At a' = 0 twice is itself. The other nodes are uniform in log a', so 2a' lies log10(2)
    node steps above its node: Catmull-Rom in log a' of log T (the profiles' own
    interpolation); beyond the last node (a' > 500), linear in log-log from the last two."""
    log_v = np.log(np.maximum(np.asarray(values, float), 1e-300))
    out = log_v.copy()
    rows = log_v[..., 1:]
    n = rows.shape[-1]
    step = np.log10(absorption[2]) - np.log10(absorption[1])
    position = np.arange(n) + np.log10(2.0) / step
    index, weight = _catmull_rom(np.asarray(position, float), n, xp=np)
    out[..., 1:] = np.sum(rows[..., index] * weight, axis=-1)
    beyond = position > n - 1
    out[..., 1:][..., beyond] = rows[..., -1:] + (rows[..., -1:] - rows[..., -2:-1]) * (position[beyond] - (n - 1))
    # An empty cell's extrapolation can overflow (a late tally that vanished at high a'): its
    # relative variance is then clipped to 1 by the caller, and it carries no value.
    with np.errstate(over="ignore"):
        return np.exp(out)


def cell_relative_variance(values, absorption, area, photons, second=None):
    r"""Relative variance :math:`\mathrm{Var}(T)/T^2` of each Monte Carlo tally of a table, from the table.

    Parameters
    ----------
    values : array_like (..., n_a)
        Cell means :math:`T(a'_j)` per unit area (or totals per photon, with ``area`` 1) at
        the absorption nodes ``absorption`` (0, then uniform in log a', as
        :class:`jsss.transport.tables.TableGrid`). Any constant factor per cell (an exit-angle
        bin's solid angle) may be left in: it cancels.
    area : array_like, broadcasting against ``values[..., 0]``
        The cell's area [transport lengths^2] by which the tally was divided.
    photons : int
        The walk's photons N.
    second : array_like (..., n_a), optional
        The cells' second moments per photon times their area, :math:`E[X^2] A`, where the walk
        tallied them (an importance-sampled walk's weights break the identity); by default the
        identity's :math:`T(2a')`.

    Returns
    -------
    ndarray (..., n_a)
        :math:`(T(2a')/(A\,T(a')^2) - 1)/N` (see the comment above), :math:`T(2a')` interpolated
        between nodes in log a'. A cell no photon reached, or one whose estimate exceeds it,
        has 1 (the relative variance of a single photon's tally). By the identity, none is below
        its value at a' = 0, the binomial :math:`(1/P - 1)/N` of the cell's share P of the
        photons (Cauchy-Schwarz: :math:`E[w 1]^2 \le E[w^2 1] P`); the interpolation at 2a' can
        undershoot that bound at a' > 100 near the source, where it is used instead. Measured
        ``second`` moments are taken as they are: under importance weights the value at a' = 0
        is not that bound (the early walks' early turns: it overstated their errors at a' 1-2.5
        by up to 17 %). The shipped cells include the modelled tail beyond the walk's cap,
        which is not a tally; read as one, it adds its share of a cell to that cell's variance
        (at a' = 0 a few percent of the cells' value near rho' = 10, less inside).
    """
    values = np.asarray(values, float)
    identity = second is None
    second = _at_double_absorption(values, absorption) if identity else np.asarray(second, float)
    area = np.expand_dims(np.asarray(area, float), -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        relative = (second / (area * values**2) - 1.0) / float(photons)
    if identity:  # a weighted walk's a' = 0 value is no bound (its weights vary there), and it needs none
        relative = np.maximum(relative, relative[..., :1])
    return np.where(values > 0, np.clip(np.nan_to_num(relative, nan=1.0, posinf=1.0), 0.0, 1.0), 1.0)


def split_relative_variance(values, early, absorption, area, photons, early_photons, early_second=None, *,
                            own=None, weight=None):
    r"""Relative variance of cells built from two walks (the shipped tables, see the comment above).

    ``values`` = late + w new + (1 - w) own: ``own`` (the full walk's paths up to the early cap)
    and late = ``values`` - w ``early`` - (1 - w) ``own`` from a plain walk of ``photons``
    photons, ``early`` (new) from one of ``early_photons`` whose second moments are
    ``early_second`` (its first flights are weighted; by default the identity), ``weight`` = w
    per absorption node (broadcast along the last axis). Then

    .. math::

        \mathrm{Var}(T) = \mathrm{Var}_\ell + w^2\,\mathrm{Var}_\mathrm{new}
            + (1 - w)^2\,\mathrm{Var}_\mathrm{own} - 2 (1 - w)\,T_\ell T_\mathrm{own} / N,

    each part's variance from :func:`cell_relative_variance` (the last term: a photon is late or
    early, never both); divided by :math:`T^2`. Without ``own`` (and ``weight``), ``values`` =
    late + ``early``. Arguments as :func:`cell_relative_variance`; ``early=None`` is that
    function."""
    if early is None:
        return cell_relative_variance(values, absorption, area, photons)
    values, early = np.asarray(values, float), np.asarray(early, float)
    w = np.ones(values.shape[-1]) if weight is None else np.asarray(weight, float)
    own = np.zeros_like(values) if own is None else np.asarray(own, float)
    late = np.maximum(values - w * early - (1 - w) * own, 0.0)
    new_variance = cell_relative_variance(early, absorption, area, early_photons, second=early_second) * early**2
    variance = (cell_relative_variance(late, absorption, area, photons) * late**2 + w**2 * new_variance
                + (1 - w) ** 2 * cell_relative_variance(own, absorption, area, photons) * own**2
                - 2 * (1 - w) * late * own / float(photons))
    with np.errstate(divide="ignore", invalid="ignore"):
        relative = np.maximum(variance, 0.0) / values**2
    return np.where(values > 0, np.clip(np.nan_to_num(relative, nan=1.0, posinf=1.0), 0.0, 1.0), 1.0)


def _table_relative_variance(cells, parts, area):
    """:func:`split_relative_variance` of shipped cells (``(eta, g, ..., n_a)``) and their early
    parts (``parts``: new, its second moments, own; ``None`` for tables without one)."""
    data = _tables()
    if parts is None:
        return cell_relative_variance(cells, data["absorption"], area, data["photons"])
    early, second, own = parts
    weight = data["early_weight"].reshape(data["early_weight"].shape[:2] + (1,) * (cells.ndim - 3) + (-1,))
    return split_relative_variance(cells, early, data["absorption"], area, data["photons"], data["early_photons"],
                                   second, own=own, weight=weight)


@functools.lru_cache(maxsize=None)
def _noise_tables():
    """Relative variances of the shipped cells: ``radiance`` (eta, g, mu, rho, a) per exit-angle
    bin, ``exitance`` (eta, g, 1, rho, a) of the cells summed over exit angles."""
    data = _tables()
    cells = data["exitance"].astype(np.float64)                          # (eta, g, rho, a, mu)
    area = np.pi * np.diff(data["rho_edges"] ** 2)
    parts = [data[key].astype(np.float64) for key in ("early_exitance", "early_second", "own_exitance")]
    # A photon leaves into one exit-angle bin: a summed cell's second moment is its bins' sum.
    per_bin = _table_relative_variance(np.moveaxis(cells, -1, 2), [np.moveaxis(p, -1, 2) for p in parts], area)
    summed = _table_relative_variance(cells.sum(-1)[:, :, None], [p.sum(-1)[:, :, None] for p in parts], area)
    return {"radiance": per_bin, "exitance": summed}


@functools.lru_cache(maxsize=None)
def _view_noise_table():
    r"""Relative variances (eta, g, view, rho, a) of the radiance toward each exact view direction
    (``exact=True``, the default; built on first use).

    A view's cell is the cones' late part, mixed with weights :math:`W_{km}`, plus the view
    walk's early part, two independent walks: :math:`\mathrm{Var} = \sum_m W_{km}^2
    \mathrm{Var}(\ell_m) + \mathrm{Var}_\mathrm{view}`, the late part's from the identity
    (a plain walk's paths), the view walk's from the spread of its batches. Past the outermost
    cones the weight is itself estimated from the cells (:func:`_late_view_mix`): its noise
    adds to the variance as a cell's own (its correlation across neighbouring radii, which the
    slope's smoothing makes, is left out)."""
    data = _tables()
    late, relative_variance, mix = _late_parts()                         # (eta, g, rho, a, mu)
    late_variance = relative_variance * late**2
    value = np.moveaxis(_late_views(mix, late), -1, 2) + data["view_radiance"].astype(np.float64)
    variance = np.moveaxis(_late_views(mix, late, late_variance), -1, 2) + data["view_variance"].astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        relative = np.clip(np.nan_to_num(variance / value**2, nan=1.0, posinf=1.0), 0.0, 1.0)
    # A cell without light, or whose variance underflowed float32 (a' of hundreds, 1e-45): no
    # information, a single photon's relative variance.
    return np.where((value > 0) & (variance > 0), relative, 1.0)


def noise_slice(eta, *, g: float = 0.0, cos_exit: float | None = None, exact: bool = True) -> FixedSlice:
    r"""The tables' relative variances, as :func:`fixed_slice` holds their values: for the same
    ``eta`` (shape ``C``), ``g`` and ``cos_exit``; ``log_rows`` holds log relative variances.

    Across eta the slice is :math:`\log T = \sum_e w_e \log T_e` over independent tables, so its
    relative variance is :math:`\sum_e w_e^2\,\mathrm{Var}_e/T_e^2` (the Catmull-Rom weights
    :math:`w_e`, squared). Evaluate with :func:`slice_cell_errors`."""
    _check_eta(eta)
    data = _tables()
    eta = np.asarray(eta, float)
    etas = data["etas"]
    index, weight = _catmull_rom(np.asarray((eta - etas[0]) / (etas[1] - etas[0]), float), etas.size, xp=np)   # C + (4,)
    if cos_exit is None:
        table, bins = _noise_tables()["exitance"][:, _g_index(g)], [0]
    else:
        table = (_view_noise_table() if exact else _noise_tables()["radiance"])[:, _g_index(g)]
        bins = [m for m, _ in _exit_bins(float(cos_exit), exact)]
    mixed = np.sum(table[:, bins][index] * (weight**2).reshape(weight.shape + (1, 1, 1)), axis=eta.ndim)
    return FixedSlice(jnp.asarray(np.log(np.maximum(mixed, 1e-300)), as_float_array(eta).dtype),
                      fixed_slice(eta, g=g, cos_exit=cos_exit, exact=exact).bin_weights)


def slice_cell_errors(noise: FixedSlice, medium: Medium):
    """Relative standard error of each cell of a :class:`FixedSlice` at ``medium``'s a'
    (``C + (n_bins, n_rho + 1)``), from :func:`noise_slice`; interpolated in log a' as the
    values are. A cell's tallies at neighbouring absorption nodes come from the same photons
    and are taken as fully correlated (between two nodes a factor 10^0.2 apart their
    correlation is above 0.97 where the cell has many photons), so the interpolated value has
    the relative error of the cell at that a'."""
    _, ratio, _ = _coefficients(medium)
    return jnp.sqrt(jnp.exp(_interpolate_absorption(noise.log_rows, ratio, _tables()["absorption"])))


def shift_slice(fixed: FixedSlice, delta) -> FixedSlice:
    """``fixed`` with the log value of every cell moved by ``delta`` (``C + (n_bins, n_rho + 1)``),
    at every absorption node alike: one cell's Monte Carlo error, for the fit's response to it."""
    return FixedSlice(fixed.log_rows + jnp.asarray(delta)[..., None], fixed.bin_weights)


@jax.jit  # eager, the forward derivative's operations were dispatched one by one (10 s)
def slice_relative_error(fixed: FixedSlice, noise: FixedSlice, medium: Medium, r):
    r"""Relative standard error of :func:`slice_values` at ``r`` (shape ``S``; result ``S + C``)
    from the tables' own Monte Carlo noise.

    The value at ``r`` is a weighted sum over the exit-angle bins of exponentials of a
    Catmull-Rom interpolation of log cells in log rho, so to first order
    :math:`\delta\ln V(r) = \sum_c \partial\ln V/\partial\ln T_c\ \delta\ln T_c` with cells
    independent (separate tallies of the walk; neighbouring radii share cells and are
    correlated through them). The profile's centre correction mixes neighbours' noise with
    weights below 2 % and is left out.
    """
    cell_errors = slice_cell_errors(noise, medium)                                     # C + (bins, rho)
    channels = medium.shape

    def one(log_rows, sigma_a, sigma_s_prime, eta, errors):
        single, one_medium = FixedSlice(log_rows, fixed.bin_weights), Medium(sigma_a, sigma_s_prime, eta)
        log_value = lambda delta: jnp.log(slice_values(shift_slice(single, delta), one_medium, r))  # noqa: E731
        jac = jax.jacfwd(log_value)(jnp.zeros_like(errors))                            # S + (bins, rho)
        return jnp.sqrt(jnp.sum((jac * errors) ** 2, axis=(-2, -1)))

    sigma_a, sigma_s_prime, eta = (jnp.broadcast_to(x, channels).reshape(-1)
                                   for x in (medium.sigma_a, medium.sigma_s_prime, medium.eta))
    rows = fixed.log_rows.reshape((-1,) + fixed.log_rows.shape[len(channels):])
    errors = cell_errors.reshape((-1,) + cell_errors.shape[len(channels):])
    out = jax.vmap(one, out_axes=-1)(rows, sigma_a, sigma_s_prime, eta, errors)
    return out.reshape(out.shape[:-1] + channels)
