r"""The polynomial-of-Gaussians basis and Kubelka-Munk layers in it (d'Eon et al. 2007 sec. 4).

Profiles written in the basis :math:`\{G(0), G(v), G(2v), \ldots, G(Nv)\}` (``G(0)`` a
:math:`\delta`) convolve like polynomials in :math:`x = G(v)`: :math:`G(iv) * G(jv) =
G((i+j)v)`, so a product of profiles is a product of coefficient vectors and the
Kubelka-Munk series :math:`\sum_m (R_2^+ R_1^-)^m` is a geometric series of polynomials,
stopped once the energy left (the sum of the coefficients of the remaining terms) falls
under a tolerance (d'Eon eq. 13). Coefficients of degree above ``N`` are folded into
degree ``N`` so that no energy is lost by truncation.

Slab profiles enter the basis from the closed-form pole fits
(:mod:`jsss.gaussians.pole_fit`) through :func:`jsss.gaussians.gaussian_sum.reduce_to`, which splits each
Gaussian between its two nearest basis variances keeping its total and second moment.
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .gaussian_sum import GaussianSum, reduce_to
from ..medium import Medium
from ..layers.kubelka_munk import layer_boundaries, relative_to
from ..diffusion.multipole import unscattered_transmittance
from ..numerics import as_float_array, is_concrete
from .pole_fit import empirical_dipole_fit, empirical_multipole_fit

__all__ = [
    "PolyGaussian",
    "geometric_series",
    "layers_as_gaussians",
    "poly_add",
    "poly_multiply",
    "poly_total",
    "to_gaussian_sum",
    "to_poly",
]


class PolyGaussian(eqx.Module):
    r""":math:`\sum_{k=0}^{N} c_k G(k v)`: ``coefficients`` of shape ``(N+1,) + C``, ``base_variance`` v [mm^2]."""

    coefficients: jax.Array
    base_variance: jax.Array

    @property
    def degree(self) -> int:
        return int(self.coefficients.shape[0]) - 1


def to_poly(gs: GaussianSum, base_variance, degree: int) -> PolyGaussian:
    """Project a GaussianSum on the basis of degree ``degree`` (two-nearest split)."""
    v = as_float_array(base_variance)
    grid = v * jnp.arange(degree + 1, dtype=v.dtype)
    return PolyGaussian(reduce_to(gs, grid).weights, v)


def to_gaussian_sum(p: PolyGaussian) -> GaussianSum:
    """The same profile as a GaussianSum (variances ``k v``)."""
    return GaussianSum(p.coefficients, p.base_variance * jnp.arange(p.degree + 1, dtype=p.coefficients.dtype))


def poly_total(p: PolyGaussian):
    """Total diffuse response (sum of coefficients), shape ``C``."""
    return jnp.sum(p.coefficients, axis=0)


def _check_same_basis(a, b):
    if a.degree != b.degree:
        raise ValueError(f"PolyGaussian degrees differ ({a.degree} vs {b.degree}); project both with to_poly.")
    if is_concrete((a.base_variance, b.base_variance)) and float(a.base_variance) != float(b.base_variance):
        raise ValueError(f"PolyGaussian base variances differ ({float(a.base_variance)} vs "
                         f"{float(b.base_variance)}); project both with the same base_variance.")


def poly_add(a: PolyGaussian, b: PolyGaussian) -> PolyGaussian:
    """``a + b`` (same basis)."""
    _check_same_basis(a, b)
    return PolyGaussian(a.coefficients + b.coefficients, a.base_variance)


def poly_multiply(a: PolyGaussian, b: PolyGaussian) -> PolyGaussian:
    """2D convolution ``a * b``: the product polynomial by FFT, degrees above N folded into N."""
    _check_same_basis(a, b)
    n = a.degree + 1
    size = 2 * n - 1
    fa = jnp.fft.rfft(a.coefficients, n=size, axis=0)
    fb = jnp.fft.rfft(b.coefficients, n=size, axis=0)
    full = jnp.fft.irfft(fa * fb, n=size, axis=0)
    folded = full[:n].at[n - 1].add(jnp.sum(full[n:], axis=0))
    return PolyGaussian(folded, a.base_variance)


_poly_multiply_jit = jax.jit(poly_multiply)


def _identity_like(p: PolyGaussian) -> PolyGaussian:
    return PolyGaussian(jnp.zeros_like(p.coefficients).at[0].set(1.0), p.base_variance)


def geometric_series(a: PolyGaussian, *, tol: float = 1e-4, max_terms: int = 2000) -> PolyGaussian:
    r""":math:`\sum_{m=0}^{M} a^m` with :math:`M` the first count whose neglected energy
    :math:`t^{M+1}/(1-t)` is below ``tol`` (d'Eon eq. 13), :math:`t` the largest channel total of ``a``.

    :math:`M` is chosen from concrete totals; inside jit the series runs ``max_terms`` terms.
    The sum is built by doubling, :math:`S_{2n} = S_n (1 + a^n)` and :math:`S_{n+1} = 1 + a S_n`,
    in about :math:`2 \log_2 M` products instead of :math:`M` (the folded product is
    associative: degrees add and cap at N either way), so a nearly non-absorbing stack
    (:math:`M` in the hundreds) costs a few dozen FFT products.
    """
    if is_concrete(a.coefficients):
        t = float(np.max(np.abs(np.asarray(poly_total(a)))))
        if t >= 1:
            raise ValueError(f"geometric_series needs a total below 1 (a reflectance product); got {t}.")
        n_terms = 1 if t == 0 else int(np.clip(np.ceil(np.log(tol * (1 - t)) / np.log(t)), 1, max_terms))
        multiply = _poly_multiply_jit  # eagerly, each product would dispatch op by op
    else:
        n_terms = max_terms
        multiply = poly_multiply
    identity = _identity_like(a)
    # count = n_terms + 1 powers a^0 .. a^n_terms; walk its binary digits from the top
    count = n_terms + 1
    series, power = identity, a  # S_1 = 1, a^1
    digits = bin(count)[3:]
    for i, bit in enumerate(digits):
        series = poly_add(series, multiply(series, power))  # S_2n = S_n + a^n S_n
        if bit == "1":
            series = poly_add(identity, multiply(series, a))  # S_2n+1 = 1 + a S_2n
        if i < len(digits) - 1:  # the last digit's power would never be read
            power = multiply(power, power)  # a^2n
            if bit == "1":
                power = multiply(power, a)  # a^2n+1
    return series


def _combine(top, bottom, tol):
    """Kubelka-Munk combination of (R+, T+, R-, T-) polynomials; the series is shared
    because polynomials commute: sum (R2+ R1-)^m = sum (R1- R2+)^m."""
    R1p, T1p, R1m, T1m = top
    R2p, T2p, R2m, T2m = bottom
    series = geometric_series(poly_multiply(R2p, R1m), tol=tol)
    T1p_s = poly_multiply(T1p, series)
    T2m_s = poly_multiply(T2m, series)
    return (
        poly_add(R1p, poly_multiply(poly_multiply(T1p_s, R2p), T1m)),
        poly_multiply(T1p_s, T2p),
        poly_add(R2m, poly_multiply(poly_multiply(T2m_s, R1m), T2p)),
        poly_multiply(T2m_s, T1m),
    )


def _default_base_variance(media):
    r"""v = :math:`\ell_{min}^2 / 32`, the shortest reduced mean free path of all media squared.

    d'Eon (sec. 5) asks the narrowest Gaussian to be no wider than :math:`\ell_{min}^2`;
    a 32x finer step resolves the profiles' cores while the default degree still reaches
    512 :math:`\ell_{min}^2`. Narrower terms are split between the delta and G(v), wider
    ones folded into G(N v); both keep the total.
    """
    ell = min(float(np.min(np.asarray(m.mean_free_path))) for m in media)
    return ell**2 / 32


def layers_as_gaussians(layers: Sequence, base: Medium | None = None, *, degree: int = 16384,
                        base_variance=None, tol: float = 1e-5, eta_above=1.0, eta_below=1.0):
    r"""The Kubelka-Munk stack of :func:`jsss.layers.stack` computed in the polynomial basis.

    Parameters
    ----------
    layers : sequence of :class:`jsss.layers.Layer`, top first
    base : Medium, optional
        Semi-infinite medium under the layers.
    degree : int, keyword-only
        Highest power N of the basis.
    base_variance : float, optional, keyword-only
        v [mm^2]; default :math:`\ell_{min}^2/32` (``_default_base_variance``).
    tol : float, keyword-only
        Energy tolerance of each geometric series (d'Eon eq. 13).
    eta_above, eta_below : float, keyword-only
        Absolute indices of the surroundings.

    Returns
    -------
    R, T : PolyGaussian
        Reflectance and transmittance for light from above (``T`` includes the
        unscattered :math:`\delta` as its degree-0 coefficient; zero over a base).
    """
    if not layers and base is None:
        raise ValueError("layers_as_gaussians needs at least one layer or a base medium.")
    sides, above_base = layer_boundaries(layers, base, eta_above=eta_above, eta_below=eta_below)
    per_layer = []
    for layer, (above, below) in zip(layers, sides):
        m, d = layer.medium, layer.thickness
        down = empirical_multipole_fit(m, d, eta_top=m.eta / above, eta_bottom=m.eta / below)
        up = empirical_multipole_fit(m, d, eta_top=m.eta / below, eta_bottom=m.eta / above)
        per_layer.append((down, up, unscattered_transmittance(m, d)))
    base_fit = None if base is None else empirical_dipole_fit(relative_to(base, above_base))
    if base_variance is None:
        base_variance = _default_base_variance([layer.medium for layer in layers] + ([base] if base is not None else []))

    def project(gs):
        return to_poly(gs, base_variance, degree)

    def with_delta(p, weight):
        return PolyGaussian(p.coefficients.at[0].add(weight), p.base_variance)

    result = None
    for (R_down, T_down), (R_up, T_up), collimated in per_layer:
        spectra = (project(R_down), with_delta(project(T_down), collimated),
                   project(R_up), with_delta(project(T_up), collimated))
        result = spectra if result is None else _combine(result, spectra, tol)
    if base_fit is not None:
        R_base = project(base_fit)
        zero = PolyGaussian(jnp.zeros_like(R_base.coefficients), R_base.base_variance)
        base_spectra = (R_base, zero, zero, zero)
        result = base_spectra if result is None else _combine(result, base_spectra, tol)
    return result[0], result[1]
