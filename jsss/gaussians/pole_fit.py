r"""Closed-form Gaussian fits of dipoles and multipoles (after d'Eon et al. 2007, Appendix A).

Every dipole and multipole is a signed sum of pole terms
:math:`z\,P(r; \sigma_{tr}, |z|)` with :math:`P = (1 + \sigma_{tr} d) e^{-\sigma_{tr} d}/d^3`,
:math:`d = \sqrt{r^2 + z^2}` (:func:`jsss.diffusion.dipole.pole_profile`). Writing :math:`r = |z|\rho`
shows that the shape of a pole depends on :math:`x = \sigma_{tr}|z|` alone:
:math:`P(r) = |z|^{-3} \tilde P(\rho; x)`. So a fit with variances fixed relative to

.. math:: v_0 = \frac{P_d}{P(0)} = \frac{z^2}{1 + x}, \qquad P_d = \int_0^\infty P\,r\,dr = \frac{e^{-x}}{|z|},

has weights :math:`w_i = C_i(x)\,P_d` with universal curves :math:`C_i`. d'Eon uses the
variances :math:`\{0.2304, 0.7225, 2.6569, 13.6\}\,v_0`; the text's formulas for the
:math:`C_i` are garbled, so we derive them: for each :math:`x`, :math:`C_i(x)` minimise the
d'Eon objective :math:`\int r (\tilde P - \sum_i c_i G(s_i \tilde v_0))^2 d\rho` subject to
:math:`\sum_i c_i = 2\pi e^{-x}` (the pole's total, so fits conserve energy exactly), a
linear least-squares problem solved once per node of a table
(:func:`derive_pole_weights`, ``scripts/derive_pole_table.py``). At run time the curves are
interpolated from that table: no iterations, so the renderer can use it.

For a pole at signed height :math:`z` the fit of :math:`z P` is then
:math:`\sum_i \mathrm{sign}(z)\,C_i(x)\,e^{-x}\,G(s_i v_0, r)`. The fit error of a single pole
(d'Eon's relative RMS power) is 0.5 % near :math:`x = 0.5` and rises to 3.7 % at
:math:`x = 0` and 3.9 % at :math:`x = 50`; sums of poles partly cancel it (see the tests).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..data.pole_weight_table import TABLE_U, TABLE_WEIGHTS
from .gaussian_sum import GaussianSum
from ..medium import Medium
from ..stored_programs import reusable_program
from ..diffusion.multipole import choose_n_dipoles, slab_geometry
from ..numerics import as_float_array, is_concrete
from ..diffusion.dipole import source_depths

__all__ = [
    "VARIANCE_RATIOS",
    "derive_pole_weights",
    "empirical_dipole_fit",
    "empirical_multipole_fit",
    "pole_weight_curves",
]

#: Variances of the four Gaussians per pole, in units of v0 (d'Eon 2007, Appendix A).
VARIANCE_RATIOS = (0.2304, 0.7225, 2.6569, 13.6)


def derive_pole_weights(x: float, *, n_nodes: int = 6000):
    """Derive :math:`C_i(x)` by constrained weighted least squares (NumPy, float64).

    Returns
    -------
    weights : ndarray (4,)
        :math:`C_1..C_4`, summing to :math:`2\\pi`.
    rel_rms : float
        The pole's relative RMS power error with these weights.
    """
    rho = np.geomspace(1e-4, 1e4, n_nodes)
    d = np.sqrt(1 + rho**2)
    pole = (1 + x * d) * np.exp(-x * d) / d**3
    v = np.asarray(VARIANCE_RATIOS) / (1 + x)
    basis = np.exp(-rho[:, None] ** 2 / (2 * v)) / (2 * np.pi * v)
    quad = np.zeros_like(rho)
    h = np.diff(rho)
    quad[:-1] += h / 2
    quad[1:] += h / 2
    quad *= rho
    gram = basis.T @ (quad[:, None] * basis)
    rhs = basis.T @ (quad * pole)
    kkt = np.zeros((5, 5))
    kkt[:4, :4] = gram
    kkt[:4, 4] = kkt[4, :4] = 1.0
    solution = np.linalg.solve(kkt, np.concatenate([rhs, [2 * np.pi * np.exp(-x)]]))
    c = solution[:4]
    residual = pole - basis @ c
    rel_rms = float(np.sqrt(np.sum(quad * residual**2) / np.sum(quad * pole**2)))
    return c * np.exp(x), rel_rms


def pole_weight_curves(x):
    r""":math:`C_i(x)` for :math:`x = \sigma_{tr}|z| \ge 0`, interpolated from the derived table.

    The table is uniform in :math:`u = x / (1 + x)` on [0, 0.995] (x up to 199); beyond it
    the curves are held constant (they have flattened, and the pole's weight carries
    :math:`e^{-x}`). Returns an array of shape ``x.shape + (4,)``.
    """
    x = as_float_array(x)
    u = jnp.clip(x / (1 + x), 0.0, TABLE_U[-1])
    table_u = jnp.asarray(TABLE_U, dtype=x.dtype)
    columns = [jnp.interp(u, table_u, jnp.asarray(TABLE_WEIGHTS[:, i], dtype=x.dtype)) for i in range(4)]
    return jnp.stack(columns, axis=-1)


def _pole_terms(z, sigma_tr):
    """Weights (..., 4) and variances (..., 4) of the four Gaussians fitting z P(r; sigma_tr, |z|)."""
    abs_z = jnp.abs(z)
    x = sigma_tr * abs_z
    curves = pole_weight_curves(x)
    weights = (jnp.sign(z) * jnp.exp(-x))[..., None] * curves
    variances = (abs_z**2 / (1 + x))[..., None] * jnp.asarray(VARIANCE_RATIOS, dtype=curves.dtype)
    return weights, variances


def _block_sum(weights, variances, scale):
    """Stack per-channel terms (P, C, 4) into one GaussianSum with block-diagonal weights.

    Each channel has its own variances; the sum carries all P*C*4 of them, with zero
    weight outside the channel they belong to.
    """
    weights = weights * scale[None, :, None]
    n_poles, n_channels, _ = weights.shape
    eye = jnp.eye(n_channels, dtype=weights.dtype)
    # (P, C, 4) -> terms ordered (channel, pole, gaussian); weights (terms, C)
    w = jnp.transpose(weights, (1, 0, 2)).reshape(n_channels, -1)
    v = jnp.transpose(variances, (1, 0, 2)).reshape(-1)
    block = (w[:, :, None] * eye[:, None, :]).reshape(-1, n_channels)
    return GaussianSum(block, v)


def _as_channels(medium, *arrays):
    shape = jnp.broadcast_shapes(medium.shape, *(jnp.shape(a) for a in arrays))
    return shape, [jnp.broadcast_to(a, shape).reshape(-1) for a in arrays]


@reusable_program()  # traced once across processes where a caller keeps programs (a command's start)
@jax.jit  # one program: op by op it took 1.2 s per call before a render's first pixel
def empirical_dipole_fit(medium: Medium) -> GaussianSum:
    r"""The closed-form 8-Gaussian fit of the dipole profile, per channel.

    Four Gaussians per pole (real and virtual source) with weights from the derived
    :math:`C_i` curves; the total equals :func:`jsss.diffusion.dipole.total_reflectance` exactly.

    Parameters
    ----------
    medium : Medium
        Of shape ``()`` or ``(C,)``.

    Returns
    -------
    GaussianSum
        ``8 C`` terms (8 for a single channel) with weights of shape ``(8 C, C)``
        (``(8,)`` for a scalar medium); each channel's terms are zero in the others.
    """
    z_r, z_v = source_depths(medium)
    scalar = medium.shape == ()
    shape, (z_r, z_v, sigma_tr, albedo) = _as_channels(medium, z_r, z_v, medium.sigma_tr, medium.reduced_albedo)
    z = jnp.stack([z_r, z_v])  # both poles add (the virtual one is a negative source above)
    weights, variances = _pole_terms(z, sigma_tr[None, :])
    gs = _block_sum(weights, variances, albedo / (4 * jnp.pi))
    if scalar:
        return GaussianSum(gs.weights[:, 0], gs.variances)
    return GaussianSum(gs.weights.reshape((-1,) + shape), gs.variances)


def empirical_multipole_fit(medium: Medium, thickness, *, eta_top=None, eta_bottom=None,
                            n_dipoles: int | None = None, tol: float = 1e-6):
    r"""Closed-form Gaussian fits of a slab's :math:`R(r)` and :math:`T(r)` (a sum of poles).

    Uses the same image train as :func:`jsss.diffusion.multipole.slab_profiles` (first-collision
    source), 4 Gaussians per pole: ``8 (2 n + 1)`` Gaussians per channel for each profile.

    Returns
    -------
    R, T : GaussianSum (weights shaped as in :func:`empirical_dipole_fit`)
    """
    if n_dipoles is None:
        n_dipoles = choose_n_dipoles(medium, thickness, tol=tol, eta_top=eta_top, eta_bottom=eta_bottom) \
            if is_concrete((medium, thickness)) else 16
    geo = slab_geometry(medium, thickness, eta_top=eta_top, eta_bottom=eta_bottom)
    scalar = medium.shape == () and jnp.ndim(thickness) == 0
    shape, (d, z0, zt, P, w, sigma_tr, albedo) = _as_channels(
        medium, geo.thickness, geo.z0, geo.zb_top, geo.period, geo.weight, medium.sigma_tr,
        medium.reduced_albedo)
    i = jnp.arange(-int(n_dipoles), int(n_dipoles) + 1, dtype=z0.dtype)[:, None]
    z_real = i * P + z0
    z_virtual = i * P - z0 - 2 * zt
    scale = w * albedo / (4 * jnp.pi)
    wr, vr = _pole_terms(z_real, sigma_tr)
    wv, vv = _pole_terms(z_virtual, sigma_tr)
    R = _block_sum(jnp.concatenate([wr, -wv]), jnp.concatenate([vr, vv]), scale)
    wr, vr = _pole_terms(d - z_real, sigma_tr)
    wv, vv = _pole_terms(d - z_virtual, sigma_tr)
    T = _block_sum(jnp.concatenate([wr, -wv]), jnp.concatenate([vr, vv]), scale)
    if scalar:
        return GaussianSum(R.weights[:, 0], R.variances), GaussianSum(T.weights[:, 0], T.variances)
    return (GaussianSum(R.weights.reshape((-1,) + shape), R.variances),
            GaussianSum(T.weights.reshape((-1,) + shape), T.variances))
